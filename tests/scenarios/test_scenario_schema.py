"""The scenario JSON Schema (generated from the Rust types) and `scenario validate`'s locations."""

from __future__ import annotations

import copy
import re
import tomllib
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from drivehierarchy import ScenarioError, _core
from drivehierarchy.cli import main
from drivehierarchy.scenario_cli import schema_text
from drivehierarchy.scenarios import builtin_root

REPO = Path(__file__).resolve().parents[2]
SCHEMA_FILE = REPO / "docs" / "scenario.schema.json"
# Every scenario file shipped (scenarios/maps/ holds netconvert build settings, not scenarios).
SCENARIO_FILES = [
    p
    for p in sorted((REPO / "scenarios").glob("**/*.toml"))
    if p.relative_to(REPO / "scenarios").parts[0] != "maps"
] + sorted((REPO / "env" / "tests" / "world_fixtures").glob("*.toml"))
TOWN01 = builtin_root() / "maps" / "town01" / "town01.net.xml"
# A valid scenario of its own (line numbers below refer to it), independent of the shipped suite.
BASE = f"""version = 1
id = "schema_test"
category = "07_sudden_brake"
map = "{TOWN01.as_posix()}"

[ego]
start = {{ lane = "C2T_1", s = 20.0 }}
destination = {{ lane = "C2T_1", s = 330.0 }}
speed_mps = 6.0

[[actors]]
kind = "car"
route = {{ lanes = ["C2T_1", "T2E_0"], start_s = 55.0 }}
speed_mps = 9.0
brake = {{ at_s = 110.0, decel_mps2 = 7.0, hold_s = 1.0 }}

[[actors]]
kind = "car"
route = {{ lanes = ["C2T_2", "T2E_1"], start_s = 40.0 }}
speed_mps = 9.0
"""


@pytest.fixture(scope="module")
def schema() -> dict[str, Any]:
    s: dict[str, Any] = _core.scenario_json_schema()
    jsonschema.Draft7Validator.check_schema(s)
    return s


def errors(schema: dict[str, Any], doc: dict[str, Any]) -> list[str]:
    v = jsonschema.Draft7Validator(schema)
    return [f"{'.'.join(map(str, e.absolute_path))}: {e.message}" for e in v.iter_errors(doc)]


def test_committed_schema_is_current(schema: dict[str, Any]) -> None:
    """docs/scenario.schema.json is exactly what the Rust types generate (regenerate with
    `drivehierarchy scenario schema --out docs/scenario.schema.json`)."""
    assert SCHEMA_FILE.read_text(encoding="utf-8") == schema_text()
    assert schema["$schema"] == "http://json-schema.org/draft-07/schema#"


def test_cli_prints_and_writes_it(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenario", "schema"]) == 0
    assert capsys.readouterr().out == schema_text()
    out = tmp_path / "s.json"
    assert main(["scenario", "schema", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == schema_text()
    assert main(["scenario", "schema", "--out", str(tmp_path / "no" / "such" / "s.json")]) == 2


@pytest.mark.parametrize("path", SCENARIO_FILES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_shipped_scenario_validates(schema: dict[str, Any], path: Path) -> None:
    doc = tomllib.loads(path.read_text(encoding="utf-8"))
    assert errors(schema, doc) == []


def test_schema_carries_descriptions_and_defaults(schema: dict[str, Any]) -> None:
    defs = schema["definitions"]
    assert "SUMO_HOME" in schema["properties"]["map"]["description"]
    assert schema["properties"]["seed"]["default"] == 0
    assert defs["VehicleParams"]["properties"]["wheelbase_m"]["default"] == 2.9
    assert defs["ActorSpec"]["properties"]["at_end"]["default"] == "stop"
    assert "01_pedestrian" in schema["properties"]["category"]["enum"]


def _base() -> dict[str, Any]:
    return tomllib.loads(BASE)


def _edits() -> list[tuple[str, Any, str]]:
    """(what, edit of the parsed scenario, the start of the schema's error: path and message)."""

    def unknown_top(d: dict[str, Any]) -> None:
        d["colour"] = "red"

    def unknown_nested(d: dict[str, Any]) -> None:
        d["actors"][0]["brake"]["decel"] = 7.0

    def wrong_type(d: dict[str, Any]) -> None:
        d["actors"][0]["speed_mps"] = "fast"

    def wrong_kind(d: dict[str, Any]) -> None:
        d["actors"][1]["kind"] = "tank"

    def missing_required(d: dict[str, Any]) -> None:
        del d["map"]

    def place_both_forms(d: dict[str, Any]) -> None:
        d["ego"]["start"]["x"] = 1.0

    def place_half_xy(d: dict[str, Any]) -> None:
        d["ego"]["destination"] = {"x": 1.0}

    def two_triggers(d: dict[str, Any]) -> None:
        d["actors"][0]["start"] = {"time_s": 1.0, "ego_within_m": 20.0}

    def brake_both(d: dict[str, Any]) -> None:
        d["actors"][0]["brake"]["after_s"] = 2.0

    def route_both(d: dict[str, Any]) -> None:
        d["actors"][0]["route"]["edges"] = ["C2T"]

    def no_path(d: dict[str, Any]) -> None:
        del d["actors"][1]["route"]

    def bad_version(d: dict[str, Any]) -> None:
        d["version"] = 2

    def bad_color(d: dict[str, Any]) -> None:
        d["actors"][0]["color"] = [300, 0, 0]

    def emergency_not_bool(d: dict[str, Any]) -> None:
        d["actors"][0]["emergency"] = "yes"

    def bad_flow(d: dict[str, Any]) -> None:
        d["traffic"] = {"flows": [{"from": "a", "to": "b", "vehs_per_hour": 5, "probability": 0.1}]}

    def bad_lane_name(d: dict[str, Any]) -> None:
        d["traffic"] = {"vehicles": [{"route": ["C2T"], "depart_lane": "leftmost"}]}

    def eta_and_after(d: dict[str, Any]) -> None:
        d["actors"][1]["start"] = {"ego_eta_s": 3.0, "of": [200.0, -4.8], "after": "x"}

    def delay_without_after(d: dict[str, Any]) -> None:
        d["actors"][1]["start"] = {"time_s": 1.0, "delay_s": 1.0}

    def bad_event(d: dict[str, Any]) -> None:
        d["actors"][1]["start"] = {"after": "actors[0]", "event": "stop"}

    def lane_change_unknown_key(d: dict[str, Any]) -> None:
        d["actors"][1]["lane_changes"] = [{"at_s": 5.0, "lane": "C2T_1"}]

    def light_offset_and_phase(d: dict[str, Any]) -> None:
        d["lights"] = [{"tls": "C", "offset_s": 3.0, "start_phase": 1}]

    def light_nothing(d: dict[str, Any]) -> None:
        d["lights"] = [{"tls": "C"}]

    def light_elapsed_alone(d: dict[str, Any]) -> None:
        d["lights"] = [{"tls": "C", "offset_s": 3.0, "phase_elapsed_s": 1.0}]

    return [
        ("unknown top-level key", unknown_top, ": Additional properties are not allowed ('colour'"),
        ("unknown nested key", unknown_nested, "actors.0.brake: Additional properties"),
        ("wrong type", wrong_type, "actors.0.speed_mps: 'fast' is not of type"),
        ("unknown kind", wrong_kind, "actors.1.kind: 'tank'"),
        ("emergency not a bool", emergency_not_bool, "actors.0.emergency: "),
        ("missing required key", missing_required, ": 'map' is a required property"),
        ("place by lane and x", place_both_forms, "ego.start: "),
        ("place with x only", place_half_xy, "ego.destination: "),
        ("two trigger kinds", two_triggers, "actors.0.start: "),
        ("brake at_s and after_s", brake_both, "actors.0.brake: "),
        ("route edges and lanes", route_both, "actors.0.route: "),
        ("scripted actor without path", no_path, "actors.1: "),
        ("version", bad_version, "version: 1 was expected"),
        ("colour component", bad_color, "actors.0.color.0: 300 is greater"),
        ("flow rate twice", bad_flow, "traffic.flows.0: "),
        ("depart_lane name", bad_lane_name, "traffic.vehicles.0.depart_lane: "),
        ("ego_eta_s and after", eta_and_after, "actors.1.start: "),
        ("delay_s without after", delay_without_after, "actors.1.start: "),
        ("chain event name", bad_event, "actors.1.start.event: 'stop'"),
        ("lane change unknown key", lane_change_unknown_key, "actors.1.lane_changes.0: Additional"),
        ("light offset and start phase", light_offset_and_phase, "lights.0: "),
        ("light without override", light_nothing, "lights.0: "),
        ("phase_elapsed_s without start_phase", light_elapsed_alone, "lights.0: "),
    ]


def test_schema_accepts_the_new_features(schema: dict[str, Any]) -> None:
    d = _base()
    d["actors"][0]["start"] = {"ego_eta_s": 3.0, "of": [200.0, -4.8]}
    d["actors"][1]["start"] = {"after": "actors[0]", "delay_s": 1.0, "event": "brake"}
    d["actors"][1]["lane_changes"] = [{"at_s": 40.0, "to_lane": "C2T_1", "length_m": 20.0}]
    d["actors"][0]["emergency"] = True
    d["lights"] = [
        {"tls": "C", "start_phase": 3, "phase_elapsed_s": 5.0},
        {"tls": "D", "phases": [{"state": "GGrr", "duration_s": 30.0}], "offset_s": 2.0},
    ]
    d["traffic"] = {
        "vehicles": [{"route": ["C2T"], "max_speed_mps": 6.0, "speed_factor": 0.8}],
        "flows": [{"from": "C2T", "to": "T2E", "vehs_per_hour": 300, "number": 3, "speed_factor": 1.1}],
    }
    assert errors(schema, d) == []


@pytest.mark.parametrize("case", _edits(), ids=lambda c: c[0])
def test_schema_rejects_what_the_reader_rejects(
    schema: dict[str, Any], case: tuple[str, Any, str], tmp_path: Path
) -> None:
    _, edit, mention = case
    base = _base()
    assert errors(schema, base) == []
    doc = copy.deepcopy(base)
    edit(doc)
    errs = errors(schema, doc)
    assert errs, "the schema must reject this"
    assert any(e.startswith(mention) for e in errs), errs


def _broken_copy(tmp_path: Path, old: str, new: str) -> Path:
    assert old in BASE
    p = tmp_path / "broken.toml"
    p.write_text(BASE.replace(old, new), encoding="utf-8")
    return p


def test_base_is_valid(tmp_path: Path) -> None:
    p = tmp_path / "ok.toml"
    p.write_text(BASE, encoding="utf-8")
    assert main(["scenario", "validate", str(p)]) == 0


@pytest.mark.parametrize(
    ("old", "new", "where", "field"),
    [
        # Semantic errors found against the map: unknown lane, s past the lane's end.
        ('"C2T_2", "T2E_1"]', '"C2T_2", "T2E_9"]', "19:29", "actors[1].route.lanes[1]"),
        ("s = 330.0 }", "s = 3300.0 }", "8:37", "ego.destination.s"),
        # A key left out: the header of its table.
        ('route = { lanes = ["C2T_2", "T2E_1"], start_s = 40.0 }\n', "", "17:1", "actors[1].waypoints"),
        # A type error, found while reading.
        ("speed_mps = 9.0\nbrake", 'speed_mps = "fast"\nbrake', "14:13", "actors[0].speed_mps"),
    ],
)
def test_validate_cli_reports_file_line_and_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str, where: str, field: str
) -> None:
    p = _broken_copy(tmp_path, old, new)
    assert main(["scenario", "validate", str(p)]) == 1
    out = capsys.readouterr().out
    assert f"INVALID {p}:{where}: field `{field}` = " in out, out
    with pytest.raises(ScenarioError, match=re.escape(f"{p}:{where}: field `{field}`")):
        _core.validate_scenario(str(p))
