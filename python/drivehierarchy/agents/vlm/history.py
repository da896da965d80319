"""History and memory for the VLM driver, this project's extension of the protocol
(docs/vlm.md#history-and-memory).

The paper's message carries the current frames only. With `HistoryOptions` the one user turn also
carries, oldest first, the front frames (and BEVs) of earlier decisions `stride` decisions apart,
each labelled with its true time offset (`t-0.50 s`), then the current frames (labelled
`t-0.00 s, the current frame`), then the ego's past positions and speeds and the model's own past
decisions as text, then the question. Two controls tell whether a model uses time:
`shuffle` permutes the past frames among their slots (labels stay, so order and labels lie) and
`freeze` fills every past slot with the current frame (no motion at all).

Episode start: a slot is sent only once its decision exists (decision n has past frames at
n − stride·k ≥ 1, k = 1..frames), so the first decision carries the current frames only and the
message grows to its full size after `frames·stride` decisions; nothing is padded or invented.
The text parts are always present once enabled (saying `none yet` at the start).

Frames are kept as the data URLs sent when they were current, so history never re-encodes an
image. The state is one episode's: a resumed run redoes an unfinished episode from its start and
rebuilds the same history.

Cost: a decision's bookkeeping is one small record appended to a bounded deque (the ego's x, y and
formatted speed; the reply's memory line, formatted once when it arrives). The texts are built
only inside `messages()`, i.e. for a request that is sent, from the records and from offset
labels formatted once per episode (scripts/bench_vlm_history.py and
scripts/bench_action_levels.py measure what it adds to a decision).
"""

from __future__ import annotations

import json
import math
from collections import deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from drivehierarchy._core import ConfigError
from drivehierarchy.agents.vlm.payload import (
    PayloadOptions,
    bev_descriptor,
    encode_images,
    front_descriptor,
    question_text,
)

Content = list[dict[str, Any]]
CURRENT_LABEL = "t-0.00 s, the current frame"
EGO_HEAD = "Ego history, oldest first, positions in the current ego frame as (forward_m, right_m)"
MEMORY_HEAD = "Your previous decisions, oldest first"


@dataclass(frozen=True)
class HistoryOptions:
    """`r4 evaluate --history N --stride S [--history-bev] --ego-history K --memory K
    [--history-shuffle | --history-freeze]`."""

    frames: int = 0  # past front frames (N)
    stride: int = 1  # decisions between two sent frames (S)
    bev: bool = False  # past BEVs too
    ego: int = 0  # past ego positions and speeds, `stride` decisions apart
    memory: int = 0  # the model's own last decisions
    shuffle: bool = False
    freeze: bool = False

    def __post_init__(self) -> None:
        for name, flag, low in (
            ("frames", "--history", 0),
            ("stride", "--stride", 1),
            ("ego", "--ego-history", 0),
            ("memory", "--memory", 0),
        ):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < low:
                raise ConfigError(f"{flag} = {v!r}: expected an integer ≥ {low}")
        if self.bev and not self.frames:
            raise ConfigError("--history-bev = True: needs --history N ≥ 1 (the BEVs of which frames?)")
        if self.shuffle and self.freeze:
            raise ConfigError("--history-shuffle and --history-freeze: choose one control")
        if self.shuffle and self.frames < 2:
            raise ConfigError(
                f"--history-shuffle with --history = {self.frames}: needs ≥ 2 past frames to reorder"
            )
        if self.freeze and not self.frames:
            raise ConfigError("--history-freeze = True: needs --history N ≥ 1 (the slots to fill)")
        if self.stride != 1 and not (self.frames or self.ego):
            raise ConfigError(f"--stride = {self.stride}: only with --history or --ego-history")

    @property
    def enabled(self) -> bool:
        return bool(self.frames or self.ego or self.memory)

    @property
    def control(self) -> str | None:
        return "history-shuffle" if self.shuffle else "history-freeze" if self.freeze else None

    def check_payload(self, payload: PayloadOptions) -> None:
        """Refuses history the message cannot carry."""
        if self.frames and not payload.images:
            raise ConfigError(f"--history = {self.frames} with --blind: a blind message carries no frames")
        if self.bev and "bev" not in payload.images:
            raise ConfigError(
                "--history-bev = True: the message carries no BEV (--no-bev or a one-image model)"
            )

    def manifest(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(slots=True)
class _Past:
    decision: int
    tick: int
    images: list[tuple[str, int, int, str]]  # (key, width, height, data URL) as sent
    x: float = 0.0
    y: float = 0.0
    speed: str = ""  # "8.1 m/s", formatted once


@lru_cache(maxsize=64)
def _ego_template(count: int) -> str:
    return EGO_HEAD + ": " + "; ".join(["{}: ({:.1f}, {:.1f}) at {}"] * count) + "."


def offset_label(ticks: int, tick_s: float) -> str:
    return f"t-{ticks * tick_s:.2f} s"


def _descriptor(key: str, w: int, h: int, when: str) -> str:
    base = front_descriptor(w, h) if key == "front" else bev_descriptor(w)
    head, rest = base.split(" (", 1)
    return f"{head} at {when} ({rest}"


def _value(v: Any) -> str:
    return v if isinstance(v, str) else repr(v) if isinstance(v, float) else json.dumps(v)


def _reply_text(reply: dict[str, Any]) -> str:
    """What became of a decision, as its memory line says (formatted once, when it is recorded)."""
    parsed, failure = reply.get("parsed"), reply.get("failure")
    if parsed is not None and failure is None:
        return ", ".join(
            [f"{k}: {v!r}" if type(v) is float else f"{k}: {_value(v)}" for k, v in parsed.items()]
        )
    if failure == "no_reply" or not reply:
        return "no reply, the previous control was held"
    return "unparseable reply, the previous control was held"


@dataclass
class DecisionHistory:
    """One episode's past frames, ego states and decisions; builds the decision messages."""

    options: HistoryOptions
    payload: PayloadOptions
    tick_s: float
    seed: int = 0
    _frames: deque[_Past] = field(init=False)
    # (asked tick, " (frame d): what happened"): the memory line but its offset label, made once.
    _replies: deque[tuple[int, str]] = field(init=False)
    _asked: dict[int, int] = field(init=False, default_factory=dict)
    # The time offsets (s) of the past frames the last message carried, oldest first (for the log).
    last_offsets_s: list[float] = field(init=False, default_factory=list)

    def __post_init__(self) -> None:
        self.options.check_payload(self.payload)
        self.reset(self.seed)

    def reset(self, seed: int) -> None:
        self.seed = seed
        o = self.options
        self._frames = deque(maxlen=max(o.frames, o.ego) * o.stride or 1)
        self._replies = deque(maxlen=o.memory or 1)
        self._asked = {}
        self._labels: dict[int, str] = {}
        self._descriptors: dict[tuple[str, int, int, str], str] = {}
        self._images = bool(self.payload.images)

    def _slots(self, count: int) -> list[_Past]:
        """The past entries of decisions n − stride·k, k = count..1 (oldest first), those that exist.
        The buffer holds consecutive decisions up to n − 1, so n − j is at index len − j."""
        frames, s = self._frames, self.options.stride
        return [frames[-k * s] for k in range(min(count, len(frames) // s), 0, -1)]

    def _descriptor(self, key: str, w: int, h: int, when: str) -> str:
        k = (key, w, h, when)
        text = self._descriptors.get(k)
        if text is None:
            text = self._descriptors[k] = _descriptor(key, w, h, when)
        return text

    def _label(self, ticks: int) -> str:
        label = self._labels.get(ticks)
        if label is None:
            label = self._labels[ticks] = offset_label(ticks, self.tick_s)
        return label

    def messages(
        self, obs: dict[str, Any], decision: int, tick: int, ego: Sequence[float] | None = None
    ) -> list[dict[str, Any]]:
        """The message of decision `decision` (1-based) asked at `tick`; records the current frames."""
        o = self.options
        if self._frames and self._frames[-1].decision != decision - 1:
            raise ValueError(
                f"decision {decision} after decision {self._frames[-1].decision}: one message per decision, "
                "in order (reset() starts an episode)"
            )
        if "prompt" not in obs:
            raise ConfigError("config `prompt` = False: the VLM agent needs the env's prompt observation")
        if o.ego and ego is None:
            raise ConfigError(f"--ego-history = {o.ego}: the ego state of decision {decision} is missing")
        current = encode_images(obs, decision, self.payload, seed=self.seed) if self._images else []
        content: Content = []
        if o.frames:
            self._add_past_frames(content, current, decision, tick)
        else:
            self.last_offsets_s = []
        for key, w, h, url in current:
            if o.frames:
                text = self._descriptor(key, w, h, CURRENT_LABEL)
            else:  # no past frames: the paper's descriptors
                text = front_descriptor(w, h) if key == "front" else bev_descriptor(w)
            content.append({"type": "text", "text": text})
            content.append({"type": "image_url", "image_url": {"url": url}})
        if o.ego:
            content.append({"type": "text", "text": self._ego_text(self._slots(o.ego), tick, ego)})
        if o.memory:
            content.append({"type": "text", "text": self._memory_text(tick)})
        content.append({"type": "text", "text": question_text(obs["prompt"], decision)})
        past = _Past(decision, tick, current)
        if ego is not None and o.ego:
            past.x, past.y, past.speed = float(ego[0]), float(ego[1]), f"{ego[3]:.1f} m/s"
        self._frames.append(past)
        if o.memory:
            self._asked[decision] = tick
        return [{"role": "user", "content": content}]

    def _add_past_frames(
        self, content: Content, current: list[tuple[str, int, int, str]], decision: int, tick: int
    ) -> None:
        o = self.options
        frame_slots = self._slots(o.frames)
        self.last_offsets_s = [round((tick - p.tick) * self.tick_s, 4) for p in frame_slots]
        sources = list(frame_slots)
        if o.shuffle and len(sources) > 1:
            sources = [sources[i] for i in self._permutation(decision, len(sources))]
        keys = ("front", "bev") if o.bev else ("front",)
        for slot, src in zip(frame_slots, sources, strict=True):
            when = self._label(tick - slot.tick)
            images = current if o.freeze else src.images
            for key, w, h, url in images:
                if key in keys:
                    content.append({"type": "text", "text": self._descriptor(key, w, h, when)})
                    content.append({"type": "image_url", "image_url": {"url": url}})

    def record_reply(self, decision: int, reply: dict[str, Any] | None) -> None:
        """The env's `info["reply"]` of the step that applied decision `decision` (memory)."""
        if not self.options.memory:
            return
        tick = self._asked.pop(decision, None)
        if tick is None:
            return
        self._replies.append((tick, f" (frame {decision}): {_reply_text(reply or {})}"))

    def _permutation(self, decision: int, n: int) -> list[int]:
        """A permutation of the n past slots that is never the identity, from seed and decision."""
        rng = np.random.default_rng([self.seed, decision, 0x5EED])
        perm = [int(i) for i in rng.permutation(n)]
        if perm == list(range(n)):
            perm = perm[1:] + perm[:1]
        return perm

    def _ego_text(self, slots: list[_Past], tick: int, ego: Sequence[float] | None) -> str:
        if not slots or ego is None:
            return f"{EGO_HEAD}: none yet (the episode has just started)."
        x0, y0, yaw0 = float(ego[0]), float(ego[1]), float(ego[2])
        c, s = math.cos(yaw0), math.sin(yaw0)
        labels, label = self._labels, self._label
        # forward is (cos, sin), left (−sin, cos), so right = dx·sin − dy·cos. One format call for
        # all the items (a template per count) costs less than formatting and joining each.
        args: list[Any] = []
        for p in slots:
            dx, dy = p.x - x0, p.y - y0
            ago = tick - p.tick
            args += (labels.get(ago) or label(ago), dx * c + dy * s, dx * s - dy * c, p.speed)
        text = _ego_template(len(slots)).format(*args)
        return text.replace("(-0.0,", "(0.0,").replace(" -0.0)", " 0.0)")

    def _memory_text(self, tick: int) -> str:
        replies = self._replies
        if not replies:
            return f"{MEMORY_HEAD}: none yet (this is the first decision)."
        labels, label = self._labels, self._label
        items = [(labels.get(tick - asked) or label(tick - asked)) + what for asked, what in replies]
        return MEMORY_HEAD + ": " + "; ".join(items) + "."
