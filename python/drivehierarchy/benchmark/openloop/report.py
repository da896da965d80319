"""Reports over a pool of models: the paper's Table 1 (Markdown + CSV), a radar plot per model,
task- and rank-level Spearman heatmaps, and correlations with R4 scores.

A pool is an ordered `{model: {task_id: score 0–100}}`, read from scored run folders
(`evaluation/final_score.json`) and/or a CSV with a `model` column and one column per task id.
"""

from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError, _core

from .records import FROZEN_WEIGHTS, RANKS, TASK_IDS, TASK_RANK, task_id_from_name

Pool = dict[str, dict[str, float]]


# --- reading scores ------------------------------------------------------------------------------


def _num(value: Any) -> float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float) and math.isfinite(value):
        return float(value)
    if isinstance(value, dict):
        for key in ("score", "mean", "task_score"):
            if key in value:
                return _num(value[key])
    return None


def extract_task_scores(result: Mapping[str, Any]) -> dict[str, float]:
    """Task id → task score from a `final_score.json` object. Reads a `tasks` mapping (task id
    → number or {score|mean}) and falls back to the original's per-file `files`/`results` entries
    (`source_file` + `mean`)."""
    out: dict[str, float] = {}
    tasks = result.get("tasks")
    if isinstance(tasks, Mapping):
        for key, value in tasks.items():
            tid = task_id_from_name(str(key))
            score = _num(value)
            if tid in TASK_IDS and score is not None:
                out[tid] = score
    elif isinstance(tasks, list):
        for item in tasks:
            if isinstance(item, Mapping):
                tid = task_id_from_name(
                    str(item.get("task") or item.get("task_id") or item.get("name") or "")
                )
                score = _num(item)
                if tid in TASK_IDS and score is not None:
                    out[tid] = score
    if out:
        return out
    for key in ("files", "results", "per_file"):
        entries = result.get(key)
        if isinstance(entries, Mapping):
            entries = [{"source_file": k, **v} for k, v in entries.items() if isinstance(v, Mapping)]
        if isinstance(entries, list):
            for item in entries:
                if not isinstance(item, Mapping):
                    continue
                tid = task_id_from_name(Path(str(item.get("source_file", ""))).name)
                score = _num(item.get("mean"))
                if tid in TASK_IDS and score is not None:
                    out[tid] = score
    return out


def model_name_of(run_dir: Path, result: Mapping[str, Any]) -> str:
    manifest = run_dir / "manifest.json"
    if manifest.exists():
        try:
            name = json.loads(manifest.read_text(encoding="utf-8")).get("model")
            if isinstance(name, str) and name:
                return name
        except (OSError, json.JSONDecodeError):
            pass
    name = result.get("model")
    return name if isinstance(name, str) and name else run_dir.resolve().name


def read_scores_table(path: Path) -> Pool:
    """CSV with a `model` column and task-id columns (other columns ignored)."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read scores CSV: {exc}") from exc
    if not rows or "model" not in (rows[0]):
        raise ConfigError(f"{path}: expected a header with a 'model' column")
    pool: Pool = {}
    for i, row in enumerate(rows, start=2):
        model = (row.get("model") or "").strip()
        if not model:
            raise ConfigError(f"{path}: line {i}: empty 'model'")
        scores: dict[str, float] = {}
        for tid in TASK_IDS:
            cell = (row.get(tid) or "").strip()
            if not cell:
                continue
            try:
                scores[tid] = float(cell)
            except ValueError:
                raise ConfigError(f"{path}: line {i}: column {tid} = {cell!r} is not a number") from None
        if model in pool:
            raise ConfigError(f"{path}: line {i}: duplicate model {model!r}")
        pool[model] = scores
    return pool


def load_pool(run_dirs: Sequence[Path], scores_csv: Path | None = None) -> Pool:
    pool: Pool = {}
    if scores_csv is not None:
        pool.update(read_scores_table(scores_csv))
    for run_dir in run_dirs:
        path = run_dir / "evaluation" / "final_score.json"
        try:
            result = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise ConfigError(
                f"{path}: cannot read ({exc}); run `drivehierarchy openloop score {run_dir}`"
            ) from exc
        except json.JSONDecodeError as exc:
            raise ConfigError(f"{path}: not valid JSON: {exc}") from exc
        name = model_name_of(run_dir, result)
        if name in pool:
            raise ConfigError(f"{run_dir}: model {name!r} appears twice in the report inputs")
        pool[name] = extract_task_scores(result)
    return pool


def read_r4_csv(path: Path) -> dict[str, float]:
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read R4 summary: {exc}") from exc
    if not rows or not {"model", "r4_score"} <= set(rows[0].keys()):
        raise ConfigError(f"{path}: expected columns 'model' and 'r4_score'")
    out: dict[str, float] = {}
    for i, row in enumerate(rows, start=2):
        try:
            out[row["model"].strip()] = float(row["r4_score"])
        except (TypeError, ValueError):
            raise ConfigError(
                f"{path}: line {i}: r4_score = {row.get('r4_score')!r} is not a number"
            ) from None
    return out


# --- aggregation ---------------------------------------------------------------------------------


def rank_means(scores: Mapping[str, float]) -> dict[str, float | None]:
    """Plain mean of each rank's tasks (None when any of its tasks is missing)."""
    out: dict[str, float | None] = {}
    for rank in RANKS:
        tasks = [t for t in TASK_IDS if TASK_RANK[t] == rank]
        vals = [scores.get(t) for t in tasks]
        out[rank] = None if any(v is None for v in vals) else sum(vals) / len(vals)  # type: ignore[arg-type]
    return out


def weighted_rank_scores(
    scores: Mapping[str, float], weights: Mapping[str, float] = FROZEN_WEIGHTS
) -> dict[str, float | None]:
    """Σ_t∈r w_t S_t / Σ_t∈r w_t per rank: the rank score behind the paper's rank-level Spearman
    figure and its R4 correlations (with it the paper's ρ(R1,R2)=0.843, ρ(R1,R4)=0.664, ... are
    reproduced from Tables 1–2; the plain means of docs/protocol.md#aggregation give other values)."""
    out: dict[str, float | None] = {}
    for rank in RANKS:
        tasks = [t for t in TASK_IDS if TASK_RANK[t] == rank]
        if any(t not in scores for t in tasks):
            out[rank] = None
            continue
        out[rank] = sum(weights[t] * scores[t] for t in tasks) / sum(weights[t] for t in tasks)
    return out


def weighted_score(
    scores: Mapping[str, float], weights: Mapping[str, float] = FROZEN_WEIGHTS
) -> float | None:
    """Σ w_t S_t over all 14 tasks (None when a task is missing)."""
    if any(t not in scores for t in weights):
        return None
    return sum(w * scores[t] for t, w in weights.items())


def spearman(x: Sequence[float], y: Sequence[float]) -> float:
    """Spearman's ρ (Pearson of average ranks, ties share their mean rank); NaN when fewer than 2
    pairs or a constant side. The calibration's own (`dh-benchmark`), so both agree."""
    return _core.openloop_spearman([float(v) for v in x], [float(v) for v in y])


def correlation_matrix(columns: Mapping[str, Sequence[float]]) -> dict[str, dict[str, float]]:
    names = list(columns)
    return {a: {b: 1.0 if a == b else spearman(columns[a], columns[b]) for b in names} for a in names}


def table1_rows(pool: Pool) -> list[dict[str, Any]]:
    rows = []
    for model, scores in pool.items():
        row: dict[str, Any] = {"model": model, "avg": weighted_score(scores)}
        for tid in TASK_IDS:
            row[tid] = scores.get(tid)
        row.update(rank_means(scores))
        row["weighted_ranks"] = weighted_rank_scores(scores)
        rows.append(row)
    return rows


# --- rendering -----------------------------------------------------------------------------------


def _fmt(v: float | None, digits: int = 2) -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def render_table1_markdown(rows: list[dict[str, Any]]) -> str:
    """Paper Table 1 layout: models × (Avg.Score, 14 tasks under their ranks, rank means), weights
    row under the header; best value per column in bold, second best in italics."""
    cols = ["avg", *TASK_IDS, *RANKS]
    best: dict[str, tuple[float | None, float | None]] = {}
    for c in cols:
        vals = sorted({round(r[c], 2) for r in rows if r[c] is not None}, reverse=True)
        best[c] = (vals[0] if vals else None, vals[1] if len(vals) > 1 else None)

    def cell(c: str, v: float | None) -> str:
        s = _fmt(v)
        if v is None or len(rows) < 2:
            return s
        if round(v, 2) == best[c][0]:
            return f"**{s}**"
        if round(v, 2) == best[c][1]:
            return f"*{s}*"
        return s

    head = (
        ["Models", "Avg.Score"] + [f"{t} ({TASK_RANK[t]})" for t in TASK_IDS] + [f"{r} mean" for r in RANKS]
    )
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines.append(
        "| *weight* | | "
        + " | ".join(f"{FROZEN_WEIGHTS[t]:.3f}" for t in TASK_IDS)
        + " |"
        + " |" * len(RANKS)
    )
    for r in rows:
        lines.append("| " + " | ".join([r["model"]] + [cell(c, r[c]) for c in cols]) + " |")
    return "\n".join(lines) + "\n"


def write_table1_csv(rows: list[dict[str, Any]], path: Path) -> None:
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["model", "avg_score", *TASK_IDS, *RANKS])
        for r in rows:
            w.writerow([r["model"], _fmt(r["avg"], 4)] + [_fmt(r[c], 4) for c in (*TASK_IDS, *RANKS)])


def _write_matrix_csv(matrix: dict[str, dict[str, float]], path: Path) -> None:
    names = list(matrix)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(["", *names])
        for a in names:
            w.writerow([a] + [_fmt(matrix[a][b], 4) for b in names])


def slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "model"


def _plot_radar(model: str, scores: Mapping[str, float], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [t for t in TASK_IDS if t in scores]
    if len(labels) < 3:
        return
    angles = [2 * math.pi * i / len(labels) for i in range(len(labels))]
    values = [scores[t] for t in labels]
    fig = plt.figure(figsize=(5.5, 5.5))
    ax = fig.add_subplot(111, polar=True)
    ax.plot([*angles, angles[0]], [*values, values[0]], linewidth=1.5)
    ax.fill([*angles, angles[0]], [*values, values[0]], alpha=0.25)
    ax.set_xticks(angles)
    ax.set_xticklabels(labels, fontsize=8)
    ax.set_ylim(0, 100)
    ax.set_title(model, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_heatmap(matrix: dict[str, dict[str, float]], title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(matrix)
    data = [[matrix[a][b] for b in names] for a in names]
    size = 1.0 + 0.55 * len(names)
    fig, ax = plt.subplots(figsize=(size + 1.5, size))
    im = ax.imshow(data, vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set_xticks(range(len(names)))
    ax.set_yticks(range(len(names)))
    ax.set_xticklabels(names, rotation=60, ha="right", fontsize=8)
    ax.set_yticklabels(names, fontsize=8)
    for i, row in enumerate(data):
        for j, v in enumerate(row):
            ax.text(j, i, _fmt(v), ha="center", va="center", fontsize=6 if len(names) > 6 else 9)
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="Spearman ρ")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def build_report(pool: Pool, out: Path, r4_csv: Path | None = None, plots: bool = True) -> list[Path]:
    """Write every report file under `out`; returns the written paths."""
    if not pool:
        raise ConfigError("report: no models to report on")
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    rows = table1_rows(pool)
    md = out / "table1.md"
    md.write_text(render_table1_markdown(rows), encoding="utf-8")
    write_table1_csv(rows, out / "table1.csv")
    written += [md, out / "table1.csv"]

    full = [r for r in rows if all(r[t] is not None for t in TASK_IDS)]
    r4 = read_r4_csv(r4_csv) if r4_csv is not None else {}
    task_m = rank_m = None
    if len(full) >= 3:
        task_m = correlation_matrix({t: [r[t] for r in full] for t in TASK_IDS})
        rank_cols = {rk: [r["weighted_ranks"][rk] for r in full] for rk in RANKS}
        with_r4 = [r for r in full if r["model"] in r4]
        if r4 and len(with_r4) == len(full):
            rank_cols["R4"] = [r4[r["model"]] for r in full]
        rank_m = correlation_matrix(rank_cols)
        _write_matrix_csv(task_m, out / "task_spearman.csv")
        _write_matrix_csv(rank_m, out / "rank_spearman.csv")
        written += [out / "task_spearman.csv", out / "rank_spearman.csv"]

    if r4:
        paired = [r for r in full if r["model"] in r4]
        ys = [r4[r["model"]] for r in paired]
        corr_rows = []
        for key in (*TASK_IDS, *RANKS, "avg"):
            xs = [r["weighted_ranks"][key] if key in RANKS else r[key] for r in paired]
            corr_rows.append(
                (key if key != "avg" else "Avg.Score", spearman(xs, ys) if len(paired) >= 3 else math.nan)
            )
        path = out / "r4_correlation.csv"
        with open(path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["column", "spearman_with_r4", "n_models"])
            for name, rho in corr_rows:
                w.writerow([name, _fmt(rho, 4), len(paired)])
        lines = ["| column | Spearman ρ with R4 |", "|---|---|"] + [
            f"| {n} | {_fmt(v, 3)} |" for n, v in corr_rows
        ]
        (out / "r4_correlation.md").write_text(
            f"Spearman correlation with R4 over {len(paired)} models.\n\n" + "\n".join(lines) + "\n",
            encoding="utf-8",
        )
        written += [path, out / "r4_correlation.md"]

    if plots:
        for model, scores in pool.items():
            path = out / f"radar_{slug(model)}.png"
            _plot_radar(model, scores, path)
            if path.exists():
                written.append(path)
        if task_m is not None and rank_m is not None:
            _plot_heatmap(task_m, "Task-level Spearman correlation", out / "heatmap_tasks.png")
            _plot_heatmap(rank_m, "Rank-level Spearman correlation", out / "heatmap_ranks.png")
            written += [out / "heatmap_tasks.png", out / "heatmap_ranks.png"]
    return written
