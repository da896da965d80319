"""R4 reports: the paper's Table 2 layout (one row per model: Sce 1..10, Avg.Score, Rank) as
Markdown and CSV, a per-category bar plot, and `r4_summary.csv` (`model,r4_score`), the file
`drivehierarchy openloop report --r4` reads for the open-loop/closed-loop correlation.

Columns are the scenario categories present, labelled `Sce N` from the category folder's number
prefix (`01_pedestrian` → Sce 1); Avg.Score is the mean of the category means (the R4 score).

Runs are rows by (model, action level, inputs): the same model driven with history, memory or a
control is another row (labelled `model [inputs]` in Table 2). `comparison.{md,csv}` puts those
columns side by side, `comparison_carla.{md,csv}` gives the same rows in the CARLA-leaderboard
dialect (driving score, route completion, infraction penalty) and `r4_comparison.png` draws both
per category (docs/vlm.md#report).
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


def run_inputs(summary: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """(action level, inputs) of a run's summary; a summary written before they were recorded is
    the paper's setting."""
    from drivehierarchy.benchmark.r4.jobs import NO_INPUTS

    return str(summary.get("action_level") or "control"), {**NO_INPUTS, **(summary.get("inputs") or {})}


def inputs_text(inputs: dict[str, Any]) -> str:
    """`history 4 (stride 2, +BEV), ego-history 4, memory 2, history-shuffle`; "" for the paper's."""
    parts = []
    if inputs["history"]:
        extra = [f"stride {inputs['stride']}"] if inputs["stride"] != 1 else []
        extra += ["+BEV"] if inputs["history_bev"] else []
        parts.append(f"history {inputs['history']}" + (f" ({', '.join(extra)})" if extra else ""))
    if inputs["ego_history"]:
        stride = f" (stride {inputs['stride']})" if inputs["stride"] != 1 and not inputs["history"] else ""
        parts.append(f"ego-history {inputs['ego_history']}{stride}")
    if inputs["memory"]:
        parts.append(f"memory {inputs['memory']}")
    parts += list(inputs["controls"])
    return ", ".join(parts)


# How each robustness control reads in a row label, in this order.
_CONTROL_LABELS: dict[str, Callable[[Any], str]] = {
    "blind": lambda v: "--blind",
    "no_bev": lambda v: "--no-bev",
    "corrupt": lambda v: f"--corrupt {v}",
    "latency_aware": lambda v: "--latency-aware",
    "conditions": lambda v: f"--conditions {v}",
    "camera_fault": lambda v: f"--camera-fault {v}",
}


def controls_text(controls: dict[str, Any] | None) -> str:
    """`--conditions night, --camera-fault dirty`; "" for a run without robustness controls."""
    return ", ".join(f(controls[k]) for k, f in _CONTROL_LABELS.items() if controls and controls.get(k))


def row_label(model: str, summary: dict[str, Any] | None) -> str:
    """The run's row name: the model, plus its level and inputs when they are not the paper's
    (`qwen [waypoints; history 4]`) and the robustness controls it ran with
    (`qwen (--conditions night)`), so each combination is its own row."""
    summary = summary or {}
    level, inputs = run_inputs(summary)
    extra = [level] if level != "control" else []
    text = inputs_text(inputs)
    extra += [text] if text else []
    label = f"{model} [{'; '.join(extra)}]" if extra else model
    controls = controls_text(summary.get("controls"))
    return f"{label} ({controls})" if controls else label


def read_run(run: Path) -> tuple[str, dict[str, Any]]:
    """(row label, summary) of a run directory; the summary gains the CARLA dialect when it was
    written before the summary carried it."""
    path = run / "summary.json"
    if not run.exists():
        raise ConfigError(f"{run}: does not exist (expected an `r4 evaluate` output directory)")
    if not path.exists():
        raise ConfigError(f"{path}: not found (is {run} a finished `r4 evaluate` output directory?)")
    summary = json.loads(path.read_text(encoding="utf-8"))
    if not summary.get("categories"):
        raise ConfigError(f"{path}: field `categories` is empty: nothing to report")
    if "carla" not in summary:
        from drivehierarchy.benchmark.r4.store import read_results
        from drivehierarchy.benchmark.r4.summary import carla_summary

        summary["carla"] = carla_summary(list(read_results(run).values()))
    summary.setdefault("model", run.name)
    return row_label(str(summary["model"]), summary), summary


_KEY_HEAD = ["model", "action_level", "history", "stride", "history_bev", "ego_history", "memory", "controls"]
_KEY_MD = ["Model", "Level", "History", "Stride", "Hist. BEV", "Ego hist.", "Memory", "Controls"]


def _key_cells(summary: dict[str, Any]) -> list[str]:
    level, inputs = run_inputs(summary)
    return [
        str(summary.get("model", "")),
        level,
        str(inputs["history"]),
        str(inputs["stride"]),
        "yes" if inputs["history_bev"] else "no",
        str(inputs["ego_history"]),
        str(inputs["memory"]),
        ", ".join([*inputs["controls"], *filter(None, [controls_text(summary.get("controls"))])]) or "none",
    ]


def _carla(summary: dict[str, Any]) -> dict[str, Any] | None:
    carla: dict[str, Any] | None = summary.get("carla")
    return carla


def _rank(values: list[float | None]) -> list[int | None]:
    order = sorted((i for i, v in enumerate(values) if v is not None), key=lambda i: -(values[i] or 0.0))
    ranks: list[int | None] = [None] * len(values)
    for rank, i in enumerate(order, 1):
        ranks[i] = rank
    return ranks


def comparison_rows(runs: list[tuple[str, dict[str, Any]]]) -> tuple[list[str], list[dict[str, Any]]]:
    """One row per (model, level, inputs): key cells, S_R4 per category and overall, the CARLA
    dialect per category and overall, rank by S_R4 and by driving score."""
    cats = sorted({c for _, s in runs for c in s["categories"]})
    rows = []
    for label, s in runs:
        carla = _carla(s)
        rows.append(
            {
                "label": label,
                "keys": _key_cells(s),
                "r4": {c: s["categories"].get(c) for c in cats},
                "r4_score": s["r4_score"],
                "ds": {c: (carla or {}).get("categories", {}).get(c) for c in cats},
                "driving_score": carla["driving_score"] if carla else None,
                "route_completion": carla["route_completion"] if carla else None,
                "infraction_penalty": carla["infraction_penalty"] if carla else None,
            }
        )
    for row, rank in zip(rows, _rank([r["r4_score"] for r in rows]), strict=True):
        row["rank"] = rank
    for row, rank in zip(rows, _rank([r["driving_score"] for r in rows]), strict=True):
        row["ds_rank"] = rank
    return cats, rows


def _num(v: float | None, digits: int) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def comparison_markdown(runs: list[tuple[str, dict[str, Any]]], dialect: str = "r4") -> str:
    """`dialect="r4"`: mean S_R4 per category; `"carla"`: the CARLA-leaderboard driving score."""
    cats, rows = comparison_rows(runs)
    if dialect == "r4":
        tail = ["S_R4", "Rank"]
    else:
        tail = ["Driving score", "Route completion", "Infraction penalty", "Rank"]
    head = [*_KEY_MD, *[category_label(c) for c in cats], *tail]
    lines = [
        "| " + " | ".join(head) + " |",
        "|---" * len(_KEY_MD) + "|---:" * (len(head) - len(_KEY_MD)) + "|",
    ]
    for r in rows:
        if dialect == "r4":
            vals = [_num(r["r4"][c], 3) for c in cats] + [_num(r["r4_score"], 3), str(r["rank"])]
        else:
            vals = [_num(r["ds"][c], 3) for c in cats]
            vals += [_num(r["driving_score"], 3), _num(r["route_completion"], 3)]
            vals += [_num(r["infraction_penalty"], 3), str(r["ds_rank"] or "–")]
        lines.append("| " + " | ".join([*r["keys"], *vals]) + " |")
    legend = ", ".join(f"{category_label(c)} = {c}" for c in cats)
    what = (
        "Scores are mean S_R4 (0–100), the mean of category means."
        if dialect == "r4"
        else "CARLA-leaderboard dialect of the same runs (not the protocol score): driving score = route "
        "completion × infraction penalty × (1 − off-road share), per category the mean of its runs, "
        "overall the mean of category means; route completion and infraction penalty are means over runs."
    )
    return "\n".join(lines) + f"\n\n{legend}. {what}\n"


def comparison_csv(runs: list[tuple[str, dict[str, Any]]], dialect: str = "r4") -> str:
    cats, rows = comparison_rows(runs)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    if dialect == "r4":
        w.writerow([*_KEY_HEAD, *cats, "r4_score", "rank"])
        for r in rows:
            w.writerow([*r["keys"], *[_csv(r["r4"][c]) for c in cats], _csv(r["r4_score"]), r["rank"]])
    else:
        tail = ["driving_score", "route_completion", "infraction_penalty", "rank"]
        w.writerow([*_KEY_HEAD, *cats, *tail])
        for r in rows:
            w.writerow(
                [
                    *r["keys"],
                    *[_csv(r["ds"][c]) for c in cats],
                    _csv(r["driving_score"]),
                    _csv(r["route_completion"]),
                    _csv(r["infraction_penalty"]),
                    "" if r["ds_rank"] is None else r["ds_rank"],
                ]
            )
    return buf.getvalue()


def _csv(v: float | None) -> str:
    return "" if v is None else f"{v:.6f}"


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


def comparison_plot(runs: list[tuple[str, dict[str, Any]]], path: Path) -> None:
    """Grouped bars per category, one bar per (model, level, inputs) row: S_R4 above, the CARLA
    driving score below (when every run has it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    cats, rows = comparison_rows(runs)
    panels = [("r4", "mean S_R4", "r4_score")]
    if all(r["driving_score"] is not None for r in rows):
        panels.append(("ds", "CARLA driving score", "driving_score"))
    labels = [*[category_name(c) for c in cats], "Mean of categories"]
    x = np.arange(len(labels))
    width = 0.8 / max(1, len(rows))
    fig, axes = plt.subplots(
        len(panels),
        1,
        figsize=(max(7.0, 1.1 * len(labels) + 2), 3.4 * len(panels) + 0.4 + 0.25 * len(rows)),
        squeeze=False,
        layout="constrained",
    )
    for ax, (key, ylabel, overall) in zip(axes[:, 0], panels, strict=True):
        for i, r in enumerate(rows):
            vals = [r[key][c] if r[key][c] is not None else 0.0 for c in cats] + [r[overall]]
            ax.bar(x + (i - (len(rows) - 1) / 2) * width, vals, width, label=r["label"])
        ax.axvline(len(cats) - 0.5, color="0.6", linewidth=0.8)
        ax.set_xticks(x, labels, rotation=30, ha="right")
        ax.set_ylabel(ylabel)
        ax.set_ylim(0, 100)
    axes[0, 0].set_title("R4 by model, action level and inputs")
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, fontsize="small", loc="outside lower center")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def build_report(run_dirs: list[Path], out: Path, *, paper: bool = False, plot: bool = True) -> list[Path]:
    """Table 2 (Markdown, CSV), r4_summary.csv, the (model, level, inputs) comparison in both
    dialects and the bar plots for several runs."""
    if not run_dirs:
        raise ConfigError("r4 report: no run directories given")
    runs = [read_run(r) for r in run_dirs]
    names = [n for n, _ in runs]
    seen: dict[str, Path] = {}
    for name, run in zip(names, run_dirs, strict=True):
        if name in seen:
            raise ConfigError(
                f"r4 report: {seen[name]} and {run} are the same model, action level, inputs and controls "
                f"({name!r}); one row per combination"
            )
        seen[name] = run
    out.mkdir(parents=True, exist_ok=True)
    models = list(dict.fromkeys(str(s["model"]) for _, s in runs))
    table_runs = runs + (paper_runs(models) if paper else [])
    written = []
    for name, text in (
        ("table2.md", table_markdown(table_runs)),
        ("table2.csv", table_csv(table_runs)),
        ("r4_summary.csv", r4_summary_csv(runs)),
        ("comparison.md", comparison_markdown(runs)),
        ("comparison.csv", comparison_csv(runs)),
        ("comparison_carla.md", comparison_markdown(runs, "carla")),
        ("comparison_carla.csv", comparison_csv(runs, "carla")),
    ):
        (out / name).write_text(text, encoding="utf-8")
        written.append(out / name)
    if plot:
        bar_plot(table_runs, out / "r4_categories.png")
        comparison_plot(runs, out / "r4_comparison.png")
        written += [out / "r4_categories.png", out / "r4_comparison.png"]
    return written
