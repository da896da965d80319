"""Closed-loop VLM harness speed, side by side in one run.

1. Overhead per decision: simulator step (world + front camera + BEV + prompt) plus building the
   request (two JPEG data URLs, the message, the JSON body the SDK sends), against the 200 ms a
   served model typically takes per decision. Target: ≤ 5 %.
2. Concurrency: `r4 evaluate --agent vlm` over the built-in suite × `--seeds` against the loopback
   test server (a separate process, scripted route driver, 200 ms per request) with `--jobs 1` and
   `--jobs 16`. Target: ≥ 10× faster with 16 jobs. The suite's scenarios with SUMO traffic run in
   worker processes with 16 jobs (in the harness's process with 1). Also printed: the bound the
   scenarios' lengths allow (all decisions one after another / the longest-first schedule of the
   same decisions on 16 slots, i.e. zero harness and server CPU) and the machine's load average,
   since on a loaded machine the harness and the server compete for CPU.

    python scripts/bench_vlm_harness.py [--latency-ms 200] [--seeds 1] [--jobs 16] [--skip-serial]

On the 100-scenario suite the `--jobs 1` run takes about 45 minutes (≈ 13,000 expert-paced
decisions at 200 ms); `--skip-serial` prints the overhead and the `--jobs` run only.
"""

from __future__ import annotations

import argparse
import heapq
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def overhead_per_decision(decisions: int = 200) -> dict[str, float]:
    from drivehierarchy.agents.vlm.payload import build_messages
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env
    from drivehierarchy.testing.openai_server import parse_chat_request, route_driver

    env = DriveHierarchyR4Env(scenario="03_turning/town01_03_right_turn_signalised")
    obs, _ = env.reset(seed=0)
    step_s, build_s, n = 0.0, 0.0, 0
    while n < decisions:
        t0 = time.perf_counter()
        messages = build_messages(obs, n + 1)
        body = json.dumps({"model": "m", "messages": messages, "temperature": 0.0, "max_tokens": 256})
        t1 = time.perf_counter()
        # The reply is computed here, outside the timed sections (the server's work).
        reply = route_driver(parse_chat_request({"messages": messages}))
        t2 = time.perf_counter()
        obs, _, terminated, truncated, _ = env.step(reply)
        t3 = time.perf_counter()
        build_s += t1 - t0
        step_s += t3 - t2
        n += 1
        assert len(body) > 10_000
        if terminated or truncated:
            obs, _ = env.reset(seed=n)
    return {"step_ms": 1e3 * step_s / n, "build_ms": 1e3 * build_s / n, "decisions": n}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_suite(base_url: str, jobs: int, seeds: int, out: Path, limit: int = 0) -> tuple[float, dict]:
    from drivehierarchy.agents.vlm import VLMOptions
    from drivehierarchy.benchmark.r4 import runner

    opts = runner.RunOptions(
        agent="vlm", vlm=VLMOptions(base_url=base_url, model="test-model"), jobs=jobs, seeds=seeds
    )
    t0 = time.perf_counter()
    scenarios = runner.suite_scenarios("builtin")
    results = runner.evaluate(scenarios[:limit] if limit else scenarios, out, opts, log=lambda _: None)
    wall = time.perf_counter() - t0
    summary = json.loads((out / "summary.json").read_text())
    summary["per_scenario_decisions"] = [r["vlm"]["decisions"] for r in results]
    summary["sumo_scenarios"] = sum(runner.uses_sumo(Path(r["scenario"]), opts.config) for r in results)
    return wall, summary


def longest_first_makespan(lengths: list[int], slots: int) -> int:
    """Decisions on the busiest of `slots` lanes when scenarios start longest first."""
    lanes = [0] * slots
    for n in sorted(lengths, reverse=True):
        heapq.heappush(lanes, heapq.heappop(lanes) + n)
    return max(lanes)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--latency-ms", type=float, default=200.0)
    ap.add_argument(
        "--seeds", type=int, default=1, help="suite repeats (default 1: 100 scenarios keep 16 jobs busy)"
    )
    ap.add_argument("--jobs", type=int, default=16)
    ap.add_argument("--skip-serial", action="store_true", help="only the overhead and the --jobs run")
    ap.add_argument(
        "--quick", action="store_true", help="smoke run (CI): 10 decisions, 2 scenarios, 2 jobs, 20 ms"
    )
    args = ap.parse_args()
    if args.quick:
        args.latency_ms, args.jobs = 20.0, 2

    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the start")
    o = overhead_per_decision(10 if args.quick else 200)
    total = o["step_ms"] + o["build_ms"]
    print(f"overhead per decision over {o['decisions']} decisions:")
    print(f"  simulator step          {o['step_ms']:7.2f} ms")
    print(f"  request building        {o['build_ms']:7.2f} ms")
    print(
        f"  total                   {total:7.2f} ms = {100 * total / args.latency_ms:.1f} % of a "
        f"{args.latency_ms:.0f} ms server latency (target ≤ 5 %)"
    )

    port = _free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "drivehierarchy.testing.openai_server", "--port", str(port), "--driver",
         "--latency-ms", str(args.latency_ms)],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert server.stderr is not None
        server.stderr.readline()  # "serving ..." once it listens
        url = f"http://127.0.0.1:{port}/v1"
        with tempfile.TemporaryDirectory() as tmp:
            limit = 2 if args.quick else 0
            fast, s_fast = run_suite(url, args.jobs, args.seeds, Path(tmp) / "parallel", limit)
            n = s_fast["scenarios"]
            print(f"\nsuite × {args.seeds} seeds = {n} scenarios ({s_fast['sumo_scenarios']} with SUMO "
                  f"traffic), {s_fast['decisions']} decisions, "
                  f"{args.latency_ms:.0f} ms per request:")  # fmt: skip
            print(f"  --jobs {args.jobs:<3}  {fast:8.1f} s   R4 {s_fast['r4_score']:.3f}")
            if not args.skip_serial:
                slow, s_slow = run_suite(url, 1, args.seeds, Path(tmp) / "serial", limit)
                print(f"  --jobs 1    {slow:8.1f} s   R4 {s_slow['r4_score']:.3f}")
                print(f"  speed-up    {slow / fast:8.1f} ×  (target ≥ 10 ×)")
                per = 1e3 * slow / s_slow["decisions"] - args.latency_ms
                print(
                    f"  --jobs 1 end to end: {per:.1f} ms per decision beyond the server's latency "
                    f"({100 * per / args.latency_ms:.1f} %; includes HTTP, the SDK, the server's own "
                    "parsing and the run's files)"
                )
                lengths = s_slow["per_scenario_decisions"]
                bound = sum(lengths) / longest_first_makespan(lengths, args.jobs)
                print(f"  bound from the scenarios' lengths: {bound:.1f} × (no CPU cost at all)")
                load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
                print(f"  load average (1, 5, 15 min) at the end: {load}")
                same = np.isclose(s_fast["r4_score"], s_slow["r4_score"])
                print(f"  same summary with 1 and {args.jobs} jobs: {bool(same)}")
    finally:
        server.terminate()
        server.wait(timeout=10)
    return 0


if __name__ == "__main__":
    sys.exit(main())
