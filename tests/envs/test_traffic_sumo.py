"""Live background traffic: SUMO co-simulated through libsumo (docs/traffic.md).

Every test starts the real SUMO of the `eclipse-sumo` / `libsumo` packages on the project's
town01 network (or the suite's Ingolstadt net) and drives the real Rust world, once per SUMO
transport: "libsumo" (libsumo's C++ API driven from Rust) and "libsumo-python" (the libsumo module).
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("libsumo")

from traffic_helpers import BENCH, IS_TRAFFIC, frame, make_env, run_expert, traffic_rows, write_scenario

from drivehierarchy import _core
from drivehierarchy._core import ConfigError, ScenarioError, SimulationError
from drivehierarchy.envs.traffic import transport
from drivehierarchy.scenarios import sumo_home
from drivehierarchy.testing.procs import process_table

FLOW_SCENARIO = "06_traffic_flow/ingolstadt_06_westbound_flow"


@pytest.fixture(params=["libsumo", "libsumo-python"])
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


# -- the [traffic] table ---------------------------------------------------------------------------


def test_traffic_table_errors_name_the_field(tmp_path: Path) -> None:
    base = """
    [ego]
    start = { lane = "W2C_1", s = 20.0 }
    destination = { lane = "C2T_1", s = 100.0 }
    """
    cases = {
        '[traffic]\nmode = "fast"\n': "traffic.mode",
        '[[traffic.vehicles]]\nroute = ["W2C", "nowhere"]\n': "traffic.vehicles[0].route[1]",
        '[[traffic.vehicles]]\nroute = ["W2C"]\nvtype = "spaceship"\n': "traffic.vehicles[0].vtype",
        '[[traffic.flows]]\nfrom = "W2C"\nto = "C2T"\n': "traffic.flows[0]",
        '[[traffic.flows]]\nfrom = "W2C"\nto = "C2T"\nprobability = 1.5\n': "traffic.flows[0].probability",
        "[traffic.random]\ndensity_per_km = -1.0\n": "traffic.random.density_per_km",
        '[[traffic.vehicles]]\nroute = ["W2C"]\ndepart_lane = "leftmost"\n': "depart_lane",
        '[traffic]\nvtypes = "missing.add.xml"\n': "traffic.vtypes",
        "[traffic]\nwarmup = 3\n": "warmup",
    }
    for i, (table, field) in enumerate(cases.items()):
        p = write_scenario(tmp_path, base + table, f"bad{i}.toml")
        with pytest.raises(ScenarioError) as e:
            _core.validate_scenario(str(p), sumo_home())
        assert str(p) in str(e.value) and field in str(e.value), (table, str(e.value))


def test_routes_are_seeded_and_dense_enough() -> None:
    env = make_env(BENCH)
    try:
        a, b, c = (env.sim.traffic_routes(s) for s in (1, 1, 2))
        assert a == b and a != c
        vehicles = a.count("<vehicle ")
        assert vehicles >= 50, vehicles
        assert a.count("<flow ") == 2 and '<route id="dh_ego_route" edges="W2C C2T"/>' in a
    finally:
        env.close()


def test_config_overrides_the_scenario_mode(tmp_path: Path, backend: str) -> None:
    env = make_env(BENCH, traffic="none")
    try:
        assert env.traffic_mode == "none"
        env.reset(seed=0)
        assert len(traffic_rows(env)) == 0 and env.sim.traffic is None
    finally:
        env.close()
    with pytest.raises(ConfigError, match="traffic"):
        make_env(BENCH, traffic="carla")
    # A scenario without a [traffic] table runs SUMO when asked (no demand: just the ego).
    p = write_scenario(tmp_path, '[ego]\nstart = { lane = "W2C_1", s = 20.0 }\nroute_edges = ["W2C"]\n')
    env = make_env(p, traffic="sumo", sumo_backend=backend)
    try:
        env.reset(seed=0)
        env.step(np.array([0.0, 5.0]))
        assert env.sim.traffic == "sumo" and len(traffic_rows(env)) == 0
    finally:
        env.close()


# Over TraCI too, where SUMO may open its port and then fail loading its inputs: the message
# must still carry SUMO's own error log (the shim waits for SUMO to exit before it is read).
@pytest.mark.parametrize("backend", ["libsumo", "libsumo-python", "traci"])
def test_sumo_start_failure_carries_sumos_message(tmp_path: Path, backend: str) -> None:
    (tmp_path / "bad.add.xml").write_text(
        '<additional><vType id="car" carFollowModel="NoSuchModel"/></additional>', encoding="utf-8"
    )
    p = write_scenario(
        tmp_path,
        """
        [ego]
        start = { lane = "W2C_1", s = 20.0 }
        route_edges = ["W2C"]
        [traffic]
        vtypes = "bad.add.xml"
        [[traffic.vehicles]]
        route = ["W2C", "C2T"]
        """,
    )
    env = make_env(p, sumo_backend=backend)
    try:
        with pytest.raises(SimulationError) as e:
            env.reset(seed=0)
        assert "SUMO failed to start" in str(e.value) and "NoSuchModel" in str(e.value), str(e.value)
        # The failure is not sticky: a working scenario starts in the same process afterwards.
        env.reset(seed=0, options={"scenario": str(BENCH)})
        assert len(traffic_rows(env)) >= 50
    finally:
        env.close()


def test_one_sumo_per_process(backend: str) -> None:
    a, b = make_env(BENCH, sumo_backend=backend), make_env(BENCH, sumo_backend=backend)
    try:
        a.reset(seed=0)
        with pytest.raises(SimulationError, match="one simulation per process"):
            b.reset(seed=0)
        a.close()
        b.reset(seed=0)  # free again once the first env is closed
    finally:
        a.close()
        b.close()


# -- behaviour -------------------------------------------------------------------------------------


def test_sumo_queues_behind_a_stopped_ego_and_never_passes_through(tmp_path: Path, backend: str) -> None:
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
    env = make_env(p, action_mode="raw", sumo_backend=backend)
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


def test_sumo_vehicles_stop_at_a_red_sumo_switches(tmp_path: Path, backend: str) -> None:
    # Light C gives W2C/T2C green for the first 45 s of its cycle; N2C is red meanwhile
    # (scenarios/maps/README.md). SUMO runs the program; the world's signal heads follow it.
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
    env = make_env(p, sumo_backend=backend)  # the expert drives east on green meanwhile
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


def test_fifty_vehicles_expert_reaches_destination_without_collision(backend: str) -> None:
    out = run_expert(BENCH, seed=0, sumo_backend=backend)
    counts = out["counts"]
    assert isinstance(counts, list) and counts[0] >= 50, counts[:3]
    info = out["info"]
    assert isinstance(info, dict)
    assert info["termination_reason"] == "destination_reached", info["events"]
    assert not [e for e in info["events"] if str(e["type"]).startswith("collision")], info["events"]


def test_sumo_traffic_is_deterministic_across_runs_and_processes(backend: str) -> None:
    a = run_expert(BENCH, seed=5, steps=60, sumo_backend=backend)
    b = run_expert(BENCH, seed=5, steps=60, sumo_backend=backend)
    c = run_expert(BENCH, seed=6, steps=60, sumo_backend=backend)
    assert a["traffic"] == b["traffic"] and a["trajectory"] == b["trajectory"]
    assert a["traffic"] != c["traffic"]
    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); import traffic_helpers as t; "
        "r = t.run_expert(t.BENCH, seed=5, steps=60, sumo_backend=sys.argv[2]); "
        "print(json.dumps([r['traffic'], r['trajectory']]))"
    )
    res = subprocess.run(
        [sys.executable, "-c", code, str(Path(__file__).parent), backend],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    assert json.loads(res.stdout.strip().splitlines()[-1]) == [a["traffic"], a["trajectory"]]


def test_builtin_traffic_flow_scenario_runs_on_sumo_by_default(backend: str) -> None:
    env = make_env(FLOW_SCENARIO, sumo_backend=backend)
    try:
        assert env.traffic_mode == "sumo"
        env.reset(seed=0)
        assert len(traffic_rows(env)) >= 5  # the start frame (gallery) shows SUMO vehicles
        for _ in range(8):
            env.step(env.expert_action())
        assert env.sim.traffic == "sumo"
    finally:
        env.close()


# -- the two SUMO backends -------------------------------------------------------------------------


def test_every_transport_gives_the_same_traffic() -> None:
    # One orchestration (command line, warm-up, movers, departure keys, vehicle order) over
    # libsumo (shim), the libsumo module and TraCI: bit-identical.
    shim = run_expert(BENCH, seed=5, steps=60, sumo_backend="libsumo")
    for other in ("libsumo-python", "traci"):
        run = run_expert(BENCH, seed=5, steps=60, sumo_backend=other)
        assert shim["counts"] == run["counts"], other
        assert shim["traffic"] == run["traffic"] and shim["trajectory"] == run["trajectory"], other


def _sumo_children() -> set[int]:
    """Pids of this process's child processes named like SUMO, zombies included."""
    me = os.getpid()
    return {pid for pid, (ppid, name, _) in process_table().items() if ppid == me and "sumo" in name.lower()}


def test_traci_starts_sumo_as_a_child_without_a_retry_and_reaps_it(capfd: pytest.CaptureFixture[str]) -> None:
    # SUMO is connected to once it listens: no refused connection, no "Retrying in 1 second"
    # printed on every reset, and each SUMO is waited for when its run closes (no zombie).
    before = _sumo_children()
    env = make_env(BENCH, sumo_backend="traci")
    try:
        seen = set()
        for seed in (0, 1):
            env.reset(seed=seed)
            env.step(env.expert_action())
            seen |= _sumo_children() - before
        assert len(seen) == 2, seen  # one SUMO per reset, each our own child
    finally:
        env.close()
    assert _sumo_children() == before
    out = capfd.readouterr()
    assert "Retrying" not in out.out + out.err and "Could not connect" not in out.out + out.err


def test_auto_runs_a_second_sumo_env_of_the_process_on_traci() -> None:
    a, b = make_env(BENCH), make_env(BENCH)
    try:
        a.reset(seed=0)
        b.reset(seed=0)
        assert a._sumo is not None and b._sumo is not None
        assert (a._sumo.transport, b._sumo.transport) == ("libsumo", "traci")
        for _ in range(5):
            a.step(a.expert_action())
            b.step(b.expert_action())
        np.testing.assert_array_equal(a.sim.actors_array(), b.sim.actors_array())
    finally:
        a.close()
        b.close()


def test_libsumo_transport_is_the_default_and_a_missing_shim_falls_back(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    env = make_env(BENCH)
    try:
        assert env._sumo is not None and env._sumo.transport == "libsumo"
    finally:
        env.close()
    # A build without SUMO's headers has no shim: "auto" says so once and uses the Python backend.
    _, lib, binary = transport.libsumo_paths()
    missing = tmp_path / _core.LIBSUMO_SUMO_SHIM
    monkeypatch.setattr(transport, "libsumo_paths", lambda: (missing, lib, binary))
    with caplog.at_level(logging.WARNING, logger=transport.__name__):
        assert transport.make_sumo_traffic("auto").transport == "libsumo-python"
    assert str(missing) in caplog.text and "libsumo-python transport" in caplog.text, caplog.text
    with pytest.raises(SimulationError, match="was not built"):
        transport.make_sumo_traffic("libsumo")
    with pytest.raises(ConfigError, match="sumo_backend"):
        make_env(BENCH, sumo_backend="cpp")


def test_libsumo_transport_loads_sumo_only_when_started_and_never_the_python_module() -> None:
    # Importing drivehierarchy pulls no SUMO library in; a SUMO env on `libsumo` loads libsumocpp
    # (and the shim) but never the libsumo module: one SUMO copy per simulation.
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import traffic_helpers as t; "
        "maps = lambda: open('/proc/self/maps').read(); before = maps(); "
        "env = t.make_env(t.BENCH, sumo_backend='libsumo'); env.reset(seed=0); "
        "env.step(env.expert_action()); "
        "after = maps(); env.close(); "
        "print('libsumocpp' in before, 'libsumocpp' in after, '_dh_sumo_shim' in after, "
        "'_libsumo' in after, 'libsumo' in sys.modules)"
    )
    res = subprocess.run(
        [sys.executable, "-c", code, str(Path(__file__).parent)],
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    assert res.stdout.split() == ["False", "True", "True", "False", "False"], res.stdout + res.stderr


def test_libsumo_and_libsumo_python_share_one_simulation_per_process() -> None:
    a, b = make_env(BENCH, sumo_backend="libsumo"), make_env(BENCH, sumo_backend="libsumo-python")
    try:
        a.reset(seed=0)
        with pytest.raises(SimulationError, match="one simulation per process"):
            b.reset(seed=0)
        a.close()
        b.reset(seed=0)
        a = make_env(BENCH, sumo_backend="libsumo")
        with pytest.raises(SimulationError, match="one simulation per process"):
            a.reset(seed=0)
    finally:
        a.close()
        b.close()


def test_backends_agree_with_mirrored_scenario_actors(tmp_path: Path) -> None:
    # The built-in crossing scenario's cars, bus and parked cars are placed in SUMO (mirrors; two
    # cars leave the world at the end of their paths, and so do their SUMO doubles) beside SUMO
    # flows on the same roads. Both backends must give the same traffic, tick for tick.
    # The crossing scenario as it was before the suite's retune (its actors' ends are this
    # test's subject, not the suite's story), kept beside the test.
    src = Path(__file__).parent / "data" / "cross_traffic_mirrors.toml"
    body = src.read_text(encoding="utf-8")
    body = body[body.index("[ego]") :] + (
        '\n[traffic]\nwarmup_s = 10.0\n[[traffic.flows]]\nfrom = "T2C"\nto = "C2W"\nvehs_per_hour = 600\n'
        '[[traffic.flows]]\nfrom = "S2C"\nto = "C2N"\nvehs_per_hour = 600\n'
    )
    p = write_scenario(tmp_path, body)
    runs = {}
    for backend in ("libsumo", "libsumo-python"):
        env = make_env(p, sumo_backend=backend)
        try:
            env.reset(seed=2)
            digest, scripted, vehicles = [], [], 0
            for _ in range(120):
                term = env.step(env.expert_action())[2]
                rows = env.sim.actors_array()
                digest.append(np.ascontiguousarray(rows).tobytes())
                scripted.append(int((rows[:, IS_TRAFFIC] == 0.0).sum()))
                vehicles = max(vehicles, int((rows[:, IS_TRAFFIC] == 1.0).sum()))
                if term:
                    break
            runs[backend] = (digest, env.sim.trajectory_hash, scripted, vehicles)
        finally:
            env.close()
    assert runs["libsumo"][0] == runs["libsumo-python"][0] and runs["libsumo"][1] == runs["libsumo-python"][1]
    _, _, scripted, vehicles = runs["libsumo"]
    assert vehicles >= 3 and scripted[0] > scripted[-1], (vehicles, scripted[0], scripted[-1])
