"""The editor's TOML edits and path confinement, without a server."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from drivehierarchy.editor.files import PathRefused, apply_edits, confine, parse_error

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
    out = apply_edits(TEXT, [{"path": ["traffic", "mode"], "value": "native"}])
    assert out == TEXT + '\n[traffic]\nmode = "native"\n' or out.endswith('[traffic]\nmode = "native"\n')
    assert apply_edits(out, [{"path": ["traffic", "mode"], "delete": True}]).startswith(TEXT)


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


def test_parse_error_splits_the_validators_message() -> None:
    e = parse_error("a/b.toml:19:13: field `actors[0].speed_mps` = -1: must be a finite number ≥ 0")
    assert (e["field"], e["value"], e["line"], e["column"]) == ("actors[0].speed_mps", "-1", 19, 13)
    assert e["reason"] == "must be a finite number ≥ 0"
    assert parse_error("something else")["field"] is None


def test_confine(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    assert confine(tmp_path, "a/x.toml") == tmp_path.resolve() / "a" / "x.toml"
    for bad, why in [("../x.toml", "`..`"), ("/etc/x.toml", "absolute"), ("C:/x.toml", "absolute"),
                     ("a\\..\\..\\x.toml", "`..`"), ("a/x.txt", "*.toml"), ("", "empty")]:  # fmt: skip
        with pytest.raises(PathRefused, match=re.escape(why)):
            confine(tmp_path, bad)
