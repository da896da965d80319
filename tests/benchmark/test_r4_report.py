"""`r4 report` over runs that differ by model, action level and inputs (history, memory, controls):
one row per combination in Table 2, the comparison table, its CARLA-leaderboard twin and the plot."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import pytest

from drivehierarchy import ConfigError
from drivehierarchy.benchmark.r4 import report
from drivehierarchy.benchmark.r4.summary import carla_summary, summarize
from drivehierarchy.cli import main

CATS = ("01_pedestrian", "03_turning")


def _record(s_r4: float, ds: float) -> dict:
    return {
        "score_composed": s_r4,
        "termination_reason": "destination_reached",
        "dialects": {
            "carla": {"driving_score": ds, "route_completion": 100.0, "infraction_penalty": ds / 100}
        },
    }


def _run(root: Path, name: str, model: str, scores: tuple[float, float], facts: dict | None = None) -> Path:
    """A finished run directory: results.jsonl and the summary `r4 evaluate` writes."""
    run = root / name
    run.mkdir()
    results = [
        {"key": f"{c}__s", "category": c, "seed": 0, "score": _record(v, v + 10)}
        for c, v in zip(CATS, scores, strict=True)
    ]
    (run / "results.jsonl").write_text("".join(json.dumps(r) + "\n" for r in results))
    summary = {**summarize(results), "model": model, **(facts or {})}
    if facts is None:  # a summary written before level, inputs and the dialect were recorded
        summary.pop("carla")
    (run / "summary.json").write_text(json.dumps(summary))
    return run


def _inputs(**kw: object) -> dict:
    base = {"history": 0, "stride": 1, "history_bev": False, "ego_history": 0, "memory": 0, "controls": []}
    return {**base, **kw}


@pytest.fixture
def runs(tmp_path: Path) -> list[Path]:
    return [
        _run(tmp_path, "paper", "qwen", (10.0, 20.0)),  # legacy summary: the paper's setting
        _run(
            tmp_path,
            "hist",
            "qwen",
            (30.0, 40.0),
            {"action_level": "control", "inputs": _inputs(history=4, stride=2, history_bev=True)},
        ),
        _run(
            tmp_path,
            "shuf",
            "qwen",
            (12.0, 22.0),
            {"action_level": "control", "inputs": _inputs(history=4, controls=["history-shuffle"])},
        ),
        _run(
            tmp_path,
            "wp",
            "qwen",
            (50.0, 70.0),
            {"action_level": "waypoints", "inputs": _inputs(memory=2, ego_history=3)},
        ),
    ]


def test_one_row_per_model_level_and_inputs(runs: list[Path], tmp_path: Path) -> None:
    out = tmp_path / "rep"
    written = report.build_report(runs, out)
    assert {p.name for p in written} >= {"comparison.md", "comparison_carla.csv", "r4_comparison.png"}
    table2 = (out / "table2.md").read_text()
    for label in (
        "| qwen |",
        "| qwen [history 4 (stride 2, +BEV)] |",
        "| qwen [history 4, history-shuffle] |",
        "| qwen [waypoints; ego-history 3, memory 2] |",
    ):
        assert label in table2
    comp = (out / "comparison.md").read_text().splitlines()
    assert comp[0] == (
        "| Model | Level | History | Stride | Hist. BEV | Ego hist. | Memory | Controls "
        "| Sce 1 | Sce 3 | S_R4 | Rank |"
    )
    assert comp[2:6] == [
        "| qwen | control | 0 | 1 | no | 0 | 0 | none | 10.000 | 20.000 | 15.000 | 4 |",
        "| qwen | control | 4 | 2 | yes | 0 | 0 | none | 30.000 | 40.000 | 35.000 | 2 |",
        "| qwen | control | 4 | 1 | no | 0 | 0 | history-shuffle | 12.000 | 22.000 | 17.000 | 3 |",
        "| qwen | waypoints | 0 | 1 | no | 3 | 2 | none | 50.000 | 70.000 | 60.000 | 1 |",
    ]
    # The leaderboard dialect: the same rows, in the same order, with its own numbers (the legacy
    # run's computed from its results.jsonl).
    carla = list(csv.reader(io.StringIO((out / "comparison_carla.csv").read_text())))
    r4 = list(csv.reader(io.StringIO((out / "comparison.csv").read_text())))
    assert carla[0][-4:] == ["driving_score", "route_completion", "infraction_penalty", "rank"]
    assert [row[:8] for row in carla[1:]] == [row[:8] for row in r4[1:]]
    assert carla[1][8:] == ["20.000000", "30.000000", "25.000000", "100.000000", "0.250000", "4"]
    md = (out / "comparison_carla.md").read_text()
    assert (
        "| qwen | waypoints | 0 | 1 | no | 3 | 2 | none | 60.000 | 80.000 | 70.000 | 100.000 | 0.700 | 1 |"
        in md
    )
    assert (out / "r4_comparison.png").stat().st_size > 5000


def test_the_same_combination_twice_is_refused(runs: list[Path], tmp_path: Path) -> None:
    twin = _run(tmp_path, "twin", "qwen", (1.0, 2.0), {"action_level": "control", "inputs": _inputs()})
    with pytest.raises(ConfigError, match="same model, action level, inputs and controls"):
        report.build_report([runs[0], twin], tmp_path / "rep")


def test_cli_report_lists_the_comparison(
    runs: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["r4", "report", *map(str, runs), "--out", str(tmp_path / "rep"), "--no-plot"]) == 0
    printed = capsys.readouterr().out.split()
    assert str(tmp_path / "rep" / "comparison.md") in printed and not any(p.endswith(".png") for p in printed)


def test_carla_summary_is_the_mean_of_category_means() -> None:
    results = [
        {"category": "01_a", "score": _record(0.0, 10.0)},
        {"category": "01_a", "score": _record(0.0, 30.0)},
        {"category": "02_b", "score": _record(0.0, 60.0)},
    ]
    c = carla_summary(results)
    assert c is not None
    assert c["categories"] == {"01_a": 20.0, "02_b": 60.0} and c["driving_score"] == 40.0
    assert c["infraction_penalty"] == pytest.approx((0.1 + 0.3 + 0.6) / 3)
    assert carla_summary([{"category": "x", "score": {"score_composed": 1.0}}]) is None
