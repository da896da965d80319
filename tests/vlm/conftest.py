"""Shared pieces of the closed-loop VLM tests: a small suite and the protocol's exact texts."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from drivehierarchy.scenarios import builtin_root

# The three shortest built-in scenarios with the scripted driver (50–100 decisions each).
# Three short scenarios of three categories (06 with SUMO traffic), named explicitly so the
# tests' decision counts do not move when the suite grows.
SHORT = [
    "02_obstacles/town01_02_cones_right_lane.toml",
    "06_traffic_flow/bs3d_09_left_turner_queue.toml",
    "09_yielding/town01_09_yield_left_turn.toml",
]

# docs/protocol.md#r4-prompt, verbatim: the action question appended to the condition prefix.
ACTION_QUESTION = (
    "Your primary objective is to reach the destination in the minimum time while remaining safe and "
    "legal. Hard constraints: do not collide with vehicles, pedestrians, or static obstacles; do not "
    "leave the drivable route; obey traffic lights, stop signs, and right-of-way rules. Driving policy: "
    "do not idle, crawl, or wait without a concrete safety or rule-based reason; if the route ahead is "
    "clear, actively increase speed toward the highest safe speed; use steering proactively to follow "
    "the future path and begin steering before turns instead of defaulting to zero steering; slow down "
    "only when required by route geometry, traffic rules, obstacles, or collision risk. For the steer "
    "value, a negative value indicates left, while a positive value indicates right.When making the "
    "decision, consider the ego speed, the future route geometry, drivable space, nearby vehicles, "
    "pedestrians, traffic lights, traffic signs, and any immediate collision or off-road risk. Never "
    "idle without a concrete safety or rule-based reason. Use steering proactively to track the future "
    "path instead of defaulting to straight driving. Output only the final action decision without "
    "explanation in the exact format:\nsteer: <float in [-1.0, 1.0]>\ntarget_speed_mps: <float in "
    "[0.0, 30.0]>"
)


def short_scenarios(n: int = 3) -> list[Path]:
    root = builtin_root() / "r4"
    return [root / name for name in SHORT[:n]]


@pytest.fixture
def suite_dir(tmp_path: Path) -> Path:
    """A scenario folder (`--suite DIR`) holding the short scenarios, maps linked beside them."""
    root = tmp_path / "suite"
    (root / "r4").mkdir(parents=True)
    os.symlink(builtin_root() / "maps", root / "maps")
    for p in short_scenarios():
        (root / "r4" / p.parent.name).mkdir()
        shutil.copy(p, root / "r4" / p.parent.name / p.name)
    return root / "r4"
