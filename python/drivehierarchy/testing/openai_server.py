"""A scripted OpenAI-compatible HTTP server on loopback, for tests and benchmarks.

Speaks `POST /v1/chat/completions` and `GET /v1/models`. Answers come from a policy callable
that sees the parsed request (system text, user text parts, decoded images); it returns the reply
text or a `Fault` (HTTP error, malformed JSON, empty choices, dropped connection). Random fault
rates and a per-request latency can be layered on top. Counters record the total requests and the
most requests seen in flight at once.

    with ScriptedOpenAIServer(lambda req: "yes", latency_s=0.02) as base_url:
        ...  # base_url == "http://127.0.0.1:<port>/v1"

`route_driver` is a scripted closed-loop driver for R4: it reads the speed and the local route
points from the protocol prompt (docs/protocol.md#r4-prompt) and answers `steer: ..\ntarget_speed_mps: ..`
by pure pursuit, so `r4 evaluate --agent vlm` can drive real episodes against this server.
`malformed_reply_rate` answers a well-formed completion whose text has no action in it.

Command line: `python -m drivehierarchy.testing.openai_server --port 8000 --answer yes`
(`--driver` for the R4 driver).
"""

from __future__ import annotations

import argparse
import base64
import binascii
import hashlib
import json
import math
import random
import re
import sys
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any


@dataclass(frozen=True)
class Fault:
    """A scripted failure. kinds: `http` (with status; a 429 carries `Retry-After: retry_after_s`),
    `malformed_json`, `empty_choices`, `no_content` (a choice without a message), `disconnect`
    (close the socket, no reply), `truncated` (headers promise the whole body, half is sent, then
    the socket closes)."""

    kind: str
    status: int = 500
    retry_after_s: float = 0.0
    message: str = "injected fault"  # the error body's message (http)

    @classmethod
    def http(cls, status: int = 500, retry_after_s: float = 0.0, message: str = "injected fault") -> Fault:
        return cls("http", status, retry_after_s, message)

    @classmethod
    def malformed_json(cls) -> Fault:
        return cls("malformed_json")

    @classmethod
    def empty_choices(cls) -> Fault:
        return cls("empty_choices")

    @classmethod
    def no_content(cls) -> Fault:
        return cls("no_content")

    @classmethod
    def disconnect(cls) -> Fault:
        return cls("disconnect")

    @classmethod
    def truncated(cls) -> Fault:
        return cls("truncated")


@dataclass(frozen=True)
class ImagePart:
    url: str
    mime: str | None  # from a data URL, else None
    data: bytes | None  # decoded bytes of a data URL, else None

    @property
    def sha256(self) -> str | None:
        return hashlib.sha256(self.data).hexdigest() if self.data is not None else None


@dataclass(frozen=True)
class ChatRequest:
    """What a policy sees of one chat-completions request."""

    body: dict[str, Any]
    model: str
    system: str  # all system message text, joined by "\n"
    user_texts: tuple[str, ...]  # text parts of user messages, in order
    images: tuple[ImagePart, ...]  # image parts of user messages, in order
    parts: tuple[tuple[str, Any], ...]  # user content in order: ("text", str) | ("image", ImagePart)
    attempt: int  # 1 for the first time this exact body is seen, 2 for its first retry, ...

    @property
    def user_text(self) -> str:
        return "\n".join(self.user_texts)

    @property
    def last_text(self) -> str:
        return self.user_texts[-1] if self.user_texts else ""


Policy = Callable[[ChatRequest], "str | Fault"]

_ROUTE_RE = re.compile(r"\(forward_m, right_m\): \[([^\]]*)\]")
_POINT_RE = re.compile(r"\((-?[\d.]+), (-?[\d.]+)\)")
_SPEED_RE = re.compile(r"driving at the speed of (-?[\d.]+) m/s")
ATTEMPTS_KEPT = 4096
MALFORMED_REPLY = "I would keep an eye on the road and drive carefully."


def route_points(text: str) -> list[tuple[float, float]]:
    """The (forward_m, right_m) route points of a decision prompt (docs/protocol.md#r4-prompt); []
    when there are none."""
    m = _ROUTE_RE.search(text)
    if m is None:
        return []
    return [(float(f), float(r)) for f, r in _POINT_RE.findall(m.group(1))]


def route_driver(req: ChatRequest) -> str:
    """Pure pursuit on the prompt's route points (8 m look-ahead); slower in curves, stops at
    the end of the route. Deterministic: the same prompt gives the same reply."""
    text = req.last_text
    pts = route_points(text)
    if not pts:
        return "steer: 0.0\ntarget_speed_mps: 0.0"
    ahead = [p for p in pts if p[0] > 1.0] or pts
    goal = next((p for p in ahead if math.hypot(*p) >= 8.0), ahead[-1])
    dist = max(math.hypot(*goal), 1.0)
    # Pure pursuit: curvature 2·right/d², steering angle atan(wheelbase·κ), normalised by 35°.
    angle = math.atan(2.9 * 2.0 * goal[1] / (dist * dist))
    steer = max(-1.0, min(1.0, angle / math.radians(35.0)))
    remaining = math.hypot(*pts[-1])
    target = 4.0 if abs(steer) > 0.25 else 8.0
    if remaining < 6.0:
        target = min(target, 3.0)
    return f"steer: {steer:.3f}\ntarget_speed_mps: {target:.1f}"


def _image_part(url: str) -> ImagePart:
    if url.startswith("data:") and "," in url:
        header, payload = url[5:].split(",", 1)
        mime = header.split(";")[0] or None
        try:
            data = (
                base64.b64decode(payload, validate=True) if header.endswith(";base64") else payload.encode()
            )
        except (binascii.Error, ValueError):
            data = None
        return ImagePart(url, mime, data)
    return ImagePart(url, None, None)


def parse_chat_request(body: dict[str, Any], attempt: int = 1) -> ChatRequest:
    system: list[str] = []
    texts: list[str] = []
    images: list[ImagePart] = []
    parts: list[tuple[str, Any]] = []
    for msg in body.get("messages") or []:
        if not isinstance(msg, dict):
            continue
        content = msg.get("content")
        items = [{"type": "text", "text": content}] if isinstance(content, str) else content or []
        for item in items:
            if not isinstance(item, dict):
                continue
            if item.get("type") == "text":
                text = str(item.get("text", ""))
                if msg.get("role") == "system":
                    system.append(text)
                elif msg.get("role") == "user":
                    texts.append(text)
                    parts.append(("text", text))
            elif item.get("type") == "image_url" and msg.get("role") == "user":
                url = item.get("image_url")
                url = url.get("url", "") if isinstance(url, dict) else str(url or "")
                img = _image_part(url)
                images.append(img)
                parts.append(("image", img))
    return ChatRequest(
        body=body,
        model=str(body.get("model", "")),
        system="\n".join(system),
        user_texts=tuple(texts),
        images=tuple(images),
        parts=tuple(parts),
        attempt=attempt,
    )


@dataclass
class ServerStats:
    total_requests: int = 0  # every HTTP request
    chat_requests: int = 0
    in_flight: int = 0
    max_in_flight: int = 0
    faults: dict[str, int] = field(default_factory=dict)
    answered: int = 0


class ScriptedOpenAIServer:
    """Threaded loopback server; use as a context manager (yields the base URL) or start()/stop()."""

    def __init__(
        self,
        policy: Policy | None = None,
        *,
        latency_s: float | Callable[[ChatRequest], float] = 0.0,
        error_rate: float = 0.0,
        rate_limit_rate: float = 0.0,
        malformed_rate: float = 0.0,
        empty_choices_rate: float = 0.0,
        malformed_reply_rate: float = 0.0,
        fail_first_attempts: int = 0,
        seed: int = 0,
        models: tuple[str, ...] = ("test-model",),
        api_key: str | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
    ):
        self.policy: Policy = policy or (lambda req: "ok")
        self.latency_s = latency_s
        self.error_rate = error_rate
        self.rate_limit_rate = rate_limit_rate
        self.malformed_rate = malformed_rate
        self.empty_choices_rate = empty_choices_rate
        self.malformed_reply_rate = malformed_reply_rate
        self.fail_first_attempts = fail_first_attempts
        self.models = models
        self.api_key = api_key
        self.stats = ServerStats()
        self.requests_log: list[ChatRequest] = []
        self.keep_log = False
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        # Attempts per identical body, for retries; bounded (oldest first out) so a long soak
        # does not grow it without end. Retries come within seconds, long before eviction.
        self._attempts: OrderedDict[str, int] = OrderedDict()
        self._httpd = _Server((host, port), _make_handler(self))
        self._thread: threading.Thread | None = None

    @property
    def port(self) -> int:
        return int(self._httpd.server_address[1])

    @property
    def base_url(self) -> str:
        host = self._httpd.server_address[0]
        host = host.decode() if isinstance(host, bytes) else host
        return f"http://{host}:{self.port}/v1"

    def start(self) -> str:
        if self._thread is None:
            self._thread = threading.Thread(
                target=self._httpd.serve_forever, name="openai-server", daemon=True
            )
            self._thread.start()
        return self.base_url

    def stop(self) -> None:
        if self._thread is not None:
            self._httpd.shutdown()
            self._thread.join()
            self._thread = None
        self._httpd.server_close()

    def __enter__(self) -> str:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # -- request handling (called from handler threads) -----------------------------------------
    def _enter(self) -> None:
        with self._lock:
            self.stats.total_requests += 1
            self.stats.in_flight += 1
            self.stats.max_in_flight = max(self.stats.max_in_flight, self.stats.in_flight)

    def _leave(self) -> None:
        with self._lock:
            self.stats.in_flight -= 1

    def _count_fault(self, kind: str) -> None:
        with self._lock:
            self.stats.faults[kind] = self.stats.faults.get(kind, 0) + 1

    def _decide(self, raw: bytes, body: dict[str, Any]) -> tuple[ChatRequest, str | Fault]:
        key = hashlib.sha256(raw).hexdigest()
        with self._lock:
            self.stats.chat_requests += 1
            attempt = self._attempts.pop(key, 0) + 1
            self._attempts[key] = attempt
            if len(self._attempts) > ATTEMPTS_KEPT:
                self._attempts.popitem(last=False)
            roll = self._rng.random()
        req = parse_chat_request(body, attempt)
        if self.keep_log:
            with self._lock:
                self.requests_log.append(req)
        delay = self.latency_s(req) if callable(self.latency_s) else self.latency_s
        if delay > 0:
            time.sleep(delay)
        if attempt <= self.fail_first_attempts:
            return req, Fault.http(500)
        edges = (
            (self.error_rate, Fault.http(500)),
            (self.rate_limit_rate, Fault.http(429)),
            (self.malformed_rate, Fault.malformed_json()),
            (self.empty_choices_rate, Fault.empty_choices()),
        )
        acc = 0.0
        for rate, fault in edges:
            acc += rate
            if roll < acc:
                return req, fault
        if roll < acc + self.malformed_reply_rate:
            self._count_fault("malformed_reply")
            return req, MALFORMED_REPLY
        return req, self.policy(req)

    def completion_body(self, req: ChatRequest, text: str) -> dict[str, Any]:
        prompt_tokens = sum(len(t.split()) for t in req.user_texts) + len(req.system.split())
        return {
            "id": f"chatcmpl-{self.stats.chat_requests}",
            "object": "chat.completion",
            "created": int(time.time()),
            "model": req.model,
            "choices": [
                {"index": 0, "message": {"role": "assistant", "content": text}, "finish_reason": "stop"}
            ],
            "usage": {
                "prompt_tokens": prompt_tokens,
                "completion_tokens": len(text.split()),
                "total_tokens": prompt_tokens + len(text.split()),
            },
        }


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    request_queue_size = 256  # the default backlog of 5 refuses bursts of concurrent clients
    allow_reuse_address = True

    def handle_error(self, request: Any, client_address: Any) -> None:
        # Clients that vanish mid-request (killed runners, timeouts) are expected in tests.
        exc = sys.exc_info()[1]
        if isinstance(exc, ConnectionError | TimeoutError):
            return
        super().handle_error(request, client_address)


def _make_handler(owner: ScriptedOpenAIServer) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"  # keep-alive, so clients can reuse connections
        # Headers and body go out in separate writes: without TCP_NODELAY, Nagle's algorithm and
        # the client's delayed ACK stall every reply by ~40 ms.
        disable_nagle_algorithm = True

        def log_message(self, format: str, *args: Any) -> None:  # quiet by default
            pass

        def _send(self, status: int, payload: bytes, content_type: str = "application/json") -> None:
            self.send_response(status)
            self.send_header("Content-Type", content_type)
            self.send_header("Content-Length", str(len(payload)))
            self.end_headers()
            self.wfile.write(payload)

        def _send_json(self, status: int, obj: Any) -> None:
            self._send(status, json.dumps(obj).encode("utf-8"))

        def _authorised(self) -> bool:
            if owner.api_key is None:
                return True
            if self.headers.get("Authorization") == f"Bearer {owner.api_key}":
                return True
            self._send_json(401, {"error": {"message": "invalid api key", "type": "invalid_request_error"}})
            return False

        def do_GET(self) -> None:
            owner._enter()
            try:
                if not self._authorised():
                    return
                if self.path.rstrip("/") in ("/v1/models", "/models"):
                    data = [{"id": m, "object": "model", "owned_by": "drivehierarchy"} for m in owner.models]
                    self._send_json(200, {"object": "list", "data": data})
                else:
                    self._send_json(404, {"error": {"message": f"no route {self.path}"}})
            finally:
                owner._leave()

        def do_POST(self) -> None:
            owner._enter()
            try:
                length = int(self.headers.get("Content-Length") or 0)
                raw = self.rfile.read(length)
                if not self._authorised():
                    return
                if self.path.rstrip("/") not in ("/v1/chat/completions", "/chat/completions"):
                    self._send_json(404, {"error": {"message": f"no route {self.path}"}})
                    return
                try:
                    body = json.loads(raw)
                    if not isinstance(body, dict):
                        raise ValueError("body is not an object")
                except ValueError as exc:
                    self._send_json(400, {"error": {"message": f"bad JSON body: {exc}"}})
                    return
                try:
                    req, outcome = owner._decide(raw, body)
                except Exception as exc:  # a broken policy must show up as a 500, not a hang
                    owner._count_fault("policy_error")
                    self._send_json(500, {"error": {"message": f"policy raised {type(exc).__name__}: {exc}"}})
                    return
                self._reply(req, outcome)
            finally:
                owner._leave()

        def _reply(self, req: ChatRequest, outcome: str | Fault) -> None:
            if isinstance(outcome, str):
                with owner._lock:
                    owner.stats.answered += 1
                self._send_json(200, owner.completion_body(req, outcome))
                return
            owner._count_fault(outcome.kind if outcome.kind != "http" else f"http_{outcome.status}")
            if outcome.kind == "http":
                headers_retry = outcome.status == 429
                self.send_response(outcome.status)
                payload = json.dumps({"error": {"message": outcome.message, "code": outcome.status}}).encode()
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(payload)))
                if headers_retry:
                    self.send_header("Retry-After", f"{outcome.retry_after_s:g}")
                self.end_headers()
                self.wfile.write(payload)
            elif outcome.kind == "malformed_json":
                self._send(200, b'{"id": "chatcmpl-x", "choices": [{"message": {"content": "tru')
            elif outcome.kind == "empty_choices":
                self._send_json(200, {"id": "chatcmpl-x", "object": "chat.completion", "choices": []})
            elif outcome.kind == "no_content":
                self._send_json(200, {"id": "chatcmpl-x", "choices": [{"index": 0, "finish_reason": "stop"}]})
            elif outcome.kind == "disconnect":
                self.close_connection = True
                self.connection.close()
            elif outcome.kind == "truncated":
                payload = json.dumps(owner.completion_body(req, "steer: 0.0\ntarget_speed_mps: 5.0")).encode()
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(payload)))
                self.end_headers()
                self.wfile.write(payload[: len(payload) // 2])
                self.wfile.flush()
                self.close_connection = True
                self.connection.close()
            else:
                self._send_json(500, {"error": {"message": f"unknown fault kind {outcome.kind!r}"}})

    return Handler


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m drivehierarchy.testing.openai_server", description=__doc__
    )
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000)
    parser.add_argument("--answer", default="ok", help="reply text for every request (default: ok)")
    parser.add_argument("--echo", action="store_true", help="reply with the last user text part instead")
    parser.add_argument(
        "--driver", action="store_true", help="answer R4 decisions with the scripted route-following driver"
    )
    parser.add_argument(
        "--malformed-reply-rate", type=float, default=0.0, help="fraction of replies without an action"
    )
    parser.add_argument("--latency-ms", type=float, default=0.0)
    parser.add_argument("--error-rate", type=float, default=0.0, help="fraction of HTTP 500 replies")
    parser.add_argument("--rate-limit-rate", type=float, default=0.0, help="fraction of HTTP 429 replies")
    parser.add_argument(
        "--malformed-rate", type=float, default=0.0, help="fraction of truncated JSON replies"
    )
    parser.add_argument("--empty-choices-rate", type=float, default=0.0)
    parser.add_argument("--model", action="append", dest="models", help="model id listed by /v1/models")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    answer: str = args.answer

    def policy(req: ChatRequest) -> str:
        if args.driver:
            return route_driver(req)
        return req.last_text if args.echo else answer

    server = ScriptedOpenAIServer(
        policy,
        latency_s=args.latency_ms / 1000.0,
        error_rate=args.error_rate,
        rate_limit_rate=args.rate_limit_rate,
        malformed_rate=args.malformed_rate,
        empty_choices_rate=args.empty_choices_rate,
        malformed_reply_rate=args.malformed_reply_rate,
        models=tuple(args.models or ["test-model"]),
        seed=args.seed,
        host=args.host,
        port=args.port,
    )
    print(f"serving OpenAI-compatible API at {server.base_url}", file=sys.stderr, flush=True)
    try:
        server._httpd.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server._httpd.server_close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
