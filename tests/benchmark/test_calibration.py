"""Calibration from a pool of models' task scores: CSV reading, Rust-backed weights."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drivehierarchy import ConfigError
from drivehierarchy.benchmark.openloop.calibration import (
    calibrate,
    calibrate_details,
    frozen_weights,
    read_scores_csv,
    write_weights,
)

TABLE1 = Path(__file__).parent / "data" / "paper_table1_task_scores.csv"


def test_paper_table1_reproduces_frozen_weights(tmp_path: Path) -> None:
    table = read_scores_csv(TABLE1)
    assert len(table.models) == 15 and len(table.tasks) == 14
    weights = calibrate(table)
    frozen = frozen_weights()
    assert list(weights) == table.tasks
    for task, w in weights.items():
        assert round(w, 3) == pytest.approx(frozen[task]), task
    assert sum(weights.values()) == pytest.approx(1.0)
    out = tmp_path / "w.json"
    write_weights(out, weights)
    assert json.loads(out.read_text(encoding="utf-8")) == pytest.approx(weights)
    d = calibrate_details(table)
    assert d["rho"][0][0] == 1.0 and len(d["load"]) == 14


def test_parameters_change_weights() -> None:
    table = read_scores_csv(TABLE1)
    flat = calibrate(table, lambda_same=0.0, lambda_cross=0.0)
    # No redundancy penalty → uniform split of each rank budget.
    assert flat["R1_1_A"] == pytest.approx(0.3 / 8) and flat["R3_1"] == pytest.approx(0.2)
    b = calibrate(table, budgets={"R1": 0.5, "R2": 0.25, "R3": 0.25})
    assert sum(v for k, v in b.items() if k.startswith("R1")) == pytest.approx(0.5)


def test_subset_without_r1_4() -> None:
    models, tasks, matrix = read_scores_csv(TABLE1)
    k = tasks.index("R1_4")
    sub = (models, tasks[:k] + tasks[k + 1 :], [row[:k] + row[k + 1 :] for row in matrix])
    w = calibrate(sub)
    assert "R1_4" not in w and sum(w.values()) == pytest.approx(1.0)


def test_reads_the_open_loop_reports_table1(tmp_path: Path) -> None:
    # `openloop report` writes avg_score and rank columns beside the tasks, and `–` for R1_4 when
    # no judge scored it: calibration takes the tasks and leaves the unscored one out.
    from drivehierarchy.benchmark.openloop.report import write_table1_csv

    models, tasks, matrix = read_scores_csv(TABLE1)
    rows = []
    for m, vals in zip(models, matrix, strict=True):
        row = dict(zip(tasks, vals, strict=True), model=m, avg=50.0, R1=1.0, R2=2.0, R3=3.0)
        row["R1_4"] = None
        rows.append(row)
    out = tmp_path / "table1.csv"
    write_table1_csv(rows, out)
    assert "avg_score" in out.read_text(encoding="utf-8") and "–" in out.read_text(encoding="utf-8")
    table = read_scores_csv(out)
    assert table.models == models and "R1_4" not in table.tasks and len(table.tasks) == 13
    partly = out.read_text(encoding="utf-8").replace("–", "12.5", 1)
    (tmp_path / "partly.csv").write_text(partly, encoding="utf-8")
    with pytest.raises(ConfigError, match="column `R1_4`: `–` is not a number"):
        read_scores_csv(tmp_path / "partly.csv")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", "empty"),
        ("name,R1_1_A\nx,1\n", "no `model` column"),
        ("model,R1_1_X\nx,1\n", "`R1_1_X` is not a task id"),
        ("model,R1_1_A\nx,abc\n", r"row 2 \(x\), column `R1_1_A`: `abc` is not a number"),
        ("model,R1_1_A\nx,101\n", "outside 0–100"),
        ("model,R1_1_A\nx,1\nx,2\n", "appears twice"),
        ("model,R1_1_A\nx\n", "row 2 has 1 cells"),
    ],
)
def test_csv_errors_name_row_column_value(tmp_path: Path, text: str, match: str) -> None:
    p = tmp_path / "s.csv"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=match):
        read_scores_csv(p)


def test_calibration_errors() -> None:
    table = (["a", "b", "c"], ["R1_1_A", "R3_1"], [[1.0, 2.0], [1.0, 3.0], [1.0, 1.0]])
    with pytest.raises(ConfigError, match="R1_1_A has the same score"):
        calibrate(table, budgets={"R1": 0.5, "R3": 0.5})
    with pytest.raises(ConfigError, match="rank R2 has budget"):
        calibrate((["a", "b", "c"], ["R1_1_A", "R3_1"], [[1, 2], [2, 3], [3, 1]]))
    with pytest.raises(ConfigError, match="at least 3 models"):
        calibrate((["a", "b"], ["R1_1_A"], [[1.0], [2.0]]), budgets={"R1": 1.0})
