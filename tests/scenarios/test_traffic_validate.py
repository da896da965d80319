"""`drivehierarchy scenario validate` catches the `[traffic]` input a run would reject (issue 16
item 11): depart lanes that do not exist or are closed to the vehicle's class (SUMO refuses the
route file without naming it) and unreachable flow edges, each at its own key's line."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root

QUEUE = builtin_root() / "r4" / "06_traffic_flow" / "town01_03_stop_and_go_queue.toml"


def _copy(tmp_path: Path, old: str, new: str, name: str) -> tuple[Path, str]:
    text = QUEUE.read_text(encoding="utf-8").replace(
        '"../../maps/', f'"{(builtin_root() / "maps").as_posix()}/'
    )
    assert old in text
    text = text.replace(old, new, 1)
    p = tmp_path / f"{name}.toml"
    p.write_text(text, encoding="utf-8")
    return p, text


def _where(text: str, needle: str, value: str) -> str:
    """`line:column` of `value` inside the (unique) line `needle` of `text`."""
    assert text.count(needle + "\n") == 1, needle
    off = text.index(needle + "\n") + needle.index(value)
    line = text[:off].count("\n") + 1
    col = off - (text.rfind("\n", 0, off) + 1) + 1
    return f"{line}:{col}"


def test_the_shipped_scene_validates(tmp_path: Path) -> None:
    p, _ = _copy(tmp_path, "depart_lane = 2", "depart_lane = 2", "ok")
    assert main(["scenario", "validate", str(p)]) == 0


@pytest.mark.parametrize(
    ("old", "new", "value", "field", "message"),
    [
        # town01's lane 0 is a sidewalk.
        (
            "depart_lane = 2",
            "depart_lane = 0",
            "0",
            "traffic.flows[0].depart_lane",
            'lane "W2C_0" is closed to vehicle class passenger (lanes of "W2C" open to it: 1, 2)',
        ),
        (
            "depart_lane = 2",
            "depart_lane = 5",
            "5",
            "traffic.flows[0].depart_lane",
            'edge "W2C" has no lane 5',
        ),
        # The oncoming flow cannot turn back onto W2C: the `to` key is named, not the header.
        ('to = "C2W"', 'to = "W2C"', '"W2C"', "traffic.flows[1].to", "not reachable"),
        # A single vehicle's depart lane.
        (
            '[[traffic.flows]]\nid = "oncoming"',
            '[[traffic.vehicles]]\nid = "parked"\nroute = ["C2T"]\ndepart_lane = 0\n\n'
            '[[traffic.flows]]\nid = "oncoming"',
            "0",
            "traffic.vehicles[0].depart_lane",
            'lane "C2T_0" is closed to vehicle class passenger',
        ),
    ],
)
def test_validate_names_line_field_and_value(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    old: str,
    new: str,
    value: str,
    field: str,
    message: str,
) -> None:
    p, text = _copy(tmp_path, old, new, "broken")
    assert main(["scenario", "validate", str(p)]) == 1
    out = capsys.readouterr().out
    # The key's own line: the only line of the edited text that sets it to that value.
    key = field.rsplit(".", 1)[1]
    (line,) = [ln for ln in new.splitlines() if ln.startswith(f"{key} = ")]
    assert f"INVALID {p}:{_where(text, line, value)}: field `{field}` = {value}: {message}" in out, out
