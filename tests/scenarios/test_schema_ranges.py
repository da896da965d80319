"""The JSON Schema's numeric ranges say exactly what the validator enforces.

Every numeric key written in a suite file is set to -1 and to 0 in a copy of that file: when the
validator refuses the value with a range message, the schema must refuse it too (so an editor
flags a negative speed), and the schema may refuse only what the validator refuses.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

import jsonschema
import pytest

from drivehierarchy import ScenarioError, _core

REPO = Path(__file__).resolve().parents[2]
SUITE = REPO / "scenarios" / "r4"
# `key = number` outside comments, inline tables included.
NUMBER = re.compile(r"(?<![\w.\"])([a-z][a-z0-9_]*)\s*=\s*(-?\d[\d_.eE+-]*)")
MAP_LINE = re.compile(r'^map\s*=\s*"([^"]+)"', re.M)
RANGE_MESSAGES = (
    "must be a finite number ≥ 0",
    "must be a finite number > 0",
    "must lie in (0",
    "must lie in [0",
)


def _occurrences() -> dict[str, tuple[Path, int, int, int]]:
    """One place per key (the first file on a project map that writes it, else any)."""
    found: dict[str, tuple[Path, int, int, int]] = {}
    for path in sorted(SUITE.glob("*/*.toml")):
        text = path.read_text(encoding="utf-8")
        local = "sumo:" not in (MAP_LINE.search(text) or [""])[0]
        for i, line in enumerate(text.split("\n")):
            code = line.split("#", 1)[0]
            for m in NUMBER.finditer(code):
                key = m.group(1)
                if key in ("version", "seed", "start_phase", "number"):
                    continue  # integers whose ranges are types (u32/u64/usize), not checks
                if key not in found or (local and "sumo:" in found[key][0].read_text(encoding="utf-8")):
                    found[key] = (path, i, m.start(2), m.end(2))
    return found


OCCURRENCES = _occurrences()


@pytest.fixture(scope="module")
def validator() -> jsonschema.Draft7Validator:
    return jsonschema.Draft7Validator(_core.scenario_json_schema())


def _edited(path: Path, line: int, a: int, b: int, value: str, tmp_path: Path) -> Path:
    lines = path.read_text(encoding="utf-8").split("\n")
    lines[line] = lines[line][:a] + value + lines[line][b:]
    text = "\n".join(lines)
    m = MAP_LINE.search(text)
    assert m is not None
    if not m.group(1).startswith(("sumo:", "builtin:", "/")):
        text = text.replace(m.group(0), f'map = "{(path.parent / m.group(1)).resolve().as_posix()}"')
    out = tmp_path / path.name
    out.write_text(text, encoding="utf-8")
    return out


def test_the_suite_writes_the_keys_that_carry_ranges() -> None:
    # Guards the test's reach: these keys have ranges and must be among those checked.
    for key in ("speed_mps", "decel_mps2", "ego_eta_s", "vehs_per_hour", "length_m", "warmup_s"):
        assert key in OCCURRENCES


@pytest.mark.parametrize("key", sorted(OCCURRENCES))
@pytest.mark.parametrize("value", ["-1", "0"])
def test_schema_range_matches_the_validator(
    key: str, value: str, validator: jsonschema.Draft7Validator, tmp_path: Path
) -> None:
    path, line, a, b = OCCURRENCES[key]
    edited = _edited(path, line, a, b, value, tmp_path)
    doc: dict[str, Any] = tomllib.loads(edited.read_text(encoding="utf-8"))
    schema_errors = [e for e in validator.iter_errors(doc) if e.absolute_path and e.absolute_path[-1] == key]
    try:
        _core.validate_scenario(str(edited))
        refusal = None
    except ScenarioError as e:
        refusal = str(e)
    where = f"{path.relative_to(REPO)}:{line + 1} {key} = {value}"
    if refusal is not None and f"{key}` = {value}:" in refusal and any(m in refusal for m in RANGE_MESSAGES):
        assert schema_errors, f"{where}: the validator refuses it ({refusal}) but the schema accepts it"
    if schema_errors:
        msg = schema_errors[0].message
        assert refusal is not None, f"{where}: the schema refuses it ({msg}) but the validator accepts it"
