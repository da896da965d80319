"""The command line as a new user meets it (issue 17): pipes, typos, missing paths, artifacts,
changed scenario files, and no output left behind by a command that failed before doing work."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root

SHORT = "01_pedestrian/town01_01_midblock_crossing"


def test_output_into_a_closed_pipe_ends_quietly() -> None:
    # The reader is gone before the first line is written (`drivehierarchy scenario list | head`
    # with the pipe already closed): the writer must stop as a Unix tool does, with no traceback.
    read, write = os.pipe()
    os.close(read)
    proc = subprocess.run(
        [sys.executable, "-m", "drivehierarchy.cli", "scenario", "list"],
        stdout=write, stderr=subprocess.PIPE, text=True, timeout=120, check=False,
    )  # fmt: skip
    os.close(write)
    assert "Traceback" not in proc.stderr and "BrokenPipeError" not in proc.stderr, proc.stderr
    assert proc.returncode == 141


def test_a_mistyped_scenario_gets_a_suggestion_not_the_whole_suite(capsys, tmp_path: Path) -> None:
    assert main(["r4", "run", "--scenario", "01_pedestrian/town01_01_midblok_crossing", "--out",
                 str(tmp_path / "o")]) == 2  # fmt: skip
    err = capsys.readouterr().err
    assert "did you mean `01_pedestrian/town01_01_midblock_crossing`?" in err
    assert len(err) < 600
    assert not (tmp_path / "o").exists()


def test_an_unknown_agent_lists_every_kind_and_suggests(capsys, tmp_path: Path) -> None:
    assert main(["r4", "run", "--agent", "exprt", "--scenario", SHORT, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "did you mean `expert`?" in err
    assert "vlm" in err and "sb3:PATH" in err
    assert not (tmp_path / "o").exists()


def test_missing_paths_are_named_as_missing(capsys, tmp_path: Path) -> None:
    nowhere = tmp_path / "nowhere"
    assert main(["r4", "evaluate", "--suite", str(nowhere), "--out", str(tmp_path / "o")]) == 2
    assert f"{nowhere} does not exist" in capsys.readouterr().err
    assert main(["r4", "rescore", str(nowhere)]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["r4", "report", str(nowhere), "--out", str(tmp_path / "rep")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["r4", "evaluate", "--suite", "bultin", "--out", str(tmp_path / "o")]) == 2
    assert "did you mean `builtin`?" in capsys.readouterr().err
    assert not (tmp_path / "o").exists() and not (tmp_path / "rep").exists()


def test_run_prints_a_short_summary_and_where_every_artifact_went(capsys, tmp_path: Path) -> None:
    out = tmp_path / "one"
    assert main(["r4", "run", "--scenario", SHORT, "--out", str(out), "--frames", "--video"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) <= 10
    assert lines[0].startswith("01_pedestrian__town01_01_midblock_crossing: S_R4 ")
    for what in ("score record", "episode log", "frames", "video"):
        (line,) = [x for x in lines if x.strip().startswith(what + ":")]
        assert Path(line.split(":", 1)[1].strip()).exists()


def test_a_changed_scenario_file_is_noticed_and_force_redoes_it(capsys, tmp_path: Path) -> None:
    suite = tmp_path / "suite"
    (suite / "r4" / "01_pedestrian").mkdir(parents=True)
    (suite / "maps").symlink_to(builtin_root() / "maps")
    scenario = suite / "r4" / "01_pedestrian" / "town01_01_midblock_crossing.toml"
    shutil.copy(builtin_root() / "r4" / f"{SHORT}.toml", scenario)
    out = tmp_path / "run"
    args = ["r4", "run", "--scenario", str(scenario), "--out", str(out), "--json"]
    assert main(args) == 0
    first = capsys.readouterr().out
    assert main(args) == 0  # unchanged: resumed, not redone
    assert "done before, skipped (scenario unchanged" in capsys.readouterr().err
    with scenario.open("a", encoding="utf-8") as fh:  # any edit changes its hash
        fh.write("\n# edited\n")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "changed since they were run" in err and "--force" in err
    assert main([*args, "--force"]) == 0
    assert capsys.readouterr().out  # a fresh record
    assert len((out / "results.jsonl").read_text(encoding="utf-8").splitlines()) == 2
    assert first


@pytest.mark.parametrize("argv", [["scenario", "list"], ["r4", "models"]])
def test_listing_commands_still_print(argv: list[str], capsys) -> None:
    assert main(argv) == 0
    assert capsys.readouterr().out.strip()


def test_map_show_lists_edges_and_lanes_of_a_shipped_map(capsys) -> None:
    assert main(["map", "show", "builtin:town01", "--edge", "C2T"]) == 0
    out = capsys.readouterr().out
    assert "edge C2T:" in out
    lanes = [x.split() for x in out.splitlines() if x.strip().startswith("lane ")]
    assert [x[1] for x in lanes] == ["C2T_0", "C2T_1", "C2T_2"]
    assert all(float(x[2]) > 100 for x in lanes)  # lengths in metres
    assert main(["map", "show", "builtin:town01", "--json"]) == 0
    net = json.loads(capsys.readouterr().out)
    lane = next(la for e in net["edges"] for la in e["lanes"] if la["id"] == "C2T_1")
    assert "passenger" in lane["allow"] and lane["length_m"] > 100
    assert main(["map", "show", "builtin:town01", "--edge", "C2X"]) == 2
    assert "did you mean" in capsys.readouterr().err


def test_a_scenario_anywhere_names_a_shipped_map_as_builtin(capsys, tmp_path: Path) -> None:
    text = (builtin_root() / "r4" / f"{SHORT}.toml").read_text(encoding="utf-8")
    lines = [('map = "builtin:town01"' if x.startswith("map = ") else x) for x in text.splitlines()]
    scenario = tmp_path / "elsewhere" / "mine.toml"
    scenario.parent.mkdir()
    scenario.write_text("\n".join(lines) + "\n", encoding="utf-8")
    assert main(["scenario", "validate", str(scenario)]) == 0
    capsys.readouterr()
    assert main(["r4", "run", "--scenario", str(scenario), "--out", str(tmp_path / "o")]) == 0
    assert "destination_reached" in capsys.readouterr().out
    scenario.write_text(scenario.read_text(encoding="utf-8").replace("builtin:town01", "builtin:town9"))
    assert main(["scenario", "validate", str(scenario)]) == 1
    out = capsys.readouterr().out
    assert "builtin:town9" in out and "shipped: bs3d_arterial, town01, town02" in out
