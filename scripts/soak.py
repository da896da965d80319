"""Soak: many episodes in one process, images on, looking for leaks and nondeterminism.

    python scripts/soak.py --episodes 10000 --out runs/soak

Mixes the SUMO scenarios of the suite on the SUMO transports of `--backends` (by default libsumo
in this process, through the shim and through the Python module; `traci` runs SUMO as a
subprocess), the expert and every bad driver of `drivehierarchy.testing.bad_agents`, driven in
this process; and a share (`--vlm-share`, 10 %) through `r4 evaluate` with the VLM agent
(`--jobs 4`) against the loopback scripted server, which answers 20 % of requests badly (prose,
empty, non-numbers, out of range, JSON), chosen by a hash of the request so a repeat gets the
same replies. Every task recurs, so repeats of the same (scenario, seed, agent) are compared.

Reports (and writes OUT/soak.json): RSS after the warm-up round and at the end (growth %; each
also after glibc's malloc_trim, which a leak survives and allocator retention does not), the
SUMO processes, child processes, threads and file descriptors left over, and the repeats that
scored differently. Must hold: RSS growth < 5 % (after malloc_trim at both points, where glibc
has it), nothing left over, identical repeats; the exit status is 1 otherwise. Linux (reads
/proc).
"""

from __future__ import annotations

import argparse
import gc
import hashlib
import json
import math
import multiprocessing as mp
import os
import shutil
import sys
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

from drivehierarchy._heap import release_free_heap
from drivehierarchy.agents.vlm import VLMOptions
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.scenarios import builtin_scenarios, scenario_id
from drivehierarchy.testing.bad_agents import KINDS, comparable_record, fuzz_episode
from drivehierarchy.testing.openai_server import ChatRequest, ScriptedOpenAIServer, route_driver
from drivehierarchy.testing.procs import descendants

AGENTS = ("expert", *KINDS)
BAD_REPLIES = (
    "I am not sure what to do here.",
    "",
    "steer: nan\ntarget_speed_mps: inf",
    "steer: 7\ntarget_speed_mps: -3",
    '```json\n{"steer": 0.1, "target_speed_mps": 8}\n```',
)


def bad_20_percent(req: ChatRequest) -> str:
    """The route driver, but a fifth of the requests (by a hash of their text, which names the
    frame, so the same request always gets the same answer) get a bad reply instead."""
    digest = hashlib.sha256(req.user_text.encode("utf-8", "surrogatepass")).digest()
    if digest[0] % 5 == 0:
        return BAD_REPLIES[digest[1] % len(BAD_REPLIES)]
    return route_driver(req)


def serve(urls: Any, stop: Any) -> None:
    """The scripted server's process: publishes its URL, serves until `stop` is set."""
    server = ScriptedOpenAIServer(bad_20_percent)
    urls.put(server.start())
    stop.wait()
    print(f"server: {server.stats.chat_requests} requests", file=sys.stderr, flush=True)
    server.stop()


def runs_sumo(path: Path) -> bool:
    return tomllib.loads(path.read_text(encoding="utf-8")).get("traffic", {}).get("mode") == "sumo"


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS in /proc/self/status")


# The soak's own helper processes (its server, multiprocessing's resource tracker): not leaks.
OWN_PIDS: set[int] = set()


def resources(trim: bool = False) -> dict[str, Any]:
    """RSS (as the process holds it) and what is left over. With `trim`, also the RSS after
    glibc's malloc_trim has returned the free heap pages: a leak survives that, allocator
    retention does not. Only the warm-up and final figures trim, so the rounds between see the
    process exactly as a user's run would."""
    gc.collect()
    kids = [(pid, name) for pid, name in descendants() if pid not in OWN_PIDS]
    out: dict[str, Any] = {
        "rss_mb": round(rss_mb(), 1),
        "py_blocks": sys.getallocatedblocks(),
        "gc_objects": len(gc.get_objects()),
        "threads": len(os.listdir("/proc/self/task")),
        "python_threads": threading.active_count(),
        "fds": len(os.listdir("/proc/self/fd")),
        "children": len(kids),
        "sumo_processes": sum("sumo" in n.lower() for _, n in kids),
    }
    if trim and release_free_heap():
        out["rss_trimmed_mb"] = round(rss_mb(), 1)
    return out


class Soak:
    def __init__(self, out: Path, jobs: int, backends: tuple[str, ...], log: Any) -> None:
        self.out = out
        self.backends = list(backends)
        self.jobs = jobs
        self.log = log
        self.first: dict[tuple[str, ...], str] = {}  # task → sha256 of its first record
        self.repeats = 0
        self.mismatches: list[str] = []
        self.errors: list[str] = []
        self.episodes = {"direct": 0, "evaluate": 0}
        self.terminations: dict[str, int] = {}
        self.rss_by_round: list[float] = []

    def _same_as_before(self, key: tuple[str, ...], record: str) -> None:
        record = hashlib.sha256(record.encode()).hexdigest()
        if key in self.first:
            self.repeats += 1
            if self.first[key] != record:
                self.mismatches.append(" ".join(key))
        else:
            self.first[key] = record

    def direct(self, scenario: Path, agent: str, backend: str) -> None:
        if agent == "expert":
            row = expert_episode(str(scenario), backend)
        else:
            row = fuzz_episode(str(scenario), agent, 0, backend, images=True)
        self.episodes["direct"] += 1
        key = (scenario_id(scenario), "seed0", agent, backend)
        if row["error"]:
            self.errors.append(f"{' '.join(key)}: {row['error']}")
            return
        if not row["rescore_equal"]:
            self.errors.append(f"{' '.join(key)}: re-scoring the log differs")
        self.terminations[row["termination"]] = self.terminations.get(row["termination"], 0) + 1
        self._same_as_before(key, row["record"])

    def evaluate(self, scenarios: list[Path], url: str, batch: int) -> None:
        out = self.out / f"evaluate_{batch:04d}"
        opts = runner.RunOptions(
            agent="vlm",
            jobs=self.jobs,
            vlm=VLMOptions(base_url=url, model="test-model", backoff_s=0.001, timeout_s=30.0),
        )
        try:
            results = runner.evaluate(scenarios, out, opts, log=lambda _: None)
        except Exception as exc:  # reported: the soak goes on
            self.errors.append(f"evaluate batch {batch}: {type(exc).__name__}: {exc}")
            return
        finally:
            shutil.rmtree(out, ignore_errors=True)
        for r in results:
            self.episodes["evaluate"] += 1
            rec = r["score"]
            self.terminations[rec["termination_reason"]] = (
                self.terminations.get(rec["termination_reason"], 0) + 1
            )
            self._same_as_before((r["key"], f"seed{r['seed']}", "vlm"), comparable_record(rec))


def expert_episode(scenario: str, backend: str) -> dict[str, Any]:
    """The expert, images on, with the same checks as a bad driver's episode."""
    from drivehierarchy import _core
    from drivehierarchy.agents.base import run_episode
    from drivehierarchy.agents.expert import ExpertAgent
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    env = DriveHierarchyR4Env(scenario=scenario, sumo_backend=backend)
    try:
        rec = run_episode(env, ExpertAgent(), seed=0).score
        again = _core.rescore(env.sim.episode_log())
        return {
            "error": None,
            "termination": rec["termination_reason"],
            "rescore_equal": comparable_record(again) == comparable_record(rec),
            "record": comparable_record(rec),
        }
    except Exception as exc:
        return {"error": f"{type(exc).__name__}: {exc}"}
    finally:
        env.close()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=10_000, help="total episodes (default 10000)")
    ap.add_argument("--vlm-share", type=float, default=0.1, help="share through `r4 evaluate` (0.1)")
    ap.add_argument("--round", type=int, default=200, help="episodes per round (the first warms up)")
    ap.add_argument("--jobs", type=int, default=4, help="`r4 evaluate --jobs` (4)")
    ap.add_argument("--distinct", type=int, default=300, help="distinct in-process tasks, cycled (300)")
    ap.add_argument(
        "--backends",
        default="libsumo,libsumo-python",
        help="SUMO transports of the in-process episodes, comma-separated "
        "(libsumo,libsumo-python; also traci)",
    )
    ap.add_argument("--out", type=Path, default=Path("runs/soak"))
    ap.add_argument(
        "--quick",
        action="store_true",
        help="smoke run (CI): 8 episodes over 3 tasks and one VLM scenario; no verdict on memory",
    )
    a = ap.parse_args(argv)
    if a.quick:
        a.episodes, a.round, a.vlm_share, a.distinct, a.jobs = 8, 4, 0.25, 3, 1
    backends = tuple(b.strip() for b in a.backends.split(",") if b.strip())
    for b in backends:
        if b not in ("libsumo", "libsumo-python", "traci"):
            ap.error(f"--backends: {b!r} is not one of libsumo, libsumo-python, traci")
    if not backends:
        ap.error("--backends: name at least one of libsumo, libsumo-python, traci")
    a.out.mkdir(parents=True, exist_ok=True)
    log_file = (a.out / "soak.log").open("a", encoding="utf-8")

    def log(msg: str) -> None:
        line = f"{time.strftime('%H:%M:%S')} {msg}"
        print(line, file=sys.stderr, flush=True)
        log_file.write(line + "\n")
        log_file.flush()

    sumo = [p for p in builtin_scenarios() if runs_sumo(p)]
    direct_tasks = [(p, agent, b) for p in sumo for agent in AGENTS for b in backends]
    # Spread the agents over the scenarios so every round mixes them.
    direct_tasks.sort(key=lambda t: hashlib.sha256(f"{scenario_id(t[0])} {t[1]} {t[2]}".encode()).hexdigest())
    # A subset, cycled, so that every task recurs and its repeats are compared.
    direct_tasks = direct_tasks[: a.distinct]
    # VLM batches run the whole suite (SUMO scenarios in worker processes, the rest in threads).
    vlm_scenarios = builtin_scenarios()[:1] if a.quick else builtin_scenarios()
    vlm_per_round = max(1, round(a.round * a.vlm_share))
    direct_per_round = a.round - vlm_per_round

    soak = Soak(a.out, a.jobs, backends, log)
    # A few episodes say nothing about memory growth: a smoke run checks everything else.
    growth_limit = math.inf if a.quick else 5.0
    # The server runs in its own process: its request bookkeeping is not the harness's memory.
    ctx = mp.get_context("spawn")
    urls: Any = ctx.Queue()
    stop = ctx.Event()
    server = ctx.Process(target=serve, args=(urls, stop), name="soak-openai-server")
    server.start()
    url = urls.get(timeout=120)
    from multiprocessing import resource_tracker

    OWN_PIDS.update(p for p in (server.pid, getattr(resource_tracker._resource_tracker, "_pid", None)) if p)
    t0 = time.perf_counter()
    warm: dict[str, Any] | None = None
    rounds = max(1, -(-a.episodes // a.round))
    # The RSS baseline is taken once every task has run once (maps and nets loaded, caches warm):
    # every later episode repeats one.
    first_pass = max(
        -(-len(direct_tasks) // max(1, direct_per_round)), -(-len(vlm_scenarios) // vlm_per_round)
    )
    warm_round = min(rounds, first_pass) - 1
    d = v = 0
    try:
        for rnd in range(rounds):
            for _ in range(direct_per_round):
                p, agent, backend = direct_tasks[d % len(direct_tasks)]
                soak.direct(p, agent, backend)
                d += 1
            batch = [vlm_scenarios[(v + i) % len(vlm_scenarios)] for i in range(vlm_per_round)]
            soak.evaluate(batch, url, rnd)
            v += vlm_per_round
            now = resources(trim=rnd == warm_round)
            soak.rss_by_round.append(now["rss_mb"])
            if rnd == warm_round:
                warm = now
            if warm is not None:
                write_report(a.out, soak, warm, t0, finished=False, growth_limit=growth_limit)
            total = sum(soak.episodes.values())
            phase = " (warm-up)" if warm is None else ""
            log(
                f"round {rnd + 1}/{rounds}{phase}: {total} episodes "
                f"({soak.episodes['evaluate']} via r4 evaluate) "
                f"in {time.perf_counter() - t0:.0f} s; {now}; repeats {soak.repeats}, "
                f"mismatches {len(soak.mismatches)}, errors {len(soak.errors)}"
            )
    finally:
        stop.set()
        server.join(timeout=30)
        urls.close()
        urls.join_thread()
    assert warm is not None
    report, ok = write_report(a.out, soak, warm, t0, finished=True, growth_limit=growth_limit)
    log(json.dumps(report, indent=2))
    log("PASS" if ok else "FAIL")
    return 0 if ok else 1


def write_report(
    out: Path, soak: Soak, warm: dict[str, Any], t0: float, finished: bool, growth_limit: float = 5.0
) -> tuple[dict[str, Any], bool]:
    """OUT/soak.json (rewritten after every round, so a stopped soak still has its figures)."""
    end = resources(trim=finished)
    raw_growth = 100.0 * (end["rss_mb"] - warm["rss_mb"]) / warm["rss_mb"]
    # The must-hold compares what the process holds: RSS after malloc_trim at both points. A
    # single raw sample moves within the allocator's band (±15 MB between rounds, see
    # `rss_by_round_mb`); a leak survives the trim. Without glibc, the raw figures.
    if "rss_trimmed_mb" in warm and "rss_trimmed_mb" in end:
        growth = 100.0 * (end["rss_trimmed_mb"] - warm["rss_trimmed_mb"]) / warm["rss_trimmed_mb"]
    else:
        growth = raw_growth
    report = {
        "finished": finished,
        "episodes": soak.episodes,
        "backends": soak.backends,
        "wall_s": round(time.perf_counter() - t0, 1),
        "warm": warm,
        "end": end,
        "rss_growth_pct": round(growth, 2),
        "rss_raw_growth_pct": round(raw_growth, 2),
        "rss_by_round_mb": soak.rss_by_round,
        "left_over": {
            "children": end["children"],
            "sumo_processes": end["sumo_processes"],
            "threads": end["threads"] - warm["threads"],
            "fds": end["fds"] - warm["fds"],
        },
        "repeats": soak.repeats,
        "mismatched_repeats": soak.mismatches,
        "errors": soak.errors,
        "terminations": dict(sorted(soak.terminations.items())),
    }
    (out / "soak.json").write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    ok = (
        growth < growth_limit
        and end["children"] == 0
        and end["sumo_processes"] == 0
        and end["threads"] <= warm["threads"]
        and end["fds"] <= warm["fds"]
        and not soak.mismatches
        and not soak.errors
    )
    return report, ok


if __name__ == "__main__":
    sys.exit(main())
