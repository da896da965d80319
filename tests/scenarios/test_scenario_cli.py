"""`drivehierarchy scenario list | show | preview | validate` on the shipped scenarios."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from PIL import Image

from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root, builtin_scenarios, scenario_id

SCEN = "07_sudden_brake/town01_07_lead_brakes"


def test_list_builtin_and_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenario", "list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split("\t")[0] for ln in lines] == [scenario_id(p) for p in builtin_scenarios()]
    folder = tmp_path / "suite" / "07_sudden_brake"
    folder.mkdir(parents=True)
    src = builtin_root() / "r4" / f"{SCEN}.toml"
    text = src.read_text(encoding="utf-8").replace(
        '"../../maps/', f'"{(builtin_root() / "maps").as_posix()}/'
    )
    (folder / "mine.toml").write_text(text, encoding="utf-8")
    assert main(["scenario", "list", str(tmp_path / "suite"), "--json"]) == 0
    (row,) = [json.loads(ln) for ln in capsys.readouterr().out.splitlines()]
    assert row["category"] == "07_sudden_brake" and row["id"].endswith("mine.toml") and row["description"]
    assert main(["scenario", "validate", str(tmp_path / "suite")]) == 0
    capsys.readouterr()
    (tmp_path / "empty").mkdir()
    assert main(["scenario", "list", str(tmp_path / "empty")]) == 2


def test_show_text_and_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenario", "show", SCEN]) == 0
    text = capsys.readouterr().out
    assert "07_sudden_brake" in text and "route:" in text and "traffic: none" in text
    assert main(["scenario", "show", SCEN, "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["category"] == "07_sudden_brake" and s["route_length_m"] > 300 and s["actors"] == 2
    assert [a["kind"] for a in s["scripted_actors"]] == ["car", "car"]
    assert main(["scenario", "show", "no/such_scenario"]) == 2
    assert "no/such_scenario" in capsys.readouterr().err


def test_preview_writes_front_and_bev(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenario", "preview", SCEN, "--out", str(tmp_path)]) == 0
    paths = [Path(p) for p in capsys.readouterr().out.split()]
    assert [p.name for p in paths] == [
        "07_sudden_brake__town01_07_lead_brakes_front.png",
        "07_sudden_brake__town01_07_lead_brakes_bev.png",
    ]
    front, bev = (Image.open(p) for p in paths)
    assert front.size == (800, 450) and bev.size == (800, 800)
    # Not a blank frame: the road, the sky and the actors give many colours.
    assert len(front.getcolors(1 << 20) or []) > 50
    shutil.rmtree(tmp_path)
