"""R4 reports: the paper's Table 2 layout (one row per model: Sce 1..10, Avg.Score, Rank) as
Markdown and CSV, a per-category bar plot, and `r4_summary.csv` (`model,r4_score`), the file
`drivehierarchy openloop report --r4` reads for the open-loop/closed-loop correlation.

Columns are the scenario categories present, labelled `Sce N` from the category folder's number
prefix (`01_pedestrian` → Sce 1); Avg.Score is the mean of the category means (the R4 score).
"""

from __future__ import annotations

import csv
import io
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from drivehierarchy import _core
from drivehierarchy._core import ConfigError

_PREFIX = re.compile(r"^(\d+)_")


def category_label(category: str) -> str:
    m = _PREFIX.match(category)
    return f"Sce {int(m.group(1))}" if m else category


def category_name(category: str) -> str:
    """`05_t_intersection` → `T intersection` (plot labels; the table keeps the paper's Sce N)."""
    name = _PREFIX.sub("", category).replace("_", " ")
    return name[:1].upper() + name[1:]


def _ci_text(ci: list[float] | None) -> str:
    return f" [{ci[0]:.3f}, {ci[1]:.3f}]" if ci else ""


def table_rows(runs: list[tuple[str, dict[str, Any]]]) -> tuple[list[str], list[dict[str, Any]]]:
    """(category columns, one row per run with `model`, per-category values, `avg`, `rank`)."""
    cats = sorted({c for _, s in runs for c in s["categories"]})
    rows = [
        {"model": name, "summary": s, **{c: s["categories"].get(c) for c in cats}, "avg": s["r4_score"]}
        for name, s in runs
    ]
    order = sorted(range(len(rows)), key=lambda i: -rows[i]["avg"])
    for rank, i in enumerate(order, 1):
        rows[i]["rank"] = rank
    return cats, rows


def table_markdown(runs: list[tuple[str, dict[str, Any]]], with_ci: bool = True) -> str:
    cats, rows = table_rows(runs)
    head = ["Models", *[category_label(c) for c in cats], "Avg.Score", "Rank"]
    lines = ["| " + " | ".join(head) + " |", "|---" + "|---:" * (len(head) - 1) + "|"]
    for r in rows:
        s = r["summary"]
        cells = [r["model"]]
        for c in cats:
            v = r[c]
            ci = (s.get("categories_ci95") or {}).get(c) if with_ci else None
            cells.append("–" if v is None else f"{v:.3f}{_ci_text(ci)}")
        cells.append(f"{r['avg']:.3f}{_ci_text(s.get('r4_score_ci95') if with_ci else None)}")
        cells.append(str(r["rank"]))
        lines.append("| " + " | ".join(cells) + " |")
    legend = ", ".join(f"{category_label(c)} = {c}" for c in cats)
    return (
        "\n".join(lines) + f"\n\n{legend}. Scores are mean S_R4 (0–100); [a, b] = bootstrap 95 % interval.\n"
    )


def table_csv(runs: list[tuple[str, dict[str, Any]]]) -> str:
    cats, rows = table_rows(runs)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["model", *cats, "avg_score", "avg_ci95_low", "avg_ci95_high", "rank"])
    for r in rows:
        ci = r["summary"].get("r4_score_ci95") or [None, None]
        w.writerow(
            [
                r["model"],
                *["" if r[c] is None else f"{r[c]:.6f}" for c in cats],
                f"{r['avg']:.6f}",
                "" if ci[0] is None else f"{ci[0]:.6f}",
                "" if ci[1] is None else f"{ci[1]:.6f}",
                r["rank"],
            ]
        )
    return buf.getvalue()


def r4_summary_csv(runs: list[tuple[str, dict[str, Any]]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["model", "r4_score"])
    for name, s in runs:
        w.writerow([name, f"{s['r4_score']:.6f}"])
    return buf.getvalue()


def write_run_tables(out: Path, summary: dict[str, Any], model: str) -> None:
    """The one-row tables an evaluation writes beside its summary."""
    runs = [(model, summary)]
    (out / "table2.md").write_text(table_markdown(runs), encoding="utf-8")
    (out / "table2.csv").write_text(table_csv(runs), encoding="utf-8")
    (out / "r4_summary.csv").write_text(r4_summary_csv(runs), encoding="utf-8")


# How each robustness control reads in a row label, in this order.
_CONTROL_LABELS: dict[str, Callable[[Any], str]] = {
    "blind": lambda v: "--blind",
    "no_bev": lambda v: "--no-bev",
    "corrupt": lambda v: f"--corrupt {v}",
    "latency_aware": lambda v: "--latency-aware",
    "conditions": lambda v: f"--conditions {v}",
    "camera_fault": lambda v: f"--camera-fault {v}",
}


def row_label(model: str, controls: dict[str, Any] | None) -> str:
    """A run's row name: the model, plus the controls it ran with (`qwen (--conditions night)`),
    so a control run is its own row beside the plain run of the same model."""
    parts = [f(controls[k]) for k, f in _CONTROL_LABELS.items() if controls and controls.get(k)]
    return f"{model} ({', '.join(parts)})" if parts else model


def read_run(run: Path) -> tuple[str, dict[str, Any]]:
    path = run / "summary.json"
    if not run.exists():
        raise ConfigError(f"{run}: does not exist (expected an `r4 evaluate` output directory)")
    if not path.exists():
        raise ConfigError(f"{path}: not found (is {run} a finished `r4 evaluate` output directory?)")
    summary = json.loads(path.read_text(encoding="utf-8"))
    if not summary.get("categories"):
        raise ConfigError(f"{path}: field `categories` is empty: nothing to report")
    return row_label(str(summary.get("model") or run.name), summary.get("controls")), summary


def paper_runs(models: list[str]) -> list[tuple[str, dict[str, Any]]]:
    """The paper's Table 2 rows of the models that match a preset (for side-by-side tables)."""
    from drivehierarchy.agents.vlm.presets import resolve_model

    cats = _core.constants()["categories"]
    out = []
    for m in models:
        _, preset = resolve_model(m)
        if preset is None:
            continue
        vals = preset.paper_r4
        out.append(
            (
                f"{preset.paper_name} (paper)",
                {"categories": dict(zip(cats, vals[: len(cats)], strict=True)), "r4_score": vals[len(cats)]},
            )
        )
    return out


def bar_plot(runs: list[tuple[str, dict[str, Any]]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    cats, rows = table_rows(runs)
    x = np.arange(len(cats))
    width = 0.8 / max(1, len(rows))
    fig, ax = plt.subplots(figsize=(max(6.0, 1.0 * len(cats) + 2), 4.0))
    for i, r in enumerate(rows):
        vals = [r[c] if r[c] is not None else 0.0 for c in cats]
        cis = (r["summary"].get("categories_ci95") or {}) if "categories_ci95" in r["summary"] else {}
        err = None
        if any(cis.get(c) for c in cats):
            err = np.array(
                [
                    [v - cis[c][0] if cis.get(c) else 0.0 for v, c in zip(vals, cats, strict=True)],
                    [cis[c][1] - v if cis.get(c) else 0.0 for v, c in zip(vals, cats, strict=True)],
                ]
            )
        ax.bar(x + (i - (len(rows) - 1) / 2) * width, vals, width, yerr=err, capsize=2, label=r["model"])
    ax.set_xticks(x, [category_name(c) for c in cats], rotation=30, ha="right")
    ax.set_ylabel("mean S_R4")
    ax.set_title("R4 per scenario category")
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def build_report(run_dirs: list[Path], out: Path, *, paper: bool = False, plot: bool = True) -> list[Path]:
    """Table 2 (Markdown, CSV), r4_summary.csv and the bar plot for several runs."""
    if not run_dirs:
        raise ConfigError("r4 report: no run directories given")
    runs = [read_run(r) for r in run_dirs]
    names = [n for n, _ in runs]
    if len(set(names)) != len(names):
        raise ConfigError(
            f"r4 report: two runs report the same model and controls ({names}); one row per model and control"
        )
    out.mkdir(parents=True, exist_ok=True)
    models = list(dict.fromkeys(str(s.get("model") or n) for n, s in runs))
    table_runs = runs + (paper_runs(models) if paper else [])
    written = []
    for name, text in (
        ("table2.md", table_markdown(table_runs)),
        ("table2.csv", table_csv(table_runs)),
        ("r4_summary.csv", r4_summary_csv(runs)),
    ):
        (out / name).write_text(text, encoding="utf-8")
        written.append(out / name)
    if plot:
        bar_plot(table_runs, out / "r4_categories.png")
        written.append(out / "r4_categories.png")
    return written
