"""`drivehierarchy hierarchy report RUN...`: the whole hierarchy in one table.

From scored open-loop runs (`openloop predict` + `openloop score`: `evaluation/final_score.json`)
and R4 runs (`r4 evaluate`: `summary.json`) of several models, it writes one row per model with
its rank profile — R1, R2, R3 (rank scores S_r, the plain mean of the rank's task scores), the
weighted headline S_open and the R4 score — and, under it, the Spearman coefficient of each
column with R4 across the models (the paper's "0.664 for R1, 0.596 for R2, 0.418 for R3").

A run's kind is read from its folder; runs are paired into models by model name (the open-loop
manifest's `model`, the R4 summary's `model`), or by the name given as `NAME=PATH`. The numbers
are the scorer's own (`_core.openloop_summarize` wrote them into final_score.json) and the
coefficient is `_core.openloop_spearman`, so the report agrees with `openloop report`/`calibrate`.

Writes `hierarchy.md`, `hierarchy.csv` and `hierarchy.json` under `--out`.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError, _core

OPEN_RANKS = ("R1", "R2", "R3")
COLUMNS = (*OPEN_RANKS, "S_open", "R4")
# Spearman's ρ needs at least this many models to mean anything (with 2 it is always ±1).
MIN_MODELS_FOR_SPEARMAN = 3


@dataclass
class OpenLoopRun:
    path: Path
    model: str
    ranks: dict[str, float]
    s_open: float
    tasks: dict[str, float]
    missing_tasks: list[str]
    data_files: dict[str, str] | None  # dataset name → sha256 (from the run manifest)


@dataclass
class R4Run:
    path: Path
    model: str
    r4_score: float
    categories: dict[str, int]  # category → runs counted


@dataclass
class Row:
    model: str
    openloop: OpenLoopRun
    r4: R4Run
    values: dict[str, float] = field(default_factory=dict)


# --- reading runs --------------------------------------------------------------------------------


def parse_run_arg(arg: str) -> tuple[str | None, Path]:
    """`PATH` or `NAME=PATH` (an existing path containing `=` is taken as a path)."""
    if Path(arg).exists() or "=" not in arg:
        return None, Path(arg)
    name, _, path = arg.partition("=")
    if not name.strip():
        raise ConfigError(f"run argument {arg!r}: empty model name before '='")
    return name.strip(), Path(path)


def run_kind(path: Path) -> str:
    """`openloop` or `r4`, from the files the tools leave in a run folder."""
    if not path.is_dir():
        raise ConfigError(f"{path}: not a run folder (does not exist or is not a directory)")
    if (path / "evaluation" / "final_score.json").is_file():
        return "openloop"
    if (path / "summary.json").is_file():
        return "r4"
    if (path / "predictions").is_dir() or list(path.glob("*_pred.jsonl")):
        raise ConfigError(
            f"{path / 'evaluation' / 'final_score.json'}: not found; the open-loop run is not scored "
            f"yet: run `drivehierarchy openloop score {path}`"
        )
    raise ConfigError(
        f"{path}: neither a scored open-loop run (evaluation/final_score.json) nor an R4 run "
        "(summary.json from `drivehierarchy r4 evaluate`)"
    )


def _load_json(path: Path) -> dict[str, Any]:
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc}") from exc
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path}: not valid JSON: {exc}") from exc
    if not isinstance(obj, dict):
        raise ConfigError(f"{path}: expected a JSON object, got {type(obj).__name__}")
    return obj


def _number(path: Path, field_name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ConfigError(f"{path}: field `{field_name}` = {value!r} is not a finite number")
    return float(value)


def read_openloop(path: Path, name: str | None = None, partial: bool = False) -> OpenLoopRun:
    """The rank profile of a scored open-loop run. Unless `partial`, every task must be scored
    (the paper's rank scores and S_open are over all 14); with it, rank scores are over the
    tasks present and S_open is the scorer's weight-renormalised `S_open_partial`."""
    fs = path / "evaluation" / "final_score.json"
    result = _load_json(fs)
    ranks = result.get("ranks")
    if not isinstance(ranks, dict):
        raise ConfigError(f"{fs}: field `ranks` = {ranks!r}: expected the scorer's rank table; re-score")
    values: dict[str, float] = {}
    missing: list[str] = []
    for rank in OPEN_RANKS:
        entry = ranks.get(rank)
        if not isinstance(entry, dict):
            raise ConfigError(f"{fs}: field `ranks.{rank}` = {entry!r}: missing")
        gone = entry.get("missing") or []
        if gone and not partial:
            raise ConfigError(
                f"{fs}: field `ranks.{rank}.missing` = {gone}: these tasks are not scored "
                "(R1_4 needs `openloop score --judge-model`); score them, or pass --partial to "
                "rank over the tasks present"
            )
        missing += list(gone)
        if entry.get("mean") is None:
            raise ConfigError(f"{fs}: field `ranks.{rank}.mean` = None: no task of {rank} is scored")
        values[rank] = _number(fs, f"ranks.{rank}.mean", entry["mean"])
    if partial:
        s_open_entry = result.get("S_open_partial")
        s_open = (s_open_entry or {}).get("value") if isinstance(s_open_entry, dict) else None
        s_open = _number(fs, "S_open_partial.value", s_open)
    else:
        s_open = _number(fs, "S_open", result.get("S_open"))
    tasks_raw = result.get("tasks")
    tasks: dict[str, float] = {}
    if isinstance(tasks_raw, dict):
        for tid, entry in tasks_raw.items():
            if isinstance(entry, dict) and "mean" in entry:
                tasks[tid] = _number(fs, f"tasks.{tid}.mean", entry["mean"])
    data_files = None
    model = name
    manifest_path = path / "manifest.json"
    if manifest_path.is_file():
        manifest = _load_json(manifest_path)
        if model is None and isinstance(manifest.get("model"), str) and manifest["model"]:
            model = manifest["model"]
        files = manifest.get("data_files")
        if isinstance(files, dict):
            data_files = {k: str(v.get("sha256")) for k, v in files.items() if isinstance(v, dict)}
    if model is None:
        models = result.get("models")
        if isinstance(models, list) and len(models) == 1 and isinstance(models[0], str):
            model = models[0]
    if model is None:
        raise ConfigError(
            f"{path}: no model name (no manifest.json `model`, final_score.json `models` = "
            f"{result.get('models')!r}); name it as NAME={path}"
        )
    return OpenLoopRun(path, model, values, s_open, tasks, sorted(set(missing)), data_files)


def read_r4(path: Path, name: str | None = None) -> R4Run:
    sp = path / "summary.json"
    summary = _load_json(sp)
    cats = summary.get("categories")
    if not isinstance(cats, dict) or not cats:
        raise ConfigError(f"{sp}: field `categories` = {cats!r}: no scored scenario category")
    if summary.get("failed"):
        raise ConfigError(
            f"{sp}: field `failed` = {summary['failed']}: scenarios failed with a system error; "
            f"rerun `drivehierarchy r4 evaluate` with the same --out to redo them"
        )
    r4 = _number(sp, "r4_score", summary.get("r4_score"))
    model = name or summary.get("model")
    if not isinstance(model, str) or not model:
        raise ConfigError(f"{sp}: field `model` = {summary.get('model')!r}; name it as NAME={path}")
    raw_counts = summary.get("counts")
    counts = raw_counts if isinstance(raw_counts, dict) else {}
    return R4Run(path, model, r4, {c: int(counts.get(c, 0)) for c in sorted(cats)})


def collect(args: Sequence[str], partial: bool = False) -> list[Row]:
    """Reads every run and pairs them into one row per model (in first-seen order)."""
    if not args:
        raise ConfigError("hierarchy report: give the open-loop and R4 run folders of each model")
    ol: dict[str, OpenLoopRun] = {}
    r4: dict[str, R4Run] = {}
    order: list[str] = []
    for arg in args:
        name, path = parse_run_arg(arg)
        kind = run_kind(path)
        run: OpenLoopRun | R4Run
        if kind == "openloop":
            run = read_openloop(path, name, partial)
            into: dict[str, Any] = ol
        else:
            run = read_r4(path, name)
            into = r4
        if run.model in into:
            label = "an open-loop" if kind == "openloop" else "an R4"
            raise ConfigError(
                f"{path}: model {run.model!r} already has {label} run ({into[run.model].path}); "
                "one per model (rename one as NAME=PATH)"
            )
        into[run.model] = run
        if run.model not in order:
            order.append(run.model)
    for model in order:
        if model not in ol:
            raise ConfigError(
                f"model {model!r}: R4 run {r4[model].path} has no open-loop run (names: {sorted(ol)})"
            )
        if model not in r4:
            raise ConfigError(
                f"model {model!r}: open-loop run {ol[model].path} has no R4 run (names: {sorted(r4)}); "
                "pair runs of differently named models as NAME=PATH"
            )
    rows = [Row(m, ol[m], r4[m]) for m in order]
    _check_comparable(rows)
    for row in rows:
        row.values = {**row.openloop.ranks, "S_open": row.openloop.s_open, "R4": row.r4.r4_score}
    return rows


def _check_comparable(rows: list[Row]) -> None:
    """All models must be measured on the same things: the same open-loop data (when the runs'
    manifests say), the same scored tasks, and the same R4 scenario categories and run counts."""
    first = rows[0]
    for row in rows[1:]:
        a, b = first.openloop, row.openloop
        if a.data_files is not None and b.data_files is not None and a.data_files != b.data_files:
            diff = sorted(
                k for k in set(a.data_files) | set(b.data_files) if a.data_files.get(k) != b.data_files.get(k)
            )
            raise ConfigError(
                f"{b.path / 'manifest.json'}: field `data_files` differs from {a.path / 'manifest.json'} "
                f"on {diff}: the models ran on different open-loop sets"
            )
        if sorted(a.tasks) != sorted(b.tasks):
            raise ConfigError(
                f"{b.path / 'evaluation' / 'final_score.json'}: field `tasks` = {sorted(b.tasks)} differs "
                f"from {a.path}'s {sorted(a.tasks)}: rank scores over different task sets do not compare"
            )
        if first.r4.categories != row.r4.categories:
            raise ConfigError(
                f"{row.r4.path / 'summary.json'}: fields `categories`/`counts` = {row.r4.categories} differ "
                f"from {first.r4.path}'s {first.r4.categories}: the models drove different R4 suites"
            )


# --- statistics ----------------------------------------------------------------------------------


def spearman_with_r4(rows: list[Row]) -> dict[str, dict[str, Any]]:
    """Per open-loop column: {"rho": float | None, "reason": None | why undefined}."""
    out: dict[str, dict[str, Any]] = {}
    r4 = [r.values["R4"] for r in rows]
    for col in (*OPEN_RANKS, "S_open"):
        if len(rows) < MIN_MODELS_FOR_SPEARMAN:
            out[col] = {"rho": None, "reason": f"{len(rows)} models (needs ≥ {MIN_MODELS_FOR_SPEARMAN})"}
            continue
        xs = [r.values[col] for r in rows]
        rho = _core.openloop_spearman(xs, r4)
        if math.isnan(rho):
            side = "R4" if len(set(r4)) == 1 else col
            out[col] = {"rho": None, "reason": f"{side} is the same for every model"}
        else:
            out[col] = {"rho": rho, "reason": None}
    return out


def r4_positions(rows: list[Row]) -> list[int]:
    """Table 2's Rank column: 1 = best R4 (ties share the better position)."""
    return [1 + sum(o.values["R4"] > r.values["R4"] for o in rows) for r in rows]


# --- rendering -----------------------------------------------------------------------------------


def _fmt(v: float | None, digits: int) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def render_markdown(rows: list[Row], rho: dict[str, dict[str, Any]], partial: bool) -> str:
    """Table 1/2 style: one row per model, best value per column bold and second best italic,
    the R4 position as Table 2's Rank, and a last row of Spearman ρ with R4."""
    digits = {"R1": 2, "R2": 2, "R3": 2, "S_open": 2, "R4": 3}
    best: dict[str, list[float]] = {
        c: sorted({round(r.values[c], digits[c]) for r in rows}, reverse=True)[:2] for c in COLUMNS
    }

    def cell(c: str, v: float) -> str:
        s = _fmt(v, digits[c])
        if len(rows) < 2:
            return s
        if round(v, digits[c]) == best[c][0]:
            return f"**{s}**"
        if len(best[c]) > 1 and round(v, digits[c]) == best[c][1]:
            return f"*{s}*"
        return s

    head = ["Models", "R1", "R2", "R3", "S_open", "R4", "Rank"]
    lines = ["| " + " | ".join(head) + " |", "|---" + "|---:" * (len(head) - 1) + "|"]
    for r, pos in zip(rows, r4_positions(rows), strict=True):
        lines.append("| " + " | ".join([r.model, *(cell(c, r.values[c]) for c in COLUMNS), str(pos)]) + " |")
    rho_cells = [
        _fmt(rho[c]["rho"], 3) if rho[c]["rho"] is not None else "undefined" for c in (*OPEN_RANKS, "S_open")
    ]
    lines.append("| *Spearman ρ with R4* | " + " | ".join(rho_cells) + " | | |")
    notes = [
        "",
        f"{len(rows)} models. R1–R3: rank scores S_r (mean of the rank's task scores, 0–100); S_open: "
        "the frozen-weight headline Σ w_t S_t; R4: mean of the R4 category means (0–100); Rank: position "
        "by R4. ρ: Spearman's rank correlation across the models.",
    ]
    undefined = {c: v["reason"] for c, v in rho.items() if v["rho"] is None}
    if undefined:
        reasons = sorted(set(undefined.values()))
        notes.append(f"ρ undefined for {', '.join(undefined)}: {'; '.join(reasons)}.")
    if partial:
        missing = sorted({t for r in rows for t in r.openloop.missing_tasks})
        notes.append(
            f"--partial: tasks not scored ({', '.join(missing) or 'none'}) are left out of their rank "
            "scores and S_open is renormalised over the scored tasks' weights."
        )
    return "\n".join(lines + notes) + "\n"


def render_csv(rows: list[Row], rho: dict[str, dict[str, Any]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["model", *COLUMNS, "r4_rank", "openloop_run", "r4_run"])
    for r, pos in zip(rows, r4_positions(rows), strict=True):
        w.writerow(
            [r.model, *(f"{r.values[c]:.6f}" for c in COLUMNS), pos, str(r.openloop.path), str(r.r4.path)]
        )
    w.writerow(
        [
            "spearman_with_r4",
            *("" if rho[c]["rho"] is None else f"{rho[c]['rho']:.6f}" for c in (*OPEN_RANKS, "S_open")),
            "",
            "",
            "",
            "",
        ]
    )
    return buf.getvalue()


def report_dict(rows: list[Row], rho: dict[str, dict[str, Any]], partial: bool) -> dict[str, Any]:
    return {
        "models": [
            {
                "model": r.model,
                **{c: r.values[c] for c in COLUMNS},
                "r4_rank": pos,
                "openloop_run": str(r.openloop.path),
                "r4_run": str(r.r4.path),
                "tasks": r.openloop.tasks,
                "missing_tasks": r.openloop.missing_tasks,
            }
            for r, pos in zip(rows, r4_positions(rows), strict=True)
        ],
        "spearman_with_r4": rho,
        "n_models": len(rows),
        "partial": partial,
        "r4_categories": rows[0].r4.categories,
    }


def build_report(args: Sequence[str], out: Path, partial: bool = False) -> tuple[list[Path], str]:
    rows = collect(args, partial)
    rho = spearman_with_r4(rows)
    out.mkdir(parents=True, exist_ok=True)
    md = render_markdown(rows, rho, partial)
    files = {
        "hierarchy.md": md,
        "hierarchy.csv": render_csv(rows, rho),
        "hierarchy.json": json.dumps(report_dict(rows, rho, partial), indent=2, ensure_ascii=False) + "\n",
    }
    written = []
    for name, text in files.items():
        (out / name).write_text(text, encoding="utf-8")
        written.append(out / name)
    return written, md


# --- CLI -----------------------------------------------------------------------------------------


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("hierarchy", help="the whole hierarchy: R1–R3 and R4 of several models")
    sub = parser.add_subparsers(dest="hierarchy_command", required=True)
    p = sub.add_parser(
        "report",
        help="rank profile (R1, R2, R3, S_open, R4) per model and each rank's Spearman ρ with R4",
    )
    p.add_argument(
        "runs",
        nargs="+",
        metavar="RUN",
        help="scored open-loop run folders and `r4 evaluate` folders; paired by model name, or "
        "NAME=PATH to name a run",
    )
    p.add_argument("--out", type=Path, default=Path("hierarchy_report"), help="output folder")
    p.add_argument(
        "--partial",
        action="store_true",
        help="allow unscored tasks (e.g. R1_4 without the judge): ranks over the tasks present",
    )
    p.set_defaults(func=_cmd_report)


def _cmd_report(args: argparse.Namespace) -> int:
    written, md = build_report(args.runs, args.out, partial=args.partial)
    print(md, end="")
    for path in written:
        print(f"wrote {path}", file=sys.stderr)
    return 0
