"""A trained Stable-Baselines3 policy (`drivehierarchy baselines train ...`) as an `Agent`.

`Sb3Agent("runs/ppo/model.zip")`, or `drivehierarchy r4 evaluate --agent sb3:runs/ppo/model.zip`.
The archive carries the `WrapperConfig` the policy was trained with, and the agent applies the
same observation and action mapping to the plain env, so the policy is scored by the same
harness (and the same actuation bridge) as the expert and the VLMs. The archive also says the
action level the policy decides at (control, waypoints or meta): `r4 evaluate` drives the model at
that level without being told, and refuses another `--action-level` (`model_level`).

Security: loading an archive unpickles Python objects from it (Stable-Baselines3's `load`), which
can execute arbitrary code. Only load model files you trust (ones you trained, or from a source
you would run code from).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from drivehierarchy._core import ConfigError


class Sb3Agent:
    def __init__(self, path: str | Path, deterministic: bool = True) -> None:
        from drivehierarchy.baselines.wrappers import ActionCodec, ObsCodec

        self.path = Path(path)
        stat = self.path.stat() if self.path.is_file() else None
        key = (str(self.path.resolve()), stat.st_mtime_ns if stat else 0, stat.st_size if stat else 0)
        self.model, self.wrapper, self.meta = _load(*key)
        self.obs_codec = ObsCodec(self.wrapper)
        self.action_codec = ActionCodec(self.wrapper)
        self.deterministic = deterministic
        self.name = f"sb3:{self.path}"
        # A BEV policy renders its own small BEV from the env's world (`observe`), exactly as it
        # did in training; it never looks at the protocol's images, so runners can switch them off.
        self.uses_images = False
        self._sim: Any = None

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        config = getattr(env.unwrapped, "config", None)
        mode = getattr(config, "action_mode", None)
        if mode is not None and mode != self.wrapper.env_action_mode:
            raise ConfigError(
                f"config `action_mode` = {mode!r}: the model {self.path} was trained with "
                f"action mode {self.wrapper.env_action_mode!r} (action level {self.wrapper.action_level!r})"
            )
        if mode == "waypoints":
            plan = (config.waypoints, config.waypoint_dt_s)  # type: ignore[union-attr]
            trained = (self.wrapper.waypoints, self.wrapper.waypoint_dt_s)
            if plan != trained:
                raise ConfigError(
                    f"config `waypoints`/`waypoint_dt_s` = {plan!r}: the model {self.path} plans "
                    f"{trained[0]} points {trained[1]} s apart"
                )
        self._sim = getattr(env.unwrapped, "sim", None) if self.wrapper.uses_images else None

    def observe(self, observation: dict[str, Any]) -> Any:
        """What the policy sees: the scaled state and/or the BEV rendered at the policy's size by
        the world of the env given to `reset` (byte-identical to the training observation)."""
        return self.obs_codec.encode(observation, self._sim)

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        action, _ = self.model.predict(self.observe(observation), deterministic=self.deterministic)
        return self.action_codec.decode(action)


def model_level(path: str | Path, asked: str | None = None) -> tuple[str, str]:
    """(action level, env action mode) the model at `path` was trained at, read from its archive
    without loading the policy. `asked`: the level the user asked for (None = the model's); a
    different one is a `ConfigError` naming the model's."""
    from drivehierarchy.baselines.model_io import read_meta
    from drivehierarchy.baselines.wrappers import WrapperConfig

    wrapper = WrapperConfig.from_dict(read_meta(Path(path))["wrapper"])
    if asked is not None and asked != wrapper.action_level:
        raise ConfigError(
            f"config `action_level` = {asked!r}: the model {path} decides at the "
            f"{wrapper.action_level!r} level (leave out --action-level to drive it there)"
        )
    return wrapper.action_level, wrapper.env_action_mode


@lru_cache(maxsize=8)
def _load(path: str, mtime_ns: int, size: int) -> tuple[Any, Any, dict[str, Any]]:
    """One load per model file (a runner builds an agent per scenario); prediction is stateless."""
    from drivehierarchy.baselines.model_io import load_model

    return load_model(Path(path))
