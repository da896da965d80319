"""RL-ready views of `DriveHierarchy-R4`: normalised actions, a scaled flat state, a small BEV image,
an optional shaped training reward, and a scenario sampler over a suite.

Every transform lives in a small codec (`ActionCodec`, `ObsCodec`) described by one JSON-able
`WrapperConfig`, so a trained policy is driven through exactly the same mapping at evaluation
time (`drivehierarchy.agents.sb3`, which reads the config stored inside `model.zip`).

The shaped reward is a training signal only: the env's own reward, `score()` record and
`info` are never changed (the wrappers sit outside the env), so the benchmark score of an
episode is the protocol's whatever the training reward was.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Literal

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from drivehierarchy._core import ConfigError
from drivehierarchy.envs.config import ACTION_LEVELS, ActionMode, BevConfig, R4Config
from drivehierarchy.envs.r4 import PATH_ACTIONS, SPEED_ACTIONS, STATE_FIELDS, DriveHierarchyR4Env

ObsKind = Literal["state", "bev", "state+bev"]
ActionKind = Literal["decision", "raw"]
ActionLevel = Literal["control", "waypoints", "meta"]
_DEFAULT_ENV = R4Config()

# The protocol's BEV covers 800 px / 8 px/m = 100 m; the small BEV keeps that field of view.
PROTOCOL_BEV_SPAN_M = 100.0
STATE_CLIP = 10.0


@dataclass(frozen=True)
class RewardConfig:
    """Weights of the shaped training reward (per decision step).

    r = score·r_env + progress·Δ(best route progress)/10 m − comfort·(Δsteer)²
        − terminal penalty by termination reason (collision, off-road, blocked; 0 at the goal).
    """

    score: float = 10.0
    progress: float = 1.0
    comfort: float = 0.1
    collision: float = 10.0
    offroad: float = 10.0
    blocked: float = 5.0
    timeout: float = 2.0


@dataclass(frozen=True)
class WrapperConfig:
    """How the env is presented to a learner (saved with every trained model)."""

    action: ActionKind = "decision"
    # Normalised a[1] ∈ [−1, 1] maps linearly to target speed ∈ [0, max_speed_mps] (0 → half of it,
    # so an untrained policy starts by driving rather than standing still).
    max_speed_mps: float = 16.0
    obs: ObsKind = "state"
    bev_size: int = 128
    reward: Literal["score", "shaped"] = "shaped"
    shaping: RewardConfig = field(default_factory=RewardConfig)
    # Background traffic of the training envs ("sumo", "idm", "none"; None = each scenario's).
    traffic: str | None = None
    # The level the policy decides at (`--action-level`, docs/r4.md#action-levels): "control"
    # (`action` above), "waypoints" (`waypoints` points `waypoint_dt_s` apart) or "meta" (a path
    # action × a speed action). Models saved before the levels existed read as "control".
    action_level: ActionLevel = "control"
    waypoints: int = _DEFAULT_ENV.waypoints
    waypoint_dt_s: float = _DEFAULT_ENV.waypoint_dt_s

    def __post_init__(self) -> None:
        if self.action not in ("decision", "raw"):
            raise ConfigError(f"config `action` = {self.action!r}: expected 'decision' or 'raw'")
        if self.action_level not in ACTION_LEVELS:
            raise ConfigError(
                f"config `action_level` = {self.action_level!r}: expected one of {', '.join(ACTION_LEVELS)}"
            )
        if self.action_level != "control" and self.action != "decision":
            raise ConfigError(
                f"config `action` = {self.action!r}: a control mode, but `action_level` is "
                f"{self.action_level!r} (raw control is the control level only)"
            )
        # R4Config checks the plan's shape with the env's own messages.
        R4Config(waypoints=self.waypoints, waypoint_dt_s=self.waypoint_dt_s, front=None, bev=None)
        if self.obs not in ("state", "bev", "state+bev"):
            raise ConfigError(f"config `obs` = {self.obs!r}: expected 'state', 'bev' or 'state+bev'")
        if self.reward not in ("score", "shaped"):
            raise ConfigError(f"config `reward` = {self.reward!r}: expected 'score' or 'shaped'")
        if not 0.0 < float(self.max_speed_mps) <= 30.0:
            raise ConfigError(f"config `max_speed_mps` = {self.max_speed_mps!r}: expected in (0, 30]")
        if not 16 <= int(self.bev_size) <= 800:
            raise ConfigError(f"config `bev_size` = {self.bev_size!r}: expected 16..800 pixels")
        if self.traffic is not None:
            from drivehierarchy.envs.traffic.modes import canonical_traffic_mode

            object.__setattr__(self, "traffic", canonical_traffic_mode(self.traffic, stacklevel=3))

    @property
    def uses_images(self) -> bool:
        return self.obs != "state"

    @property
    def env_action_mode(self) -> ActionMode:
        """The env's `action_mode` this policy drives."""
        return self.action if self.action_level == "control" else ACTION_LEVELS[self.action_level]

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> WrapperConfig:
        data = dict(data)
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"config `{unknown[0]}` = {data[unknown[0]]!r}: unknown wrapper setting")
        shaping = data.pop("shaping", None)
        if isinstance(shaping, dict):
            rknown = {f.name for f in dataclasses.fields(RewardConfig)}
            bad = sorted(set(shaping) - rknown)
            if bad:
                raise ConfigError(f"config `shaping.{bad[0]}` = {shaping[bad[0]]!r}: unknown reward weight")
            data["shaping"] = RewardConfig(**shaping)
        return cls(**data)

    def bev_config(self) -> BevConfig:
        """The policy's BEV: `bev_size` pixels over the protocol's 100 m field of view."""
        return BevConfig(size_px=self.bev_size, px_per_m=self.bev_size / PROTOCOL_BEV_SPAN_M)

    def env_config(self, base: R4Config | None = None) -> R4Config:
        """The env settings this view needs: no front camera or prompt; a small BEV if used."""
        base = base or R4Config()
        bev = self.bev_config() if self.uses_images else None
        traffic = self.traffic if self.traffic is not None else base.traffic
        return base.replace(
            action_mode=self.env_action_mode,
            waypoints=self.waypoints,
            waypoint_dt_s=self.waypoint_dt_s,
            front=None,
            bev=bev,
            prompt=False,
            traffic=traffic,
        )


# -- actions ------------------------------------------------------------------------------------
class ActionCodec:
    """The policy's action ↔ the env's action, by level.

    control, decision: a ∈ [−1, 1]², [steer, speed] → [steer, (speed + 1)/2 · max_speed] (the
    protocol's bridge then turns it into pedals); raw: [steer, accel] → [throttle = max(accel, 0),
    brake = max(−accel, 0), steer].
    waypoints: a ∈ [−1, 1]^(K×2); point i (at t_i = (i + 1)·dt) is x = (a_x + 1)/2 · r_i forward and
    y = a_y · r_i left, r_i = max_speed · t_i the farthest the car gets by then at max_speed (so
    every action is a plan the car can drive, and a = 0 drives straight on at half max_speed, like
    the control level).
    meta: the env's `MultiDiscrete([6, 4])` as it is (path action, speed action).
    """

    def __init__(self, config: WrapperConfig) -> None:
        self.kind = config.action
        self.level = config.action_level
        self.max_speed = float(config.max_speed_mps)
        self.space: spaces.Space[Any]
        if self.level == "meta":
            self.space = spaces.MultiDiscrete([len(PATH_ACTIONS), len(SPEED_ACTIONS)])
        elif self.level == "waypoints":
            k = int(config.waypoints)
            self.space = spaces.Box(-1.0, 1.0, (k, 2), np.float32)
            reach = self.max_speed * float(config.waypoint_dt_s) * np.arange(1, k + 1, dtype=np.float32)
            self.reach = reach.reshape(k, 1).astype(np.float32)
        else:
            self.space = spaces.Box(-1.0, 1.0, (2,), np.float32)

    def decode(self, a: np.ndarray) -> np.ndarray:
        if self.level == "meta":
            # Out-of-range indices (a stray sample) are clipped into the space, as Box actions are.
            idx = np.asarray(a).reshape(2).astype(np.int64)
            return np.clip(idx, 0, np.asarray(self.space.nvec) - 1)  # type: ignore[attr-defined]
        if self.level == "waypoints":
            w = np.clip(np.asarray(a, dtype=np.float32).reshape(self.reach.shape[0], 2), -1.0, 1.0)
            x = (w[:, :1] + 1.0) * 0.5 * self.reach
            return np.concatenate([x, w[:, 1:] * self.reach], axis=1).astype(np.float32)
        a = np.clip(np.asarray(a, dtype=np.float32).reshape(2), -1.0, 1.0)
        if self.kind == "decision":
            return np.array([a[0], (a[1] + 1.0) * 0.5 * self.max_speed], np.float32)
        return np.array([max(a[1], 0.0), max(-a[1], 0.0), a[0]], np.float32)

    def encode(self, env_action: np.ndarray) -> np.ndarray:
        """The policy action that decodes to (the clipped) `env_action` (for imitation labels)."""
        if self.level == "meta":
            return self.decode(env_action)
        e = np.asarray(env_action, dtype=np.float32)
        if self.level == "waypoints":
            w = e.reshape(self.reach.shape[0], 2) / self.reach
            out = np.concatenate([2.0 * w[:, :1] - 1.0, w[:, 1:]], axis=1)
        elif self.kind == "decision":
            out = np.array([e[0], 2.0 * e[1] / self.max_speed - 1.0], np.float32)
        else:
            out = np.array([e[2], e[0] - e[1]], np.float32)
        return np.clip(out, -1.0, 1.0).astype(np.float32)

    def perturb(self, env_action: np.ndarray, rng: np.random.Generator, noise: float) -> np.ndarray:
        """DART-style noise of strength `noise` on an env action (what the collector executes;
        labels stay clean), of the same size at every level: control σ·[0.1 steer, 2 m/s speed];
        waypoints a lateral drift growing to σ·1 m at the plan's end and the speed scaled by
        (1 + σ·0.15·N); meta a uniformly random action with probability min(0.1·σ, 1)."""
        if self.level == "meta":
            if rng.random() < min(0.1 * noise, 1.0):
                return rng.integers(0, np.asarray(self.space.nvec)).astype(np.int64)  # type: ignore[attr-defined]
            return np.asarray(env_action, np.int64)
        if self.level == "waypoints":
            plan = np.array(env_action, dtype=np.float32).reshape(self.reach.shape[0], 2)
            k = plan.shape[0]
            drift, scale = rng.normal(0.0, noise), 1.0 + 0.15 * rng.normal(0.0, noise)
            plan[:, 0] *= max(scale, 0.0)
            plan[:, 1] += drift * np.arange(1, k + 1, dtype=np.float32) / k
            return self.decode(self.encode(plan))  # into the policy's range
        a = np.asarray(env_action, np.float32)
        if self.kind != "decision":
            raise ConfigError("config `action` = 'raw': demonstrations are decisions, not raw control")
        a = a + rng.normal(0.0, noise, 2).astype(np.float32) * np.array([0.1, 2.0], np.float32)
        return np.clip(a, [-1.0, 0.0], [1.0, 30.0]).astype(np.float32)


# -- observations ---------------------------------------------------------------------------------
def _field_scale(name: str) -> float:
    if name in ("speed_mps",) or name.endswith("_speed_mps"):
        return 10.0
    if name in ("progress_m", "route_length_m", "distance_to_go_m"):
        return 100.0
    if name == "time_s":
        return 60.0
    if name == "lateral_offset_m":
        return 2.0
    if name.endswith("heading_rad"):
        return float(np.pi)
    if name.startswith(("route_p", "actor")) and name.endswith("_m"):
        return 20.0
    if name == "light_ahead_distance_m":
        return 50.0
    return 1.0  # flags, controls, heading error (rad)


_SCALE = np.array([_field_scale(n) for n in STATE_FIELDS], np.float32)
_COMMAND = STATE_FIELDS.index("command")
N_COMMANDS = 6


class ObsCodec:
    """The env's observation dict → what the policy sees.

    state: the 60 state fields each divided by a fixed scale (metres by 20–100, speeds by 10, …),
    the navigation command one-hot (6) instead of its code, clipped to ±10 — fixed, so nothing
    has to be saved beside the model. bev: the small BEV image (H×W×3 uint8), rendered at
    that size by the world (never resized from another image).
    """

    def __init__(self, config: WrapperConfig) -> None:
        self.kind = config.obs
        self.bev_size = int(config.bev_size)
        self.bev_config = config.bev_config()
        self.state_dim = len(STATE_FIELDS) - 1 + N_COMMANDS
        state_space = spaces.Box(-STATE_CLIP, STATE_CLIP, (self.state_dim,), np.float32)
        bev_space = spaces.Box(0, 255, (self.bev_size, self.bev_size, 3), np.uint8)
        if self.kind == "state":
            self.space: spaces.Space[Any] = state_space
        elif self.kind == "bev":
            self.space = bev_space
        else:
            self.space = spaces.Dict({"bev": bev_space, "state": state_space})

    def state(self, raw: np.ndarray) -> np.ndarray:
        s = np.asarray(raw, dtype=np.float32) / _SCALE
        onehot = np.zeros(N_COMMANDS, np.float32)
        cmd = round(float(raw[_COMMAND]))
        if 1 <= cmd <= N_COMMANDS:
            onehot[cmd - 1] = 1.0
        out = np.concatenate([np.delete(s, _COMMAND), onehot])
        return np.clip(out, -STATE_CLIP, STATE_CLIP).astype(np.float32)

    def bev(self, obs: dict[str, Any], sim: Any = None) -> np.ndarray:
        """The policy's BEV. With `sim` (an evaluation env playing the protocol's 800×800 BEV, or
        none), the world renders it at the policy's size: the same renderer and settings as a
        training env's observation, so a policy sees byte-identical images in training and at
        evaluation (a downsampled 800×800 BEV differs: its route line is faint at 128 px)."""
        if sim is not None:
            return np.asarray(sim.render_bev(self.bev_config), dtype=np.uint8)
        img = obs.get("bev")
        if img is None:
            raise ConfigError("config `obs` = 'bev': the env gives no BEV image (bev=None)")
        img = np.asarray(img, dtype=np.uint8)
        if img.shape[:2] != (self.bev_size, self.bev_size):
            raise ConfigError(
                f"config `bev.size_px` = {img.shape[0]}: the policy sees a {self.bev_size}×"
                f"{self.bev_size} BEV rendered at that size (`WrapperConfig.env_config`), or pass "
                "the env's `sim` to render it"
            )
        return img

    def encode(self, obs: dict[str, Any], sim: Any = None) -> Any:
        """What the policy sees of `obs`; `sim` (optional) renders the BEV (see `bev`)."""
        if self.kind == "state":
            return self.state(obs["state"])
        if self.kind == "bev":
            return self.bev(obs, sim)
        return {"bev": self.bev(obs, sim), "state": self.state(obs["state"])}


# -- the scenario sampler -----------------------------------------------------------------------
def split_suite(
    scenarios: Sequence[Path], held_out: float | Sequence[str] = 0.3
) -> tuple[list[Path], list[Path]]:
    """Splits scenario files into (train, held-out), by file.

    `held_out` is a fraction (files ranked by a hash of `<category>/<file name>`, so the split is
    stable and does not depend on the order or the machine) or a list of `<category>/<stem>` ids.
    """
    paths = [Path(p) for p in scenarios]
    ids = [f"{p.parent.name}/{p.stem}" for p in paths]
    if isinstance(held_out, (int, float)):
        if not 0.0 <= float(held_out) < 1.0:
            raise ConfigError(f"config `held_out` = {held_out!r}: expected a fraction in [0, 1)")
        n_out = round(len(paths) * float(held_out))
        ranked = sorted(range(len(paths)), key=lambda i: hashlib.sha256(ids[i].encode()).hexdigest())
        out_set = {ids[i] for i in ranked[:n_out]}
    else:
        out_set = set(held_out)
        unknown = sorted(out_set - set(ids))
        if unknown:
            raise ConfigError(f"config `held_out` = {unknown[0]!r}: not a scenario of the suite")
    train = [p for p, i in zip(paths, ids, strict=True) if i not in out_set]
    test = [p for p, i in zip(paths, ids, strict=True) if i in out_set]
    if not train:
        raise ConfigError(f"config `held_out` = {held_out!r}: leaves no training scenario")
    return train, test


class SuiteEnv(gym.Env[dict[str, Any], np.ndarray]):
    """One `DriveHierarchy-R4` over many scenario files: each reset drives one of them.

    The scenario is drawn from the env's seeded `np_random` (uniformly, or in turn with
    `order="cycle"`), or forced with `reset(options={"scenario": path})`. One Rust world is kept per
    scenario, so switching costs nothing after the first load. With `train_seeds=(lo, hi)` (a
    training env, see `splits`) every episode seed is drawn from [lo, hi), an explicit
    `reset(seed=s)` only seeding that draw, so the benchmark's test seeds are never played.
    `expert_action()`, `score()`, `sim` and `scenario_path` refer to the current scenario, so the
    expert and the runner work unchanged.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}  # type: ignore[misc]

    def __init__(
        self,
        scenarios: Sequence[str | Path],
        config: R4Config | None = None,
        order: Literal["random", "cycle"] = "random",
        train_seeds: tuple[int, int] | None = None,
    ) -> None:
        if not scenarios:
            raise ConfigError("config `scenarios` = []: the suite has no scenario files")
        if order not in ("random", "cycle"):
            raise ConfigError(f"config `order` = {order!r}: expected 'random' or 'cycle'")
        self.scenarios = [str(p) for p in scenarios]
        self.config = config or R4Config()
        self.order = order
        if train_seeds is not None and not 0 <= train_seeds[0] < train_seeds[1]:
            raise ConfigError(f"config `train_seeds` = {train_seeds!r}: expected 0 ≤ lo < hi")
        self.train_seeds = train_seeds
        self._envs: dict[str, DriveHierarchyR4Env] = {}
        self._cycle = 0
        self.episode_seed: int | None = None
        self.current = self._env(self.scenarios[0])
        self.observation_space = self.current.observation_space
        self.action_space = self.current.action_space

    def _env(self, path: str) -> DriveHierarchyR4Env:
        env = self._envs.get(path)
        if env is None:
            env = DriveHierarchyR4Env(scenario=path, config=self.config)
            self._envs[path] = env
        return env

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        path = options.pop("scenario", None)
        if path is None:
            if self.order == "cycle":
                path = self.scenarios[self._cycle % len(self.scenarios)]
                self._cycle += 1
            else:
                path = self.scenarios[int(self.np_random.integers(len(self.scenarios)))]
        previous, self.current = self.current, self._env(str(path))
        if previous is not self.current:
            # One libsumo simulation per process: the scenario left behind gives SUMO back.
            previous.release_traffic()
        # An explicit seed reaches the scenario as given (reset(seed=0) is the canonical scenario,
        # as in `r4 evaluate`); unseeded resets draw one, so training sees the seeded variations.
        if self.train_seeds is not None:
            sub_seed = int(self.np_random.integers(*self.train_seeds))
        else:
            sub_seed = seed if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
        obs, info = self.current.reset(seed=sub_seed, options=options)
        info = dict(info)
        info["scenario"] = str(path)
        info["episode_seed"] = self.episode_seed = sub_seed
        return obs, info

    def step(self, action: Any) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        return self.current.step(action)

    # privileged / runner access to the current scenario
    def expert_action(self) -> np.ndarray:
        return self.current.expert_action()

    def score(self) -> dict[str, Any]:
        return self.current.score()

    @property
    def sim(self) -> Any:
        return self.current.sim

    @property
    def scenario_path(self) -> str:
        return self.current.scenario_path

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()


# -- wrappers -----------------------------------------------------------------------------------
class NormalizedActions(gym.ActionWrapper[Any, np.ndarray, np.ndarray]):
    """The policy's action space of the level: [−1, 1]², [−1, 1]^(K×2) or the meta
    `MultiDiscrete` (see `ActionCodec`)."""

    def __init__(self, env: gym.Env[Any, Any], config: WrapperConfig) -> None:
        super().__init__(env)
        self.codec = ActionCodec(config)
        self.action_space = self.codec.space

    def action(self, action: np.ndarray) -> np.ndarray:
        return self.codec.decode(action)


class PolicyObservation(gym.ObservationWrapper[Any, Any, dict[str, Any]]):
    """The flat scaled state, the small BEV, or both (see `ObsCodec`)."""

    def __init__(self, env: gym.Env[Any, Any], config: WrapperConfig) -> None:
        super().__init__(env)
        self.codec = ObsCodec(config)
        self.observation_space = self.codec.space

    def observation(self, observation: dict[str, Any]) -> Any:
        return self.codec.encode(observation)


class ShapedReward(gym.Wrapper[Any, Any, Any, Any]):
    """Training reward (see `RewardConfig`). The env's own per-step reward is kept in
    `info["score_reward"]`; the env's `score()` record is untouched."""

    def __init__(self, env: gym.Env[Any, Any], config: RewardConfig) -> None:
        super().__init__(env)
        self.weights = config
        self._best = 0.0
        self._steer = 0.0

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self._best = float(info.get("best_progress_m", 0.0))
        self._steer = float(info.get("control", {}).get("steer", 0.0))
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        w = self.weights
        best = float(info.get("best_progress_m", self._best))
        steer = float(info.get("control", {}).get("steer", self._steer))
        shaped = (
            w.score * float(reward)
            + w.progress * (best - self._best) / 10.0
            - w.comfort * (steer - self._steer) ** 2
        )
        self._best, self._steer = best, steer
        if terminated:
            shaped -= terminal_penalty(w, info.get("termination_reason"))
        info = dict(info)
        info["score_reward"] = reward
        return obs, float(shaped), terminated, truncated, info


def terminal_penalty(w: RewardConfig, reason: str | None) -> float:
    if reason is None or reason == "destination_reached":
        return 0.0
    if reason.startswith("collision"):
        return w.collision
    if reason == "offroad_timeout":  # a route deviation ends as offroad_timeout too
        return w.offroad
    if reason == "blocked_timeout":
        return w.blocked
    return w.timeout


def make_env(
    scenarios: Sequence[str | Path],
    config: WrapperConfig | None = None,
    *,
    base: R4Config | None = None,
    order: Literal["random", "cycle"] = "random",
    monitor: bool = True,
    train_seeds: tuple[int, int] | None = None,
) -> gym.Env[Any, Any]:
    """A learner's env over `scenarios`: sampler → (shaped reward) → normalised actions → policy
    observation (→ SB3 `Monitor`, which records episode returns and lengths). `train_seeds`:
    see `SuiteEnv` (training passes `splits.Split.train_seeds`)."""
    config = config or WrapperConfig()
    env: gym.Env[Any, Any] = SuiteEnv(
        scenarios, config.env_config(base), order=order, train_seeds=train_seeds
    )
    if config.reward == "shaped":
        env = ShapedReward(env, config.shaping)
    env = NormalizedActions(env, config)
    env = PolicyObservation(env, config)
    if monitor:
        from stable_baselines3.common.monitor import Monitor

        env = Monitor(env, info_keywords=("termination_reason",))
    return env
