"""Unit checks of the probe's cell / seed parsing, result merging and the CI subset choice."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivehierarchy import suite_probe
from drivehierarchy._core import ConfigError
from drivehierarchy.agents.follower import _IDX, LateExpertAgent, LightObeyingFollowerAgent


def test_cells_and_seeds_parse() -> None:
    assert suite_probe.parse_cell("follower@6") == ("follower", 6.0)
    assert suite_probe.parse_cell("late_expert") == ("late_expert", None)
    assert suite_probe.expand_cells("expert,follower") == (
        "expert",
        *(f"follower@{v}" for v in (4, 6, 8, 10, 12)),
    )
    assert suite_probe.parse_seeds("0-2,5") == (0, 1, 2, 5)
    for bad in ("follower", "expert@3", "constant@0", "walker@4"):
        with pytest.raises(ConfigError, match="probe cell"):
            suite_probe.parse_cell(bad)
    with pytest.raises(ConfigError, match="--seeds"):
        suite_probe.parse_seeds("a-b")


def test_sweep_covers_the_required_speeds() -> None:
    speeds = {c: suite_probe.parse_cell(c) for c in suite_probe.SWEEP}
    assert {v for n, v in speeds.values() if n == "follower"} == {4.0, 6.0, 8.0, 10.0, 12.0}
    assert {v for n, v in speeds.values() if n == "constant"} == {2.0, 4.0, 6.0, 8.0, 10.0, 12.0}
    assert {"expert", "late_expert", "lights@4"} <= set(suite_probe.SWEEP)


def test_ci_subset_is_deterministic_and_stratified() -> None:
    ids = [f"s{i:03d}" for i in range(100)]
    a = suite_probe.ci_subset(ids)
    assert a == suite_probe.ci_subset(list(reversed(ids)))
    assert all(len(p) == 2 and len(set(p)) == 2 for p in a.values())
    cells = {c for pairs in a.values() for c, _ in pairs}
    assert len(cells) >= len(suite_probe.SWEEP) - 2, "the subset spreads over (nearly) every cell"


def test_results_round_trip_and_merge(tmp_path: Path) -> None:
    row = {
        "category": "07_sudden_brake",
        "id": "x",
        "cell": "expert",
        "seed": 0,
        "score": 0.1 + 0.2,
        "termination": "destination_reached",
        "sim_s": 12.25,
        "trajectory_hash": "ab" * 32,
        "scenario_sha256": "0123456789abcdef",
    }
    p = tmp_path / "r.csv"
    suite_probe.write_results(p, [row])
    (back,) = suite_probe.read_results(p)
    assert back["score"] == row["score"], "scores round-trip bit for bit"
    assert back["trajectory_hash"] == row["trajectory_hash"][: suite_probe.TRAJECTORY_HASH_HEX]
    newer = {**row, "score": 50.0}
    merged = suite_probe.merge([back, {**row, "seed": 1}], [newer])
    assert [(r["seed"], r["score"]) for r in merged] == [(0, 50.0), (1, row["score"])]


def _state(**fields: float) -> np.ndarray:
    s = np.zeros(max(_IDX.values()) + 1, dtype=np.float32)
    for k in range(1, 9):
        s[_IDX[f"route_p{k}_forward_m"]] = 5.0 * k  # straight ahead
    for k, v in fields.items():
        s[_IDX[k]] = v
    return s


def test_light_obeying_follower_stops_for_red_only_when_it_can() -> None:
    agent = LightObeyingFollowerAgent(cruise_mps=10.0)
    go = agent.act({"state": _state(speed_mps=10.0, light_ahead_distance_m=200.0, light_ahead_stop=1.0)}, {})
    stop = agent.act({"state": _state(speed_mps=10.0, light_ahead_distance_m=20.0, light_ahead_stop=1.0)}, {})
    late = agent.act({"state": _state(speed_mps=10.0, light_ahead_distance_m=3.0, light_ahead_stop=1.0)}, {})
    green = agent.act(
        {"state": _state(speed_mps=10.0, light_ahead_distance_m=20.0, light_ahead_stop=0.0)}, {}
    )
    assert (go[1], stop[1], late[1], green[1]) == (10.0, 0.0, 10.0, 10.0)


class _FakeEnv:
    unwrapped: _FakeEnv

    def __init__(self) -> None:
        self.unwrapped = self
        self.speeds = iter([3.0, 4.0, 5.0, 6.0])

    def expert_action(self) -> np.ndarray:
        return np.array([0.25, next(self.speeds)], dtype=np.float32)


def test_late_expert_applies_the_speed_two_decisions_late() -> None:
    agent = LateExpertAgent(delay=2)
    agent.reset(_FakeEnv(), {})  # type: ignore[arg-type]
    obs = {"state": _state(speed_mps=7.0)}
    got = [tuple(agent.act(obs, {})) for _ in range(4)]
    assert got == [(0.25, 7.0), (0.25, 7.0), (0.25, 3.0), (0.25, 4.0)]
