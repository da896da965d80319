"""The privileged expert autopilot (Rust, `dh-agents`) as an `Agent`.

It reads the world directly through the env's Rust episode (positions of every actor and the
state of every light) — privileged, like CARLA's autopilot — and answers in the env's action
space, so it is scored through exactly the interface a VLM uses."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np


class ExpertAgent:
    name = "expert"
    uses_images = False

    def __init__(self) -> None:
        self._env: Any = None

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        self._env = env.unwrapped
        if not hasattr(self._env, "expert_action"):
            raise TypeError(f"ExpertAgent needs a DriveHierarchy-R4 env, got {type(self._env).__name__}")

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        if self._env is None:
            raise RuntimeError("ExpertAgent.act called before reset")
        return np.asarray(self._env.expert_action(), dtype=np.float32)
