"""The editor's TOML edits and path confinement, without a server."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from drivehierarchy.editor.files import PathRefused, apply_edits, confine, error_fields

TEXT = """version = 1   # schema
id = "t"

[ego]
start = { lane = "C2T_1", s = 30.0 }  # keep me

# the walker
[[actors]]
name = "p"
start = { ego_eta_s = 2.9, of = { lane = "C2T_1", s = 140.0 } }
"""


def test_no_edit_keeps_every_byte() -> None:
    assert apply_edits(TEXT, []) == TEXT


def test_set_keeps_the_rest_and_the_inline_layout() -> None:
    out = apply_edits(TEXT, [{"path": ["actors", 0, "start", "of"], "value": {"lane": "C2T_1", "s": 150.5}}])
    assert out == TEXT.replace("s = 140.0", "s = 150.5")
    out = apply_edits(TEXT, [{"path": ["actors", 0, "start"], "value": {"time_s": 2.0}}])
    assert out == TEXT.replace('{ ego_eta_s = 2.9, of = { lane = "C2T_1", s = 140.0 } }', "{ time_s = 2.0 }")


def test_append_and_delete() -> None:
    out = apply_edits(
        TEXT, [{"path": ["obstacles"], "append": {"kind": "cone", "at": {"lane": "C2T_1", "s": 60.0}}}]
    )
    assert out.startswith(TEXT)
    assert out.endswith('}\n\n[[obstacles]]\nkind = "cone"\nat = { lane = "C2T_1", s = 60.0 }\n')
    out2 = apply_edits(out, [{"path": ["actors"], "append": {"name": "q", "kind": "car"}}])
    assert out2.count("[[actors]]") == 2
    assert apply_edits(TEXT, [{"path": ["actors", 0, "name"], "delete": True}]) == TEXT.replace(
        'name = "p"\n', ""
    )


def test_a_key_of_a_missing_table_makes_the_table() -> None:
    out = apply_edits(TEXT, [{"path": ["traffic", "mode"], "value": "idm"}])
    assert out == TEXT + '\n[traffic]\nmode = "idm"\n' or out.endswith('[traffic]\nmode = "idm"\n')
    assert apply_edits(out, [{"path": ["traffic", "mode"], "delete": True}]).startswith(TEXT)


TRAFFIC = """version = 1

[[lights]]
tls = "J"
phases = [                      # the program
  { state = "GGrr", duration_s = 30.0 },
  { state = "yyrr", duration_s = 3.0 },  # yellow
]

[traffic]
mode = "sumo"

[[traffic.flows]]
id = "a"
from = "E1"
to = "E2"
route_hint = ["E1"]
"""


def test_row_edits_of_the_forms_keep_the_rest() -> None:
    """What the forms send: a cell of a `[[traffic.flows]]` row or of an inline phase row, a new
    row of either, a row removed, an id added to a list, and `[traffic.random]` as a table."""
    one = apply_edits(TRAFFIC, [{"path": ["traffic", "flows", 0, "to"], "value": "E3"}])
    assert one == TRAFFIC.replace('to = "E2"', 'to = "E3"')
    one = apply_edits(TRAFFIC, [{"path": ["lights", 0, "phases", 1, "duration_s"], "value": 4.0}])
    assert one == TRAFFIC.replace("duration_s = 3.0 },  # yellow", "duration_s = 4.0 },  # yellow")
    more = apply_edits(
        TRAFFIC, [{"path": ["lights", 0, "phases"], "append": {"state": "rrGG", "duration_s": 9.0}}]
    )
    assert more == TRAFFIC.replace("  # yellow\n]", '  # yellow\n  { state = "rrGG", duration_s = 9.0 },\n]')
    less = apply_edits(TRAFFIC, [{"path": ["lights", 0, "phases", 0], "delete": True}])
    assert less == TRAFFIC.replace('  { state = "GGrr", duration_s = 30.0 },\n', "")
    flows = apply_edits(
        TRAFFIC, [{"path": ["traffic", "flows"], "append": {"id": "b", "vehs_per_hour": 300}}]
    )
    assert flows == TRAFFIC + '\n[[traffic.flows]]\nid = "b"\nvehs_per_hour = 300\n'
    assert apply_edits(flows, [{"path": ["traffic", "flows", 1], "delete": True}]) == TRAFFIC
    via = apply_edits(TRAFFIC, [{"path": ["traffic", "flows", 0, "route_hint"], "append": "E5"}])
    assert via == TRAFFIC.replace('route_hint = ["E1"]', 'route_hint = ["E1", "E5"]')
    rnd = apply_edits(
        TRAFFIC,
        [
            {
                "path": ["traffic", "random"],
                "value": {"density_per_km": 8.0, "mix": {"car": 1.0}},
                "table": True,
            }
        ],
    )
    assert rnd == TRAFFIC + "\n[traffic.random]\ndensity_per_km = 8.0\nmix = { car = 1.0 }\n"
    with pytest.raises(ValueError, match="array of tables takes a table"):
        apply_edits(TRAFFIC, [{"path": ["traffic", "flows"], "append": "E5"}])
    with pytest.raises(ValueError, match="no array here"):
        apply_edits(TRAFFIC, [{"path": ["traffic", "vehicles"], "append": "E5"}])


def test_a_new_key_goes_after_the_tables_last_key() -> None:
    """Not after the blank line and comments that lead to the next table: adding and removing a
    key gives back the file."""
    text = TEXT + '\n[[actors]]\nname = "q"\n'
    out = apply_edits(text, [{"path": ["ego", "speed_mps"], "value": 5.0}])
    assert out == text.replace("# keep me\n", "# keep me\nspeed_mps = 5.0\n")
    out = apply_edits(text, [{"path": ["actors", 0, "pace"], "value": {"gap_s": 1.5}}])
    assert out == text.replace("s = 140.0 } }\n", "s = 140.0 } }\npace = { gap_s = 1.5 }\n")
    assert apply_edits(out, [{"path": ["actors", 0, "pace"], "delete": True}]) == text


def test_a_whole_number_over_a_float_stays_a_float() -> None:
    # The page's numbers are JSON: 45 may stand for 45.0, which the file keeps.
    assert apply_edits(TEXT, [{"path": ["ego", "start", "s"], "value": 45}]) == TEXT.replace("30.0", "45.0")
    out = apply_edits(
        TRAFFIC, [{"path": ["lights", 0, "phases", 0], "value": {"state": "GGrr", "duration_s": 20}}]
    )
    assert out == TRAFFIC.replace("duration_s = 30.0", "duration_s = 20.0")
    assert apply_edits(TEXT, [{"path": ["version"], "value": 2}]).startswith("version = 2   # schema")
    # New keys from the page's float fields say so.
    out = apply_edits(
        TEXT, [{"path": ["ego", "destination"], "value": {"lane": "C2T_1", "s": 200}, "floats": True}]
    )
    assert 'destination = { lane = "C2T_1", s = 200.0 }' in out
    out = apply_edits(TEXT, [{"path": ["lights"], "append": {"tls": "C", "start_phase": 2}}])
    assert out.endswith('[[lights]]\ntls = "C"\nstart_phase = 2\n')


@pytest.mark.parametrize(
    "edit",
    [
        {"path": [], "value": 1},
        {"path": ["nope", "x"], "delete": True},
        {"path": ["actors", 5, "name"], "value": "x"},
        {"path": ["id"]},
        {"path": ["nope"], "delete": True},
    ],
)
def test_bad_edits_are_refused_with_the_path(edit: dict) -> None:
    with pytest.raises(ValueError, match=r"edit|path"):
        apply_edits(TEXT, [edit])


def test_error_fields_are_the_core_errors_attributes(tmp_path: Path) -> None:
    from drivehierarchy import ScenarioError, _core

    p = tmp_path / "sub" / "b.toml"
    p.parent.mkdir()
    p.write_text(
        'version = 1\nid = "b"\ncategory = "no_such"\nmap = "builtin:town01"\n\n[ego]\n'
        'start = { lane = "C2T_1", s = 20.0 }\ndestination = { lane = "C2T_1", s = 330.0 }\n',
        encoding="utf-8",
    )
    with pytest.raises(ScenarioError) as info:
        _core.validate_scenario(str(p))
    e = error_fields(info.value, tmp_path)
    assert (e["file"], e["field"], e["value"], e["line"], e["column"]) == (
        "sub/b.toml",
        "category",
        "no_such",
        3,
        12,
    )
    assert e["reason"].startswith("must be one of 01_pedestrian")
    assert e["message"].startswith("sub/b.toml:3:") and e["reason"] in e["message"]
    # An error without a location (raised from Python) has None fields, not a guess from its text.
    e = error_fields(ScenarioError("a/b.toml:19:13: field `x` = 1: looks located"))
    assert (e["field"], e["line"], e["file"]) == (None, None, None)


def test_confine(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    assert confine(tmp_path, "a/x.toml") == tmp_path.resolve() / "a" / "x.toml"
    for bad, why in [("../x.toml", "`..`"), ("/etc/x.toml", "absolute"), ("C:/x.toml", "absolute"),
                     ("a\\..\\..\\x.toml", "`..`"), ("a/x.txt", "*.toml"), ("", "empty")]:  # fmt: skip
        with pytest.raises(PathRefused, match=re.escape(why)):
            confine(tmp_path, bad)
