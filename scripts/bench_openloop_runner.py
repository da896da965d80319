#!/usr/bin/env python3
"""Runner throughput against the scripted loopback server.

Writes ~2,000 synthetic records (all 14 task schemas) with tiny images into a temporary folder,
serves them with a fixed scripted latency (100 ms by default, still far below a VLM's) and runs
`predict` once. Prints requests/s and the most requests the server saw in flight at once
(target: >= 32). With `--latency-ms 20` the loop is bound by the CPU of this one process (client
and server share it: ~850 requests/s on 2 cores), so fewer requests overlap.

    python scripts/bench_openloop_runner.py [--records 2000] [--latency-ms 100] [--concurrency 64]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from drivehierarchy.benchmark.openloop.catalog import default_catalog, load_dataset
from drivehierarchy.benchmark.openloop.runner import RunConfig, predict
from drivehierarchy.benchmark.openloop.synthetic import OraclePolicy, make_synthetic_records, write_images
from drivehierarchy.testing.openai_server import ScriptedOpenAIServer


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--records", type=int, default=2000, help="about this many records in total")
    ap.add_argument("--latency-ms", type=float, default=100.0)
    ap.add_argument("--concurrency", type=int, default=64)
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 70 records; no in-flight target")
    args = ap.parse_args()
    if args.quick:
        args.records, args.latency_ms, args.concurrency = 70, 20.0, 8

    per_task = max(1, round(args.records / 14))
    with tempfile.TemporaryDirectory(prefix="olrun-bench-") as tmp:
        root = Path(tmp)
        data = make_synthetic_records(root / "data", per_task, root / "images")
        cat = default_catalog(data)
        records = [r for spec in cat.datasets for r in load_dataset(cat, spec).records]
        write_images(records)
        policy = OraclePolicy(records)
        server = ScriptedOpenAIServer(policy, latency_s=args.latency_ms / 1000.0)
        with server as url:
            t0 = time.perf_counter()
            summary = predict(
                RunConfig(
                    base_url=url,
                    model="bench",
                    out=root / "run",
                    data_dir=data,
                    concurrency=args.concurrency,
                    progress=False,
                )
            )
            dt = time.perf_counter() - t0
        ok = summary.complete and policy.unmatched == 0
        n = summary.written
        print(f"records            {n} ({per_task} per task, {len(cat.datasets)} tasks)")
        print(f"scripted latency   {args.latency_ms:g} ms, concurrency {args.concurrency}")
        print(f"wall time          {dt:.2f} s")
        print(f"requests/s         {n / dt:.1f}")
        print(f"max in flight      {server.stats.max_in_flight} (target >= 32)")
        print(f"all answered right {ok}")
        # In a smoke run the overlap depends on the machine's load; only the answers must hold.
        overlap = args.quick or server.stats.max_in_flight >= min(32, args.concurrency)
        return 0 if ok and overlap else 1


if __name__ == "__main__":
    sys.exit(main())
