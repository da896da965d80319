"""`DriveHierarchy-R4` as a native vector env: N Rust worlds stepped on a thread pool.

`gymnasium.make_vec("DriveHierarchy-R4", num_envs=N, vectorization_mode="vector_entry_point")`
builds `DriveHierarchyR4VectorEnv`. One `step()` hands the N actions to Rust
(`_core.SimBatch`), which steps the N worlds on a rayon pool with the GIL released and returns
each observation key as one (N, …) array (`prompt`: a tuple of N str). Everything else is the
single env's: same config, observation and action spaces, rewards and infos, so the batch equals
N `DriveHierarchyR4Env`s in a `SyncVectorEnv` step for step.

Autoreset is Gymnasium 1.x's default (`NEXT_STEP`): the step after an env terminates resets it
(its action is ignored, reward 0) and returns the new episode's first observation. Seeds follow
`SyncVectorEnv`: `reset(seed=s)` seeds env i with `s + i`, a list seeds each env, and the world
seed of every reset (autoresets too) is drawn from the env's own `np_random` exactly as the
single env draws it. `info` is batched as Gymnasium batches it (arrays + `_key` masks), except
that a `None` value counts as absent (see `drop_none`). `reset(options={"scenario": ...})`
switches the scenario of every env (a str) or of each env (a list of N, `None` keeps one).

`autoreset_mode=AutoresetMode.DISABLED` leaves terminated envs alone until the caller resets
them, and `reset(options={"reset_mask": mask})` resets only the envs where `mask` is True (the
others keep their episode; `info` holds the reset envs only), as Gymnasium 1.x's vector API
defines it — what an SB3 `VecEnv` built on it (`baselines.vec_sb3`) needs. `env_infos` holds
the last call's per-env info dicts unbatched (`None` for envs the call left alone).

SUMO traffic is refused (each world would need its own SUMO process): pass `traffic="idm"`
for the Rust IDM traffic, or use `envs.traffic.sumo_vector_env` (docs/baselines.md).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from drivehierarchy import _core
from drivehierarchy._core import ConfigError
from drivehierarchy.envs.config import R4Config
from drivehierarchy.envs.r4 import (
    _shallow,
    single_spaces,
)
from drivehierarchy.scenarios import resolve_scenario, sumo_home

_SEED_BOUND = 2**63 - 1  # the single env's world-seed draw: np_random.integers(0, 2**63 - 1)


def drop_none(info: dict[str, Any]) -> dict[str, Any]:
    """`info` without its `None` values (recursively): batched, an absent value is a False mask.

    Gymnasium batches a key by the type of the first env's value, so a `None` in one env (e.g.
    `reply` right after a reset) beside a dict in another (`reply` after a step) breaks
    `VectorEnv._add_info` (`SyncVectorEnv` of single envs fails the same way).
    """
    return {k: drop_none(v) if isinstance(v, dict) else v for k, v in info.items() if v is not None}


class DropNoneInfo(gym.Wrapper[dict[str, Any], np.ndarray, dict[str, Any], np.ndarray]):
    """A single env whose infos go through `drop_none`: what Gymnasium's `SyncVectorEnv` and
    `AsyncVectorEnv` need to batch `DriveHierarchy-R4` across autoresets (they fail on
    `reply=None` beside `reply={...}`), and what the native vector env's infos equal."""

    def reset(self, **kwargs: Any) -> tuple[dict[str, Any], dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return obs, drop_none(info)

    def step(self, action: Any) -> tuple[dict[str, Any], Any, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, drop_none(info)


class DriveHierarchyR4VectorEnv(VectorEnv[dict[str, Any], np.ndarray, np.ndarray]):
    """N `DriveHierarchy-R4` episodes stepped in Rust on a thread pool (see the module docs).

    **Arguments**: `num_envs`; `scenario` (one suite id or path for every env, or a sequence of
    `num_envs`); `config` (an `R4Config` or a dict) and any `R4Config` field as a keyword, as for
    the single env; `threads` (worker threads, 0 = one per core).
    """

    # Gymnasium declares `metadata` an instance variable (mypy refuses a ClassVar override).
    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}  # noqa: RUF012

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str | Path | Sequence[str | Path | None] | None = None,
        config: R4Config | dict[str, Any] | None = None,
        render_mode: str | None = None,
        *,
        threads: int = 0,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        **overrides: Any,
    ) -> None:
        if not isinstance(num_envs, int) or isinstance(num_envs, bool) or num_envs < 1:
            raise ConfigError(f"config `num_envs` = {num_envs!r}: expected an integer ≥ 1")
        if not isinstance(threads, int) or isinstance(threads, bool) or threads < 0:
            raise ConfigError(f"config `threads` = {threads!r}: expected an integer ≥ 0 (0 = one per core)")
        if render_mode is not None:
            raise ConfigError(
                f"config `render_mode` = {render_mode!r}: the native vector env does not render; "
                "add front/bev images to the observation instead"
            )
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in (AutoresetMode.NEXT_STEP, AutoresetMode.DISABLED):
            raise ConfigError(
                f"config `autoreset_mode` = {autoreset_mode!r}: expected AutoresetMode.NEXT_STEP or DISABLED"
            )
        self.autoreset_mode = mode
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        if isinstance(config, dict):
            config = R4Config.from_dict(config)
        config = config or R4Config()
        if overrides:
            config = R4Config.from_dict({**_shallow(config), **overrides})
        scenarios = self._per_env("scenario", scenario, num_envs)
        config = config.replace(scenario=None)
        self.config = config
        self.num_envs = num_envs
        self.render_mode = None
        self._paths = [resolve_scenario(None if s is None else str(s)) for s in scenarios]
        self._batch: Any = _core.SimBatch(self._paths, config.to_core(), config.traffic, sumo_home(), threads)

        self.single_observation_space, self.single_action_space = single_spaces(config)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._keys = tuple(self.single_observation_space.spaces)
        self._rngs: list[np.random.Generator | None] = [None] * num_envs
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._obs: dict[str, Any] | None = None
        self.env_infos: list[dict[str, Any] | None] = [None] * num_envs
        self._live = False
        self._closed_batch = False

    @property
    def scenario_ids(self) -> list[str]:
        """Each env's scenario id."""
        return list(self._batch.scenario_ids)

    @property
    def scenario_paths(self) -> list[str]:
        """Each env's scenario file."""
        return list(self._paths)

    def score(self, index: int) -> dict[str, Any]:
        """Env `index`'s scene score record so far (final once its episode has terminated)."""
        self._check_open("score")
        record: dict[str, Any] = self._batch.score(index)
        return record

    # -- Gymnasium API ---------------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        self._check_open("reset")
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, (int, np.integer)):
            seeds = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ConfigError(
                    f"config `seed` = {seed!r}: expected an int or a list of num_envs={self.num_envs} seeds"
                )
        options = dict(options or {})
        scenario = options.pop("scenario", None)
        mask = options.pop("reset_mask", None)
        if options:
            key = sorted(options)[0]
            raise ConfigError(
                f"config `options.{key}` = {options[key]!r}: unknown reset option of the native "
                "vector env (known: scenario, reset_mask)"
            )
        if mask is not None:
            if not (
                isinstance(mask, np.ndarray) and mask.dtype == np.bool_ and mask.shape == (self.num_envs,)
            ):
                raise ConfigError(
                    f"config `options.reset_mask` = {mask!r}: expected a bool numpy array of shape "
                    f"({self.num_envs},)"
                )
            if not mask.any():
                raise ConfigError(f"config `options.reset_mask` = {mask!r}: resets no env (all False)")
            if not self._live and not mask.all():
                raise gym.error.ResetNeeded("reset_mask before a first full reset(): reset every env first")
        else:
            mask = np.ones(self.num_envs, dtype=np.bool_)
        if scenario is not None:
            for i, s in enumerate(self._per_env("options.scenario", scenario, self.num_envs)):
                if s is not None and mask[i]:
                    path = resolve_scenario(str(s))
                    if path != self._paths[i]:
                        self._batch.load(i, path)
                        self._paths[i] = path
        if mask.all():
            resets = [self._draw(i, s) for i, s in enumerate(seeds)]
            obs, _, _, infos = self._batch.run(resets)
            self._obs = self._shape_obs(obs)
            self.env_infos = list(infos)
        else:
            assert self._obs is not None
            resets_some = [self._draw(i, s) if mask[i] else None for i, s in enumerate(seeds)]
            part, infos = self._batch.reset_some(resets_some)
            rows = np.flatnonzero(mask)
            self._obs = self._scatter(self._obs, self._shape_obs(part), rows)
            self.env_infos = [None] * self.num_envs
            for row, info in zip(rows.tolist(), infos, strict=True):
                self.env_infos[row] = info
        self._autoreset[mask] = False
        self._live = True
        return self._obs, self._batch_infos(self.env_infos)

    def step(
        self, actions: np.ndarray
    ) -> tuple[dict[str, Any], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._check_open("step")
        if not self._live:
            raise gym.error.ResetNeeded("step() before reset(): call reset() on the vector env first")
        arr = np.asarray(actions, dtype=np.float64)
        expected = self.action_space.shape
        if arr.shape != expected:
            raise ConfigError(f"config `actions` = {actions!r}: expected shape {expected}, got {arr.shape}")
        if self.autoreset_mode == AutoresetMode.DISABLED and self._autoreset.any():
            done = int(np.flatnonzero(self._autoreset)[0])
            raise gym.error.ResetNeeded(
                f"env {done} terminated and autoreset_mode is DISABLED: reset it first "
                "(reset(options={'reset_mask': mask}))"
            )
        arr = arr.reshape(self.num_envs, -1)  # waypoint plans (N, K, 2) go to the core as rows
        # Envs that autoreset ignore their action, as in SyncVectorEnv.
        stepping = ~self._autoreset
        if not np.all(np.isfinite(arr[stepping])):
            bad = int(np.flatnonzero(stepping & ~np.all(np.isfinite(arr), axis=1))[0])
            raise ConfigError(f"config `actions[{bad}]` = {arr[bad]!r}: contains NaN or infinity")
        resets = [self._draw(i, None) if self._autoreset[i] else None for i in range(self.num_envs)]
        obs, rewards, terminated, infos = self._batch.run(resets, np.ascontiguousarray(arr))
        truncated = np.zeros(self.num_envs, dtype=np.bool_)
        self._autoreset = terminated.copy()
        self._obs = self._shape_obs(obs)
        self.env_infos = list(infos)
        return self._obs, rewards, terminated, truncated, self._batch_infos(infos)

    def close_extras(self, **kwargs: Any) -> None:
        self._batch = None
        self._closed_batch = True
        self._live = False

    # -- helpers ---------------------------------------------------------------------------
    def _draw(self, i: int, seed: int | None) -> tuple[int, int]:
        """(world seed, variation) of env i's reset, as `DriveHierarchyR4Env.reset` draws them."""
        rng = self._rngs[i]
        if seed is not None:
            rng, _ = seeding.np_random(seed)
        elif rng is None:
            rng, _ = seeding.np_random()
        self._rngs[i] = rng
        world_seed = int(rng.integers(0, _SEED_BOUND))
        # Seed 0 plays the scenario as written, other seeds vary it; unseeded resets vary.
        return world_seed, int(seed) if seed is not None else world_seed

    def _shape_obs(self, raw: dict[str, Any]) -> dict[str, Any]:
        return {key: raw[key] for key in self._keys}

    def _batch_infos(self, infos: Sequence[dict[str, Any] | None]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for i, info in enumerate(infos):
            if info is not None:
                out = self._add_info(out, drop_none(info), i)
        return out

    @staticmethod
    def _scatter(old: dict[str, Any], part: dict[str, Any], rows: np.ndarray) -> dict[str, Any]:
        """`old` with rows `rows` replaced by `part`'s (new arrays: returned batches stay valid)."""
        out: dict[str, Any] = {}
        for key, value in old.items():
            if isinstance(value, tuple):  # prompt: a tuple of N str
                items = list(value)
                for j, i in enumerate(rows):
                    items[int(i)] = part[key][j]
                out[key] = tuple(items)
            else:
                arr = value.copy()
                arr[rows] = part[key]
                out[key] = arr
        return out

    def _check_open(self, what: str) -> None:
        if self._closed_batch:
            raise gym.error.ClosedEnvironmentError(
                f"{what}() on a closed DriveHierarchy-R4 vector env: make a new one (gym.make_vec)"
            )

    @staticmethod
    def _per_env(name: str, value: Any, n: int) -> list[Any]:
        if value is None or isinstance(value, (str, Path)):
            return [value] * n
        values = list(value)
        if len(values) != n:
            raise ConfigError(
                f"config `{name}` = {value!r}: expected one scenario or a sequence of num_envs={n}, "
                f"got {len(values)}"
            )
        return values
