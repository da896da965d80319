"""Chat client against the real loopback test server: payload, retries, typed failures, images."""

from __future__ import annotations

import base64
import json
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from drivehierarchy import ConfigError
from drivehierarchy.benchmark.openloop.client import (
    ChatClient,
    ConnectionFailure,
    DecodingConfig,
    HttpStatusError,
    ImageError,
    MalformedResponse,
    RequestTimeout,
    image_data_url,
)
from drivehierarchy.benchmark.openloop.synthetic import synthetic_image_bytes
from drivehierarchy.testing.openai_server import Fault, ScriptedOpenAIServer

MSGS = [{"role": "system", "content": "sys"}, {"role": "user", "content": [{"type": "text", "text": "hi"}]}]


def _client(url: str, **kw) -> ChatClient:
    return ChatClient(url, "m", backoff_s=0.001, max_backoff_s=0.01, **kw)


def test_decoding_payload_is_the_protocol() -> None:
    c = ChatClient("http://127.0.0.1:1/v1", "model-x")
    assert c.payload(MSGS) == {
        "model": "model-x",
        "messages": MSGS,
        "temperature": 0.0,
        "top_p": 1.0,
        "max_tokens": 256,
        "repetition_penalty": 1.0,
        "presence_penalty": 0.0,
        "seed": 0,
    }
    assert DecodingConfig(max_tokens=128).payload()["max_tokens"] == 128


def test_request_reaches_server_with_body_and_key() -> None:
    seen = []
    server = ScriptedOpenAIServer(lambda req: (seen.append(req), "  yes \n")[1], api_key="sekret")
    with server as url:
        out = _client(url, api_key="sekret").complete(MSGS)
        with pytest.raises(HttpStatusError) as err:
            _client(url, api_key="wrong").complete(MSGS)
    assert out.text == "yes" and out.attempts == 1 and out.usage["total_tokens"] >= 1
    assert err.value.status == 401 and err.value.attempts == 1  # 4xx is not retried
    (req,) = seen
    assert req.system == "sys" and req.user_texts == ("hi",)
    assert req.body["temperature"] == 0.0 and req.body["seed"] == 0 and req.body["repetition_penalty"] == 1.0


def test_500_and_429_are_retried() -> None:
    server = ScriptedOpenAIServer(lambda req: "ok", fail_first_attempts=3)
    with server as url:
        out = _client(url).complete(MSGS)
    assert out.text == "ok" and out.attempts == 4
    assert server.stats.faults == {"http_500": 3}
    calls = iter([Fault.http(429), Fault.http(503), "fine"])
    with ScriptedOpenAIServer(lambda req: next(calls)) as url:
        assert _client(url).complete(MSGS).attempts == 3


def test_server_attempt_memory_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    # A soak sends millions of distinct requests: the retry memory keeps only the newest bodies.
    from drivehierarchy.testing import openai_server

    monkeypatch.setattr(openai_server, "ATTEMPTS_KEPT", 8)
    server = ScriptedOpenAIServer(lambda req: f"attempt {req.attempt}")
    with server as url:
        client = _client(url)
        for i in range(20):
            msgs = [MSGS[0], {"role": "user", "content": [{"type": "text", "text": f"q{i}"}]}]
            assert client.complete(msgs).text == "attempt 1"
        assert len(server._attempts) == 8
        recent = [MSGS[0], {"role": "user", "content": [{"type": "text", "text": "q19"}]}]
        assert client.complete(recent).text == "attempt 2"  # a repeat of a recent body still counts
        oldest = [MSGS[0], {"role": "user", "content": [{"type": "text", "text": "q0"}]}]
        assert client.complete(oldest).text == "attempt 1"  # evicted: counted afresh


def test_retries_exhausted_gives_typed_failure() -> None:
    with ScriptedOpenAIServer(lambda req: Fault.http(500)) as url, pytest.raises(HttpStatusError) as err:
        _client(url, max_retries=2).complete(MSGS)
    assert err.value.kind == "http_error" and err.value.status == 500 and err.value.attempts == 3


@pytest.mark.parametrize("fault", [Fault.malformed_json(), Fault.empty_choices(), Fault.no_content()])
def test_malformed_replies_are_failures(fault: Fault) -> None:
    with ScriptedOpenAIServer(lambda req: fault) as url, pytest.raises(MalformedResponse) as err:
        _client(url).complete(MSGS)
    assert err.value.kind == "malformed_response"


def test_timeout_and_dropped_connection() -> None:
    slow = ScriptedOpenAIServer(lambda req: "late", latency_s=0.5)
    with slow as url, pytest.raises(RequestTimeout) as err:
        _client(url, timeout_s=0.1, max_retries=1).complete(MSGS)
    assert err.value.kind == "timeout" and err.value.attempts == 2
    with ScriptedOpenAIServer(lambda req: Fault.disconnect()) as url, pytest.raises(ConnectionFailure):
        _client(url, max_retries=1).complete(MSGS)
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(ConnectionFailure):
        _client(f"http://127.0.0.1:{port}/v1", max_retries=0).complete(MSGS)


def test_bad_base_url() -> None:
    with pytest.raises(ConfigError, match="base-url"):
        ChatClient("localhost:8000", "m")


def test_image_data_urls_take_mime_from_content(tmp_path: Path) -> None:
    jpeg = synthetic_image_bytes("k", "JPEG")
    png = synthetic_image_bytes("k", "PNG")
    (tmp_path / "really_jpeg.png").write_bytes(jpeg)
    (tmp_path / "a.png").write_bytes(png)
    url = image_data_url(str(tmp_path / "really_jpeg.png"))
    assert url.startswith("data:image/jpeg;base64,")
    assert base64.b64decode(url.split(",", 1)[1]) == jpeg
    assert image_data_url(str(tmp_path / "a.png")).startswith("data:image/png;base64,")
    from PIL import Image

    Image.new("RGB", (4, 4)).save(tmp_path / "b.bmp")
    assert image_data_url(str(tmp_path / "b.bmp")).startswith("data:image/png;base64,")  # re-encoded
    with pytest.raises(ImageError) as err:
        image_data_url(str(tmp_path / "absent.jpg"))
    assert err.value.kind == "missing_image"
    (tmp_path / "broken.jpg").write_bytes(b"\xff\xd8\xff garbage")
    with pytest.raises(ImageError) as err:
        image_data_url(str(tmp_path / "broken.jpg"))
    assert err.value.kind == "unreadable_image"
    (tmp_path / "text.jpg").write_text("hello")
    with pytest.raises(ImageError) as err:
        image_data_url(str(tmp_path / "text.jpg"))
    assert err.value.kind == "unreadable_image"


def test_server_sees_images_and_counts_in_flight(tmp_path: Path) -> None:
    import threading

    (tmp_path / "i.png").write_bytes(synthetic_image_bytes("x", "PNG"))
    url_img = image_data_url(str(tmp_path / "i.png"))
    seen = []
    server = ScriptedOpenAIServer(lambda req: (seen.append(req), "ok")[1], latency_s=0.2)
    msgs = [
        {
            "role": "user",
            "content": [{"type": "image_url", "image_url": {"url": url_img}}, {"type": "text", "text": "q"}],
        }
    ]
    with server as url:
        client = _client(url)
        threads = [threading.Thread(target=client.complete, args=(msgs,)) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        with urllib.request.urlopen(url + "/models") as resp:
            models = json.loads(resp.read())
    assert server.stats.chat_requests == 8 and server.stats.max_in_flight == 8
    assert models["data"][0]["id"] == "test-model"
    req = seen[0]
    assert req.images[0].mime == "image/png" and req.images[0].data == (tmp_path / "i.png").read_bytes()
    assert [k for k, _ in req.parts] == ["image", "text"] and req.last_text == "q"


def test_server_runs_as_a_module() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "drivehierarchy.testing.openai_server", "--port", str(port), "--answer", "no"],
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                out = ChatClient(f"http://127.0.0.1:{port}/v1", "m", max_retries=0).complete(MSGS)
                break
            except ConnectionFailure:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        assert out.text == "no"
    finally:
        proc.kill()
        proc.wait()
