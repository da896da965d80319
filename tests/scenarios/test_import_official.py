"""`scenario import-official`: the original release's scenes as our scenario files.

Unit tests use crafted files on the shipped town01 network; the official tests read the real
scenes from `../shared/official/` and skip when it is absent (nothing of it is in the project).
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy import ScenarioError, _core
from drivehierarchy.cli import main
from drivehierarchy.scenario_import import (
    CATEGORY_BY_NUMBER,
    OfficialImporter,
    carla_to_sumo,
    carla_yaw_to_heading_deg,
    category_for,
    sumo_to_carla,
)
from drivehierarchy.scenarios import builtin_root, sumo_home

TOWN01 = builtin_root() / "maps" / "town01" / "town01.net.xml"
CLOSE_LOOP = "Close_Loop_Evaluation"
TONGJI = f"{CLOSE_LOOP}/Carla_Simulation/Co-Simulation/Sumo/tongji"


# ---------------------------------------------------------------------------------------------
# Coordinate frames and categories


def test_carla_sumo_frames_follow_protocol() -> None:
    # docs/protocol.md#r4-categories: CARLA x = SUMO x − 761.28, CARLA y = 488.05 − SUMO y (a point
    # of a real scene).
    assert carla_to_sumo(-716.3723579563067, 199.96828165326565) == pytest.approx(
        (44.90764204369327, 288.08171834673436)
    )
    assert sumo_to_carla(44.90764204369327, 288.08171834673436) == pytest.approx(
        (-716.3723579563067, 199.96828165326565)
    )
    for x, y in [(0.0, 0.0), (123.4, -56.7), (-1e4, 3e3)]:
        assert sumo_to_carla(*carla_to_sumo(x, y, (10.0, -3.0)), (10.0, -3.0)) == pytest.approx((x, y))
    # The y axis flips: north in SUMO is −y in CARLA.
    assert carla_to_sumo(0.0, 1.0, (0.0, 0.0)) == (0.0, -1.0)


def test_carla_yaw_to_heading() -> None:
    assert carla_yaw_to_heading_deg(0.0) == 0.0
    assert carla_yaw_to_heading_deg(-90.0) == pytest.approx(90.0)  # CARLA −y = north
    assert carla_yaw_to_heading_deg(-128.0197923645324) == pytest.approx(128.0197923645324)
    assert carla_yaw_to_heading_deg(180.0) == pytest.approx(180.0)
    assert carla_yaw_to_heading_deg(90.0) == pytest.approx(-90.0)


def test_category_folders_map_to_ours() -> None:
    assert category_for("01_pedestrain_recognition") == "01_pedestrian"
    assert category_for("02_obstacles_avoid") == "02_obstacles"
    assert category_for("03_right_turn") == "03_turning"
    assert category_for("05_T_intersection") == "05_t_intersection"
    assert category_for("09_yield_intersection") == "09_yielding"
    assert category_for("10_roundabout") == "10_roundabout"
    assert sorted(CATEGORY_BY_NUMBER.values()) == sorted(
        p.name for p in (builtin_root() / "r4").iterdir() if p.is_dir()
    )
    with pytest.raises(ValueError, match="11_extra"):
        category_for("11_extra")
    with pytest.raises(ValueError, match="misc"):
        category_for("misc")


# ---------------------------------------------------------------------------------------------
# A crafted scene on town01 (CARLA frame = town01 with offset 0: CARLA y = −SUMO y)


def _point(kind: str, x: float, y: float, kmh: float = 0.0) -> dict:
    return {"point_type": kind, "speed_kmh": kmh, "carla_x": x, "carla_y": -y, "pass": True}


def _actor(aid: str, role: str, edges: list[str], lane: int, pos: float, pts: list[dict], **kw) -> dict:
    return {
        "actor_id": aid,
        "name": kw.get("name", f"{role}{aid}"),
        "role": role,
        "sumo_type_id": kw.get("type", "vehicle.dodge.charger_2020"),
        "vclass": "passenger",
        "route_edges": edges,
        "depart": {
            "time_seconds": 0.0,
            "edge_id": edges[0] if edges else None,
            "lane_index": lane,
            "lane_id": f"{edges[0]}_{lane}" if edges else None,
            "lane_pos": pos,
            "speed_kmh": 0.0,
        },
        "reference_points": pts,
        "estimated_duration_seconds": kw.get("est", 20.0),
    }


VTYPES_XML = """<routes>
  <vType id="vehicle.lincoln.mkz_2020" length="4.89" width="1.84" height="1.49" vClass="passenger"/>
  <vType id="vehicle.dodge.charger_2020" length="5.01" width="1.88" height="1.53" vClass="passenger"/>
</routes>
"""


def _crafted_scene(root: Path) -> Path:
    scene = root / "src" / "07_sudden_brake" / "SC_TEST"
    scene.mkdir(parents=True)
    hero = _actor(
        "1",
        "main",
        ["C2T"],
        1,
        20.0,
        [_point("start", 30.0, -4.8), _point("end", 300.0, -4.2, 20.0)],
        type="vehicle.lincoln.mkz_2020",
        est=30.0,
    )
    others = [
        _actor("100", "slave", ["C2T", "T2E"], 1, 60.0, [_point("start", 70.0, -4.8)]),
        _actor("101", "slave", ["NOPE", "T2E"], 1, 5.0, [_point("start", 0.0, 0.0)]),
        _actor(
            "200",
            "pedestrian",
            ["C2T"],
            0,
            100.0,
            [_point("start", 150.0, -7.4), _point("end", 150.0, 2.0, 5.4), _point("end", 152.0, 6.0)],
        ),
        _actor("201", "pedestrian", ["C2T"], 0, 100.0, [_point("start", 120.0, -7.4)]),
        _actor("300", "bicycle", ["C2T"], 1, 10.0, [_point("start", 20.0, -4.8)]),
    ]
    data = {
        "schema_version": 1,
        "map": {"name": "town01", "net_offset": [0.0, 0.0]},
        "hero": hero,
        "background_vehicles": others,
        "scenario_duration_seconds": 42.0,
        "random_seed": 3,
    }
    (scene / "entity_sumo.json").write_text(json.dumps(data), encoding="utf-8")
    editor_parts = [{"id": a["actor_id"], "type": a["role"], "name": a["name"]} for a in [hero, *others]]
    editor_parts.append({"id": "400", "type": "slave", "name": "lost car"})
    editor = {
        "testSceneDesc": "crafted",
        "trajectoryInfo": json.dumps({"participantTrajectories": editor_parts}),
        "customizedParams": json.dumps({"obstacles": [{"x": 1}], "trigger": [], "trafficLight": []}),
    }
    (scene / "entity.json").write_text(json.dumps(editor), encoding="utf-8")
    (root / "types.rou.xml").write_text(VTYPES_XML, encoding="utf-8")
    return root / "src"


def test_unmappable_actors_are_reported_not_dropped(tmp_path: Path) -> None:
    src = _crafted_scene(tmp_path)
    out = tmp_path / "out"
    report = OfficialImporter(TOWN01, out, vtypes=tmp_path / "types.rou.xml").import_dir(src)
    (scene,) = report.scenes
    assert scene.imported, scene.error
    assert scene.validation == "ok"
    assert (scene.vehicles, scene.pedestrians) == (1, 1)
    reasons = {u.actor.split(" (")[0]: u.reason for u in scene.unmapped}
    assert set(reasons) == {"slave 101", "pedestrian 201", "bicycle 300", "slave 400"}
    assert "'NOPE' are not in the network" in reasons["slave 101"].replace("[", "").replace("]", "")
    assert "a walk needs a start and a target point" in reasons["pedestrian 201"]
    assert "role 'bicycle'" in reasons["bicycle 300"]
    assert "not in entity_sumo.json" in reasons["slave 400"]
    assert any("1 editor obstacles not imported" in n for n in scene.notes)
    # Every actor of the file is accounted for: mapped or listed.
    assert scene.actors_in_file == 1 + scene.vehicles + scene.pedestrians + len(scene.unmapped) - 1

    doc = tomllib.loads((out / "07_sudden_brake" / "SC_TEST.toml").read_text(encoding="utf-8"))
    assert doc["category"] == "07_sudden_brake"
    assert doc["reference_duration_s"] == 30.0 and doc["duration_s"] == 42.0 and doc["seed"] == 3
    assert doc["ego"]["route_edges"] == ["C2T"]
    assert doc["ego"]["start"]["lane"] == "C2T_1"
    assert doc["ego"]["start"]["s"] == pytest.approx(30.0 - 10.4)
    assert doc["ego"]["destination"] == {"lane": "C2T_1", "s": pytest.approx(300.0 - 10.4)}
    assert doc["ego"]["vehicle"] == {"length_m": 4.89, "width_m": 1.84, "height_m": 1.49}
    (ped,) = doc["actors"]
    assert ped["kind"] == "pedestrian"
    assert [(w["x"], w["y"]) for w in ped["waypoints"]] == [(150.0, -7.4), (150.0, 2.0), (152.0, 6.0)]
    # The target point's speed (5.4 km/h), else the default 1.2 m/s.
    assert [w.get("speed_mps") for w in ped["waypoints"]] == [None, pytest.approx(1.5), 1.2]
    (veh,) = doc["traffic"]["vehicles"]
    assert veh == {
        "id": "slave_100",
        "vtype": "vehicle.dodge.charger_2020",
        "route": ["C2T", "T2E"],
        "depart_s": 0.0,
        "depart_lane": 1,
        "depart_pos_m": 60.0,
        "depart_speed": 0.0,
    }
    assert doc["traffic"]["mode"] == "sumo" and doc["traffic"]["warmup_s"] == 0.0
    assert (out / doc["traffic"]["vtypes"].split("/")[-1]).is_file()  # copied into OUT
    assert json.loads((out / "import_report.json").read_text(encoding="utf-8"))["unmapped_actors"] == 4


def test_written_file_keeps_the_style_of_the_shipped_scenarios(tmp_path: Path) -> None:
    """The whole file as written (tomlkit, set to the shipped scenarios' style: spaced inline
    tables, one per line two spaces in), so a format change shows up here, not in users' diffs."""
    src = _crafted_scene(tmp_path)
    out = tmp_path / "out"
    OfficialImporter(TOWN01, out, vtypes=tmp_path / "types.rou.xml").import_dir(src)
    text = (out / "07_sudden_brake" / "SC_TEST.toml").read_text(encoding="utf-8")
    head, tail = text.split("\nmap = ", 1)
    assert head == (
        "# Imported from the original DriveHierarchy release by\n"
        "# `drivehierarchy scenario import-official`.\n"
        "# Source: 07_sudden_brake/SC_TEST/entity_sumo.json\n"
        "version = 1\n"
        'id = "official_SC_TEST"\n'
        'name = "07_sudden_brake/SC_TEST"\n'
        'category = "07_sudden_brake"\n'
        "description = \"Original R4 scene SC_TEST (07_sudden_brake) on the user's network; "
        'editor note: crafted"'
    )
    assert (
        tail.split("\n", 1)[1]
        == """reference_duration_s = 30.0
duration_s = 42.0
seed = 3

[ego]
route_edges = ["C2T"]
start = { lane = "C2T_1", s = 19.6, offset_m = 0.0 }
destination = { lane = "C2T_1", s = 289.6 }
speed_mps = 0.0

[ego.vehicle]
length_m = 4.89
width_m = 1.84
height_m = 1.49

[[actors]]
name = "pedestrian 200 (pedestrian200)"
kind = "pedestrian"
waypoints = [
  { x = 150.0, y = -7.4 },
  { x = 150.0, y = 2.0, speed_mps = 1.5 },
  { x = 152.0, y = 6.0, speed_mps = 1.2 },
]
at_end = "stop"

[traffic]
mode = "sumo"
vtypes = "../types.rou.xml"
warmup_s = 0.0

[[traffic.vehicles]]
id = "slave_100"
vtype = "vehicle.dodge.charger_2020"
route = ["C2T", "T2E"]
depart_s = 0.0
depart_lane = 1
depart_pos_m = 60.0
depart_speed = 0.0
"""
    )


def test_vehicles_of_unknown_class_or_placed_by_longitude_latitude_are_reported(tmp_path: Path) -> None:
    src = _crafted_scene(tmp_path)
    f = src / "07_sudden_brake" / "SC_TEST" / "entity_sumo.json"
    data = json.loads(f.read_text(encoding="utf-8"))
    data["background_vehicles"][0]["vclass"] = "hovercraft"
    ped = data["background_vehicles"][2]
    ped["reference_points"][0] = {"point_type": "start", "longitude": 121.2, "latitude": 31.3}
    f.write_text(json.dumps(data), encoding="utf-8")
    report = OfficialImporter(TOWN01, tmp_path / "out").import_dir(src)  # no type file: vclass used
    (scene,) = report.scenes
    reasons = {u.actor.split(" (")[0]: u.reason for u in scene.unmapped}
    assert reasons["slave 100"] == "vehicle class 'hovercraft' is not a SUMO vehicle class"
    # town01 has no geo-projection (projParameter "!"): said so, with the network's name.
    assert "point 0: only longitude/latitude given" in reasons["pedestrian 200"]
    assert "town01.net.xml has no geo-projection" in reasons["pedestrian 200"]


def test_unreadable_network_names_file_line_attribute_and_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _crafted_scene(tmp_path)
    bad = tmp_path / "bad.net.xml"
    bad.write_text(
        '<net>\n<edge id="A"><lane id="A_0" index="0" speed="x" length="5" shape="0,0 1,1"/></edge></net>\n',
        encoding="utf-8",
    )
    with pytest.raises(ScenarioError, match=r'bad\.net\.xml: line 2: .*attribute speed = "x"'):
        OfficialImporter(bad, tmp_path / "out")
    args = ["scenario", "import-official", str(src), "--net", str(bad), "--out", str(tmp_path / "o")]
    assert main(args) == 2
    assert 'attribute speed = "x": not a finite number' in capsys.readouterr().err


def test_cli_strict_exit_and_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = _crafted_scene(tmp_path)
    args = [
        "scenario",
        "import-official",
        str(src),
        "--net",
        str(TOWN01),
        "--vtypes",
        str(tmp_path / "types.rou.xml"),
    ]
    assert main([*args, "--out", str(tmp_path / "a")]) == 0
    text = capsys.readouterr().out
    assert "NOT MAPPED slave 101" in text and "1 of 1 scenes imported" in text
    assert main([*args, "--out", str(tmp_path / "b"), "--strict"]) == 1
    capsys.readouterr()
    # Nothing to import is an error, not an empty success.
    (tmp_path / "empty").mkdir()
    assert (
        main(
            [
                "scenario",
                "import-official",
                str(tmp_path / "empty"),
                "--net",
                str(TOWN01),
                "--out",
                str(tmp_path / "c"),
            ]
        )
        == 2
    )
    assert "no entity_sumo.json" in capsys.readouterr().err


def test_broken_hero_fails_the_scene_with_reason(tmp_path: Path) -> None:
    src = _crafted_scene(tmp_path)
    f = src / "07_sudden_brake" / "SC_TEST" / "entity_sumo.json"
    data = json.loads(f.read_text(encoding="utf-8"))
    data["hero"]["route_edges"] = ["NOPE"]
    f.write_text(json.dumps(data), encoding="utf-8")
    report = OfficialImporter(TOWN01, tmp_path / "out", vtypes=tmp_path / "types.rou.xml").import_dir(src)
    (scene,) = report.scenes
    assert not scene.imported
    assert "hero" in scene.error and "NOPE" in scene.error and "entity_sumo.json" in scene.error
    assert not (tmp_path / "out" / "07_sudden_brake" / "SC_TEST.toml").exists()


# ---------------------------------------------------------------------------------------------
# The real scenes of the original release


@pytest.fixture(scope="module")
def imported(
    tmp_path_factory: pytest.TempPathFactory, official_dir: Path, require_official: Any
) -> tuple[Path, dict]:
    scenes = require_official(official_dir / CLOSE_LOOP / "Scenario_Onsite", "official scenes")
    net = require_official(official_dir / TONGJI / "tongji.net.xml", "tongji.net.xml")
    out = tmp_path_factory.mktemp("official")
    assert main(["scenario", "import-official", str(scenes), "--net", str(net), "--out", str(out)]) == 0
    return out, json.loads((out / "import_report.json").read_text(encoding="utf-8"))


def test_all_official_scenes_import_and_validate(imported: tuple[Path, dict]) -> None:
    out, report = imported
    n = len(report["scenes"])
    assert n >= 13
    assert report["imported"] == n and report["failed"] == 0
    for s in report["scenes"]:
        assert s["validation"] == "ok", s
        total = 1 + s["mapped"]["vehicles"] + s["mapped"]["pedestrians"] + len(s["unmapped"])
        assert total >= s["actors_in_file"], s  # no actor vanished without a line in the report
    files = sorted(out.glob("*/*.toml"))
    assert len(files) == n
    assert main(["scenario", "validate", str(out)]) == 0
    # The original's 8 categories land in ours.
    assert {f.parent.name for f in files} >= {
        "01_pedestrian",
        "02_obstacles",
        "07_sudden_brake",
        "09_yielding",
    }


def test_official_positions_match_the_reference_points(
    imported: tuple[Path, dict], official_dir: Path
) -> None:
    out, _ = imported
    src = official_dir / CLOSE_LOOP / "Scenario_Onsite" / "01_pedestrain_recognition" / "SC20260319211139GNGY"
    data = json.loads((src / "entity_sumo.json").read_text(encoding="utf-8"))
    doc = tomllib.loads((out / "01_pedestrian" / "SC20260319211139GNGY.toml").read_text(encoding="utf-8"))
    peds = [a for a in data["background_vehicles"] if a["role"] == "pedestrian"]
    assert len(doc["actors"]) == len(peds)
    for ped, actor in zip(peds, doc["actors"], strict=True):
        for p, w in zip(ped["reference_points"], actor["waypoints"], strict=True):
            assert math.hypot(p["sumo_x"] - w["x"], p["sumo_y"] - w["y"]) < 1e-3
        assert actor["waypoints"][-1]["speed_mps"] == pytest.approx(
            ped["reference_points"][-1]["speed_kmh"] / 3.6, abs=1e-4
        )
    assert doc["reference_duration_s"] == pytest.approx(data["hero"]["estimated_duration_seconds"], abs=1e-4)
    assert doc["duration_s"] == pytest.approx(data["scenario_duration_seconds"], abs=1e-4)
    assert doc["ego"]["route_edges"] == data["hero"]["route_edges"]
    slaves = [a for a in data["background_vehicles"] if a["role"] == "slave"]
    assert [v["route"] for v in doc["traffic"]["vehicles"]] == [a["route_edges"] for a in slaves]
    summary = _core.validate_scenario(str(out / "01_pedestrian" / "SC20260319211139GNGY.toml"), sumo_home())
    assert summary["actors"] == len(peds)


def test_official_scenes_run_to_a_termination_and_the_expert_completes(
    imported: tuple[Path, dict], tmp_path: Path
) -> None:
    """Each imported scene runs with its SUMO traffic to a termination; the expert reaches the
    destination in every scene but GNGY (see docs/importing.md).

    GNGY cannot be finished by any driver: its ego lane `-68_0` is link 1 of light `559` in
    tongji.net.xml, whose static program (offset 0) is red for that link for the first 48 s
    (phases `gr` 42 s, `yr` 3 s, `rr` 3 s), while its scenario timeout is 2 × 24.59 s = 49.2 s.
    The original release holds no other light setting that the importer could carry: the
    editor's `customizedParams.trafficLight` is `[]` in all 13 `entity.json` files and
    `entity_sumo.json` has no light field (`test_official_scenes_hold_no_light_settings`)."""
    pytest.importorskip("libsumo")
    from drivehierarchy.benchmark.r4 import runner

    out, report = imported
    results = runner.evaluate(
        runner.suite_scenarios(str(out)), tmp_path / "run", runner.RunOptions(), log=lambda m: None
    )
    assert len(results) == len(report["scenes"])
    reasons = {r["key"]: r["score"]["termination_reason"] for r in results}
    assert all(reasons.values()), reasons
    missed = sorted(k for k, v in reasons.items() if v != "destination_reached")
    assert len(missed) <= 1 and all("GNGY" in k for k in missed), reasons


def test_official_scenes_hold_no_light_settings(official_dir: Path, require_official: Any) -> None:
    """The evidence behind GNGY's expected miss above: no scene of the original release sets
    its lights, so the network's static programs (offset 0) are all there is to import."""
    scenes = require_official(official_dir / CLOSE_LOOP / "Scenario_Onsite", "official scenes")
    editors = sorted(scenes.glob("*/*/entity.json"))
    assert len(editors) >= 13
    for f in editors:
        params = json.loads(json.loads(f.read_text(encoding="utf-8"))["customizedParams"])
        assert params["trafficLight"] == [], f
        sumo = json.loads((f.parent / "entity_sumo.json").read_text(encoding="utf-8"))
        assert not [k for k in sumo if "light" in k.lower() or "tls" in k.lower()], f


def test_import_is_deterministic(tmp_path: Path) -> None:
    src = _crafted_scene(tmp_path)
    texts = []
    for name in ("a", "b"):
        OfficialImporter(TOWN01, tmp_path / name, vtypes=tmp_path / "types.rou.xml").import_dir(src)
        texts.append((tmp_path / name / "07_sudden_brake" / "SC_TEST.toml").read_bytes())
    assert texts[0] == texts[1]


def test_official_start_states_match_the_reference_points(
    imported: tuple[Path, dict], official_dir: Path
) -> None:
    """After reset (SUMO running) the ego stands at the hero's start point and the SUMO vehicles
    at their start points (SUMO places a vehicle's front there; the world its centre)."""
    pytest.importorskip("libsumo")
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    _out, report = imported
    scenes = official_dir / CLOSE_LOOP / "Scenario_Onsite"
    for s in report["scenes"]:
        data = json.loads((scenes / s["source"]).read_text(encoding="utf-8"))
        env = DriveHierarchyR4Env(scenario=s["out"], front=None, bev=None)
        try:
            env.reset(seed=0)
            ego = env.unwrapped.sim.ego_array()
            actors = [a for a in env.unwrapped.sim.actors_array() if a[7] == 1.0]
        finally:
            env.close()
        h = data["hero"]["reference_points"][0]
        assert math.hypot(ego[0] - h["sumo_x"], ego[1] - h["sumo_y"]) < 1.6, s["source"]
        gaps = sorted(
            min(math.hypot(a[1] - p["sumo_x"], a[2] - p["sumo_y"]) for a in actors)
            for v in data["background_vehicles"]
            if v["role"] == "slave"
            for p in v["reference_points"][:1]
        )
        assert gaps[len(gaps) // 2] < 3.2, (s["source"], gaps)


def test_out_inside_the_project_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    src = _crafted_scene(tmp_path)
    inside = builtin_root() / "imported_by_test"
    assert main(["scenario", "import-official", str(src), "--net", str(TOWN01), "--out", str(inside)]) == 2
    assert "folder of your own" in capsys.readouterr().err
    assert not inside.exists()


def test_copy_net_makes_out_self_contained(tmp_path: Path) -> None:
    src = _crafted_scene(tmp_path)
    out = tmp_path / "out"
    OfficialImporter(TOWN01, out, vtypes=tmp_path / "types.rou.xml", copy_net=True).import_dir(src)
    doc = tomllib.loads((out / "07_sudden_brake" / "SC_TEST.toml").read_text(encoding="utf-8"))
    assert doc["map"] == "../town01.net.xml" and (out / "town01.net.xml").is_file()


def test_without_a_type_file_vehicles_use_our_types(tmp_path: Path) -> None:
    src = _crafted_scene(tmp_path)
    report = OfficialImporter(TOWN01, tmp_path / "out").import_dir(src)
    (scene,) = report.scenes
    assert scene.imported and scene.validation == "ok", scene.error
    assert report.vtypes is None
    assert any("drawn as our 'car' (no vehicle-type file given)" in n for n in scene.notes)
    doc = tomllib.loads((tmp_path / "out" / "07_sudden_brake" / "SC_TEST.toml").read_text(encoding="utf-8"))
    assert "vtypes" not in doc["traffic"] and doc["traffic"]["vehicles"][0]["vtype"] == "car"
    assert "vehicle" not in doc["ego"]


def test_official_scene_is_deterministic_with_sumo(imported: tuple[Path, dict]) -> None:
    pytest.importorskip("libsumo")
    from drivehierarchy.agents.base import run_episode
    from drivehierarchy.agents.expert import ExpertAgent
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    out, _ = imported
    scene = out / "04_intersection" / "SC20260322015632GBSE.toml"
    hashes = []
    for _ in range(2):
        env = DriveHierarchyR4Env(scenario=scene, front=None, bev=None)
        try:
            run_episode(env, ExpertAgent(), seed=3)
            hashes.append(env.unwrapped.sim.trajectory_hash)
        finally:
            env.close()
    assert hashes[0] == hashes[1]
