"""`_core.constants()` is the one source of the Rust facts: every value it lists is known to the
scenario JSON Schema, to the editor page (which builds its pickers from it) and to the Python
tables that label those values. A Rust enum or constant that gains a value fails here until each
of them knows it."""

from __future__ import annotations

import inspect
import itertools
import json
import re
import warnings
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy import ConfigError, ScenarioError, _core
from drivehierarchy.scenarios import builtin_root

REPO = Path(__file__).resolve().parents[2]
EDITOR_JS = REPO / "python" / "drivehierarchy" / "editor" / "static" / "editor.js"
FACTS = _core.constants()
# The scenario-format enums and the schema definition each one comes from.
SCHEMA_ENUMS = {
    "kinds": "ActorKind",
    "sign_kinds": "SignKind",
    "traffic_modes": "TrafficMode",
    "behaviors": "BehaviorSpec",
    "at_end": "AtEndSpec",
    "chain_events": "ChainEventSpec",
    "depart_lanes": "LaneChoice",
    "depart_speeds": "SpeedChoice",
    "times_of_day": "TimeOfDay",
    "weathers": "Weather",
}
# What the editor page takes from `/api/facts` (`K().<key>` in editor.js).
EDITOR_KEYS = [
    "actor_kinds",
    "obstacle_kinds",
    "sign_kinds",
    "traffic_modes",
    "behaviors",
    "at_end",
    "chain_events",
    "depart_lanes",
    "depart_speeds",
    "times_of_day",
    "weathers",
    "vclass_of",
    "actor_keys",
    "start_triggers",
    "brake_triggers",
    "ego_vclass",
    "builtin_vtypes",
    "default_vtype",
    "of_rules",
]


def _strings(schema: Any) -> list[str]:
    """Every string of `enum` / `const` in a schema (its alternatives included)."""
    out: list[str] = []
    if isinstance(schema, dict):
        out += [v for v in schema.get("enum", []) if isinstance(v, str)]
        if isinstance(schema.get("const"), str):
            out.append(schema["const"])
        for v in schema.values():
            out += _strings(v)
    elif isinstance(schema, list):
        for v in schema:
            out += _strings(v)
    return out


@pytest.fixture(scope="module")
def schema() -> dict[str, Any]:
    s: dict[str, Any] = _core.scenario_json_schema()
    return s


def test_the_step_and_decision_rate_agree() -> None:
    from drivehierarchy.envs.config import R4Config

    assert FACTS["decision_hz"] * FACTS["tick_s"] * FACTS["ticks_per_decision"] == pytest.approx(1.0)
    cfg = R4Config()
    assert (cfg.decision_interval_ticks, cfg.warmup_ticks) == (
        FACTS["ticks_per_decision"],
        FACTS["warmup_ticks"],
    )


@pytest.mark.parametrize("key", sorted(SCHEMA_ENUMS))
def test_every_enum_value_is_the_schemas(schema: dict[str, Any], key: str) -> None:
    definition = (schema.get("definitions") or schema.get("$defs"))[SCHEMA_ENUMS[key]]
    assert FACTS[key] and set(FACTS[key]) == set(_strings(definition)), key


def test_categories_and_kinds_are_the_schemas(schema: dict[str, Any]) -> None:
    assert FACTS["categories"] == _strings(schema["properties"]["category"])
    assert len(FACTS["categories"]) == 10
    assert set(FACTS["actor_kinds"]) | set(FACTS["obstacle_kinds"]) == set(FACTS["kinds"])
    assert sorted(FACTS["obstacle_kinds"]) == sorted(FACTS["kinds"])
    assert set(FACTS["actor_keys"]) == set(schema["definitions"]["ActorSpec"]["properties"])
    assert set(FACTS["deprecated_traffic_modes"].values()) <= set(FACTS["traffic_modes"])
    assert not set(FACTS["deprecated_traffic_modes"]) & set(FACTS["traffic_modes"])


def test_every_kind_routes_on_a_sumo_class_the_map_reader_knows() -> None:
    assert sorted(FACTS["vclass_of"]) == sorted(FACTS["kinds"])
    net = str(builtin_root() / "maps" / "town01" / "town01.net.xml")
    for kind, vclass in FACTS["vclass_of"].items():
        # An unknown class name is a ConfigError; a known one snaps (or finds no lane).
        _core.snap_to_lane(net, 0.0, 0.0, 1e6, vclass)
        assert vclass, kind


def test_the_editor_page_takes_every_fact_from_the_server() -> None:
    js = EDITOR_JS.read_text(encoding="utf-8")
    used = set(re.findall(r"K\(\)\.([a-z_]+)", js))
    assert used == set(EDITOR_KEYS)
    # No hand copy of an enum: no array literal that lists two values of one enum.
    for key in [*SCHEMA_ENUMS, "categories"]:
        values = FACTS[key]
        for a, b in itertools.pairwise(values):
            assert f'"{a}", "{b}"' not in js, (key, a, b)
    vclass_for = js[js.index("function vclassFor(") :]
    assert "K().vclass_of[kind]" in vclass_for[: vclass_for.index("\n}\n")]


def test_every_trigger_form_is_the_schemas_and_has_an_editor_default(schema: dict[str, Any]) -> None:
    for key, definition in (("start_triggers", "TriggerSpec"), ("brake_triggers", "BrakeSpec")):
        props = schema["definitions"][definition]["properties"]
        assert FACTS[key] and set(FACTS[key]) <= set(props), key
    js = EDITOR_JS.read_text(encoding="utf-8")
    trigger_fields = js[js.index("function triggerFields(") :]
    # Picking a form in the editor writes that form's default: one per form.
    for k in {*FACTS["start_triggers"], *FACTS["brake_triggers"]}:
        assert re.search(rf"\b{k}: \{{ {k}: ", trigger_fields), f"editor.js has no default for trigger `{k}`"


def test_the_actor_form_has_a_field_for_every_actor_key() -> None:
    js = EDITOR_JS.read_text(encoding="utf-8")
    form = js[js.index("function actorForm(") :]
    form = form[: form.index("\n}\n")]
    missing = [k for k in FACTS["actor_keys"] if f'[...p, "{k}"]' not in form]
    assert not missing, f"editor.js actorForm has no field for {missing}"


def test_the_editor_serves_the_facts(client: Any) -> None:
    d = client.get("/api/facts").json()
    assert d["constants"] == json.loads(json.dumps(FACTS))
    assert d["schema"] == _core.scenario_json_schema()


@pytest.fixture
def client(tmp_path: Path) -> Any:
    from starlette.testclient import TestClient

    from drivehierarchy.editor import create_app

    app = create_app(tmp_path, "builtin:town01", precompute=False)
    with TestClient(app, base_url="http://127.0.0.1:8765") as c:
        yield c


def test_python_tables_cover_every_value() -> None:
    from drivehierarchy.benchmark.openloop.generate import rollout
    from drivehierarchy.benchmark.r4 import report, vlm_drive
    from drivehierarchy.envs.traffic import TRAFFIC_MODES
    from drivehierarchy.scenario_import import CATEGORY_BY_NUMBER

    assert set(rollout.CATEGORY) == set(FACTS["kinds"])
    assert sorted(CATEGORY_BY_NUMBER.values()) == sorted(FACTS["categories"])
    labels = [report.category_label(c) for c in FACTS["categories"]]
    assert len(set(labels)) == len(labels) and all(lab.startswith("Sce ") for lab in labels)
    assert "destination_reached" in FACTS["termination_reasons"]
    # The RL reward's terminal penalties name real reasons only (a stale name never matches).
    from drivehierarchy.baselines.wrappers import terminal_penalty

    named = set(re.findall(r'"([a-z_]+)"', inspect.getsource(terminal_penalty)))
    assert named - {"collision"} <= set(FACTS["termination_reasons"]), named
    assert tuple(FACTS["traffic_modes"]) == TRAFFIC_MODES
    assert FACTS["tick_s"] == vlm_drive.TICK_S and FACTS["decision_hz"] == rollout.DECISION_HZ == 4.0
    task_ids = [t["id"] for t in _core.openloop_tasks()]
    assert FACTS["openloop_tasks"] == task_ids


def test_scenario_error_carries_where(tmp_path: Path) -> None:
    p = tmp_path / "bad.toml"
    p.write_text(
        'version = 1\nid = "x"\ncategory = "07_sudden_brake"\nmap = "builtin:town01"\n\n'
        '[ego]\nstart = { lane = "C2T_1", s = 20.0 }\ndestination = { lane = "C2T_1", s = 330.0 }\n'
        "speed_mps = -1.0\n",
        encoding="utf-8",
    )
    with pytest.raises(ScenarioError) as info:
        _core.validate_scenario(str(p))
    e = info.value
    assert (e.file, e.line, e.field, e.value) == (str(p), 9, "ego.speed_mps", "-1")
    assert isinstance(e.column, int) and e.reason and e.reason in str(e)
    # Raised from Python: the attributes exist and are None.
    assert ScenarioError("x").field is None and ConfigError("y").line is None


def test_old_traffic_names_warn_and_mean_the_new_ones(tmp_path: Path) -> None:
    from drivehierarchy.envs.config import R4Config
    from drivehierarchy.envs.traffic.modes import warn_deprecated_scenario_mode

    with pytest.warns(DeprecationWarning, match="'native' is deprecated.*'idm'"):
        assert R4Config(traffic="native").traffic == "idm"
    with pytest.warns(DeprecationWarning, match="'python' is deprecated.*'libsumo-python'"):
        assert R4Config(sumo_backend="python").sumo_backend == "libsumo-python"
    with pytest.warns(DeprecationWarning, match="'native' is deprecated.*'libsumo'"):
        assert R4Config(sumo_backend="native").sumo_backend == "libsumo"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert R4Config(traffic="idm", sumo_backend="libsumo").traffic == "idm"
        warn_deprecated_scenario_mode("x.toml", '[traffic]\nmode = "idm"\n')
    with pytest.raises(ConfigError, match="expected one of sumo, idm, none"):
        R4Config(traffic="fast")
    with pytest.warns(DeprecationWarning, match=r"x.toml: field `traffic.mode` = 'native'"):
        warn_deprecated_scenario_mode("x.toml", '[traffic]\nmode = "native"\n')
    with pytest.warns(DeprecationWarning, match="envs.traffic.transport"):
        import importlib

        import drivehierarchy.envs.traffic.native as old

        importlib.reload(old)
    assert old.native_sumo_paths is old.libsumo_paths


OF_CHECKS = ("goes with", "the only name allowed", "needs `of`")


def _of_verdict(tmp_path: Path, table: str, key: str, of: Any) -> bool:
    """Whether the resolver's `of` rules accept `of` on a `table` trigger keyed `key` (an error
    elsewhere in the trigger, e.g. a point off the route, is not the rules' verdict)."""
    import tomlkit

    src = builtin_root() / "r4" / "07_sudden_brake" / "town01_07_lead_brakes.toml"
    doc = tomlkit.parse(src.read_text(encoding="utf-8"))
    lead = doc["actors"][0]
    value: Any = {"after": "actors[1]"}.get(key, 2.0)
    trig: dict[str, Any] = {key: value}
    if of is not None:
        trig["of"] = of
    if table == "start":
        lead["start"] = trig
    else:
        lead["brake"] = {**trig, "decel_mps2": 7.0}
    p = tmp_path / f"{table}_{key}.toml"
    p.write_text(tomlkit.dumps(doc), encoding="utf-8")
    try:
        _core.validate_scenario(str(p))
    except ScenarioError as e:
        return not (str(e.field).endswith(".of") and any(c in str(e.reason) for c in OF_CHECKS))
    return True


def test_the_of_rules_the_editor_reads_are_the_resolvers(tmp_path: Path) -> None:
    rules = {(r["table"], r["key"]): r for r in FACTS["of_rules"]}
    assert {t for t, _ in rules} == {"start", "brake"}
    for table, keys in (("start", FACTS["start_triggers"]), ("brake", FACTS["brake_triggers"])):
        for key in keys:
            rule = rules.get((table, key))
            point = _of_verdict(tmp_path, table, key, [0.0, 0.0])
            assert point == (rule is not None), (table, key, "of = [x, y]")
            assert _of_verdict(tmp_path, table, key, "actor_self") == bool(rule and rule["actor_self"]), (
                table,
                key,
                "of = actor_self",
            )
            assert _of_verdict(tmp_path, table, key, None) == (not (rule and rule["required"])), (
                table,
                key,
                "no of",
            )


def test_the_shipped_vehicle_types_and_the_egos_class_are_known_to_the_map_reader() -> None:
    from drivehierarchy import scenarios

    classes = set(FACTS["vclass_of"].values())
    assert FACTS["ego_vclass"] in classes
    assert FACTS["default_vtype"] in FACTS["builtin_vtypes"]
    shipped = (scenarios.builtin_root() / "traffic" / "vtypes.add.xml").read_text(encoding="utf-8")
    ids = re.findall(r'<vType\s[^>]*\bid="([^"]+)"', shipped)
    assert list(FACTS["builtin_vtypes"]) == ids
