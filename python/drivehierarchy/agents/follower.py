"""Reference drivers that measure how much of a scenario can be scored without handling its
hazards (`drivehierarchy scenario probe`, `docs/suite.md`):

* `RouteFollowerAgent` — hazard-blind: pure pursuit on the protocol's 8 future route points (the
  state vector's `route_p*` fields, the same points the VLM prompt carries) at one cruise speed,
  slower in turns, ignoring every actor, obstacle and light;
* `LightObeyingFollowerAgent` — the same, but it stops at a red or yellow light on its route
  (the state vector's `light_ahead_*` fields) and is otherwise blind;
* `LateExpertAgent` — hazard-aware but slow to react: the privileged expert whose speed decision
  is applied a fixed number of decisions late (2 decisions = 0.5 s at the protocol's 4 Hz).

A suite on which the blind drivers score well at some speed does not test hazard handling.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import gymnasium as gym
import numpy as np

from drivehierarchy.agents.expert import ExpertAgent
from drivehierarchy.envs.r4 import STATE_FIELDS

_IDX = {name: i for i, name in enumerate(STATE_FIELDS)}
_ROUTE = [(_IDX[f"route_p{k}_forward_m"], _IDX[f"route_p{k}_right_m"]) for k in range(1, 9)]


class RouteFollowerAgent:
    """Pure pursuit on the route points at `cruise_mps`, `turn_mps` where the route bends within
    ~30 m (a point 15–30 m ahead lies more than 12° off the heading); the turn speed is capped
    at the cruise speed."""

    uses_images = False

    def __init__(
        self,
        name: str = "follower",
        cruise_mps: float = 10.0,
        turn_mps: float = 4.0,
        turn_threshold_deg: float = 12.0,
        wheelbase_m: float = 2.9,
        max_steer_deg: float = 35.0,
    ) -> None:
        if not cruise_mps > 0.0 or not turn_mps > 0.0:
            raise ValueError(f"cruise_mps = {cruise_mps}, turn_mps = {turn_mps}: must be > 0")
        self.name = name
        self.cruise_mps = cruise_mps
        self.turn_mps = min(turn_mps, cruise_mps)
        self.turn_threshold = math.radians(turn_threshold_deg)
        self.wheelbase_m = wheelbase_m
        self.max_steer = math.radians(max_steer_deg)

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        pass

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        state = np.asarray(observation["state"], dtype=np.float64)
        steer, target_speed = self._pursue(state)
        return np.array([steer, target_speed], dtype=np.float32)

    def _pursue(self, state: np.ndarray) -> tuple[float, float]:
        speed = float(state[_IDX["speed_mps"]])
        points = [(float(state[f]), float(state[r])) for f, r in _ROUTE]
        lookahead = min(max(4.0, 2.0 + 0.6 * speed), 20.0)
        target = points[-1]
        for p in points:
            if math.hypot(*p) >= lookahead:
                target = p
                break
        dist = max(math.hypot(*target), 1e-3)
        alpha = math.atan2(target[1], target[0])
        # Pure pursuit: road-wheel angle for the arc through the target; right is positive.
        wheel = math.atan2(2.0 * self.wheelbase_m * math.sin(alpha), dist)
        steer = float(np.clip(wheel / self.max_steer, -1.0, 1.0))
        turning = any(abs(math.atan2(r, f)) > self.turn_threshold for f, r in points[2:5])
        return steer, self.turn_mps if turning else self.cruise_mps


class LightObeyingFollowerAgent(RouteFollowerAgent):
    """The route follower that stops for a red or yellow light on its route and sees nothing else.

    It stops when the light is within its comfortable stopping distance (v²/(2·3 m/s²) + 8 m);
    a light that turns yellow closer than that is passed, as a human driver would."""

    def __init__(self, name: str = "lights", **kwargs: Any) -> None:
        super().__init__(name=name, **kwargs)

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        state = np.asarray(observation["state"], dtype=np.float64)
        steer, target_speed = self._pursue(state)
        speed = float(state[_IDX["speed_mps"]])
        dist = float(state[_IDX["light_ahead_distance_m"]])
        if state[_IDX["light_ahead_stop"]] > 0.5:
            comfortable = speed * speed / (2.0 * 3.0) + 8.0
            hard = speed * speed / (2.0 * 7.0) + 1.0
            # Stopped (or able to stop) before the line: wait; too close at speed: go through.
            if dist <= comfortable and (dist > hard or speed < 0.5):
                target_speed = 0.0
        return np.array([steer, target_speed], dtype=np.float32)


class LateExpertAgent(ExpertAgent):
    """The expert, with each speed decision applied `delay` decisions late (steering on time).

    Until `delay` decisions have been made it holds the ego's speed at reset."""

    def __init__(self, delay: int = 2, name: str = "late_expert") -> None:
        super().__init__()
        if delay < 0:
            raise ValueError(f"delay = {delay}: must be ≥ 0 decisions")
        self.name = name
        self.delay = delay
        self._speeds: deque[float] = deque()

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        super().reset(env, info)
        self._speeds = deque()

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        action = super().act(observation, info)
        if not self._speeds:
            held = float(np.asarray(observation["state"])[_IDX["speed_mps"]])
            self._speeds.extend([held] * self.delay)
        self._speeds.append(float(action[1]))
        return np.array([action[0], self._speeds.popleft()], dtype=np.float32)
