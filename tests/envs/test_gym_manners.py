"""Gymnasium manners an RL user relies on (issue 17): closed envs, copies, render buffers, time left."""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

from drivehierarchy import SimulationError
from drivehierarchy.envs.r4 import DriveHierarchyR4Env

SCENARIO = "03_turning/town01_03_right_turn_signalised"
OTHER = "07_sudden_brake/town01_07_lead_brakes"
SMALL = {"front": {"width": 160, "height": 90}, "bev": None}


def make(**kw: object) -> DriveHierarchyR4Env:
    return gym.make("DriveHierarchy-R4", scenario=SCENARIO, **kw).unwrapped  # type: ignore[return-value]


@pytest.mark.parametrize(
    "call",
    [
        lambda e: e.reset(seed=0),
        lambda e: e.step([0.0, 1.0]),
        lambda e: e.step("steer: 0\ntarget_speed_mps: 1"),
        lambda e: e.render(),
        lambda e: e.score(),
    ],
)
def test_a_closed_env_says_so(call) -> None:
    env = make(render_mode="rgb_array", **SMALL)
    env.reset(seed=0)
    env.close()
    env.close()  # idempotent, as Gymnasium expects
    with pytest.raises(gym.error.ClosedEnvironmentError, match="closed"):
        call(env)


@pytest.mark.parametrize("clone", [copy.deepcopy, lambda e: pickle.loads(pickle.dumps(e))])
def test_copies_keep_the_scenario_and_config_and_need_a_reset(clone) -> None:
    env = make(**SMALL)
    env.reset(seed=0, options={"scenario": OTHER})  # the loaded scenario, not the constructor's
    env.step([0.0, 5.0])
    twin = clone(env)
    assert twin.scenario_path == env.scenario_path
    # Same settings; the copy's config names the scenario it will run (the one loaded by reset).
    assert twin.config.replace(scenario=None) == env.config.replace(scenario=None)
    assert twin.config.scenario == env.scenario_path
    with pytest.raises(gym.error.ResetNeeded, match="reset"):
        twin.step([0.0, 5.0])
    # Still a SimulationError, as every world failure is.
    with pytest.raises(SimulationError):
        twin.step([0.0, 5.0])
    a, _ = env.reset(seed=3)
    b, _ = twin.reset(seed=3)
    assert np.array_equal(a["state"], b["state"])
    assert np.array_equal(a["front"], b["front"])


def test_render_returns_a_frame_no_caller_can_corrupt() -> None:
    env = make(render_mode="rgb_array", **SMALL)
    env.reset(seed=0)
    first = env.render()
    kept = first.copy()
    with pytest.raises(ValueError, match="read-only"):
        first[:] = 0
    assert np.array_equal(env.render(), kept)
    env.step([0.0, 5.0])
    assert env.render().flags.writeable is False


def test_info_says_how_much_time_is_left_before_the_scenario_timeout() -> None:
    env = make(front=None, bev=None)
    _, info = env.reset(seed=0)
    limit = info["time_limit_s"]
    assert limit > 0
    assert info["time_left_s"] == pytest.approx(limit - info["time_s"])
    _, _, _, _, after = env.step([0.0, 0.0])
    assert after["time_limit_s"] == limit
    assert after["time_left_s"] == pytest.approx(info["time_left_s"] - 0.25)
    # Standing still until the protocol ends the episode: the clock runs out exactly at the limit.
    terminated = False
    while not terminated:
        _, _, terminated, truncated, after = env.step([0.0, 0.0])
        assert not truncated
    assert after["time_left_s"] >= 0
    if after["termination_reason"] == "max_sim_time":
        assert after["time_left_s"] == pytest.approx(0.0, abs=1e-9)


def test_the_env_class_documents_its_spaces_arguments_and_termination() -> None:
    doc = DriveHierarchyR4Env.__doc__ or ""
    for needle in ("Observation", "Action", "Arguments", "terminated", "truncated", "ResetNeeded"):
        assert needle in doc
