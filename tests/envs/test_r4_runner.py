"""R4 evaluation runner and CLI: results, resume after a crash, re-scoring, scenario validation."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from drivehierarchy import ConfigError, ScenarioError
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root, builtin_scenarios

TWO = [builtin_root() / "r4" / "01_pedestrian", builtin_root() / "r4" / "07_sudden_brake"]


def two_scenarios() -> list[Path]:
    """One scenario of each of two categories (the first of each folder)."""
    return [sorted(d.glob("*.toml"))[0] for d in TWO]


def test_evaluate_writes_records_logs_and_summary(tmp_path: Path) -> None:
    out = tmp_path / "run"
    results = runner.evaluate(two_scenarios(), out, runner.RunOptions(agent="expert"), log=lambda _: None)
    assert [r["category"] for r in results] == ["01_pedestrian", "07_sudden_brake"]
    for r in results:
        scene = out / "scenes" / r["key"]
        record = json.loads((scene / "scene_score.json").read_text())
        assert record["score_composed"] >= 90.0
        assert (scene / "episode_log.jsonl").stat().st_size > 0
        assert json.loads((scene / "events.json").read_text()) == record["events"]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["r4_score"] == pytest.approx(sum(r["score"]["score_composed"] for r in results) / 2)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["agent"] == "expert" and len(manifest["scenarios"]) == 2
    assert all(len(v["sha256"]) == 64 for v in manifest["scenarios"].values())
    assert "| **R4 (mean of categories)** |" in (out / "summary.md").read_text()


def test_resume_skips_finished_scenarios_and_redoes_a_torn_one(tmp_path: Path) -> None:
    out = tmp_path / "run"
    opts = runner.RunOptions(agent="expert")
    first = runner.evaluate(two_scenarios(), out, opts, log=lambda _: None)
    results = out / "results.jsonl"
    lines = results.read_text().splitlines(keepends=True)
    # Simulate a kill in the middle of writing the second line.
    results.write_text(lines[0] + lines[1][: len(lines[1]) // 2])
    logged: list[str] = []
    again = runner.evaluate(two_scenarios(), out, opts, log=logged.append)
    assert "done before, skipped" in logged[0]
    assert "S_R4" in logged[1]
    assert [r["score"]["score_composed"] for r in again] == [r["score"]["score_composed"] for r in first]
    # The torn tail is kept (append-only) and the redone scenario is appended after it.
    assert len(runner.read_results(out)) == 2


def test_an_output_dir_of_another_agent_is_refused(tmp_path: Path) -> None:
    out = tmp_path / "run"
    runner.evaluate(two_scenarios()[:1], out, runner.RunOptions(agent="expert"), log=lambda _: None)
    with pytest.raises(ConfigError, match="another run"):
        runner.evaluate(two_scenarios()[:1], out, runner.RunOptions(agent="zero"), log=lambda _: None)


def test_rescore_command_reproduces_the_recorded_scores(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    results = runner.evaluate(two_scenarios(), out, runner.RunOptions(agent="expert"), log=lambda _: None)
    assert main(["r4", "rescore", str(out)]) == 0
    for r in results:
        rescored = json.loads((out / "scenes" / r["key"] / "scene_score.rescored.json").read_text())
        for key in ("score_composed", "score_route", "score_safety", "score_efficiency", "events"):
            assert rescored[key] == r["score"][key]
    assert "S_R4" in capsys.readouterr().out


def test_unknown_agent_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="unknown agent"):
        runner.evaluate(two_scenarios()[:1], tmp_path, runner.RunOptions(agent="nobody"), log=lambda _: None)


def test_the_probes_drivers_are_agents_by_the_same_names(tmp_path: Path) -> None:
    """`r4 run --agent follower@8` is the probe's (and the editor's) follower@8: a committed
    probe row is reproduced from the command line."""
    import csv

    from drivehierarchy.benchmark.r4.agents import AGENTS
    from drivehierarchy.suite_probe import _agent

    for name in ("expert", "late_expert", "zero", "follower@8", "lights@6", "constant@10"):
        a, b = AGENTS.create(name), _agent(name)
        assert type(a) is type(b) and getattr(a, "name", None) == getattr(b, "name", None), name
    for bad in ("follower@0", "lights@fast", "constant@31"):
        with pytest.raises(ConfigError, match=r"expected \w+@V with V a speed in m/s"):
            AGENTS.create(bad)
    rows = csv.DictReader((Path(__file__).resolve().parents[2] / "docs" / "suite_probe.csv").open())
    want = next(
        r
        for r in rows
        if (r["id"], r["cell"], r["seed"]) == ("town01_01_midblock_crossing", "follower@8", "0")
    )
    proc = subprocess.run(
        [sys.executable, "-m", "drivehierarchy.cli", "r4", "run", "--agent", "follower@8",
         "--scenario", "01_pedestrian/town01_01_midblock_crossing", "--seed", "0",
         "--out", str(tmp_path), "--json"],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    record = json.loads(proc.stdout)
    assert (round(record["score_composed"], 1), record["termination_reason"]) == (
        float(want["score"]),
        want["termination"],
    )


def test_cli_run_writes_frames(tmp_path: Path) -> None:
    out = tmp_path / "one"
    proc = subprocess.run(
        [sys.executable, "-m", "drivehierarchy.cli", "r4", "run", "--agent", "expert",
         "--scenario", "01_pedestrian/town01_01_midblock_crossing", "--out", str(out), "--frames", "--json"],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    record = json.loads(proc.stdout)
    assert record["termination_reason"] == "destination_reached"
    frames = sorted((out / "scenes").glob("*/frames/*_front.png"))
    assert len(frames) == record["decisions"]


def test_scenario_validate_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    files = [str(p) for p in builtin_scenarios()]
    assert main(["scenario", "validate", *files]) == 0
    assert capsys.readouterr().out.count("ok ") == len(files)
    bad = tmp_path / "bad.toml"
    bad.write_text('version = 1\nid = "x"\n', encoding="utf-8")
    assert main(["scenario", "validate", str(bad)]) == 1
    assert "INVALID" in capsys.readouterr().out


def test_a_traffic_table_without_mode_is_sumo_and_runs_in_a_worker(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The Rust loader decides (a `[traffic]` table without `mode` is SUMO), not the file's text."""
    from drivehierarchy.benchmark.r4 import dispatch
    from drivehierarchy.benchmark.r4.workers import WorkerPool
    from drivehierarchy.envs.config import R4Config

    src = builtin_root() / "r4" / "06_traffic_flow" / "bs3d_09_left_turner_queue.toml"
    text = src.read_text(encoding="utf-8")
    assert text.count('mode = "sumo"\n') == 1
    folder = tmp_path / "suite" / "r4" / "06_traffic_flow"
    folder.mkdir(parents=True)
    (tmp_path / "suite" / "maps").symlink_to(builtin_root() / "maps")
    path = folder / src.name
    path.write_text(text.replace('mode = "sumo"\n', ""), encoding="utf-8")
    assert runner.uses_sumo(path, R4Config())
    assert not runner.uses_sumo(path, R4Config(traffic="none"))

    started: list[int] = []

    class CountingPool(WorkerPool):
        def _start(self):  # type: ignore[no-untyped-def]
            w = super()._start()
            started.append(w.process.pid)
            return w

    monkeypatch.setattr(dispatch, "WorkerPool", CountingPool)
    results = runner.evaluate([path], tmp_path / "run", runner.RunOptions(seeds=2, jobs=2), log=print)
    assert len(started) == 2, "both seeds ran at once, each in a SUMO worker of its own"
    assert [r["score"]["termination_reason"] for r in results] == ["destination_reached"] * 2


def test_a_bad_scenario_file_fails_the_run_before_anything_is_written(tmp_path: Path) -> None:
    bad = tmp_path / "suite" / "01_x" / "bad.toml"
    bad.parent.mkdir(parents=True)
    bad.write_text('version = 1\nid = "x"\n', encoding="utf-8")
    with pytest.raises(ScenarioError, match=r"bad\.toml"):
        runner.evaluate([*two_scenarios(), bad], tmp_path / "run", runner.RunOptions(), log=print)
    assert not (tmp_path / "run").exists()


def test_help_warns_that_sb3_archives_are_unpickled(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit):
        main(["r4", "evaluate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "unpickles" in text and "only load model files you trust" in text
