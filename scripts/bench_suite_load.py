"""Load + reset time of every suite scenario, without and with SUMO, beside highway-env.

    python scripts/bench_suite_load.py [FOLDER_OR_FILE ...] [--repeat 5] [--no-sumo] [--jobs 1]

Default: the built-in suite (`scenarios/r4`). The issue's budget: loading any suite scenario and
resetting it takes ≤ 50 ms without SUMO and ≤ 300 ms with SUMO start.

Per scenario, each measurement series runs in a fresh spawned process (nothing loaded, no map
cached), `import drivehierarchy` (and `import libsumo` for the SUMO series) done before the clock
starts — those are once-per-process costs and printed on their own:

* no SUMO: `DriveHierarchyR4Env(scenario, front=None, bev=None, prompt=False, traffic="none")`
  + `reset()`; cold = the first one in the process (the map is parsed), warm = the median of
  `--repeat` more (map cached). The cold surplus is split into the map's parse (timed on a fresh
  copy of the net in the warm process) and the first env's other set-up (init).
* SUMO (scenarios whose `[traffic]` runs SUMO): the same with the scenario's traffic; every
  reset starts SUMO afresh (libsumo) and runs the warm-up. The SUMO time is split into
  `libsumo.start` (SUMO loading the net and the routes), the warm-up's steps and moves, and the
  rest (our map, demand, subscriptions).

Printed: one line per scenario, max / p50 per scenario class (map × traffic mode), the budget
ratios (measured / budget; > 1 is over), and highway-env's `highway-v0` `gym.make` + `reset()`
(cold in a fresh process, and warm) with the side-by-side ratios, when highway-env is installed.
Wall-clock times; the machine may be shared, so run it on an idle machine for absolute numbers.
"""

from __future__ import annotations

import argparse
import functools
import json
import multiprocessing as mp
import re
import shutil
import statistics
import sys
import tempfile
import time
import warnings
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import tomllib

BUDGET_NO_SUMO_MS = 50.0
BUDGET_SUMO_MS = 300.0


# -- workers (each call runs in a fresh process) -----------------------------------------------
def _time_reset(scenario: str, traffic: str, after: Any = None) -> tuple[float, float]:
    """(construct ms, reset ms) of one env; `after()` runs before it is closed (untimed)."""
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    t0 = time.perf_counter()
    env = DriveHierarchyR4Env(scenario, front=None, bev=None, prompt=False, traffic=traffic)
    t1 = time.perf_counter()
    try:
        env.reset(seed=0)
        t2 = time.perf_counter()
        if after is not None:
            after()
    finally:
        env.close()
    return (t1 - t0) * 1e3, (t2 - t1) * 1e3


def _fresh_copy(scenario: str, tmp: Path) -> str:
    """The scenario with its map copied to `tmp`: a path the process's map cache has not seen,
    so constructing it times the map's parse alone (the process is already initialised)."""
    from drivehierarchy.scenarios import sumo_home

    src = Path(scenario).resolve()
    text = src.read_text(encoding="utf-8")
    ref = str(tomllib.loads(text)["map"])
    net = Path(str(sumo_home())) / ref.removeprefix("sumo:") if ref.startswith("sumo:") else src.parent / ref
    copy = tmp / net.name
    shutil.copyfile(net, copy)
    text = re.sub(r'(?m)^map\s*=\s*"[^"]*"', f"map = {json.dumps(str(copy))}", text)
    # Other files the scenario names stay where they are.
    text = re.sub(
        r'(?m)^vtypes\s*=\s*"([^"]*)"', lambda m: f"vtypes = {json.dumps(str(src.parent / m[1]))}", text
    )
    out = tmp / src.name
    out.write_text(text, encoding="utf-8")
    return str(out)


def worker_no_sumo(scenario: str, repeat: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    import drivehierarchy.envs.r4  # noqa: F401

    imp = (time.perf_counter() - t0) * 1e3
    cold = _time_reset(scenario, "none")
    warm = [_time_reset(scenario, "none") for _ in range(repeat)]
    warm_construct = statistics.median(w[0] for w in warm)
    parses = []
    for _ in range(3):  # median of three fresh copies: a single parse is noisy on a busy machine
        with tempfile.TemporaryDirectory() as tmp:
            parses.append(_time_reset(_fresh_copy(scenario, Path(tmp)), "none")[0] - warm_construct)
    parse = statistics.median(parses)
    return {
        "import_ms": imp,
        "cold_ms": sum(cold),
        "cold_construct_ms": cold[0],
        "warm_ms": statistics.median(sum(w) for w in warm),
        "warm_construct_ms": warm_construct,
        "parse_ms": parse,
        # The first env of a process pays more than the map (construct or first reset): set-up on
        # first use in Python and Rust.
        "init_ms": sum(cold) - statistics.median(sum(w) for w in warm) - parse,
    }


class _Clock:
    """Accumulates the wall time of wrapped libsumo calls."""

    def __init__(self) -> None:
        self.spent: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)

    def wrap(self, owner: Any, attr: str, key: str) -> None:
        fn = getattr(owner, attr)

        def timed(*a: Any, **k: Any) -> Any:
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.spent[key] += time.perf_counter() - t
                self.calls[key] += 1

        setattr(owner, attr, timed)

    def take(self) -> dict[str, float]:
        out = {k: v * 1e3 for k, v in self.spent.items()}
        self.spent.clear()
        self.calls.clear()
        return out


def _collect(clock: _Clock, into: dict[str, float]) -> None:
    into.update(clock.take())


def worker_sumo(scenario: str, repeat: int) -> dict[str, Any]:
    t0 = time.perf_counter()
    import drivehierarchy.envs.r4  # noqa: F401

    t1 = time.perf_counter()
    import libsumo

    t2 = time.perf_counter()
    clock = _Clock()
    clock.wrap(libsumo, "start", "start")
    clock.wrap(libsumo, "simulationStep", "step")
    clock.wrap(libsumo.vehicle, "moveToXY", "move")
    runs = []
    for _ in range(1 + repeat):
        parts: dict[str, float] = {}
        clock.take()
        construct, reset = _time_reset(scenario, "sumo", after=functools.partial(_collect, clock, parts))
        total = construct + reset
        start, warmup = parts.get("start", 0.0), parts.get("step", 0.0) + parts.get("move", 0.0)
        runs.append({"total": total, "start": start, "warmup": warmup, "other": total - start - warmup})
    cold, warm = runs[0], runs[1:]

    def med(key: str) -> float:
        return statistics.median(r[key] for r in warm)

    return {
        "import_ms": (t1 - t0) * 1e3,
        "import_libsumo_ms": (t2 - t1) * 1e3,
        "cold_ms": cold["total"],
        "cold_parts": (cold["start"], cold["warmup"], cold["other"]),
        "warm_ms": med("total"),
        "start_ms": med("start"),
        "warmup_ms": med("warmup"),
        "other_ms": med("other"),
    }


def worker_highway(repeat: int) -> dict[str, Any] | None:
    try:
        t0 = time.perf_counter()
        import gymnasium as gym
        import highway_env  # noqa: F401
    except ImportError:
        return None
    imp = (time.perf_counter() - t0) * 1e3
    times = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(1 + repeat):
            t = time.perf_counter()
            env = gym.make("highway-v0")
            env.reset(seed=0)
            times.append((time.perf_counter() - t) * 1e3)
            env.close()
    return {"import_ms": imp, "cold_ms": times[0], "warm_ms": statistics.median(times[1:])}


# -- driver --------------------------------------------------------------------------------------
def scenario_files(targets: list[str]) -> list[Path]:
    out: list[Path] = []
    for t in targets:
        p = Path(t)
        if p.is_dir():
            out += sorted(p.glob("*/*.toml")) + sorted(p.glob("*.toml"))
        elif p.is_file():
            out.append(p)
        else:
            raise SystemExit(f"{t}: no such scenario file or folder")
    if not out:
        raise SystemExit(f"no scenario files under {', '.join(targets)}")
    return out


def describe(path: Path) -> tuple[str, str]:
    """(map name, the scenario's own traffic mode) from the file, for grouping."""
    doc = tomllib.loads(path.read_text(encoding="utf-8"))
    ref = str(doc["map"])
    name = Path(ref.removeprefix("sumo:")).name.removesuffix(".gz").removesuffix(".net.xml")
    if ref.startswith("sumo:"):
        name = f"sumo:{Path(ref.removeprefix('sumo:')).parent.name}/{name}"
    traffic = doc.get("traffic")
    mode = "none" if traffic is None else str(traffic.get("mode", "sumo"))
    return name, mode


def fmt(v: float | None) -> str:
    return "–" if v is None else f"{v:7.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("targets", nargs="*", help="scenario files or folders (default: the built-in suite)")
    ap.add_argument("--repeat", type=int, default=5, help="warm repetitions per scenario")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes at once (1 = cleanest timing)")
    ap.add_argument("--no-sumo", action="store_true", help="skip the SUMO series")
    args = ap.parse_args()

    from drivehierarchy.scenarios import builtin_root

    files = scenario_files(args.targets or [str(builtin_root() / "r4")])
    info = {f: describe(f) for f in files}
    ctx = mp.get_context("spawn")
    # One task per process: every series starts process-cold.
    with ProcessPoolExecutor(max_workers=max(1, args.jobs), mp_context=ctx, max_tasks_per_child=1) as pool:
        peer_f = pool.submit(worker_highway, args.repeat)
        plain = {f: pool.submit(worker_no_sumo, str(f), args.repeat) for f in files}
        sumo = {}
        if not args.no_sumo:
            sumo = {f: pool.submit(worker_sumo, str(f), args.repeat) for f in files if info[f][1] == "sumo"}
        failed: dict[Path, str] = {}

        def collect(futures: dict[Path, Any], what: str) -> dict[Path, dict[str, Any]]:
            out = {}
            for f, fu in futures.items():
                try:
                    out[f] = fu.result()
                except Exception as exc:  # a scenario that does not load is reported, not timed
                    failed[f] = f"{what}: {type(exc).__name__}: {exc}"
            return out

        res_plain = collect(plain, "no SUMO")
        res_sumo = collect(sumo, "SUMO")
        peer = peer_f.result()
    if failed:
        print("could not time (left out below):", file=sys.stderr)
        for f, msg in failed.items():
            print(f"  {f}: {msg}", file=sys.stderr)
        files = [f for f in files if f in res_plain]
        res_sumo = {f: r for f, r in res_sumo.items() if f in res_plain}
        if not files:
            raise SystemExit("no scenario could be timed")

    root = files[0].parent.parent if len(files) > 1 else files[0].parent
    print(f"{len(files)} scenarios under {root}; times in ms (wall), warm = median of {args.repeat}\n")
    head = (
        f"{'scenario':52s} {'map':24s} {'cold':>7s} {'warm':>7s} {'parse':>7s} {'init':>7s} │ "
        f"{'S cold':>7s} {'S warm':>7s} {'start':>7s} {'warmup':>7s} {'other':>7s}"
    )
    print(
        "no SUMO: construct + reset (traffic='none'); parse = the map alone (a fresh copy in a warm "
        "process), init = the rest of the first env's extra time │ S = with the scenario's SUMO "
        "traffic: start = libsumo.start, warmup = the warm-up's steps and moves (warm medians)"
    )
    print(head)
    print("─" * len(head))
    for f in files:
        p, s = res_plain[f], res_sumo.get(f)
        name = f"{f.parent.name}/{f.stem}"[:52]
        row = (
            f"{name:52s} {info[f][0][:24]:24s} {fmt(p['cold_ms'])} {fmt(p['warm_ms'])} "
            f"{fmt(p['parse_ms'])} {fmt(p['init_ms'])} │ "
        )
        if s is None:
            row += " " * 7 + "      –"
        else:
            row += (
                f"{fmt(s['cold_ms'])} {fmt(s['warm_ms'])} {fmt(s['start_ms'])} "
                f"{fmt(s['warmup_ms'])} {fmt(s['other_ms'])}"
            )
        print(row)

    # Per class: map × the scenario's traffic mode.
    classes: dict[tuple[str, str], list[Path]] = defaultdict(list)
    for f in files:
        classes[info[f]].append(f)
    print()
    head = (
        f"{'class (map · traffic)':40s} {'n':>3s} │ {'cold max':>8s} {'cold p50':>8s} {'warm max':>8s} "
        f"{'warm p50':>8s} │ {'S cold max':>10s} {'S cold p50':>10s} {'S warm max':>10s} {'S warm p50':>10s}"
    )
    print(head)
    print("─" * len(head))
    for (m, mode), fs in sorted(classes.items()):
        cold = [res_plain[f]["cold_ms"] for f in fs]
        warm = [res_plain[f]["warm_ms"] for f in fs]
        row = (
            f"{m + ' · ' + mode:40s} {len(fs):3d} │ {max(cold):8.1f} {statistics.median(cold):8.1f} "
            f"{max(warm):8.1f} {statistics.median(warm):8.1f} │ "
        )
        sc = [res_sumo[f]["cold_ms"] for f in fs if f in res_sumo]
        sw = [res_sumo[f]["warm_ms"] for f in fs if f in res_sumo]
        if sc:
            row += (
                f"{max(sc):10.1f} {statistics.median(sc):10.1f} {max(sw):10.1f} {statistics.median(sw):10.1f}"
            )
        else:
            row += f"{'–':>10s} {'–':>10s} {'–':>10s} {'–':>10s}"
        print(row)

    print()
    imports = [r["import_ms"] for r in res_plain.values()]
    print(f"once per process: import drivehierarchy p50 {statistics.median(imports):.0f} ms", end="")
    if res_sumo:
        libs = [r["import_libsumo_ms"] for r in res_sumo.values()]
        print(f", import libsumo p50 {statistics.median(libs):.0f} ms (not in the times above)")
    else:
        print()

    print("\nbudget (measured / budget; > 1.00 is over):")
    all_cold = [r["cold_ms"] for r in res_plain.values()]
    all_warm = [r["warm_ms"] for r in res_plain.values()]
    print(
        f"  no SUMO  ≤ {BUDGET_NO_SUMO_MS:.0f} ms: cold max {max(all_cold):.1f} ms "
        f"= {max(all_cold) / BUDGET_NO_SUMO_MS:.2f}x, p50 {statistics.median(all_cold):.1f} ms; "
        f"warm max {max(all_warm):.1f} ms = {max(all_warm) / BUDGET_NO_SUMO_MS:.2f}x"
    )
    over = [f for f in files if res_plain[f]["cold_ms"] > BUDGET_NO_SUMO_MS]
    if res_sumo:
        sc = [r["cold_ms"] for r in res_sumo.values()]
        sw = [r["warm_ms"] for r in res_sumo.values()]
        print(
            f"  SUMO     ≤ {BUDGET_SUMO_MS:.0f} ms: cold max {max(sc):.1f} ms "
            f"= {max(sc) / BUDGET_SUMO_MS:.2f}x, "
            f"p50 {statistics.median(sc):.1f} ms; warm max {max(sw):.1f} ms = {max(sw) / BUDGET_SUMO_MS:.2f}x"
        )
        over += [f for f, r in res_sumo.items() if r["cold_ms"] > BUDGET_SUMO_MS]
    if over:
        print("  over budget (cold):")
        for f in dict.fromkeys(over):
            p, s = res_plain[f], res_sumo.get(f)
            parts = (
                f"no-SUMO cold {p['cold_ms']:.0f} = map parse {p['parse_ms']:.0f} + first-env init "
                f"{p['init_ms']:.0f} + warm {p['warm_ms']:.0f}"
            )
            if s is not None:
                start, warmup, other = s["cold_parts"]
                parts += (
                    f", SUMO cold {s['cold_ms']:.0f} = libsumo.start {start:.0f} + warm-up "
                    f"{warmup:.0f} + other {other:.0f}"
                )
            print(f"    {f.parent.name}/{f.stem}: {parts}")
    else:
        print("  every scenario within budget")

    print()
    if peer is None:
        print("highway-env not installed: `pip install highway-env` for the side-by-side row")
        return
    print(
        f"peer: highway-env highway-v0 gym.make + reset: cold {peer['cold_ms']:.1f} ms, warm "
        f"{peer['warm_ms']:.1f} ms (import {peer['import_ms']:.0f} ms, not included)"
    )
    ours_warm = statistics.median(all_warm)
    ours_cold = statistics.median(all_cold)
    print(
        f"ratio ours no-SUMO p50 / highway-v0: cold {ours_cold / peer['cold_ms']:.2f}x, "
        f"warm {ours_warm / peer['warm_ms']:.2f}x (< 1 = ours faster)"
    )
    if res_sumo:
        print(
            f"ratio ours with SUMO p50 / highway-v0: cold {statistics.median(sc) / peer['cold_ms']:.2f}x, "
            f"warm {statistics.median(sw) / peer['warm_ms']:.2f}x"
        )
    sys.stdout.flush()


if __name__ == "__main__":
    main()
