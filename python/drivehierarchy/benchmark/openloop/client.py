"""A small, thread-safe OpenAI chat-completions client over HTTP (stdlib only).

Each worker thread keeps one keep-alive connection. 429, 5xx, timeouts and connection errors
are retried with capped exponential backoff; anything else (4xx, a reply that is not the
chat-completions shape) fails at once. Failures are typed (`RequestFailure.kind`) so the runner
can log them as failure records, never as predictions.
"""

from __future__ import annotations

import base64
import http.client
import io
import json
import os
import random
import threading
import time
from dataclasses import asdict, dataclass, field
from typing import Any
from urllib.parse import urlsplit

from drivehierarchy import ConfigError


@dataclass(frozen=True)
class DecodingConfig:
    """Decoding settings of the original open-loop protocol (paper Table 9, PROTOCOL §1.1)."""

    temperature: float = 0.0
    top_p: float = 1.0
    max_tokens: int = 256
    repetition_penalty: float = 1.0
    presence_penalty: float = 0.0
    seed: int = 0

    def payload(self) -> dict[str, Any]:
        # repetition_penalty is not an OpenAI field; vLLM/SGLang read it from the body top
        # level (what the OpenAI SDK's `extra_body` produces).
        return asdict(self)


class RequestFailure(Exception):
    """A request that produced no usable completion. `kind` names the failure class."""

    kind = "request_failed"

    def __init__(self, detail: str, *, status: int | None = None, attempts: int = 1):
        super().__init__(detail)
        self.detail = detail
        self.status = status
        self.attempts = attempts


class HttpStatusError(RequestFailure):
    kind = "http_error"


class RequestTimeout(RequestFailure):
    kind = "timeout"


class ConnectionFailure(RequestFailure):
    kind = "connection_error"


class MalformedResponse(RequestFailure):
    kind = "malformed_response"


@dataclass(frozen=True)
class Completion:
    text: str  # stripped
    usage: dict[str, Any] = field(default_factory=dict)
    latency_s: float = 0.0
    attempts: int = 1
    finish_reason: str | None = None


class ImageError(Exception):
    """An input image is missing (`kind` = missing_image) or cannot be decoded (unreadable_image)."""

    def __init__(self, kind: str, path: str, detail: str):
        super().__init__(f"{path}: {detail}")
        self.kind = kind
        self.path = path
        self.detail = detail


_MAGIC = (
    (b"\xff\xd8\xff", "image/jpeg"),
    (b"\x89PNG\r\n\x1a\n", "image/png"),
    (b"GIF87a", "image/gif"),
    (b"GIF89a", "image/gif"),
)


def _sniff_mime(data: bytes) -> str | None:
    for magic, mime in _MAGIC:
        if data.startswith(magic):
            return mime
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "image/webp"
    return None


def image_data_url(path: str) -> str:
    """`data:<mime>;base64,...` of an image file, mime from its content. Formats servers may not
    accept (BMP, TIFF, ...) are re-encoded as PNG. Raises `ImageError`."""
    try:
        data = open(path, "rb").read()  # noqa: SIM115 - one short read
    except FileNotFoundError:
        raise ImageError("missing_image", path, "file not found") from None
    except OSError as exc:
        raise ImageError(
            "missing_image" if not os.path.exists(path) else "unreadable_image", path, str(exc)
        ) from exc
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as im:
            im.verify()  # header + structure check without a full decode
        mime = _sniff_mime(data)
        if mime is None:
            with Image.open(io.BytesIO(data)) as im:
                buf = io.BytesIO()
                im.convert("RGB").save(buf, format="PNG")
            data, mime = buf.getvalue(), "image/png"
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise ImageError("unreadable_image", path, f"not a decodable image: {exc}") from exc
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


class ChatClient:
    """POSTs to `{base_url}/chat/completions` (base_url as for the OpenAI SDK, e.g. `.../v1`)."""

    def __init__(
        self,
        base_url: str,
        model: str,
        *,
        api_key: str | None = None,
        decoding: DecodingConfig | None = None,
        timeout_s: float = 300.0,
        max_retries: int = 6,
        backoff_s: float = 0.5,
        max_backoff_s: float = 30.0,
    ):
        parts = urlsplit(base_url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ConfigError(f"--base-url: expected http(s)://host[:port][/path], got {base_url!r}")
        self.base_url = base_url.rstrip("/")
        self.model = model
        self.decoding = decoding or DecodingConfig()
        self.timeout_s = timeout_s
        self.max_retries = max_retries
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self._scheme = parts.scheme
        self._host = parts.hostname
        self._port = parts.port
        self._path = (parts.path.rstrip("/") or "") + "/chat/completions"
        self._headers = {"Content-Type": "application/json", "Accept": "application/json"}
        if api_key:
            self._headers["Authorization"] = f"Bearer {api_key}"
        self._local = threading.local()

    # -- connection handling -------------------------------------------------------------------
    def _conn(self) -> http.client.HTTPConnection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            cls = http.client.HTTPSConnection if self._scheme == "https" else http.client.HTTPConnection
            conn = cls(self._host, self._port, timeout=self.timeout_s)
            self._local.conn = conn
        return conn

    def _drop_conn(self) -> None:
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None

    def _post_once(self, body: bytes) -> tuple[int, bytes, dict[str, str]]:
        conn = self._conn()
        try:
            conn.request("POST", self._path, body=body, headers=self._headers)
            resp = conn.getresponse()
            data = resp.read()
            headers = {k.lower(): v for k, v in resp.getheaders()}
        except BaseException:
            self._drop_conn()
            raise
        if headers.get("connection", "").lower() == "close":
            self._drop_conn()
        return resp.status, data, headers

    def payload(self, messages: list[dict[str, Any]]) -> dict[str, Any]:
        return {"model": self.model, "messages": messages, **self.decoding.payload()}

    def complete(self, messages: list[dict[str, Any]]) -> Completion:
        body = json.dumps(self.payload(messages), ensure_ascii=False).encode("utf-8")
        start = time.monotonic()
        last: RequestFailure | None = None
        for attempt in range(1, self.max_retries + 2):
            retry_after: float | None = None
            try:
                status, data, headers = self._post_once(body)
            except TimeoutError as exc:
                last = RequestTimeout(f"no reply within {self.timeout_s:g} s: {exc}", attempts=attempt)
            except (ConnectionError, http.client.HTTPException, OSError) as exc:
                last = ConnectionFailure(f"{type(exc).__name__}: {exc}", attempts=attempt)
            else:
                if status == 200:
                    return self._parse(data, start, attempt)
                snippet = data[:300].decode("utf-8", errors="replace")
                last = HttpStatusError(f"HTTP {status}: {snippet}", status=status, attempts=attempt)
                if status != 429 and status < 500:
                    raise last
                try:
                    retry_after = float(headers.get("retry-after", ""))
                except ValueError:
                    retry_after = None
            if attempt > self.max_retries:
                break
            delay = min(self.max_backoff_s, self.backoff_s * 2 ** (attempt - 1))
            delay *= 0.5 + random.random()  # jitter so many workers do not retry in lockstep
            if retry_after is not None:
                delay = max(delay, min(retry_after, self.max_backoff_s))
            time.sleep(delay)
        assert last is not None
        raise last

    def _parse(self, data: bytes, start: float, attempt: int) -> Completion:
        try:
            obj = json.loads(data)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise MalformedResponse(f"reply is not JSON: {exc}", status=200, attempts=attempt) from None
        choices = obj.get("choices") if isinstance(obj, dict) else None
        if not isinstance(choices, list) or not choices:
            raise MalformedResponse(f"reply has no choices: {data[:200]!r}", status=200, attempts=attempt)
        first = choices[0]
        message = first.get("message") if isinstance(first, dict) else None
        content = message.get("content") if isinstance(message, dict) else None
        if isinstance(content, list):  # some servers return content parts
            content = "".join(p.get("text", "") for p in content if isinstance(p, dict))
        if content is None and isinstance(message, dict) and "content" in message:
            content = ""  # a null content is an empty answer, not a transport failure
        if not isinstance(content, str):
            raise MalformedResponse(
                f"reply has no message content: {data[:200]!r}", status=200, attempts=attempt
            )
        usage = obj.get("usage") if isinstance(obj.get("usage"), dict) else {}
        return Completion(
            text=content.strip(),
            usage=usage,
            latency_s=time.monotonic() - start,
            attempts=attempt,
            finish_reason=first.get("finish_reason"),
        )

    def close(self) -> None:
        self._drop_conn()
