"""The `waypoints` and `meta` action levels (docs/r4.md#action-levels; this project's extension of
the protocol): spaces and env checkers at every level, replies parsed by the level's parser, the
tracker's per-decision log, the expert's plans, and clear errors for bad plans."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from gymnasium import spaces

from drivehierarchy import ConfigError
from drivehierarchy.agents.base import run_episode
from drivehierarchy.agents.expert import ExpertAgent
from drivehierarchy.envs.r4 import PATH_ACTIONS, SPEED_ACTIONS, DriveHierarchyR4Env

SCENARIO = "03_turning/town01_03_right_turn_signalised"
LEVELS = ["decision", "waypoints", "meta"]


def make(**kw: Any) -> DriveHierarchyR4Env:
    kw.setdefault("front", None)
    kw.setdefault("bev", None)
    return DriveHierarchyR4Env(scenario=SCENARIO, **kw)


def test_action_spaces() -> None:
    w = make(action_mode="waypoints")
    assert isinstance(w.action_space, spaces.Box) and w.action_space.shape == (8, 2)
    assert make(action_mode="waypoints", waypoints=4).action_space.shape == (4, 2)
    m = make(action_mode="meta")
    assert isinstance(m.action_space, spaces.MultiDiscrete)
    assert m.action_space.nvec.tolist() == [len(PATH_ACTIONS), len(SPEED_ACTIONS)] == [6, 4]


@pytest.mark.parametrize("level", LEVELS)
def test_gymnasium_env_checker_passes_at_every_level(level: str) -> None:
    from gymnasium.utils.env_checker import check_env

    check_env(make(action_mode=level), skip_render_check=True)


@pytest.mark.parametrize("level", LEVELS)
def test_sb3_env_checker_passes_at_every_level(level: str) -> None:
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(make(action_mode=level, prompt=False))


def test_level_prompts_are_the_extensions() -> None:
    obs, _ = make(action_mode="waypoints").reset(seed=0)
    assert obs["prompt"].startswith("The ego vehicle is driving at the speed of 0.0 m/s")
    assert obs["prompt"].endswith("waypoints: [(<forward_m>, <right_m>), ... 8 points]")
    obs, _ = make(action_mode="meta").reset(seed=0)
    assert obs["prompt"].endswith("speed_action: <one of KEEP, ACCELERATE, DECELERATE, STOP>")
    obs, _ = make().reset(seed=0)  # the paper's prompt stays the control level's
    assert obs["prompt"].endswith("target_speed_mps: <float in [0.0, 30.0]>")


def test_waypoint_plan_is_tracked_and_logged() -> None:
    env = make(action_mode="waypoints")
    env.reset(seed=0)
    plan = np.array([[4.0 * (k + 1), 0.0] for k in range(8)], np.float32)  # 8 m/s straight on
    for _ in range(12):
        _, _, _, _, info = env.step(plan)
    rec = info["reply"]
    # An array's plan is the caller's own: the log keeps it, the step's info does not echo it.
    assert "plan" not in rec
    assert env.decision_log()[-1]["plan"]["waypoints"][0] == [4.0, 0.0]
    assert rec["tracking"]["ticks"] == 5
    assert rec["tracking"]["lateral_max_m"] < 1.0
    assert abs(info["speed_mps"] - 8.0) < 1.5
    assert "tracking" in env.decision_log()[0]


def test_replies_at_each_level_and_failures_hold_the_plan() -> None:
    env = make(action_mode="waypoints")
    env.reset(seed=0)
    _, _, _, _, info = env.step(
        "waypoints: [(2, 0), (4, 0), (6, 0), (8, 0.5), (10, 1), (12, 1), (14, 1), (16, 1)]"
    )
    assert info["reply"]["failure"] is None
    # Replies give (forward, right); the plan is (x forward, y left).
    assert info["reply"]["plan"]["waypoints"][3] == [8.0, -0.5]
    speed = info["speed_mps"]
    for bad in ["steer: 0.1 target_speed_mps: 3", "", None]:
        _, _, _, _, info = env.step(bad)
        assert info["reply"]["failure"] in ("missing_waypoints", "no_reply")
        assert "plan" not in info["reply"]
    assert info["parse_failures"] == 3 and info["speed_mps"] > 0.0 and speed >= 0.0

    env = make(action_mode="meta")
    env.reset(seed=0)
    _, _, _, _, info = env.step("path_action: FOLLOW_LANE\nspeed_action: ACCELERATE")
    assert info["reply"]["plan"] == {"meta": {"path": "FOLLOW_LANE", "speed": "ACCELERATE"}}
    _, _, _, _, info = env.step("path_action: FLY\nspeed_action: KEEP")
    assert info["reply"]["failure"] == "missing_path_action" and info["parse_failures"] == 1


def test_bad_plans_are_rejected_clearly_and_change_nothing() -> None:
    env = make(action_mode="waypoints")
    env.reset(seed=0)
    good = np.zeros((8, 2), np.float32)
    env.step(good)
    before = env.sim.episode_log()[:-1]
    bad_plan = good.copy()
    bad_plan[3, 1] = math.nan
    with pytest.raises(ConfigError, match=r"(?s)config `action` = .*: contains NaN or infinity"):
        env.step(bad_plan)
    with pytest.raises(ConfigError, match=r"expected shape \(8, 2\)"):
        env.step(np.zeros((3, 2)))
    meta = make(action_mode="meta")
    meta.reset(seed=0)
    for bad in ([6, 0], [0, 4], [-1, 0], [0.5, 1]):
        with pytest.raises(ConfigError, match=r"config `action`"):
            meta.step(np.array(bad))
    assert env.sim.episode_log()[:-1] == before
    with pytest.raises(ConfigError, match="waypoints"):
        make(action_mode="waypoints", waypoints=0)
    with pytest.raises(ConfigError, match="waypoint_dt_s"):
        make(action_mode="waypoints", waypoint_dt_s=math.nan)


@pytest.mark.parametrize("level", ["waypoints", "meta"])
def test_expert_plans_reach_the_destination(level: str) -> None:
    env = make(action_mode=level)
    result = run_episode(env, ExpertAgent(), seed=0)
    assert result.score["termination_reason"] == "destination_reached", result.score
    assert result.score["score_composed"] > 90.0
    action = env.expert_action()
    assert action.shape == ((8, 2) if level == "waypoints" else (2,))
    assert env.action_space.contains(action.astype(env.action_space.dtype))


def test_same_seed_and_plans_give_the_same_episode() -> None:
    hashes = []
    for _ in range(2):
        env = make(action_mode="meta")
        result = run_episode(env, ExpertAgent(), seed=1)
        hashes.append((env.sim.trajectory_hash, result.steps))
    assert hashes[0] == hashes[1]
