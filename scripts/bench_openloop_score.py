"""Speed of `score_run` on 14,000 and 76,798 synthetic predictions, beside a pure-Python
reference of the same scorers (tests/benchmark/openloop_reference.py, the test suite's oracle).
Both must give identical per-record scores, which also cross-checks the Rust parsers on varied
and odd replies.

Usage: python scripts/bench_openloop_score.py [--sizes 14000 76798] [--strict-time]
Targets (excluding the R1_4 judge): 14,000 ≤ 1 s, 76,798 ≤ 5 s.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

from drivehierarchy.benchmark.openloop.scoring import score_run

REPO = Path(__file__).resolve().parents[1]
# The pure-Python reference scorer is the test suite's differential oracle; the benchmark reuses it.
sys.path.insert(0, str(REPO / "tests" / "benchmark"))
from openloop_reference import build_run, ref_score_run  # noqa: E402

TARGETS = {14000: 1.0, 76798: 5.0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[14000, 76798])
    ap.add_argument("--strict-time", action="store_true", help="exit 1 when a time target is missed")
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 1,400 predictions, no time target")
    args = ap.parse_args()
    if args.quick:
        args.sizes, args.strict_time = [1400], False
    failed = False
    for n in args.sizes:
        with tempfile.TemporaryDirectory() as tmp:
            run = Path(tmp) / "run"
            build_run(run, n)
            best = math.inf
            for _ in range(3):
                t0 = time.perf_counter()
                result = score_run(run)
                best = min(best, time.perf_counter() - t0)
            t0 = time.perf_counter()
            ref = ref_score_run(run)
            t_ref = time.perf_counter() - t0
            ours = {}
            for line in (run / "evaluation" / "per_record.jsonl").read_text(encoding="utf-8").splitlines():
                o = json.loads(line)
                ours[(o["task"], o["id"])] = (o["score"], o["parsed"])
            mismatches = [(k, ours.get(k), v) for k, v in ref.items() if ours.get(k) != v]
            total = sum(1 for _ in run.glob("predictions/*.jsonl") for _ in _.open(encoding="utf-8"))
            target = TARGETS.get(n)
            verdict = ""
            if target is not None:
                verdict = f" (target ≤ {target:.0f} s: {'ok' if best <= target else 'MISSED'})"
            same = len(ref) - len(mismatches)
            print(
                f"{total:>6} predictions: score_run {best:.3f} s{verdict}; "
                f"pure-Python reference {t_ref:.3f} s ({t_ref / best:.1f}× slower); "
                f"rule-scored records {len(ref)}, identical: {same}; "
                f"overall mean {result['overall']['mean']:.4f}, parse_fail {result['overall']['parse_fail']}"
            )
            for k, a, b in mismatches[:10]:
                print(f"  MISMATCH {k}: rust {a} vs python {b}")
            if mismatches or (args.strict_time and target is not None and best > target):
                failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
