"""Scenario-format features that reach SUMO (docs/scenario-format.md): `[[lights]]` overrides
drive SUMO's signals with the same timing as the world's own light model, and per-vehicle
`max_speed_mps` / `speed_factor` of `[traffic]` reach SUMO's vehicles.

Real libsumo (both in-process SUMO transports: "libsumo", libsumo's C++ API from Rust, and
"libsumo-python", the libsumo module) on the project's town01 network; the ego drives east on
C2T, away from light C, whose west approach (W2C_1) is watched.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("libsumo")

from traffic_helpers import make_env, traffic_rows, write_scenario

EGO = """
[ego]
start = { lane = "C2T_1", s = 20.0 }
destination = { lane = "C2T_1", s = 370.0 }
"""

TRAFFIC = """
[traffic]
mode = "sumo"
warmup_s = 2.0

[[traffic.vehicles]]
id = "slow"
route = ["T2C"]
depart_s = 0.0
depart_lane = 1
depart_pos_m = 40.0
depart_speed = 0.0
max_speed_mps = 5.0

[[traffic.flows]]
id = "half"
from = "T2C"
to = "T2C"
vehs_per_hour = 600
number = 1
begin_s = 0.0
depart_lane = 2
depart_pos_m = 150.0
depart_speed = 0.0
speed_factor = 0.5
"""

G, R = "G" * 20, "r" * 20
LIGHTS = {
    "phases": (
        f'[[lights]]\ntls = "C"\nphases = [{{ state = "{G}", duration_s = 8.0 }}, '
        f'{{ state = "{R}", duration_s = 4.0 }}]\n'
    ),
    "start_phase": '[[lights]]\ntls = "C"\nstart_phase = 3\nphase_elapsed_s = 30.0\n',
    "offset": '[[lights]]\ntls = "C"\noffset_s = 10.0\n',
}


Timeline = list[tuple[float, str]]


def _head(env: object) -> str:
    return {lane: c for _, lane, c in env.sim.light_states()}["W2C_1"]  # type: ignore[attr-defined]


@pytest.fixture(params=["libsumo", "libsumo-python"])
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def _timeline(
    scenario: Path, traffic: str, seconds: float, backend: str = "auto"
) -> tuple[Timeline, list[np.ndarray]]:
    """(time, W2C_1 head colour) after every step, and the traffic rows, under the expert."""
    env = make_env(scenario, traffic=traffic, sumo_backend=backend)
    try:
        env.reset(seed=0)
        out = [(0.0, _head(env))]
        rows = []
        while out[-1][0] < seconds:
            _, _, term, _, info = env.step(env.expert_action())
            out.append((float(info["time_s"]), _head(env)))
            rows.append(traffic_rows(env))
            assert not term, info
        return out, rows
    finally:
        env.close()


def _switches(timeline: list[tuple[float, str]]) -> list[tuple[float, str]]:
    return [(t, c) for (t, c), (_, prev) in zip(timeline[1:], timeline[:-1], strict=True) if c != prev]


@pytest.mark.parametrize("kind", sorted(LIGHTS))
def test_light_override_timing_matches_in_sumo_and_the_world(tmp_path: Path, kind: str, backend: str) -> None:
    p = write_scenario(tmp_path, EGO + LIGHTS[kind] + TRAFFIC)
    sumo, _ = _timeline(p, "sumo", 26.0, backend)
    own, _ = _timeline(p, "none", 26.0)
    s_sw, o_sw = _switches(sumo), _switches(own)
    assert [c for _, c in s_sw] == [c for _, c in o_sw], (s_sw, o_sw)
    # Same switch times within one decision step (SUMO counts phases in 0.05 s steps).
    assert all(abs(a - b) <= 0.26 for (a, _), (b, _) in zip(s_sw, o_sw, strict=True)), (s_sw, o_sw)
    expected_first = {"phases": (8.0, "red"), "start_phase": (15.0, "green"), "offset": (10.0, "green")}[kind]
    assert s_sw and abs(s_sw[0][0] - expected_first[0]) <= 0.26 and s_sw[0][1] == expected_first[1], s_sw
    if kind == "phases":
        # The replaced two-phase program keeps cycling: green again at 12 s, red at 20 s.
        assert [c for _, c in s_sw[:3]] == ["red", "green", "red"], s_sw
        assert abs(s_sw[1][0] - 12.0) <= 0.26 and abs(s_sw[2][0] - 20.0) <= 0.26, s_sw


def test_per_vehicle_speeds_reach_sumo(tmp_path: Path, backend: str) -> None:
    p = write_scenario(tmp_path, EGO + TRAFFIC)
    _, rows = _timeline(p, "sumo", 15.0, backend)
    last = rows[-1]
    assert len(last) == 2, last
    by_x = last[np.argsort(last[:, 1])]
    half, slow = by_x[0], by_x[1]  # westbound: the flow vehicle departed further west
    top = max(float(r[np.argsort(r[:, 1])][1, 4]) for r in rows if len(r) == 2)
    assert top <= 5.0 + 1e-6 and abs(slow[4] - 5.0) < 0.2, (top, slow)
    assert abs(half[4] - 0.5 * 13.89) < 0.3, half
