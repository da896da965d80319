"""Our R4 record against an independent port of the original scorer's arithmetic.

The original (`SceneScoreTracker` of the release, docs/protocol.md#r4-scene-score) updates once at
t = 0 and after
every tick, accounts each interval's off-road time by the sample that opens it, rounds every
score with Python's `round`, composes `score_composed` from the rounded terms and decides the
status by thresholds. This port is written from that description, in plain Python floats, and
fed with our episode log (header + ticks): every number of the record must come out equal.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from drivehierarchy.agents.base import ConstantAgent, run_episode
from drivehierarchy.agents.expert import ExpertAgent

NO_IMAGES = {"front": None, "bev": None}


def make(scenario: str, **kw: Any) -> Any:
    return gym.make("DriveHierarchy-R4", scenario=scenario, **kw).unwrapped


PENALTY = {
    "collision_pedestrian": 0.0,
    "collision_vehicle": 0.2,
    "collision_static": 0.3,
    "scenario_timeout": 0.7,
    "blocked_timeout": 0.7,
    "route_deviation": 0.0,
}
FAILURES = {
    "collision_pedestrian",
    "collision_vehicle",
    "collision_static",
    "offroad_timeout",
    "scenario_timeout",
    "blocked_timeout",
    "manual_interrupt",
    "system_error",
    "unknown",
}


def project(p: tuple[float, float], pts: list[tuple[float, float]]) -> tuple[float, float]:
    """(arc length, distance) of the closest point of the polyline; first segment wins ties."""
    best_d, best_s, acc = None, 0.0, 0.0
    for (ax, ay), (bx, by) in itertools.pairwise(pts):
        dx, dy = bx - ax, by - ay
        seg2 = dx * dx + dy * dy
        seg = math.hypot(dx, dy)
        if seg <= 1e-9:
            continue
        t = min(1.0, max(0.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / seg2))
        d = math.hypot(p[0] - (ax + t * dx), p[1] - (ay + t * dy))
        if best_d is None or d < best_d:
            best_d, best_s = d, acc + t * seg
        acc += seg
    return best_s, best_d if best_d is not None else math.inf


def original_record(lines: list[dict[str, Any]], record: dict[str, Any]) -> dict[str, Any]:
    head = lines[0]
    ticks = [x for x in lines if x["kind"] == "tick"]
    route = [tuple(p) for p in head["route"]]
    length = sum(math.dist(a, b) for a, b in itertools.pairwise(route))
    t_ref = head["reference_duration_s"] or length / 5.56
    dest = tuple(head["destination"])
    radius = head["params"]["destination_radius_m"]

    state = {"best": 0.0, "travel": 0.0, "off": 0.0, "dur": 0.0, "last_rd": None, "reached": False}
    last: dict[str, Any] = {"t": None, "xy": None, "off": False}

    def update(xy: tuple[float, float], t: float, offroad: bool) -> None:
        state["dur"] = max(state["dur"], t)
        if last["t"] is not None:
            if last["off"]:
                state["off"] += max(0.0, t - last["t"])
            state["travel"] += math.dist(last["xy"], xy)
        last.update(t=t, xy=xy, off=offroad)
        if not offroad:
            s, d = project(xy, route)
            state["last_rd"] = d
            if d <= 6.0:
                state["best"] = max(state["best"], min(s, state["best"] + 20.0))
        if math.dist(xy, dest) <= radius:
            state["reached"] = True
            state["best"] = max(state["best"], length)

    update(tuple(head["start"]), 0.0, not head["start_on_road"])
    for k in ticks:
        update((k["x"], k["y"]), k["tick"] * 0.05, not k["on_road"])

    reason = record["termination_reason"]
    product = 1.0
    for e in record["events"]:
        product *= PENALTY.get(e["type"], 1.0)
    if reason == "offroad_timeout":
        run = 0
        for k in reversed(ticks):
            if k["on_road"]:
                break
            run += 1
        state["off"] = max(state["off"], (run - 1) * 0.05)

    route_s = 100.0 if reason == "destination_reached" else min(100.0, max(0.0, 100 * state["best"] / length))
    route_s = round(route_s, 6)
    dur = state["dur"]
    ratio = min(1.0, max(0.0, state["off"] / dur)) if dur > 1e-6 else 0.0
    safety = round(min(1.0, max(0.0, product * (1.0 - ratio))), 6)
    dref = length * 1.10
    d_eff = 1.0 if state["travel"] <= dref + 1e-6 else dref / state["travel"]
    tref = t_ref * 1.50
    t_eff = 1.0 if (t_ref <= 1e-6 or dur <= 1e-6 or dur <= tref + 1e-6) else tref / dur
    eff = round(min(1.0, max(0.0, 0.7 * d_eff + 0.3 * t_eff)), 6)
    penalty = round(max(safety * eff, 0.0), 6)
    composed = round(max(route_s * penalty, 0.0), 6)
    if route_s >= 100.0 and reason not in FAILURES:
        status = "Perfect" if safety >= 0.999999 and eff >= 0.999999 else "Completed"
    else:
        status = "Failed"
    return {
        "status": status,
        "score_route": route_s,
        "score_safety": safety,
        "score_efficiency": eff,
        "score_penalty": penalty,
        "score_composed": composed,
        "meta": {
            "route_length_m": round(length, 3),
            "completed_distance_m": round(state["best"], 3),
            "travel_distance_m": round(state["travel"], 3),
            "offroad_time_s": round(state["off"], 3),
            "offroad_ratio": round(ratio, 6),
            "lane_keep_penalty": round(1.0 - ratio, 6),
            "duration_game": round(dur, 3),
            "reference_duration_s": round(t_ref, 3),
            "distance_efficiency": round(d_eff, 6),
            "time_efficiency": round(t_eff, 6),
            "destination_radius": round(radius, 3),
            "last_route_distance_m": None if state["last_rd"] is None else round(state["last_rd"], 3),
        },
    }


class Weave:
    """Leaves the road and comes back a few times (off-road time without the timeout)."""

    name = "weave"
    uses_images = False

    def __init__(self) -> None:
        self.k = 0

    def reset(self, env: Any, info: dict[str, Any]) -> None:
        self.k = 0

    def act(self, obs: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        self.k += 1
        steer = 0.4 * math.sin(self.k / 6.0)
        return np.array([steer, 7.0], np.float32)


CASES = [
    ("07_sudden_brake/town01_07_lead_brakes", ExpertAgent),
    ("10_roundabout/town01_10_roundabout_exit_south", ExpertAgent),
    ("03_turning/town01_03_right_turn_signalised", lambda: ConstantAgent([0.0, 0.0])),
    ("03_turning/town01_03_right_turn_signalised", lambda: ConstantAgent([0.3, 8.0])),
    ("01_pedestrian/town01_01_midblock_crossing", lambda: ConstantAgent([0.0, 9.0])),
    ("02_obstacles/town01_02_cones_right_lane", Weave),
    ("04_intersection/town01_04_straight_cross_traffic", lambda: ConstantAgent([0.0, 2.5])),
]


@pytest.fixture(scope="module")
def case_runs() -> list[tuple[dict[str, Any], list[dict[str, Any]]]]:
    """Each case driven once: (its score record, its episode log)."""
    runs = []
    for scenario, agent in CASES:
        env = make(scenario, **NO_IMAGES)
        runs.append((run_episode(env, agent(), seed=0).score, env.sim.episode_log()))
    return runs


@pytest.mark.parametrize("case", range(len(CASES)), ids=[f"{s}-{i}" for i, (s, _) in enumerate(CASES)])
def test_record_equals_the_original_scorers_arithmetic(case: int, case_runs: list) -> None:
    rec, log = case_runs[case]
    want = original_record(log, rec)
    scores = ("score_route", "score_safety", "score_efficiency", "score_penalty", "score_composed")
    for key in ("status", *scores):
        assert rec[key] == want[key], (key, rec[key], want[key], rec["termination_reason"])
    for key, value in want["meta"].items():
        assert rec["meta"][key] == value, (key, rec["meta"][key], value)


def test_the_cases_cover_the_branches(case_runs: list) -> None:
    reasons, offroad, statuses = set(), [], set()
    for rec, _log in case_runs:
        reasons.add(rec["termination_reason"])
        offroad.append(rec["meta"]["offroad_time_s"])
        statuses.add(rec["status"])
    assert {"destination_reached", "blocked_timeout", "offroad_timeout"} <= reasons, reasons
    assert any(t > 0 for t in offroad)
    assert "Perfect" in statuses and "Failed" in statuses
