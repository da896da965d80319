"""The one chat-completions transport of the project (open loop and closed loop).

Built on the official `openai` SDK (`AsyncOpenAI`): HTTP, connection pooling, timeouts, typed
errors and response parsing are the SDK's (the body is the OpenAI chat-completions body plus the
decoding fields vLLM/SGLang read at its top level). Retries are ours around it (the SDK is created with
`max_retries=0`): the SDK's back-off constants (0.5 s doubling to 8 s) cannot be configured and it
does not report how many attempts a reply took, and both matter here — the attempts are recorded
per decision / prediction, and tests and dry runs need millisecond back-off. 429, 5xx, timeouts and
connection errors are retried with capped exponential back-off and jitter, honouring
`Retry-After`; any other 4xx and a reply that is not the chat-completions shape fail at once.
Failures are typed (`RequestFailure.kind`) so runners log them as failures, never as answers.

`AsyncChatTransport` is for asyncio callers (the closed-loop harness); `ChatClient` is a
thread-safe blocking facade over the same transport, running it on a private event loop (the
open-loop runner's worker threads).
"""

from __future__ import annotations

import asyncio
import inspect
import json
import random
import threading
import time
from collections.abc import Coroutine
from dataclasses import asdict, dataclass, field
from typing import Any, TypeVar
from urllib.parse import urlsplit

from drivehierarchy._core import ConfigError

T = TypeVar("T")


@dataclass(frozen=True)
class DecodingConfig:
    """Decoding settings of the original protocol (paper Table 9, docs/protocol.md#open-loop-prompting)."""

    temperature: float = 0.0
    top_p: float = 1.0
    max_tokens: int = 256
    # Not an OpenAI field: vLLM/SGLang read it from the body top level (the SDK's `extra_body`);
    # None leaves it out (strict servers such as `transformers serve` reject unknown fields).
    repetition_penalty: float | None = 1.0
    presence_penalty: float = 0.0
    seed: int = 0

    def payload(self) -> dict[str, Any]:
        d = asdict(self)
        if d["repetition_penalty"] is None:
            del d["repetition_penalty"]
        return d

    def __post_init__(self) -> None:
        if not isinstance(self.max_tokens, int) or not 1 <= self.max_tokens <= 32768:
            raise ConfigError(f"config `max_tokens` = {self.max_tokens!r}: expected an integer in [1, 32768]")
        if not 0.0 <= float(self.temperature) <= 2.0:
            raise ConfigError(f"config `temperature` = {self.temperature!r}: expected a value in [0, 2]")


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


class ServerUnavailable(ConfigError):
    """The health check failed: the server is down, refuses the key, or does not serve the model."""


@dataclass(frozen=True)
class Completion:
    text: str  # stripped
    usage: dict[str, Any] = field(default_factory=dict)
    latency_s: float = 0.0
    attempts: int = 1
    finish_reason: str | None = None


def check_base_url(base_url: str) -> str:
    parts = urlsplit(base_url)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ConfigError(f"--base-url: expected http(s)://host[:port][/path], got {base_url!r}")
    return base_url.rstrip("/")


# Stands for a data URL while the rest of a body is serialised (private-use characters: never in
# a prompt; if one ever is, `encode_body` falls back to serialising everything).
_URL_MARK = "\ue000drivehierarchy-data-url\ue000"
_URL_MARK_JSON = json.dumps(_URL_MARK, ensure_ascii=False)


def encode_body(body: dict[str, Any]) -> bytes:
    """`body` as the JSON bytes the SDK would send (UTF-8, compact separators), with every
    `payload.DataURL` written in as it is instead of being scanned for characters to escape:
    most of a request's bytes are its base64 images, and with history the same frame is sent with
    several decisions."""
    from drivehierarchy.agents.vlm.payload import DataURL

    urls: list[str] = []

    def swap(part: Any) -> Any:
        image = part.get("image_url") if isinstance(part, dict) else None
        if isinstance(image, dict) and type(image.get("url")) is DataURL:
            urls.append(image["url"])
            return {**part, "image_url": {**image, "url": _URL_MARK}}
        return part

    messages = [
        {**m, "content": [swap(p) for p in m["content"]]}
        if isinstance(m, dict) and isinstance(m.get("content"), list)
        else m
        for m in body.get("messages", [])
    ]
    text = json.dumps({**body, "messages": messages}, ensure_ascii=False, separators=(",", ":"))
    pieces = text.split(_URL_MARK_JSON)
    if len(pieces) != len(urls) + 1:
        return json.dumps(body, ensure_ascii=False, separators=(",", ":")).encode("utf-8")
    out = [pieces[0]]
    for url, piece in zip(urls, pieces[1:], strict=True):
        out += ['"', url, '"', piece]
    return "".join(out).encode("utf-8")


class AsyncChatTransport:
    """POSTs to `{base_url}/chat/completions` (base_url as for the OpenAI SDK, e.g. `.../v1`).

    Create and use it inside one event loop (the SDK's connection pool is bound to it)."""

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
        max_connections: int = 256,
    ):
        import openai

        try:  # the SDK's HTTP layer: httpx2 in openai >= 3, httpx before
            import httpx2 as httpx
        except ImportError:  # pragma: no cover - depends on the installed SDK
            import httpx  # type: ignore[no-redef]

        self.base_url = check_base_url(base_url)
        self.model = model
        self.decoding = decoding or DecodingConfig()
        self._omit_repetition_penalty = False
        self.timeout_s = timeout_s
        self.max_retries = max_retries
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        limits = httpx.Limits(max_connections=max_connections, max_keepalive_connections=max_connections)
        self._openai = openai
        from openai.types.chat import ChatCompletion

        self._completion_type = ChatCompletion
        self._client = openai.AsyncOpenAI(
            base_url=self.base_url,
            # Local servers (vLLM, SGLang) accept any key; the SDK insists on one.
            api_key=api_key or "EMPTY",
            timeout=openai.Timeout(timeout_s, connect=min(timeout_s, 10.0)),
            max_retries=0,
            http_client=openai.DefaultAsyncHttpxClient(limits=limits),
        )
        # Our own serialisation (`encode_body`) goes out through `post(content=...)` where the SDK
        # has it.
        self._post_content = "content" in inspect.signature(self._client.post).parameters

    def payload(self, messages: list[dict[str, Any]]) -> dict[str, Any]:
        """The request body this transport sends for `messages`."""
        body = {"model": self.model, "messages": messages, **self.decoding.payload()}
        if self._omit_repetition_penalty:
            body.pop("repetition_penalty", None)
        return body

    def _server_rejects_neutral_penalty(self, status: int, text: str) -> bool:
        """A strict server (`transformers serve`) refuses vLLM's `repetition_penalty` field. At the
        protocol's 1.0 the field changes nothing, so it is left out from then on instead of
        failing every request; any other value is a real setting and the error stands."""
        # Requests already in flight when the first refusal came back retry too.
        if status not in (400, 422) or "repetition_penalty" not in text:
            return False
        if self.decoding.repetition_penalty != 1.0:
            return False
        self._omit_repetition_penalty = True
        return True

    async def complete(self, messages: list[dict[str, Any]]) -> Completion:
        start = time.monotonic()
        last: RequestFailure | None = None
        oa = self._openai
        for attempt in range(1, self.max_retries + 2):
            retry_after: float | None = None
            try:
                # `post` with the finished body: the SDK's typed-params walk over the two
                # base64 images costs ~2 ms per request, a third of the client's CPU per decision.
                if self._post_content:
                    resp = await self._client.post(
                        "/chat/completions",
                        cast_to=self._completion_type,
                        content=encode_body(self.payload(messages)),
                    )
                else:  # an SDK before `content=`: it serialises the body itself
                    resp = await self._client.post(
                        "/chat/completions", cast_to=self._completion_type, body=self.payload(messages)
                    )
            except oa.APITimeoutError as exc:
                last = RequestTimeout(f"no reply within {self.timeout_s:g} s: {exc}", attempts=attempt)
            except oa.APIConnectionError as exc:
                cause = exc.__cause__ or exc
                last = ConnectionFailure(f"{type(cause).__name__}: {cause}", attempts=attempt)
            except oa.APIStatusError as exc:
                status = exc.status_code
                snippet = exc.response.text[:300] if exc.response is not None else str(exc)
                last = HttpStatusError(f"HTTP {status}: {snippet}", status=status, attempts=attempt)
                if self._server_rejects_neutral_penalty(status, snippet):
                    continue
                if status != 429 and status < 500:
                    raise last from None
                try:
                    retry_after = float(exc.response.headers.get("retry-after", ""))
                except (ValueError, AttributeError):
                    retry_after = None
            except (oa.APIResponseValidationError, ValueError) as exc:
                # A 200 whose body is not JSON / not the chat-completions shape: not retried.
                raise MalformedResponse(
                    f"reply is not a chat completion: {exc}", status=200, attempts=attempt
                ) from None
            else:
                return self._parse(resp, start, attempt)
            if attempt > self.max_retries:
                break
            delay = min(self.max_backoff_s, self.backoff_s * 2 ** (attempt - 1))
            delay *= 0.5 + random.random()  # jitter so many callers do not retry in lockstep
            if retry_after is not None:
                delay = max(delay, min(retry_after, self.max_backoff_s))
            await asyncio.sleep(delay)
        assert last is not None
        raise last

    @staticmethod
    def _parse(resp: Any, start: float, attempt: int) -> Completion:
        choices = getattr(resp, "choices", None)
        if not isinstance(choices, list) or not choices:
            raise MalformedResponse(f"reply has no choices: {str(resp)[:200]}", status=200, attempts=attempt)
        first = choices[0]
        message = getattr(first, "message", None)
        if message is None:
            raise MalformedResponse(
                f"reply has no message content: {str(resp)[:200]}", status=200, attempts=attempt
            )
        content = getattr(message, "content", None)
        if isinstance(content, list):  # some servers return content parts
            content = "".join(p.get("text", "") if isinstance(p, dict) else "" for p in content)
        if content is None:
            content = ""  # a null content is an empty answer, not a transport failure
        if not isinstance(content, str):
            raise MalformedResponse(
                f"reply has no message content: {str(resp)[:200]}", status=200, attempts=attempt
            )
        usage_obj = getattr(resp, "usage", None)
        usage = (
            usage_obj.model_dump(exclude_none=True)
            if usage_obj is not None and hasattr(usage_obj, "model_dump")
            else {}
        )
        return Completion(
            text=content.strip(),
            usage=usage,
            latency_s=time.monotonic() - start,
            attempts=attempt,
            finish_reason=getattr(first, "finish_reason", None),
        )

    async def served_models(self) -> list[str]:
        """The ids `/v1/models` lists. Raises `ServerUnavailable` with the reason."""
        oa = self._openai
        try:
            page = await self._client.models.list()
        except oa.APIConnectionError as exc:
            raise ServerUnavailable(
                f"--base-url {self.base_url}: no OpenAI-compatible server answers "
                f"({type(exc.__cause__ or exc).__name__}: {exc.__cause__ or exc}); start it first"
            ) from None
        except oa.APIStatusError as exc:
            raise ServerUnavailable(
                f"--base-url {self.base_url}: GET /models failed with HTTP {exc.status_code}"
                + (" (check --api-key-env)" if exc.status_code in (401, 403) else "")
            ) from None
        return [m.id for m in page.data]

    async def health_check(self) -> list[str]:
        """Fails unless the server is up and lists `self.model`; returns the served ids."""
        served = await self.served_models()
        if self.model not in served:
            raise ServerUnavailable(
                f"--model {self.model!r}: not served at {self.base_url} (it serves: "
                f"{', '.join(served) or 'nothing'})"
            )
        return served

    async def aclose(self) -> None:
        await self._client.close()


class ChatClient:
    """Blocking, thread-safe facade over `AsyncChatTransport` (one private event-loop thread)."""

    def __init__(self, base_url: str, model: str, **kwargs: Any):
        check_base_url(base_url)
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="chat-transport", daemon=True)
        self._thread.start()
        self._closed = False

        async def make() -> AsyncChatTransport:
            return AsyncChatTransport(base_url, model, **kwargs)

        self.transport = self._run(make())

    def _run(self, coro: Coroutine[Any, Any, T]) -> T:
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result()

    @property
    def model(self) -> str:
        return self.transport.model

    @property
    def base_url(self) -> str:
        return self.transport.base_url

    @property
    def decoding(self) -> DecodingConfig:
        return self.transport.decoding

    def payload(self, messages: list[dict[str, Any]]) -> dict[str, Any]:
        return self.transport.payload(messages)

    def complete(self, messages: list[dict[str, Any]]) -> Completion:
        return self._run(self.transport.complete(messages))

    def health_check(self) -> list[str]:
        return self._run(self.transport.health_check())

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._run(self.transport.aclose())
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join()
        self._loop.close()

    def __del__(self) -> None:  # best effort: never leave the loop thread behind
        try:
            if not self._closed and self._loop.is_running():
                self._loop.call_soon_threadsafe(self._loop.stop)
        except Exception:
            pass
