"""Where a long run's memory growth comes from: RSS per episode with and without SUMO in-process.

    python scripts/sumo_retention.py [--episodes 600] [--traci]

Each variant runs in a fresh process over the suite's SUMO scenarios (images off, 40 decisions =
200 ticks per episode), and reports its RSS after glibc's malloc_trim once every scenario has run
(the warm-up), halfway and at the end, as KB per episode over the whole run and over its second
half (a leak keeps its slope there; a heap settling once does not), side by side:

  env, traffic "none"       drivehierarchy alone: no SUMO in the process
  env, SUMO (shim)          libsumo's C++ API in this process (the soak's and `auto`'s transport)
  env, SUMO (module)        SUMO's `libsumo` Python module in this process
  libsumo alone             SUMO's `libsumo` module replaying the env's exact start commands, then
                            200 `simulationStep()`s and `close()`: no drivehierarchy code runs
  libsumo, loads only       the same starts, then `close()` at once (no step)
  libsumo, networks only    `sumo --net-file NET` of the same scenarios, then `close()`: no routes,
                            no options of ours
  env, SUMO (TraCI)         SUMO in a subprocess (`--traci`)

What libsumo keeps per load shows up in every SUMO variant alike, stepped or not, with our
routes and options or the bare network; drivehierarchy's own growth is the first. Linux with
glibc (reads /proc, calls malloc_trim).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from soak import rss_mb, runs_sumo  # scripts/ is this script's first import path

from drivehierarchy._heap import release_free_heap
from drivehierarchy.scenarios import builtin_scenarios

DECISIONS = 40
TICKS = DECISIONS * 5
VARIANTS = {
    "none": 'env, traffic "none"',
    "shim": "env, SUMO (shim)",
    "module": "env, SUMO (module)",
    "alone": "libsumo alone",
    "loads": "libsumo, loads only",
    "nets": "libsumo, networks only",
    "traci": "env, SUMO (TraCI)",
}


def trimmed_rss() -> float:
    gc.collect()
    release_free_heap()
    return rss_mb()


def sumo_scenarios() -> list[Path]:
    return [p for p in builtin_scenarios() if runs_sumo(p)]


def env_episode(scenario: Path, variant: str) -> None:
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    kw: dict[str, Any] = {"front": None, "bev": None}
    if variant == "none":
        kw["traffic"] = "none"
    else:
        kw["sumo_backend"] = {"shim": "libsumo", "module": "libsumo-python", "traci": "traci"}[variant]
    env = DriveHierarchyR4Env(scenario=str(scenario), **kw)
    try:
        env.reset(seed=0)
        for _ in range(DECISIONS):
            _, _, terminated, truncated, _ = env.step([0.0, 6.0])
            if terminated or truncated:
                break
    finally:
        env.close()


def recorded_commands(scenarios: list[Path], keep: Path) -> list[list[str]]:
    """The libsumo start command of each scenario's env, with its temporary files kept in `keep`."""
    import libsumo

    cmds: list[list[str]] = []
    start = libsumo.start

    def record(cmd: list[str], *args: Any, **kwargs: Any) -> Any:
        cmd = list(cmd)
        for i, tok in enumerate(cmd):
            # The env's per-run folder is removed at close: its inputs are copied, outputs moved.
            if tok.startswith(tempfile.gettempdir()) and not tok.startswith(str(keep)):
                dest = keep / f"{len(cmds)}_{i}_{os.path.basename(tok)}"
                if os.path.isfile(tok):
                    shutil.copy(tok, dest)
                cmd[i] = str(dest)
        cmds.append(cmd)
        return start(cmd, *args, **kwargs)

    libsumo.start = record
    try:
        for s in scenarios:
            env_episode(s, "module")
    finally:
        libsumo.start = start
    return cmds


def run_variant(variant: str, episodes: int, limit: int = 0) -> dict[str, Any]:
    scenarios = sumo_scenarios()[:limit] if limit else sumo_scenarios()
    if variant in ("alone", "loads", "nets"):
        import libsumo

        keep = Path(tempfile.mkdtemp(prefix="dh_retention_"))
        cmds = recorded_commands(scenarios, keep)
        if variant == "nets":
            cmds = [[c[0], "--net-file", c[c.index("--net-file") + 1], "--no-warnings", "true"] for c in cmds]
        ticks = TICKS if variant == "alone" else 0

        def episode(i: int) -> None:
            libsumo.start(cmds[i % len(cmds)])
            for _ in range(ticks):
                libsumo.simulationStep()
            libsumo.close()

    else:

        def episode(i: int) -> None:
            env_episode(scenarios[i % len(scenarios)], variant)

    warm_up = len(scenarios)
    for i in range(warm_up):
        episode(i)
    warm = trimmed_rss()
    half = episodes // 2
    for i in range(warm_up, warm_up + half):
        episode(i)
    mid = trimmed_rss()
    for i in range(warm_up + half, warm_up + episodes):
        episode(i)
    end = trimmed_rss()
    if variant in ("alone", "loads", "nets"):
        shutil.rmtree(keep, ignore_errors=True)
    return {
        "variant": variant,
        "episodes": episodes,
        "warm_mb": round(warm, 1),
        "end_mb": round(end, 1),
        "kb_per_episode": round((end - warm) * 1024.0 / episodes, 2),
        # A one-time step (an allocator's heap settling) shows in the first half only; a leak
        # keeps its slope in the second.
        "mid_mb": round(mid, 1),
        "kb_per_episode_late": round((end - mid) * 1024.0 / max(1, episodes - half), 2),
        "growth_pct": round(100.0 * (end - warm) / warm, 2),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--episodes", type=int, default=600, help="episodes after the warm-up (600)")
    ap.add_argument("--traci", action="store_true", help="also SUMO over TraCI (SUMO as a subprocess)")
    ap.add_argument("--variant", choices=sorted(VARIANTS), help=argparse.SUPPRESS)  # one child's run
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 2 scenarios, 4 episodes each")
    a = ap.parse_args(argv)
    limit = 2 if a.quick else 0
    if a.quick:
        a.episodes = 4
    if a.variant:
        print(json.dumps(run_variant(a.variant, a.episodes, limit)), flush=True)
        return 0
    variants = ["none", "shim", "module", "alone", "loads", "nets"] + (["traci"] if a.traci else [])
    n = min(len(sumo_scenarios()), limit or len(sumo_scenarios()))
    print(f"{a.episodes} episodes over {n} SUMO scenarios, {TICKS} ticks each, after a warm-up pass")
    print(f"{'':28} {'RSS warm':>9} {'RSS end':>9} {'KB/episode':>11} {'2nd half':>9} {'growth':>8}")
    for v in variants:
        done = subprocess.run(
            [sys.executable, __file__, "--variant", v, "--episodes", str(a.episodes)]
            + (["--quick"] if a.quick else []),
            capture_output=True,
            text=True,
            check=False,
        )
        if done.returncode != 0:
            print(f"{VARIANTS[v]}: failed (exit {done.returncode})\n{done.stderr[-2000:]}", file=sys.stderr)
            return 1
        r = json.loads(done.stdout.strip().splitlines()[-1])
        print(
            f"{VARIANTS[v]:28} {r['warm_mb']:8.1f}M {r['end_mb']:8.1f}M {r['kb_per_episode']:11.2f}"
            f" {r['kb_per_episode_late']:9.2f} {r['growth_pct']:7.2f}%",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
