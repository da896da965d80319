"""The `idm` traffic mode, reactive background traffic without SUMO: the same [traffic] demand
driven by the Rust world's IDM model (docs/traffic.md, "IDM mode"). Same behaviour checks as the
SUMO tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from traffic_helpers import BENCH, frame, make_env, run_expert, traffic_rows, write_scenario


def test_idm_queues_behind_a_stopped_ego_and_never_passes_through(tmp_path: Path) -> None:
    # One-lane road T2R: the ego stands 40 m in while SUMO runs 60 s of warm-up (the protocol
    # ends an episode after 5 s at rest, so the long wait happens in the warm-up, where SUMO
    # sees the ego standing at its start), then for 4.5 s of the episode with the brake held.
    p = write_scenario(
        tmp_path,
        """
        [ego]
        start = { lane = "T2R_0", s = 40.0 }
        route_edges = ["T2R"]
        [traffic]
        warmup_s = 60.0
        [[traffic.flows]]
        from = "C2T"
        to = "R2AS"
        vehs_per_hour = 900
        """,
    )
    env = make_env(p, action_mode="raw", traffic="idm")
    try:
        env.reset(seed=3)
        queued_max = 0
        for step in range(19):
            if step:
                _, _, term, _, info = env.step(np.array([0.0, 1.0, 0.0]))
                assert not term and not info["contacts"], info
            ego, rows = frame(env)
            fwd, lat = rows[:, -2], rows[:, -1]
            # Every vehicle came from behind; none got past (through) the ego.
            assert len(rows) >= 5 and np.all(fwd < 0), rows
            behind = (np.abs(lat) < 1.5) & (fwd > -80)
            # Along the queue nobody overlaps the car ahead (or the ego).
            order = np.argsort(-fwd[behind])
            pos = fwd[behind][order]
            half = rows[behind][order][:, 5] / 2
            fronts = np.concatenate([[-ego[4] / 2], pos[:-1] - half[:-1]])
            assert np.all(pos + half <= fronts + 1e-6), (pos, half, fronts)
            queued_max = max(queued_max, int((behind & (rows[:, 4] < 0.1)).sum()))
        assert queued_max >= 4, queued_max
    finally:
        env.close()


def test_idm_vehicles_stop_at_red(tmp_path: Path) -> None:
    # Light C gives W2C/T2C green for the first 45 s of its cycle; N2C is red meanwhile
    # (scenarios/maps/README.md). The idm mode runs the map's programs.
    p = write_scenario(
        tmp_path,
        """
        [ego]
        start = { lane = "W2C_1", s = 20.0 }
        route_edges = ["W2C", "C2T", "T2E"]
        [traffic]
        warmup_s = 30.0
        [[traffic.flows]]
        from = "N2C"
        to = "C2S"
        vehs_per_hour = 1200
        """,
    )
    env = make_env(p, traffic="idm")  # the expert drives east on green meanwhile
    try:
        env.reset(seed=0)
        waited, crossed_on_green, head_colours = 0, 0, set()
        for _ in range(4 * 75):
            if env.step(env.expert_action())[2]:
                break
            colour = dict(((lane, c) for _, lane, c in env.sim.light_states()))["N2C_1"]
            head_colours.add(colour)
            rows = traffic_rows(env)
            southbound = np.abs(np.sin(rows[:, 3]) + 1.0) < 0.1  # heading ≈ −90°
            near_x = np.abs(rows[:, 1]) < 8.0
            inside = southbound & near_x & (rows[:, 2] < 8.0) & (rows[:, 2] > -8.0)
            if colour == "red":
                # Nobody enters the crossing on red; the first car waits at the line.
                assert not inside.any(), rows[inside]
                at_line = southbound & near_x & (rows[:, 2] > 8.0) & (rows[:, 2] < 20.0) & (rows[:, 4] < 0.1)
                waited = max(waited, int(at_line.sum()))
            elif colour == "green":
                crossed_on_green += int(inside.sum())
        assert {"red", "green"} <= head_colours, head_colours
        assert waited >= 1 and crossed_on_green > 0, (waited, crossed_on_green)
    finally:
        env.close()


def test_idm_fifty_vehicles_expert_reaches_destination_without_collision() -> None:
    out = run_expert(BENCH, seed=0, traffic="idm")
    counts = out["counts"]
    assert isinstance(counts, list) and counts[0] >= 50, counts[:3]
    info = out["info"]
    assert isinstance(info, dict)
    assert info["termination_reason"] == "destination_reached", info["events"]
    assert not [e for e in info["events"] if str(e["type"]).startswith("collision")], info["events"]


def test_idm_traffic_is_deterministic() -> None:
    a = run_expert(BENCH, seed=5, steps=60, traffic="idm")
    b = run_expert(BENCH, seed=5, steps=60, traffic="idm")
    c = run_expert(BENCH, seed=6, steps=60, traffic="idm")
    assert a["traffic"] == b["traffic"] and a["trajectory"] == b["trajectory"]
    assert a["traffic"] != c["traffic"]
    env = make_env(BENCH, traffic="idm")
    try:
        assert env.traffic_mode == "idm" and env.reset(seed=0) and env.sim.traffic == "idm"
    finally:
        env.close()


def test_the_old_mode_name_still_runs_idm_with_a_deprecation_warning(tmp_path: Path) -> None:
    p = write_scenario(
        tmp_path,
        '[ego]\nstart = { lane = "C2T_1", s = 20.0 }\nroute_edges = ["C2T"]\n\n'
        '[traffic]\nmode = "native"\n[[traffic.vehicles]]\nroute = ["C2T"]\ndepart_s = 0.0\n',
    )
    with pytest.warns(DeprecationWarning, match=r"s\.toml: field `traffic\.mode` = 'native' .* use 'idm'"):
        env = make_env(p)
    try:
        assert env.traffic_mode == "idm" and env.reset(seed=0) and env.sim.traffic == "idm"
    finally:
        env.close()
