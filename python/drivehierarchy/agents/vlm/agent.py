"""The VLM driver: builds the decision message, sends it, hands the raw reply to the env.

Parsing is not done here: the env parses the raw reply in Rust (`dh_agents::vlm::parse_reply`,
docs/protocol.md#r4-actuation) and holds the previous control when it is unparseable. A transport
failure (timeout,
HTTP error, dropped connection, after the transport's retries) becomes `None` — "no decision" —
which the env also holds and counts (docs/protocol.md#r4-actuation treats it as an unparseable reply).

`VLMDriver` is the async core the closed-loop harness shares across scenarios (one connection
pool, many scenarios in flight); `VLMAgent` is the blocking `Agent` for `run_episode` and scripts.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import gymnasium as gym

from drivehierarchy import _core
from drivehierarchy._core import ConfigError
from drivehierarchy.agents.vlm.history import DecisionHistory, HistoryOptions
from drivehierarchy.agents.vlm.payload import PayloadOptions, build_messages, prompt_hash
from drivehierarchy.agents.vlm.presets import ModelPreset, resolve_model
from drivehierarchy.agents.vlm.transport import (
    AsyncChatTransport,
    ChatClient,
    DecodingConfig,
    RequestFailure,
)

# Closed-loop decoding: the paper's deterministic protocol (T = 0, top-p 1, seed 0) and its 256-token
# bound, which keeps a rambling model's latency bounded (a reply is two short lines). The
# repetition penalty is left at the server's neutral default rather than sent as 1.0, so strict
# servers (`transformers serve`) accept the request.
TICK_S: float = _core.constants()["tick_s"]  # the protocol's simulation step
CLOSED_LOOP_DECODING = DecodingConfig(temperature=0.0, top_p=1.0, max_tokens=256, repetition_penalty=None)


@dataclass(frozen=True)
class VLMOptions:
    base_url: str
    model: str  # a preset key or the served model id
    api_key_env: str | None = None
    decoding: DecodingConfig = CLOSED_LOOP_DECODING
    payload: PayloadOptions = field(default_factory=PayloadOptions)
    timeout_s: float = 60.0
    max_retries: int = 2
    backoff_s: float = 0.5
    # A scenario whose requests fail this many decisions in a row (after retries) is aborted as
    # `server_unavailable` (redone on resume) instead of being driven on held controls.
    max_consecutive_transport_failures: int = 3
    latency_aware: bool = False
    # Past frames, ego states and decisions (this project's extension, docs/vlm.md#history-and-memory).
    history: HistoryOptions = field(default_factory=HistoryOptions)

    def __post_init__(self) -> None:
        self.history.check_payload(self.effective_payload())
        if self.max_consecutive_transport_failures < 1:
            raise ConfigError(
                "config `max_consecutive_transport_failures` = "
                f"{self.max_consecutive_transport_failures!r}: expected ≥ 1"
            )

    @property
    def served_model(self) -> str:
        return resolve_model(self.model)[0]

    @property
    def preset(self) -> ModelPreset | None:
        return resolve_model(self.model)[1]

    def effective_payload(self) -> PayloadOptions:
        """The payload options with the preset's image limit applied."""
        p = self.preset
        if p is not None and p.images_per_prompt < self.payload.max_images:
            from dataclasses import replace

            return replace(self.payload, max_images=p.images_per_prompt)
        return self.payload

    def api_key(self) -> str | None:
        if not self.api_key_env:
            return None
        key = os.environ.get(self.api_key_env)
        if not key:
            raise ConfigError(f"--api-key-env: environment variable {self.api_key_env!r} is not set")
        return key

    def manifest(self) -> dict[str, Any]:
        """What the run manifest records (never the key itself)."""
        p = self.preset
        return {
            "base_url": self.base_url,
            "model": self.served_model,
            "preset": p.key if p is not None else None,
            "api_key_env": self.api_key_env,
            "decoding": asdict(self.decoding),
            "payload": asdict(self.effective_payload()),
            "timeout_s": self.timeout_s,
            "max_retries": self.max_retries,
            "max_consecutive_transport_failures": self.max_consecutive_transport_failures,
            "latency_aware": self.latency_aware,
            "history": self.history.manifest(),
        }

    def inputs(self) -> dict[str, Any]:
        """What the model is given, as `r4 report` compares runs (docs/vlm.md#history-and-memory)."""
        h, p = self.history, self.effective_payload()
        controls = [
            name
            for name, on in (
                ("blind", p.blind),
                ("no-bev", p.no_bev),
                (f"corrupt-{p.corrupt}", p.corrupt is not None),
                ("latency-aware", self.latency_aware),
                ("history-shuffle", h.shuffle),
                ("history-freeze", h.freeze),
            )
            if on
        ]
        return {
            "history": h.frames,
            "stride": h.stride if (h.frames or h.ego) else 1,
            "history_bev": h.bev,
            "ego_history": h.ego,
            "memory": h.memory,
            "controls": controls,
        }

    def transport_kwargs(self) -> dict[str, Any]:
        return {
            "api_key": self.api_key(),
            "decoding": self.decoding,
            "timeout_s": self.timeout_s,
            "max_retries": self.max_retries,
            "backoff_s": self.backoff_s,
        }


@dataclass
class Reply:
    """One decision's request outcome (before the env parses it)."""

    raw: str | None
    prompt_hash: str
    latency_s: float
    attempts: int = 1
    error: str | None = None  # transport failure kind, None when a reply arrived
    error_detail: str | None = None
    images: int = 0

    def log_fields(self) -> dict[str, Any]:
        return {
            "prompt_hash": self.prompt_hash,
            "latency_s": round(self.latency_s, 4),
            "attempts": self.attempts,
            "transport_error": self.error,
            "transport_detail": self.error_detail,
        }


class VLMDriver:
    """Async: `messages()` builds a decision's message, `request()` sends it."""

    def __init__(self, options: VLMOptions, transport: AsyncChatTransport | None = None):
        self.options = options
        self.payload = options.effective_payload()
        self.transport = transport or AsyncChatTransport(
            options.base_url, options.served_model, **options.transport_kwargs()
        )

    def messages(self, obs: dict[str, Any], decision: int, seed: int = 0) -> list[dict[str, Any]]:
        return build_messages(obs, decision, self.payload, seed=seed)

    async def request(self, messages: list[dict[str, Any]]) -> Reply:
        h = prompt_hash(messages)
        n_images = sum(p["type"] == "image_url" for m in messages for p in m["content"])
        t0 = time.monotonic()
        try:
            c = await self.transport.complete(messages)
        except RequestFailure as exc:
            return Reply(None, h, time.monotonic() - t0, exc.attempts, exc.kind, exc.detail, n_images)
        return Reply(c.text, h, c.latency_s, c.attempts, None, None, n_images)


class VLMAgent:
    """Blocking `Agent`: `act` returns the raw reply (str) or None; the env parses it."""

    name = "vlm"

    def __init__(self, options: VLMOptions) -> None:
        self.options = options
        self.payload = options.effective_payload()
        self.uses_images = bool(self.payload.images)
        self.client = ChatClient(options.base_url, options.served_model, **options.transport_kwargs())
        self.decision = 0
        self.seed = 0
        self.log: list[dict[str, Any]] = []
        self.history = (
            DecisionHistory(options.history, self.payload, TICK_S) if options.history.enabled else None
        )
        self._sim: Any = None

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        self.decision = 0
        self.log = []
        self._sim = getattr(env.unwrapped, "sim", None)
        if self.history is not None:
            self.history.reset(self.seed)

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> str | None:
        if self.history is not None and self.decision:
            reply = info.get("reply")
            self.history.record_reply(self.decision, reply if isinstance(reply, dict) else None)
        self.decision += 1
        if self.history is not None:
            ego = (
                self._sim.ego_array().tolist() if self.options.history.ego and self._sim is not None else None
            )
            messages = self.history.messages(observation, self.decision, int(info.get("tick", 0)), ego)
        else:
            messages = build_messages(observation, self.decision, self.payload, seed=self.seed)
        h = prompt_hash(messages)
        t0 = time.monotonic()
        try:
            c = self.client.complete(messages)
            reply = Reply(c.text, h, c.latency_s, c.attempts)
        except RequestFailure as exc:
            reply = Reply(None, h, time.monotonic() - t0, exc.attempts, exc.kind, exc.detail)
        self.log.append({"decision": self.decision, "raw": reply.raw, **reply.log_fields()})
        return reply.raw

    def close(self) -> None:
        self.client.close()
