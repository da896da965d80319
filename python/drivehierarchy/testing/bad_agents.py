"""Bad drivers: the agents this benchmark exists for drive badly, so its robustness is tested
against them (fuzzing in CI, `scripts/soak.py`).

Each kind is a seeded `Agent` (same seed → same actions) that drives a `DriveHierarchy-R4` env in
a way the reference policies never do: random actions, a noisy or late expert, full lock, swapped
pedals, and raw VLM replies that are garbage, empty, 1 MB long, missing (`None`) or full of
non-numbers. `fuzz_episode` drives one episode with one of them and checks what must hold for
every driver: the episode ends with a protocol termination, no exception escapes `step`, and
re-scoring the episode log gives the same record.

Non-finite numeric actions (NaN, ±inf) are rejected, not repaired: `step` raises `ConfigError`
naming the action and leaves the world untouched (a NaN from a policy is a bug in the policy that
holding or clipping would hide). A reply text is never rejected: whatever it says, the protocol's
parser decides (no decision → the previous control is held and counted in `parse_failures`).

They live in `testing/` beside the loopback VLM server because they are test drivers, not policies
anyone would report a score for.
"""

from __future__ import annotations

import json
import math
import time
import traceback
from typing import Any

import gymnasium as gym
import numpy as np

from drivehierarchy._core import ConfigError

# Score-record fields that measure wall-clock time (differ between a run and its re-scoring).
WALL_CLOCK_KEYS = ("wall_duration", "duration_system")
MEGABYTE = 1 << 20


class _Seeded:
    """Base: a name, no images, a per-episode RNG seeded from the agent seed and the episode seed."""

    name = "bad"
    uses_images = False
    action_mode = "decision"  # the env's `action_mode` this driver needs

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.env: Any = None

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        self.env = env.unwrapped
        self.rng = np.random.default_rng(self.seed)

    def expert(self) -> np.ndarray:
        return np.asarray(self.env.expert_action(), dtype=np.float64)


class RandomAgent(_Seeded):
    """Uniform random actions from the env's action space."""

    name = "random"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        space = self.env.action_space
        return self.rng.uniform(space.low, space.high).astype(np.float32)


class NoisyExpertAgent(_Seeded):
    """The expert with Gaussian steering noise of standard deviation `sigma` (float64, unclipped:
    the env clips as the protocol says)."""

    def __init__(self, sigma: float, seed: int = 0) -> None:
        super().__init__(seed)
        self.sigma = sigma
        self.name = f"noisy_expert_{sigma:g}"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        a = self.expert()
        a[0] += self.rng.normal(0.0, self.sigma)
        return a


class DelayedExpertAgent(_Seeded):
    """The expert whose steering arrives one decision late (the target speed is current)."""

    name = "delayed_expert"

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        super().reset(env, info)
        self.prev_steer = 0.0

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        a = self.expert()
        a[0], self.prev_steer = self.prev_steer, float(a[0])
        return a.astype(np.float32)


class FullLockAgent(_Seeded):
    """Full steering lock (right) at 15 m/s: circles off the road."""

    name = "full_lock"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        return np.array([1.0, 15.0], np.float32)


class BangBangAgent(_Seeded):
    """Full lock left and right on alternate decisions at 10 m/s (worst case for the rate limit)."""

    name = "bang_bang"

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        super().reset(env, info)
        self.k = 0

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        self.k += 1
        return np.array([1.0 if self.k % 2 else -1.0, 10.0], np.float32)


class ReversedPedalsAgent(_Seeded):
    """Raw mode (`[throttle, brake, steer]`): the expert's pedals swapped — it brakes to go and
    floors it to stop."""

    name = "reversed_pedals"
    action_mode = "raw"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        throttle, brake, steer = self.expert()
        return np.array([brake, throttle, steer], np.float32)


class OutOfRangeAgent(_Seeded):
    """Finite actions far outside the action space (±1e30, negative speeds); the env clamps them."""

    name = "out_of_range"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        mag = 10.0 ** self.rng.integers(1, 31)
        return np.array([self.rng.choice([-mag, mag]), self.rng.choice([-mag, mag, 12.0])], np.float64)


class NonFiniteAgent(_Seeded):
    """NaN / ±inf actions on every other decision, the expert in between. Each non-finite action
    must be rejected with `ConfigError` and change nothing (`fuzz_episode` checks both)."""

    name = "non_finite"
    rejects = True
    BAD = (math.nan, math.inf, -math.inf)

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        super().reset(env, info)
        self.k = 0

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        self.k += 1
        a = self.expert()
        if self.k % 2:
            a[int(self.rng.integers(0, 2))] = self.BAD[int(self.rng.integers(0, 3))]
        return a.astype(np.float32)

    def fallback(self) -> np.ndarray:
        """What the driver sends after a rejection: the expert's action."""
        return self.expert().astype(np.float32)


class GarbageReplyAgent(_Seeded):
    """Raw replies of random printable and non-ASCII text, with no decision in them."""

    name = "garbage_reply"
    ALPHABET = (*"abcxyz:;.,-+0123456789 \n\t{}[]\"'", "é", "→", "驾", "🚗", "\u200b", "\x00", "\ufffd")

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> str:
        n = int(self.rng.integers(1, 400))
        return "".join(self.rng.choice(self.ALPHABET, n))


class EmptyReplyAgent(_Seeded):
    """Raw replies that are the empty string."""

    name = "empty_reply"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> str:
        return ""


class HugeReplyAgent(_Seeded):
    """1 MB raw replies: filler with the expert's decision at the end on every other decision."""

    name = "huge_reply"

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        super().reset(env, info)
        self.k = 0

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> str:
        self.k += 1
        steer, speed = self.expert()
        tail = f"\nsteer: {steer:.3f}\ntarget_speed_mps: {speed:.1f}" if self.k % 2 else ""
        return self.FILLER[: MEGABYTE - len(tail)] + tail

    FILLER = ("Let me think step by step about the road ahead. " * (MEGABYTE // 48 + 1))[:MEGABYTE]


class NoneReplyAgent(_Seeded):
    """No reply at all (`None`: a transport error) on every decision."""

    name = "none_reply"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> None:
        return None


class MixedReplyAgent(_Seeded):
    """What a weak VLM sends: the expert's decision as text most of the time, and otherwise
    non-numbers, out-of-range numbers, one field only, prose, JSON, a lone surrogate (what a JSON
    `\\ud800` escape decodes to), or nothing."""

    name = "mixed_reply"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> str | None:
        steer, speed = self.expert()
        good = f"steer: {steer:.3f}\ntarget_speed_mps: {speed:.1f}"
        bad: list[str | None] = [
            "steer: nan\ntarget_speed_mps: inf",
            "steer: -inf\ntarget_speed_mps: nan",
            f"steer: 1e308\ntarget_speed_mps: -{speed:.1f}",
            f"steer: {steer:.3f}",
            f"target_speed_mps: {speed:.1f}",
            "I would slow down and turn slightly left.",
            json.dumps({"steer": float(steer), "target_speed_mps": float(speed)}),
            f"steer: {steer:.3f}\ud800\ntarget_speed_mps: {speed:.1f}",
            "steer: 0x1p3\ntarget_speed_mps: 1_000",
            None,
        ]
        if self.rng.random() < 0.5:
            return good
        return bad[int(self.rng.integers(0, len(bad)))]


# -- the waypoint and meta levels (docs/r4.md#action-levels) ---------------------------------------


class _PlanLevel(_Seeded):
    """Base of the plan levels' bad drivers: the expert's plan at the env's level as text."""

    def expert_reply(self) -> str:
        plan = self.env.expert_action()
        if self.action_mode == "meta":
            from drivehierarchy.envs.r4 import PATH_ACTIONS, SPEED_ACTIONS

            return f"path_action: {PATH_ACTIONS[int(plan[0])]}\nspeed_action: {SPEED_ACTIONS[int(plan[1])]}"
        # Replies give (forward, right); the plan is (x forward, y left).
        return "waypoints: [" + ", ".join(f"({x:.2f}, {-y:.2f})" for x, y in plan) + "]"


class RandomPlanAgent(_PlanLevel):
    """Uniform random plans from the level's action space."""

    def __init__(self, mode: str, seed: int = 0) -> None:
        super().__init__(seed)
        self.action_mode = mode
        self.name = f"{mode}_random"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        space = self.env.action_space
        if self.action_mode == "meta":
            return np.array([self.rng.integers(0, n) for n in space.nvec], np.int64)
        return self.rng.uniform(space.low, space.high).astype(np.float32)


class HugePlanAgent(_PlanLevel):
    """Finite waypoint plans of huge coordinates (±1e30, beyond the space; the tracker clips)."""

    action_mode = "waypoints"
    name = "waypoints_huge"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        k = self.env.config.waypoints
        mag = 10.0 ** self.rng.integers(3, 31, size=(k, 2))
        return (mag * self.rng.choice([-1.0, 1.0], size=(k, 2))).astype(np.float64)


class ZeroPlanAgent(_PlanLevel):
    """The empty plan: every point at the ego (stand still), every decision."""

    action_mode = "waypoints"
    name = "waypoints_zero"

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        return np.zeros((self.env.config.waypoints, 2), np.float32)


class NonFinitePlanAgent(_PlanLevel):
    """NaN / ±inf in the plan on every other decision, the expert's plan in between; each must be
    rejected with `ConfigError` and change nothing."""

    rejects = True

    def __init__(self, mode: str, seed: int = 0) -> None:
        super().__init__(seed)
        self.action_mode = mode
        self.name = f"{mode}_non_finite"

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        super().reset(env, info)
        self.k = 0

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        self.k += 1
        a = self.fallback().astype(np.float64)
        if self.k % 2:
            a.reshape(-1)[int(self.rng.integers(0, a.size))] = NonFiniteAgent.BAD[
                int(self.rng.integers(0, 3))
            ]
        return a

    def fallback(self) -> np.ndarray:
        return np.asarray(self.env.expert_action())


class PlanReplyAgent(_PlanLevel):
    """Replies at a plan level: `garbage` (random text), `empty` (""), `huge` (1 MB, the expert's
    plan at the end on every other decision), `none` (no reply) or `mixed` (the expert's plan half
    the time, else broken plans: NaN, one point, the other level's words, prose, nothing)."""

    def __init__(self, mode: str, style: str, seed: int = 0) -> None:
        super().__init__(seed)
        self.action_mode = mode
        self.style = style
        self.name = f"{mode}_{style}_reply"

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        super().reset(env, info)
        self.k = 0

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> str | None:
        self.k += 1
        if self.style == "garbage":
            return "".join(self.rng.choice(GarbageReplyAgent.ALPHABET, int(self.rng.integers(1, 400))))
        if self.style == "empty":
            return ""
        if self.style == "none":
            return None
        if self.style == "huge":
            tail = "\n" + self.expert_reply() if self.k % 2 else ""
            return HugeReplyAgent.FILLER[: MEGABYTE - len(tail)] + tail
        bad: list[str | None] = [
            "waypoints: [(nan, inf), (1e999, -1e999)]",
            "waypoints: [(5.0, 0.0)]",
            "waypoints: []",
            "path_action: TURN_LEFT",
            "speed_action: STOP",
            "path_action: FLY\nspeed_action: WARP",
            "steer: 0.1\ntarget_speed_mps: 5",
            "I would keep my lane and slow down a little.",
            None,
        ]
        if self.rng.random() < 0.5:
            return self.expert_reply()
        return bad[int(self.rng.integers(0, len(bad)))]


def _plan_kinds() -> dict[str, Any]:
    kinds: dict[str, Any] = {
        "waypoints_huge": HugePlanAgent,
        "waypoints_zero": ZeroPlanAgent,
    }
    for mode in ("waypoints", "meta"):
        kinds[f"{mode}_random"] = lambda seed, m=mode: RandomPlanAgent(m, seed)
        kinds[f"{mode}_non_finite"] = lambda seed, m=mode: NonFinitePlanAgent(m, seed)
        for style in ("garbage", "empty", "huge", "none", "mixed"):
            kinds[f"{mode}_{style}_reply"] = lambda seed, m=mode, st=style: PlanReplyAgent(m, st, seed)
    return kinds


# The bad drivers of the waypoint and meta levels (tests/fuzz/test_plan_fuzz.py).
PLAN_KINDS: tuple[str, ...] = tuple(_plan_kinds())


def _kinds() -> dict[str, Any]:
    return {
        "random": RandomAgent,
        "noisy_expert_0.1": lambda seed: NoisyExpertAgent(0.1, seed),
        "noisy_expert_0.3": lambda seed: NoisyExpertAgent(0.3, seed),
        "delayed_expert": DelayedExpertAgent,
        "full_lock": FullLockAgent,
        "bang_bang": BangBangAgent,
        "reversed_pedals": ReversedPedalsAgent,
        "out_of_range": OutOfRangeAgent,
        "non_finite": NonFiniteAgent,
        "garbage_reply": GarbageReplyAgent,
        "empty_reply": EmptyReplyAgent,
        "huge_reply": HugeReplyAgent,
        "none_reply": NoneReplyAgent,
        "mixed_reply": MixedReplyAgent,
    }


KINDS: tuple[str, ...] = tuple(_kinds())


def make_bad_agent(kind: str, seed: int = 0) -> Any:
    """A bad driver by name (`KINDS`)."""
    factories = {**_kinds(), **_plan_kinds()}
    if kind not in factories:
        known = ", ".join([*KINDS, *PLAN_KINDS])
        raise ConfigError(f"config `agent` = {kind!r}: unknown bad driver (known: {known})")
    return factories[kind](seed)


def comparable_record(record: dict[str, Any]) -> str:
    """A score record as canonical JSON without its wall-clock fields: equal for equal episodes."""
    meta = {k: v for k, v in record.get("meta", {}).items() if k not in WALL_CLOCK_KEYS}
    return json.dumps({**record, "meta": meta}, sort_keys=True)


def drive(env: Any, agent: Any, seed: int) -> dict[str, Any]:
    """Drives one episode to its protocol termination. Only a `ConfigError` for a non-finite action
    of an agent that `rejects` is caught (and checked to have changed nothing); everything else
    propagates. Returns the score record, the decision count and the rejections."""
    _obs, info = env.reset(seed=seed)
    agent.reset(env, info)
    steps = rejected = 0
    while True:
        action = agent.act(_obs, info)
        try:
            _obs, _reward, terminated, truncated, info = env.step(action)
        except ConfigError as exc:
            finite = isinstance(action, np.ndarray) and bool(np.all(np.isfinite(action)))
            if not getattr(agent, "rejects", False) or finite or "NaN or infinity" not in str(exc):
                raise
            logged = len(env.unwrapped.decision_log())
            if logged != steps:
                msg = f"a rejected action was logged: {logged} decisions after {steps} steps"
                raise RuntimeError(msg) from exc
            rejected += 1
            _obs, _reward, terminated, truncated, info = env.step(agent.fallback())
        steps += 1
        if terminated or truncated:
            break
    return {"score": env.unwrapped.score(), "steps": steps, "rejected": rejected, "info": info}


def fuzz_episode(
    scenario: str, kind: str, seed: int = 0, backend: str = "libsumo", images: bool = False
) -> dict[str, Any]:
    """One episode of a bad driver; runs in a worker process. Never raises: an exception is
    returned as `error` (with its traceback) so one run reports every failing episode."""
    from drivehierarchy import _core
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    row: dict[str, Any] = {"scenario": scenario, "kind": kind, "seed": seed, "backend": backend}
    row["images"] = images
    t0 = time.perf_counter()
    env = None
    try:
        agent = make_bad_agent(kind, seed)
        overrides: dict[str, Any] = {"sumo_backend": backend, "action_mode": agent.action_mode}
        if not images:
            overrides.update(front=None, bev=None, prompt=False)
        env = DriveHierarchyR4Env(scenario=scenario, **overrides)
        out = drive(env, agent, seed)
        rec = out["score"]
        rescored = _core.rescore(env.sim.episode_log())
        row.update(
            termination=rec["termination_reason"],
            score=float(rec["score_composed"]),
            steps=out["steps"],
            rejected=out["rejected"],
            parse_failures=rec.get("parse_failures"),
            traffic=env.traffic_mode,
            rescore_equal=comparable_record(rescored) == comparable_record(rec),
            record=comparable_record(rec),
            error=None,
        )
    except Exception as exc:  # reported, not raised: the caller lists every failing episode
        row.update(error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc())
    finally:
        if env is not None:
            try:
                env.close()
            except Exception as exc:
                row.setdefault("close_error", f"{type(exc).__name__}: {exc}")
    row["wall_s"] = round(time.perf_counter() - t0, 3)
    return row
