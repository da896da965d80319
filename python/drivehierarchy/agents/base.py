"""The agent protocol: every policy (VLM, expert, RL, IL, scripted) sees only the Gymnasium
observation and info, so any of them runs in the same `run_episode(env, agent)` loop."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np


@runtime_checkable
class Agent(Protocol):
    """A driving policy. `reset` is called after each `env.reset`; `act` once per decision.

    An agent may set `uses_images = False` to let runners drop image observations (faster).
    """

    name: str

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None: ...

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray: ...


@dataclass
class EpisodeResult:
    score: dict[str, Any]
    steps: int
    total_reward: float
    infos: list[dict[str, Any]] = field(default_factory=list)


def run_episode(
    env: gym.Env[Any, Any],
    agent: Agent,
    *,
    seed: int | None = None,
    options: dict[str, Any] | None = None,
    max_steps: int | None = None,
    on_step: Any = None,
) -> EpisodeResult:
    """Runs one episode to termination and returns its score record."""
    obs, info = env.reset(seed=seed, options=options)
    agent.reset(env, info)
    steps, total = 0, 0.0
    while True:
        action = agent.act(obs, info)
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        total += float(reward)
        if on_step is not None:
            on_step(steps, obs, reward, info)
        if terminated or truncated or (max_steps is not None and steps >= max_steps):
            break
    score: dict[str, Any] = env.unwrapped.score()  # type: ignore[attr-defined]  # an R4 env's
    return EpisodeResult(score=score, steps=steps, total_reward=total)


class ConstantAgent:
    """Holds one action forever (zero-speed and off-road probes, smoke tests)."""

    uses_images = False

    def __init__(self, action: Any, name: str = "constant") -> None:
        self.action = np.asarray(action, dtype=np.float32)
        self.name = name

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        pass

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        return self.action
