"""A Stable-Baselines3 `VecEnv` over the native vector env: SB3 training at Rust batch speed.

`NativeSuiteVecEnv(scenarios, WrapperConfig(), n_envs)` is what `DummyVecEnv` of N
`make_env(scenarios, wrapper)` learner envs is (scenario sampler → shaped reward → normalised
actions → policy observation), stepped as one `DriveHierarchyR4VectorEnv` batch: the N worlds
step on Rust threads with the GIL released and come back as one array.

It equals that `DummyVecEnv` step for step (`tests/baselines/test_vec_sb3.py`): env i draws its
scenario and episode seed from its own generator exactly as `SuiteEnv` does (seeded `seed + i`
by `seed()`), the policy observation, action decoding and shaped reward are the same codecs,
and on the step an episode ends the env is reset at once (`autoreset_mode=DISABLED` +
`reset(options={"reset_mask": ...})`) with the last observation in `infos[i]["terminal_observation"]`
and the new episode's reset info in `reset_infos[i]`, as SB3 defines it.

Every action level works (`WrapperConfig(action_level="waypoints" | "meta")`): the batch's worlds
take the level's plans as rows, like the single env.

The native vector env runs no SUMO: pass `WrapperConfig(traffic="idm")` (or "none") for suites
with SUMO scenarios; with `traffic=None` a SUMO scenario is refused with its name.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices, VecEnvObs, VecEnvStepReturn
from stable_baselines3.common.vec_env.util import obs_space_info

from drivehierarchy._core import ConfigError
from drivehierarchy.baselines.wrappers import (
    ActionCodec,
    ObsCodec,
    RewardConfig,
    WrapperConfig,
    terminal_penalty,
)
from drivehierarchy.envs.config import R4Config
from drivehierarchy.envs.vector_native import DriveHierarchyR4VectorEnv, drop_none


class NativeSuiteVecEnv(VecEnv):
    """`n_envs` learner envs over `scenarios` in one native batch (see the module docs).

    `train_seeds=(lo, hi)`: every episode seed is drawn from [lo, hi) (see `splits`); `order`
    as `SuiteEnv`'s; `threads`: the batch's worker threads (0 = one per core)."""

    def __init__(
        self,
        scenarios: Sequence[str | Path],
        wrapper: WrapperConfig | None = None,
        n_envs: int = 8,
        *,
        base: R4Config | None = None,
        order: Literal["random", "cycle"] = "random",
        train_seeds: tuple[int, int] | None = None,
        threads: int = 0,
    ) -> None:
        if not scenarios:
            raise ConfigError("config `scenarios` = []: the suite has no scenario files")
        if order not in ("random", "cycle"):
            raise ConfigError(f"config `order` = {order!r}: expected 'random' or 'cycle'")
        if train_seeds is not None and not 0 <= train_seeds[0] < train_seeds[1]:
            raise ConfigError(f"config `train_seeds` = {train_seeds!r}: expected 0 ≤ lo < hi")
        self.wrapper = wrapper or WrapperConfig()
        self.scenarios = [str(p) for p in scenarios]
        self.order = order
        self.train_seeds = train_seeds
        self.venv = DriveHierarchyR4VectorEnv(
            num_envs=n_envs,
            scenario=[self.scenarios[0]] * n_envs,
            config=self.wrapper.env_config(base),
            threads=threads,
            autoreset_mode=AutoresetMode.DISABLED,
        )
        self.obs_codec = ObsCodec(self.wrapper)
        self.action_codec = ActionCodec(self.wrapper)
        self.shaping: RewardConfig | None = self.wrapper.shaping if self.wrapper.reward == "shaped" else None
        self.render_mode = None  # read by VecEnv.__init__ through get_attr
        super().__init__(n_envs, self.obs_codec.space, self.action_codec.space)
        self.keys, _, _ = obs_space_info(self.observation_space)
        self._rngs: list[np.random.Generator | None] = [None] * n_envs
        self._cycles = [0] * n_envs
        self._best = np.zeros(n_envs)
        self._steer = np.zeros(n_envs)
        self._actions: np.ndarray | None = None
        self._options_scenario: list[str | None] = [None] * n_envs
        # What SuiteEnv reports beside the env's reset info (its sampler's choice).
        self.episode_seeds: list[int | None] = [None] * n_envs

    # -- the sampler (SuiteEnv's draws, one generator per env) -----------------------------------
    def _draw(self, i: int, seed: int | None) -> tuple[str, int]:
        rng = self._rngs[i]
        if seed is not None or rng is None:
            rng, _ = seeding.np_random(seed)
            self._rngs[i] = rng
        forced = self._options_scenario[i]
        if forced is not None:
            path = forced
        elif self.order == "cycle":
            path = self.scenarios[self._cycles[i] % len(self.scenarios)]
            self._cycles[i] += 1
        else:
            path = self.scenarios[int(rng.integers(len(self.scenarios)))]
        if self.train_seeds is not None:
            sub_seed = int(rng.integers(*self.train_seeds))
        else:
            sub_seed = seed if seed is not None else int(rng.integers(0, 2**31 - 1))
        return path, sub_seed

    def _reset_envs(
        self, mask: np.ndarray, seeds: Sequence[int | None]
    ) -> tuple[dict[str, Any], list[dict[str, Any]]]:
        """Resets the envs of `mask`; returns the whole batch's raw observation and the reset
        infos (as `SuiteEnv` gives them) of those envs (empty dicts elsewhere)."""
        draws = {int(i): self._draw(int(i), seeds[int(i)]) for i in np.flatnonzero(mask)}
        scen = [draws[i][0] if i in draws else None for i in range(self.num_envs)]
        sub = [draws[i][1] if i in draws else None for i in range(self.num_envs)]
        options: dict[str, Any] = {"scenario": scen}
        if not mask.all():
            options["reset_mask"] = mask
        obs, _ = self.venv.reset(seed=sub, options=options)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i, (path, s) in draws.items():
            info = dict(self.venv.env_infos[i] or {})
            info["scenario"] = path
            info["episode_seed"] = self.episode_seeds[i] = s
            self._best[i] = float(info.get("best_progress_m", 0.0))
            self._steer[i] = float((info.get("control") or {}).get("steer", 0.0))
            infos[i] = info
        return obs, infos

    def _encode(self, raw: dict[str, Any], i: int) -> Any:
        one = {k: raw[k][i] for k in raw if k != "prompt"}
        return self.obs_codec.encode(one)

    def _stack(self, items: list[Any]) -> VecEnvObs:
        if isinstance(items[0], dict):
            return {k: np.stack([o[k] for o in items]) for k in self.keys}
        return np.stack(items)

    # -- SB3 VecEnv API ----------------------------------------------------------------------------
    def reset(self) -> VecEnvObs:
        seeds = list(self._seeds)
        opts = [o.get("scenario") if isinstance(o, dict) else None for o in self._options]
        self._options_scenario = [None if s is None else str(s) for s in opts]
        raw, infos = self._reset_envs(np.ones(self.num_envs, dtype=np.bool_), seeds)
        self._options_scenario = [None] * self.num_envs
        self.reset_infos = infos
        self._reset_seeds()
        self._reset_options()
        return self._stack([self._encode(raw, i) for i in range(self.num_envs)])

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise gym.error.ResetNeeded("step_wait() without step_async(actions)")
        env_actions = np.stack([self.action_codec.decode(a) for a in self._actions])
        self._actions = None
        raw, rewards, terminated, truncated, _ = self.venv.step(env_actions)
        step_infos = [dict(drop_none(info or {})) for info in self.venv.env_infos]
        dones = np.logical_or(terminated, truncated)
        shaped = np.zeros(self.num_envs, np.float32)
        obs = [self._encode(raw, i) for i in range(self.num_envs)]
        for i, info in enumerate(step_infos):
            r = float(rewards[i])
            if self.shaping is not None:
                w = self.shaping
                best = float(info.get("best_progress_m", self._best[i]))
                steer = float((info.get("control") or {}).get("steer", self._steer[i]))
                r = (
                    w.score * r
                    + w.progress * (best - self._best[i]) / 10.0
                    - w.comfort * (steer - self._steer[i]) ** 2
                )
                self._best[i], self._steer[i] = best, steer
                if terminated[i]:
                    r -= terminal_penalty(w, info.get("termination_reason"))
                info["score_reward"] = rewards[i]
            shaped[i] = r
            info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        if dones.any():
            ended = np.flatnonzero(dones).tolist()
            for k in ended:
                step_infos[k]["terminal_observation"] = obs[k]
            raw2, reset_infos = self._reset_envs(dones, [None] * self.num_envs)
            for k in ended:
                obs[k] = self._encode(raw2, k)
                self.reset_infos[k] = reset_infos[k]
        return self._stack(obs), shaped, dones, step_infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return [getattr(self, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise ConfigError(
            f"config `set_attr` = {attr_name!r}: the native batch's envs share their settings; "
            "make a new NativeSuiteVecEnv instead"
        )

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        """Per-env methods of the single env that make sense on a batch member: `score`."""
        if method_name != "score":
            raise ConfigError(
                f"config `env_method` = {method_name!r}: the native batch offers per env only 'score'"
            )
        return [self.venv.score(i) for i in self._get_indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper[Any, Any, Any, Any]], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def _get_indices(self, indices: VecEnvIndices) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return list(indices)
