"""The hazard-blind route follower: a probe that measures how much of a scenario can be scored
without looking at anything but the route.

Pure pursuit on the protocol's 8 future route points (the state vector's `route_p*` fields, the
same points the VLM prompt carries) at 10 m/s on straights and 6 m/s in turns, ignoring every
actor, obstacle and light. A suite on which this policy scores well does not test hazard
handling; `docs/suite.md` publishes its scores beside the expert's.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from drivehierarchy.envs.r4 import STATE_FIELDS

_IDX = {name: i for i, name in enumerate(STATE_FIELDS)}
_ROUTE = [(_IDX[f"route_p{k}_forward_m"], _IDX[f"route_p{k}_right_m"]) for k in range(1, 9)]


class RouteFollowerAgent:
    """Pure pursuit on the route points; 10 m/s, 6 m/s where the route bends within 30 m
    (a point 15–30 m ahead lies more than 12° off the heading)."""

    uses_images = False

    def __init__(
        self,
        name: str = "follower",
        cruise_mps: float = 10.0,
        turn_mps: float = 6.0,
        turn_threshold_deg: float = 12.0,
        wheelbase_m: float = 2.9,
        max_steer_deg: float = 35.0,
    ) -> None:
        self.name = name
        self.cruise_mps = cruise_mps
        self.turn_mps = turn_mps
        self.turn_threshold = math.radians(turn_threshold_deg)
        self.wheelbase_m = wheelbase_m
        self.max_steer = math.radians(max_steer_deg)

    def reset(self, env: gym.Env[Any, Any], info: dict[str, Any]) -> None:
        pass

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        state = np.asarray(observation["state"], dtype=np.float64)
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
        target_speed = self.turn_mps if turning else self.cruise_mps
        return np.array([steer, target_speed], dtype=np.float32)
