"""Generating a question set: rollouts over the suite, task builders, quality checks, files.

`generate(suite, out, per_task=..., seed=..., split=...)` writes `out/<task file>.jsonl` for
every registered task (the original release's names and record fields), the images once each
under `out/images/` (content-addressed names, paths relative to `out`) and
`out/generation.json` (what was generated from what). Same suite, seed and options give
byte-identical files: every choice comes from a `random.Random` seeded by (seed, task) or
(seed, scenario, driver), rollouts are deterministic, and nothing records time or host.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import random
import re
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError

from . import quality
from .rollout import DRIVERS, FRONT, IMAGE_SIZE, Frame, Moment, Needs, Rollout, builders, rollout

SPLITS = ("eval", "train")
# R4 plays seeds 0–4 (docs/suite.md); the train split never uses them.
EVAL_SEEDS = (0, 1, 2, 3, 4)
TRAIN_SEED_BASE = 100_000
# Rollouts per record asked of each task: 200 per task plays every scenario of the R4 suite
# once and half of them again with another driver and seed (each rollout yields ~22.5 regular
# moments, one every 1.5 s from a seeded offset, and the extra ones where a still object is in
# view). Fewer leave R1_4 (distinct situations) and R1_1_C (still vehicles) short.
ROLLOUTS_PER_RECORD = 0.75
MOMENTS_PER_ROLLOUT = 22.5
# Enough scenes for small sets (tests) to have an answer for every task.
MIN_ROLLOUTS = 10
# Anchors with costly frames beyond `oversample × per_task` (small sets vary the most).
SPARE_ANCHORS = 10


# Train episodes start the ego this much farther back on its start lane (seeded, metres), so
# even scenarios without live traffic (where the seed changes nothing) play other states.
TRAIN_START_BACK_M = (3.0, 15.0)
_EGO_START = re.compile(r"^(start\s*=\s*\{\s*lane\s*=\s*\"[^\"]*\"\s*,\s*s\s*=\s*)([0-9.]+)", re.M)
_MAP = re.compile(r'^(map\s*=\s*)"([^"]*)"', re.M)


@dataclass(frozen=True)
class Episode:
    scenario: str
    driver: str
    seed: int
    start_back_m: float = 0.0


def shifted_scenario(path: Path, back_m: float) -> str:
    """The scenario's TOML with the ego starting `back_m` farther back on its start lane (at
    least 1 m into it) and a relative map path made absolute (the text is loaded elsewhere;
    `sumo:` and built-in map names stay)."""
    text = path.read_text(encoding="utf-8")
    ego = text.find("[ego]")
    m = _EGO_START.search(text, ego) if ego >= 0 else None
    if m is None:
        raise ConfigError(f"{path}: field [ego].start: expected `start = {{ lane = ..., s = ... }}` to shift")
    s_new = max(1.0, float(m.group(2)) - back_m)
    text = text[: m.start(2)] + f"{s_new:.2f}" + text[m.end(2) :]
    mm = _MAP.search(text)
    if mm and ":" not in mm.group(2) and ("/" in mm.group(2) or mm.group(2).startswith(".")):
        full = (path.parent / mm.group(2)).resolve().as_posix()
        text = text[: mm.start(2)] + full + text[mm.end(2) :]
    return text


def suite_files(suite: Path) -> list[Path]:
    """Scenario files of a suite folder (sorted), or the one file given."""
    if suite.is_file():
        return [suite]
    if not suite.is_dir():
        raise ConfigError(f"--suite {suite}: no such scenario file or folder")
    files = sorted(p for p in suite.rglob("*.toml") if p.is_file())
    if not files:
        raise ConfigError(f"--suite {suite}: no scenario files (*.toml) in it")
    return files


def plan_episodes(
    files: list[Path], per_task: int, seed: int, split: str, drivers: tuple[str, ...]
) -> list[Episode]:
    """Which (scenario, driver, seed) to roll out: scenarios in a seeded order interleaved
    over their folders (categories), drivers and seeds cycled over them."""
    if split not in SPLITS:
        raise ConfigError(f"--split {split!r}: expected one of {', '.join(SPLITS)}")
    rng = random.Random(f"episodes|{seed}|{split}")
    by_cat: dict[str, list[Path]] = {}
    for f in files:
        by_cat.setdefault(f.parent.name, []).append(f)
    for v in by_cat.values():
        rng.shuffle(v)
    order: list[Path] = []
    while any(by_cat.values()):
        for k in sorted(by_cat):
            if by_cat[k]:
                order.append(by_cat[k].pop())
    n = max(MIN_ROLLOUTS, round(per_task * ROLLOUTS_PER_RECORD))
    eps = []
    for i in range(n):
        f = order[i % len(order)]
        lap = i // len(order)
        driver = drivers[(i + lap + seed) % len(drivers)]
        if split == "eval":
            eps.append(Episode(str(f), driver, EVAL_SEEDS[(i + lap) % len(EVAL_SEEDS)]))
        else:
            back = round(rng.uniform(*TRAIN_START_BACK_M), 2)
            eps.append(Episode(str(f), driver, TRAIN_SEED_BASE + rng.randrange(1_000_000), back))
    return eps


def _run(ep: Episode, needs: tuple[Needs, ...], shares: tuple[float, ...], split: str) -> Rollout:
    if not ep.start_back_m:
        return rollout(ep.scenario, ep.driver, ep.seed, needs, shares=shares, split=split)
    with tempfile.TemporaryDirectory() as tmp:
        derived = Path(tmp) / Path(ep.scenario).name
        derived.write_text(shifted_scenario(Path(ep.scenario), ep.start_back_m), encoding="utf-8")
        ro = rollout(derived, ep.driver, ep.seed, needs, shares=shares, split=split)
    ro.scenario = ep.scenario
    return ro


def need_shares(needs: tuple[Needs, ...], per_task: int, n_rollouts: int) -> tuple[float, ...]:
    """Share of anchors at which each need's frames are rendered."""
    moments = max(1.0, n_rollouts * MOMENTS_PER_ROLLOUT)
    return tuple(
        1.0
        if (nd.cameras, nd.clip, nd.history) == ((FRONT,), 0, 0)
        else min(1.0, (nd.oversample * per_task + SPARE_ANCHORS) / moments)
        for nd in needs
    )


def run_rollouts(
    eps: list[Episode],
    needs: tuple[Needs, ...],
    shares: tuple[float, ...],
    split: str,
    jobs: int,
    progress: bool,
) -> list[Rollout]:
    t0 = time.perf_counter()
    if jobs <= 1:
        out = []
        for i, ep in enumerate(eps):
            out.append(_run(ep, needs, shares, split))
            if progress:
                print(f"[{i + 1}/{len(eps)} {time.perf_counter() - t0:5.0f}s] {ep.scenario}", file=sys.stderr)
        return out
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
        futs = [pool.submit(_run, ep, needs, shares, split) for ep in eps]
        out = []
        for i, fut in enumerate(futs):
            try:
                out.append(fut.result())
            except Exception as exc:
                raise RuntimeError(
                    f"{eps[i].scenario} ({eps[i].driver}, seed {eps[i].seed}): rollout failed: {exc}"
                ) from exc
            if progress:
                print(
                    f"[{i + 1}/{len(eps)} {time.perf_counter() - t0:5.0f}s] {eps[i].scenario}",
                    file=sys.stderr,
                )
        return out


def _line(rec: dict[str, Any]) -> str:
    return json.dumps(rec, ensure_ascii=False) + "\n"


def generate(
    suite: str | Path,
    out: str | Path,
    *,
    per_task: int = 200,
    seed: int = 0,
    split: str = "eval",
    tasks: list[str] | None = None,
    drivers: tuple[str, ...] = DRIVERS,
    jobs: int = 2,
    progress: bool = False,
    strict: bool | None = None,
) -> dict[str, Any]:
    """Writes the question set; returns the summary also written to `generation.json`, with
    the quality table (`quality`: text-only prior against chance, balance and diversity per
    task). With `strict` (default: from `quality.PRIOR_STRICT_MIN_RECORDS` records per task on)
    a task whose table row names a problem (a short task included) fails the set after it is
    written; a task with no records fails it at any size unless `strict` is False."""
    from drivehierarchy.benchmark.openloop.records import TASK_FILE_STEM

    if per_task < 1:
        raise ConfigError(f"--per-task {per_task}: must be at least 1")
    suite, out = Path(suite), Path(out)
    registry = builders()
    if tasks is not None:
        unknown = [t for t in tasks if t not in registry]
        if unknown:
            raise ConfigError(f"--tasks: no generator for {', '.join(unknown)} (have {', '.join(registry)})")
        registry = {t: registry[t] for t in tasks}
    files = suite_files(suite)
    eps = plan_episodes(files, per_task, seed, split, drivers)
    needs = tuple(nd for _, nd in registry.values())
    shares = need_shares(needs, per_task, len(eps))
    rollouts = run_rollouts(eps, needs, shares, split, jobs, progress)
    moments: list[Moment] = [m for r in rollouts for m in r.moments()]
    ours = (out / "generation.json").is_file()  # regenerating over an earlier set
    out.mkdir(parents=True, exist_ok=True)
    (out / "images").mkdir(exist_ok=True)
    written: set[str] = set()
    summary: dict[str, Any] = {
        "suite": suite.as_posix(),
        "split": split,
        "seed": seed,
        "per_task": per_task,
        "drivers": list(drivers),
        "episodes": [
            {
                "scenario": Path(e.scenario).relative_to(suite).as_posix()
                if suite.is_dir()
                else Path(e.scenario).name,
                "driver": e.driver,
                "seed": e.seed,
                "start_back_m": e.start_back_m,
                "moments": len(r.moments()),
                "termination": r.termination,
            }
            for e, r in zip(eps, rollouts, strict=True)
        ],
        "tasks": {},
    }
    cat_of = {r.scenario_id: r.category for r in rollouts}
    built: dict[str, list[dict[str, Any]]] = {}
    funnels: dict[str, dict[str, int]] = {}
    cats: dict[str, set[str]] = {}
    for task, (build, _) in registry.items():
        rng = random.Random(f"{seed}|{split}|{task}")
        with quality.tracking() as funnel:
            recs = build(moments, per_task, rng)
        funnels[task] = dict(sorted(funnel.items()))
        built[task] = recs
        cats[task] = {cat_of.get(quality.scene_of(r), "") for r in recs} - {""}
        lines = []
        for rec in recs:
            frames: list[Frame] = rec.pop("_frames", [])
            for f in frames:
                if f.name not in written:
                    (out / "images" / f.name).write_bytes(f.image)
                    written.add(f.name)
            lines.append(_line(rec))
        quality.check(task, recs, out, IMAGE_SIZE)
        path = out / f"{TASK_FILE_STEM[task]}.jsonl"
        path.write_text("".join(lines), encoding="utf-8")
        summary["tasks"][task] = {
            "file": path.name,
            "records": len(recs),
            "sha256": hashlib.sha256("".join(lines).encode()).hexdigest(),
            "candidates": funnels[task],
        }
    if ours:  # images of the earlier set that this one no longer uses
        for p in sorted((out / "images").iterdir()):
            if p.is_file() and p.name not in written:
                p.unlink()
    summary["images"] = len(written)
    rows = quality.quality_rows(built, cats, asked=per_task, funnels=funnels)
    summary["quality"] = rows
    summary["scenario_categories"] = sorted(set(cat_of.values()))
    (out / "generation.json").write_text(
        json.dumps(summary, indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
    )
    # By default an empty task file is an error at any size; a short one (like every other
    # problem) only from the default size on (small sets are previews: their table flags it).
    # `strict=False` (timing runs) never fails, `strict=True` fails on any problem.
    empty_fails = strict is not False
    if strict is None:
        strict = per_task >= quality.PRIOR_STRICT_MIN_RECORDS
    bad = [r for r in rows if r["problems"] and (strict or (empty_fails and r["records"] == 0))]
    if bad:
        raise quality.QualityError(
            f"{out}: the set fails its quality checks:\n"
            + "\n".join(f"  {r['task']}: {'; '.join(r['problems'])}" for r in bad)
            + "\n"
            + quality.format_table(rows)
        )
    return summary
