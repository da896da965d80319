"""Time of `openloop generate` on the R4 suite: 200 records per task (2,800 when all 14 task
builders are present), images included, with the default 2 rollout workers.

Usage: python scripts/bench_generate.py [--per-task 200] [--out DIR] [--strict-time]
Target (issue 18): ≤ 180 s on a 2-core machine.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

from drivehierarchy.benchmark.openloop.generate.quality import format_table
from drivehierarchy.benchmark.openloop.generate.writer import generate

REPO = Path(__file__).resolve().parents[1]
TARGET_S = 180.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-task", type=int, default=200)
    ap.add_argument("--suite", type=Path, default=REPO / "scenarios" / "r4")
    ap.add_argument("--out", type=Path, default=None, help="keep the set here (default: a temp folder)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--strict-time", action="store_true", help=f"exit 1 above {TARGET_S:.0f} s")
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 2 per task from one category")
    args = ap.parse_args()
    if args.quick:
        args.per_task, args.suite, args.jobs, args.strict_time = 2, args.suite / "02_obstacles", 1, False
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "generated"
        t0 = time.perf_counter()
        # Timing only: the quality table is printed, not enforced (the CLI enforces it).
        summary = generate(args.suite, out, per_task=args.per_task, jobs=args.jobs, strict=False)
        dt = time.perf_counter() - t0
    cpu = sum(
        getattr(resource.getrusage(who), f)
        for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
        for f in ("ru_utime", "ru_stime")
    )
    n = sum(t["records"] for t in summary["tasks"].values())
    for task, info in summary["tasks"].items():
        print(f"{task:8} {info['records']:5d}")
    print(format_table(summary["quality"]))
    moments = sum(e["moments"] for e in summary["episodes"])
    print(
        f"{n} records over {len(summary['tasks'])} tasks, {len(summary['episodes'])} rollouts, "
        f"{moments} moments, {summary['images']} images in {dt:.1f} s (target {TARGET_S:.0f} s); "
        f"{cpu:.1f} CPU-s over all processes (wall time on an idle machine ≈ CPU-s / jobs)"
    )
    return 1 if args.strict_time and dt > TARGET_S else 0


if __name__ == "__main__":
    sys.exit(main())
