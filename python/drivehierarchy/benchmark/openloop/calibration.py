"""Weight calibration from a pool of models' task scores (`drivehierarchy openloop calibrate`).

SCORES.csv has a `model` column and one column per task id (`R1_1_A … R3_2`, any subset that
covers every rank with a budget) holding task scores in 0–100; the report's `table1.csv` is one
(its `avg_score` and rank columns are skipped). The weights follow
docs/protocol.md#aggregation: Spearman ρ between tasks across models, L_i = 1 + λ_same Σ_same
max(ρ,0)^γ + λ_cross
Σ_other max(ρ,0)^γ, u_i = 1/L_i normalised within the rank, times the rank budget. The
arithmetic is in Rust (`dh-benchmark`).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from drivehierarchy import ConfigError, _core

# docs/protocol.md#aggregation's λ_same, λ_cross, γ and rank budgets, as the Rust calibration defines them.
DEFAULTS: dict[str, Any] = dict(_core.openloop_calibration_defaults())
DEFAULT_BUDGETS: dict[str, float] = dict(DEFAULTS["budgets"])
TASK_IDS: tuple[str, ...] = tuple(t["id"] for t in _core.openloop_tasks())
# Columns `openloop report`'s table1.csv writes beside the tasks: its output feeds calibration.
NOT_SCORED = ("", "–", "-")
REPORT_COLUMNS: frozenset[str] = frozenset({"avg_score", *(t["rank"] for t in _core.openloop_tasks())})


class ScoresTable(NamedTuple):
    """Models × tasks score matrix (`matrix[model][task]`)."""

    models: list[str]
    tasks: list[str]
    matrix: list[list[float]]


def read_scores_csv(path: str | Path) -> ScoresTable:
    """Reads SCORES.csv; errors name the file, row, column and value."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read scores CSV: {exc}") from exc
    rows = list(csv.reader(text.splitlines()))
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise ConfigError(f"{p}: empty scores CSV (expected a header `model,R1_1_A,...`)")
    header = [h.strip() for h in rows[0]]
    if "model" not in header:
        raise ConfigError(f"{p}: header has no `model` column: {header}")
    task_cols: list[tuple[int, str]] = []
    for i, name in enumerate(header):
        if name == "model" or name in REPORT_COLUMNS:
            continue
        if name not in TASK_IDS:
            raise ConfigError(f"{p}: column {i + 1} `{name}` is not a task id (expected one of {TASK_IDS})")
        if name in [t for _, t in task_cols]:
            raise ConfigError(f"{p}: column `{name}` appears twice")
        task_cols.append((i, name))
    # A task nobody scored (R1_4 without the judge: `–` in table1.csv) is left out, not a 0.
    task_cols = [
        (i, name)
        for i, name in task_cols
        if not all(len(row) > i and row[i].strip() in NOT_SCORED for row in rows[1:])
    ]
    if not task_cols:
        raise ConfigError(f"{p}: no task columns")
    mcol = header.index("model")
    models: list[str] = []
    matrix: list[list[float]] = []
    for r, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise ConfigError(f"{p}: row {r} has {len(row)} cells, header has {len(header)}")
        model = row[mcol].strip()
        if not model:
            raise ConfigError(f"{p}: row {r}: empty `model`")
        if model in models:
            raise ConfigError(f"{p}: row {r}: model `{model}` appears twice")
        values: list[float] = []
        for i, name in task_cols:
            cell = row[i].strip()
            try:
                v = float(cell)
            except ValueError:
                raise ConfigError(
                    f"{p}: row {r} ({model}), column `{name}`: `{cell}` is not a number"
                ) from None
            if not math.isfinite(v) or not 0.0 <= v <= 100.0:
                raise ConfigError(f"{p}: row {r} ({model}), column `{name}`: {cell} is outside 0–100")
            values.append(v)
        models.append(model)
        matrix.append(values)
    return ScoresTable(models, [t for _, t in task_cols], matrix)


def calibrate_details(
    table: ScoresTable | tuple[Sequence[str], Sequence[str], Sequence[Sequence[float]]],
    *,
    lambda_same: float | None = None,
    lambda_cross: float | None = None,
    gamma: float | None = None,
    budgets: Mapping[str, float] | None = None,
) -> dict[str, Any]:
    """Weights plus the intermediate ρ matrix, loads L_i and uniqueness u_i (a parameter left
    as None takes its default, `DEFAULTS`)."""
    _models, tasks, matrix = table
    return dict(
        _core.openloop_calibrate(
            list(tasks),
            [list(map(float, row)) for row in matrix],
            lambda_same,
            lambda_cross,
            gamma,
            dict(budgets) if budgets is not None else None,
        )
    )


def calibrate(
    table: ScoresTable | tuple[Sequence[str], Sequence[str], Sequence[Sequence[float]]],
    *,
    lambda_same: float | None = None,
    lambda_cross: float | None = None,
    gamma: float | None = None,
    budgets: Mapping[str, float] | None = None,
) -> dict[str, float]:
    """Task id → weight (in the table's task order) from `(models, tasks, matrix)`."""
    d = calibrate_details(
        table, lambda_same=lambda_same, lambda_cross=lambda_cross, gamma=gamma, budgets=budgets
    )
    w: dict[str, float] = d["weights"]
    return {t: w[t] for t in d["tasks"]}


def write_weights(path: str | Path, weights: Mapping[str, float]) -> None:
    """Saves `{task id: weight}` as JSON (tasks in the registry's order)."""
    order = {t: i for i, t in enumerate(TASK_IDS)}
    ordered = dict(sorted(weights.items(), key=lambda kv: order.get(kv[0], len(order))))
    Path(path).write_text(json.dumps(ordered, indent=2) + "\n", encoding="utf-8")


def frozen_weights() -> dict[str, float]:
    """The paper's frozen weights (Table 1)."""
    return dict(_core.openloop_frozen_weights())
