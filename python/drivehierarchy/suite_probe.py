"""`drivehierarchy scenario probe`: how discriminating is a scenario suite?

Runs four reference policies over every scenario, state-only (no images), and tabulates their
S_R4 per category:

* `expert`   — the privileged autopilot (solvability: it should score high everywhere);
* `zero`     — target speed 0 (a suite must not reward standing still);
* `constant` — steer 0 at 8 m/s (a suite must not reward driving blindly straight);
* `follower` — the hazard-blind route follower (pure pursuit on the route points at 10 m/s,
  6 m/s in turns, ignoring every actor and light): what route-following alone earns.

Episodes run in worker processes (one at a time per process, so SUMO scenarios are fine).
"""

from __future__ import annotations

import csv
import json
import multiprocessing as mp
import statistics
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from drivehierarchy._core import ConfigError

POLICIES = ("expert", "zero", "constant", "follower")


def _agent(policy: str) -> Any:
    from drivehierarchy.agents.base import ConstantAgent
    from drivehierarchy.agents.expert import ExpertAgent
    from drivehierarchy.agents.follower import RouteFollowerAgent

    if policy == "expert":
        return ExpertAgent()
    if policy == "zero":
        return ConstantAgent([0.0, 0.0], name="zero")
    if policy == "constant":
        return ConstantAgent([0.0, 8.0], name="constant")
    if policy == "follower":
        return RouteFollowerAgent()
    raise ValueError(f"unknown probe policy {policy!r}: expected one of {POLICIES}")


def run_one(scenario: str, policy: str, seed: int, traffic: str | None) -> dict[str, Any]:
    """One episode; returns the record's essentials (runs in a worker process)."""
    from drivehierarchy.agents.base import run_episode
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    overrides: dict[str, Any] = {"front": None, "bev": None, "prompt": False}
    if traffic is not None:
        overrides["traffic"] = traffic
    env = DriveHierarchyR4Env(scenario=scenario, **overrides)
    t0 = time.perf_counter()
    try:
        result = run_episode(env, _agent(policy), seed=seed)
        traffic_mode = env.traffic_mode
        category = env.sim.category
        trajectory = env.sim.trajectory_hash
    finally:
        env.close()
    rec = result.score
    return {
        "scenario": scenario,
        "id": rec["scene_id"],
        "category": category,
        "policy": policy,
        "seed": seed,
        "traffic": traffic_mode,
        "score": float(rec["score_composed"]),
        "route": float(rec["score_route"]),
        "safety": float(rec["score_safety"]),
        "efficiency": float(rec["score_efficiency"]),
        "status": rec["status"],
        "termination": rec["termination_reason"],
        "events": sorted({e["type"] for e in rec["events"]}),
        "sim_s": float(rec["meta"]["duration_game"]),
        "trajectory_hash": trajectory,
        "wall_s": round(time.perf_counter() - t0, 3),
    }


def probe(
    scenarios: list[Path],
    policies: tuple[str, ...] = POLICIES,
    seed: int = 0,
    jobs: int = 2,
    traffic: str | None = None,
    progress: bool = True,
) -> list[dict[str, Any]]:
    tasks = [(str(s), p) for s in scenarios for p in policies]
    rows: list[dict[str, Any]] = []
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, jobs), mp_context=ctx) as pool:
        futs = {pool.submit(run_one, s, p, seed, traffic): (s, p) for s, p in tasks}
        for done, fut in enumerate(as_completed(futs), start=1):
            s, p = futs[fut]
            try:
                row = fut.result()
            except Exception as exc:
                raise RuntimeError(f"{s}: policy {p} failed: {exc}") from exc
            rows.append(row)
            if progress:
                print(
                    f"[{done}/{len(tasks)}] {row['id']:40} {p:9} {row['score']:6.1f} {row['termination']}",
                    file=sys.stderr,
                )
    rows.sort(key=lambda r: (r["category"], r["id"], POLICIES.index(r["policy"])))
    return rows


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    by: dict[tuple[str, str], list[float]] = defaultdict(list)
    completed: dict[str, int] = defaultdict(int)
    for r in rows:
        by[(r["category"], r["policy"])].append(r["score"])
        if r["termination"] == "destination_reached":
            completed[r["policy"]] += 1
    cats = sorted({c for c, _ in by})
    pols = [p for p in POLICIES if any((c, p) in by for c in cats)]
    table = {c: {p: statistics.fmean(by[(c, p)]) for p in pols if (c, p) in by} for c in cats}
    overall = {p: statistics.fmean(table[c][p] for c in cats if p in table[c]) for p in pols}
    counts = {c: len(by[(c, pols[0])]) for c in cats}
    return {
        "categories": table,
        "overall": overall,
        "completed": dict(completed),
        "counts": counts,
        "policies": pols,
    }


def markdown(rows: list[dict[str, Any]], summary: dict[str, Any]) -> str:
    pols = summary["policies"]
    out = ["| category | n | " + " | ".join(pols) + " |", "|---|---:|" + "---:|" * len(pols)]
    for c, vals in summary["categories"].items():
        cells = " | ".join(f"{vals[p]:.1f}" if p in vals else "–" for p in pols)
        out.append(f"| {c} | {summary['counts'][c]} | {cells} |")
    total = sum(summary["counts"].values())
    cells = " | ".join(f"**{summary['overall'][p]:.1f}**" for p in pols)
    out.append(f"| **mean of categories** | {total} | {cells} |")
    done = " | ".join(f"{summary['completed'].get(p, 0)}" for p in pols)
    out.append(f"| destination reached | | {done} |")
    out.append("")
    # Per scenario, for the authors: the score of each policy and how the episode ended.
    out.append("| scenario | traffic | " + " | ".join(pols) + " |")
    out.append("|---|---|" + "---|" * len(pols))
    per: dict[str, dict[str, dict[str, Any]]] = defaultdict(dict)
    for r in rows:
        per[r["id"]][r["policy"]] = r
    for sid in sorted(per, key=lambda k: (next(iter(per[k].values()))["category"], k)):
        first = next(iter(per[sid].values()))
        cells = " | ".join(
            f"{per[sid][p]['score']:.1f} ({_short(per[sid][p])})" if p in per[sid] else "–" for p in pols
        )
        out.append(f"| {first['category']}/{sid} | {first['traffic']} | {cells} |")
    return "\n".join(out) + "\n"


def _short(row: dict[str, Any]) -> str:
    ev = [e for e in row["events"] if e.startswith("collision")]
    if row["termination"].startswith("collision_"):
        return ", ".join(e.replace("collision_", "hit ") for e in ev)
    term = {
        "destination_reached": "done",
        "scenario_timeout": "timeout",
        "blocked_timeout": "blocked",
        "offroad_timeout": "off-road",
    }.get(row["termination"], row["termination"])
    return ", ".join([term] + [e.replace("collision_", "hit ") for e in ev])


def write_outputs(rows: list[dict[str, Any]], out: Path) -> dict[str, Any]:
    summary = summarize(rows)
    out.mkdir(parents=True, exist_ok=True)
    with (out / "probe.csv").open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({**r, "events": ";".join(r["events"])})
    (out / "probe_summary.json").write_text(
        json.dumps(summary, indent=2, sort_keys=True) + "\n", encoding="utf-8"
    )
    (out / "probe.md").write_text(markdown(rows, summary), encoding="utf-8")
    return summary


BEGIN, END = "<!-- probe:begin -->", "<!-- probe:end -->"


def update_doc(path: Path, table: str) -> None:
    """Replaces the generated part of a Markdown page (between the probe markers)."""
    text = path.read_text(encoding="utf-8")
    if text.count(BEGIN) != 1 or text.count(END) != 1 or text.index(BEGIN) > text.index(END):
        raise ConfigError(f"{path}: needs exactly one {BEGIN} … {END} block")
    head, rest = text.split(BEGIN)
    _, tail = rest.split(END)
    path.write_text(f"{head}{BEGIN}\n{table}{END}{tail}", encoding="utf-8")
