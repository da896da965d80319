"""An R4 run's statistics and tables: category means with bootstrap intervals, summary.json/csv/md,
the Table 2 files, and the offline re-scoring of a run's episode logs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from drivehierarchy import _core
from drivehierarchy._core import ConfigError
from drivehierarchy.benchmark.r4.store import write_json_atomic, write_text_atomic

BOOTSTRAP_RESAMPLES = 2000


def bootstrap_ci(values: list[float], seed: int = 0) -> tuple[float, float] | None:
    """Percentile bootstrap 95 % interval of the mean (fixed seed: the summary is reproducible);
    None with fewer than two values."""
    if len(values) < 2:
        return None
    rng = np.random.default_rng(seed)
    arr = np.asarray(values, dtype=np.float64)
    means = arr[rng.integers(0, len(arr), (BOOTSTRAP_RESAMPLES, len(arr)))].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)


def summarize(results: list[dict[str, Any]], failed: list[str] | None = None) -> dict[str, Any]:
    """Category means (± bootstrap 95 % intervals over the category's runs: scenarios × seeds)
    and the model's R4 score (mean of the categories present, with an interval from resampling
    within every category). `failed`: keys of scenarios that failed with a system error; they
    are listed, not scored (a resume redoes them)."""
    by_cat: dict[str, list[float]] = {}
    for r in results:
        by_cat.setdefault(r["category"], []).append(float(r["score"]["score_composed"]))
    by_cat = dict(sorted(by_cat.items()))
    cats = {c: float(np.mean(v)) for c, v in by_cat.items()}
    ci = {c: bootstrap_ci(v) for c, v in by_cat.items()}
    r4_ci = None
    if by_cat and any(len(v) > 1 for v in by_cat.values()):
        rng = np.random.default_rng(0)
        cat_means = [
            np.asarray(v)[rng.integers(0, len(v), (BOOTSTRAP_RESAMPLES, len(v)))].mean(axis=1)
            for v in by_cat.values()
        ]
        lo, hi = np.percentile(np.mean(cat_means, axis=0), [2.5, 97.5])
        r4_ci = [float(lo), float(hi)]
    carla = carla_summary(results)
    vlm = [r["vlm"] for r in results if r.get("vlm")]
    out: dict[str, Any] = {
        "categories": cats,
        "categories_ci95": {c: list(v) if v is not None else None for c, v in ci.items()},
        "counts": {c: len(v) for c, v in by_cat.items()},
        "r4_score": float(np.mean(list(cats.values()))) if cats else 0.0,
        "r4_score_ci95": r4_ci,
        "scenarios": len(results),
        "seeds": sorted({int(r.get("seed", 0)) for r in results}),
        "completed": sum(r["score"]["termination_reason"] == "destination_reached" for r in results),
        "failed": sorted(failed or []),
    }
    if carla is not None:
        out["carla"] = carla
    if vlm:
        out["decisions"] = sum(v["decisions"] for v in vlm)
        out["parse_failures"] = sum(v["parse_failures"] for v in vlm)
        out["transport_errors"] = sum(v["transport_errors"] for v in vlm)
    return out


def carla_summary(results: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The CARLA-leaderboard dialect of the same runs (`dialects.carla` of each record): driving
    score per category (mean over its runs) and their mean, like S_R4; route completion and
    infraction penalty as means over all runs. None when a record has no dialect."""
    dialects = [r["score"].get("dialects", {}).get("carla") for r in results]
    if not results or any(d is None for d in dialects):
        return None
    by_cat: dict[str, list[float]] = {}
    for r, d in zip(results, dialects, strict=True):
        by_cat.setdefault(r["category"], []).append(float(d["driving_score"]))
    cats = {c: float(np.mean(v)) for c, v in sorted(by_cat.items())}
    return {
        "categories": cats,
        "driving_score": float(np.mean(list(cats.values()))),
        "route_completion": float(np.mean([d["route_completion"] for d in dialects])),
        "infraction_penalty": float(np.mean([d["infraction_penalty"] for d in dialects])),
    }


def write_summary(
    out: Path,
    results: list[dict[str, Any]],
    model: str | None = None,
    failed: list[str] | None = None,
    facts: dict[str, Any] | None = None,
    controls: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """`facts`: the run's action level and inputs (`RunOptions.run_facts`), which `r4 report`
    compares."""
    from drivehierarchy.benchmark.r4 import report

    if not results:
        raise ConfigError(f"{out}: no finished scenario to summarize")
    summary = summarize(results, failed)
    if model is not None:
        summary["model"] = model
    summary.update(facts or {})
    if controls:
        summary["controls"] = controls
    write_json_atomic(out / "summary.json", summary)
    rows = [
        "scenario,category,seed,status,termination_reason,score_route,score_safety,score_efficiency,"
        "score_composed"
    ]
    for r in results:
        s = r["score"]
        rows.append(
            f"{r['key']},{r['category']},{r.get('seed', 0)},{s['status']},{s['termination_reason']},"
            f"{s['score_route']:.4f},{s['score_safety']:.4f},{s['score_efficiency']:.4f},{s['score_composed']:.4f}"
        )
    write_text_atomic(out / "summary.csv", "\n".join(rows) + "\n")
    write_text_atomic(out / "summary.md", summary_table(results, summary))
    report.write_run_tables(out, summary, report.row_label(model or "model", summary))
    return summary


def summary_table(results: list[dict[str, Any]], summary: dict[str, Any] | None = None) -> str:
    summary = summary or summarize(results)
    lines = [
        "| scenario | status | termination | route | safety | efficiency | S_R4 |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    for r in results:
        s = r["score"]
        lines.append(
            f"| {r['key']} | {s['status']} | {s['termination_reason']} | {s['score_route']:.1f} | "
            f"{s['score_safety']:.3f} | {s['score_efficiency']:.3f} | {s['score_composed']:.2f} |"
        )
    lines += ["", "| category | runs | mean S_R4 | 95 % CI |", "|---|---:|---:|---|"]
    for c, v in summary["categories"].items():
        ci = summary.get("categories_ci95", {}).get(c)
        ci_text = f"[{ci[0]:.2f}, {ci[1]:.2f}]" if ci else "–"
        lines.append(f"| {c} | {summary['counts'][c]} | {v:.2f} | {ci_text} |")
    r4_ci = summary.get("r4_score_ci95")
    r4_ci_text = f"[{r4_ci[0]:.2f}, {r4_ci[1]:.2f}]" if r4_ci else "–"
    lines.append(
        f"| **R4 (mean of categories)** | {summary['scenarios']} | **{summary['r4_score']:.2f}** "
        f"| {r4_ci_text} |"
    )
    if summary.get("failed"):
        lines += [
            "",
            f"**{len(summary['failed'])} scenario(s) failed with a system error** (not scored; run the "
            f"same command again to redo them): {', '.join(summary['failed'])}",
        ]
    return "\n".join(lines) + "\n"


def rescore_dir(out: Path) -> list[dict[str, Any]]:
    """Recomputes every scene score of a run from its episode logs, without simulating."""
    if not out.exists():
        raise ConfigError(f"{out}: does not exist (expected an `r4 evaluate` or `r4 run` output directory)")
    scenes = sorted((out / "scenes").glob("*/episode_log.jsonl"))
    if not scenes:
        single = out / "episode_log.jsonl"
        if single.exists():
            scenes = [single]
        else:
            raise ConfigError(f"{out}: no episode_log.jsonl found (expected scenes/*/episode_log.jsonl)")
    rescored = []
    for log_path in scenes:
        record = _core.rescore_file(log_path)
        write_json_atomic(log_path.parent / "scene_score.rescored.json", record)
        rescored.append({"key": log_path.parent.name, "score": record})
    return rescored
