"""Load + reset time of every suite scenario, without and with SUMO, beside highway-env.

    python scripts/bench_suite_load.py [FOLDER_OR_FILE ...] [--repeat 5] [--no-sumo] [--jobs 1]

(≈ 4 s per SUMO scenario and 1 s per other scenario at --repeat 5.)

Default: the built-in suite (`scenarios/r4`). The issue's budget: loading any suite scenario and
resetting it takes ≤ 50 ms without SUMO and ≤ 300 ms with SUMO start.

Per scenario, each measurement series runs in a fresh spawned process (nothing loaded, no map
cached), `import drivehierarchy` (and `import libsumo` for the SUMO series) done before the clock
starts — those are once-per-process costs and printed on their own:

* no SUMO: `DriveHierarchyR4Env(scenario, front=None, bev=None, prompt=False, traffic="none")`
  + `reset()`; cold = the first one in the process (the map is parsed), warm = the median of
  `--repeat` more (map cached). The cold surplus is split into the map's parse (timed on a fresh
  copy of the net in the warm process) and the first env's other set-up (init).
* SUMO (scenarios whose `[traffic]` runs SUMO): the same with the scenario's traffic, on each
  SUMO transport: `libsumo` (SUMO's C++ library driven from Rust, the env's default when built;
  its first start in a process loads libsumocpp) and `libsumo-python` (the libsumo module; shown
  as "python"). Every reset starts SUMO afresh and runs the warm-up. The `libsumo-python` time is
  split into `libsumo.start` (SUMO loading the net and the routes), the warm-up's steps and moves,
  and the rest (our map, demand, subscriptions); `libsumo` (shown as "native") does the same
  SUMO work.

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
import tomllib
import warnings
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

BUDGET_NO_SUMO_MS = 50.0
BUDGET_SUMO_MS = 300.0


# -- workers (each call runs in a fresh process) -----------------------------------------------
def _time_reset(scenario: str, traffic: str, after: Any = None, backend: str = "auto") -> tuple[float, float]:
    """(construct ms, reset ms) of one env; `after()` runs before it is closed (untimed)."""
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    t0 = time.perf_counter()
    env = DriveHierarchyR4Env(
        scenario, front=None, bev=None, prompt=False, traffic=traffic, sumo_backend=backend
    )
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
    from drivehierarchy.scenarios import builtin_root, sumo_home

    src = Path(scenario).resolve()
    text = src.read_text(encoding="utf-8")
    ref = str(tomllib.loads(text)["map"])
    if ref.startswith("builtin:"):
        name = ref.removeprefix("builtin:")
        net = builtin_root() / "maps" / name / f"{name}.net.xml"
    elif ref.startswith("sumo:"):
        net = Path(str(sumo_home())) / ref.removeprefix("sumo:")
    else:
        net = src.parent / ref
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


def worker_sumo_python(scenario: str, repeat: int) -> dict[str, Any]:
    """The Python backend (libsumo), its SUMO time split by wrapping libsumo's calls."""
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
        construct, reset = _time_reset(
            scenario, "sumo", after=functools.partial(_collect, clock, parts), backend="libsumo-python"
        )
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


def worker_sumo_native(scenario: str, repeat: int) -> dict[str, Any]:
    """The native backend (the env's default when built): SUMO's C++ library driven from Rust.
    Its first start in a process loads libsumocpp (part of cold)."""
    import drivehierarchy.envs.r4  # noqa: F401

    runs = [sum(_time_reset(scenario, "sumo", backend="libsumo")) for _ in range(1 + repeat)]
    return {"cold_ms": runs[0], "warm_ms": statistics.median(runs[1:])}


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
    return "      –" if v is None else f"{v:7.1f}"


def maxp50(vals: list[float]) -> str:
    return f"{max(vals):7.1f} {statistics.median(vals):7.1f}" if vals else f"{'–':>7s} {'–':>7s}"


def budget_line(label: str, budget: float, res: dict[Path, dict[str, Any]]) -> None:
    cold = [r["cold_ms"] for r in res.values()]
    warm = [r["warm_ms"] for r in res.values()]
    print(
        f"  {label:34s} ≤ {budget:3.0f} ms: cold max {max(cold):6.1f} ms = {max(cold) / budget:.2f}x, "
        f"p50 {statistics.median(cold):6.1f} ms; warm max {max(warm):6.1f} ms = {max(warm) / budget:.2f}x"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("targets", nargs="*", help="scenario files or folders (default: the built-in suite)")
    ap.add_argument("--repeat", type=int, default=5, help="warm repetitions per scenario")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes at once (1 = cleanest timing)")
    ap.add_argument("--no-sumo", action="store_true", help="skip the SUMO series")
    ap.add_argument(
        "--quick", action="store_true", help="smoke run (CI): one scenario with SUMO, one without, once"
    )
    args = ap.parse_args()

    from drivehierarchy.scenarios import builtin_root

    if args.quick:
        r4 = builtin_root() / "r4"
        args.repeat = 1
        args.targets = args.targets or [
            str(r4 / "02_obstacles" / "town01_02_cones_right_lane.toml"),
            str(r4 / "06_traffic_flow" / "bs3d_09_left_turner_queue.toml"),
        ]
    files = scenario_files(args.targets or [str(builtin_root() / "r4")])
    info = {f: describe(f) for f in files}
    with_sumo = [] if args.no_sumo else [f for f in files if info[f][1] == "sumo"]
    ctx = mp.get_context("spawn")
    failed: dict[Path, list[str]] = defaultdict(list)
    # One task per process: every series starts process-cold.
    with ProcessPoolExecutor(max_workers=max(1, args.jobs), mp_context=ctx, max_tasks_per_child=1) as pool:
        peer_f = pool.submit(worker_highway, args.repeat)
        plain = {f: pool.submit(worker_no_sumo, str(f), args.repeat) for f in files}
        native = {f: pool.submit(worker_sumo_native, str(f), args.repeat) for f in with_sumo}
        python = {f: pool.submit(worker_sumo_python, str(f), args.repeat) for f in with_sumo}

        def collect(futures: dict[Path, Any], what: str) -> dict[Path, dict[str, Any]]:
            out = {}
            for f, fu in futures.items():
                try:
                    out[f] = fu.result()
                except Exception as exc:  # reported, not timed (a broken scenario, no native build)
                    failed[f].append(f"{what}: {type(exc).__name__}: {exc}")
            return out

        res_plain = collect(plain, "no SUMO")
        res_native = collect(native, "SUMO native")
        res_python = collect(python, "SUMO python")
        peer = peer_f.result()
    if failed:
        print("could not time (left out of that series):", file=sys.stderr)
        for f, msgs in failed.items():
            for m in msgs:
                print(f"  {f}: {m}", file=sys.stderr)
        if args.quick:  # a smoke run exists to catch exactly this
            raise SystemExit(1)
    files = [f for f in files if f in res_plain]
    if not files:
        raise SystemExit("no scenario could be timed")

    root = files[0].parent.parent if len(files) > 1 else files[0].parent
    print(f"{len(files)} scenarios under {root}; times in ms (wall), warm = median of {args.repeat}")
    print(
        "no SUMO: construct + reset with traffic='none'; parse = the map alone (a fresh copy timed in a "
        "warm process), init = the rest of the first env's surplus.\n"
        "SUMO native / python: the same with the scenario's SUMO traffic on each backend (native = the "
        "default when built); python split: start = libsumo.start (SUMO loading net + routes), "
        "warmup = the warm-up's steps and moves, other = the rest (warm medians).\n"
    )
    head = (
        f"{'scenario':50s} {'map':22s}│{'cold':>7s} {'warm':>7s} {'parse':>7s} {'init':>7s} │"
        f"{'native':>7s} {'warm':>7s} │{'python':>7s} {'warm':>7s} {'start':>7s} {'warmup':>7s} {'other':>7s}"
    )
    print(head)
    print("─" * len(head))
    for f in files:
        p, n, y = res_plain[f], res_native.get(f), res_python.get(f)
        row = (
            f"{(f.parent.name + '/' + f.stem)[:50]:50s} {info[f][0][:22]:22s}│{fmt(p['cold_ms'])} "
            f"{fmt(p['warm_ms'])} {fmt(p['parse_ms'])} {fmt(p['init_ms'])} │"
            f"{fmt(n and n['cold_ms'])} {fmt(n and n['warm_ms'])} │"
        )
        if y is None:
            row += " ".join([fmt(None)] * 5)
        else:
            row += " ".join(fmt(y[k]) for k in ("cold_ms", "warm_ms", "start_ms", "warmup_ms", "other_ms"))
        print(row)

    # Per class: map × the scenario's own traffic mode; max and p50 of each series.
    classes: dict[tuple[str, str], list[Path]] = defaultdict(list)
    for f in files:
        classes[info[f]].append(f)
    print()
    sub = f"{'max':>7s} {'p50':>7s}"
    print(
        f"{'class (map · traffic)':36s} {'n':>3s} │ {'no SUMO cold':^15s} │ {'no SUMO warm':^15s} │ "
        f"{'native cold':^15s} │ {'native warm':^15s} │ {'python cold':^15s} │ {'python warm':^15s}"
    )
    head = f"{'':36s} {'':>3s} │ " + " │ ".join([sub] * 6)
    print(head)
    print("─" * len(head))
    for (m, mode), fs in sorted(classes.items()):
        cells = []
        for res in (res_plain, res_native, res_python):
            for key in ("cold_ms", "warm_ms"):
                cells.append(maxp50([res[f][key] for f in fs if f in res]))
        print(f"{m + ' · ' + mode:36s} {len(fs):3d} │ " + " │ ".join(cells))

    print()
    imports = [r["import_ms"] for r in res_plain.values()]
    line = "once per process, not in the times above: "
    line += f"import drivehierarchy p50 {statistics.median(imports):.0f} ms"
    if res_python:
        libs = [r["import_libsumo_ms"] for r in res_python.values()]
        line += f", import libsumo (python backend) p50 {statistics.median(libs):.0f} ms"
    print(line)
    if res_native:
        surplus = [r["cold_ms"] - r["warm_ms"] for r in res_native.values()]
        print(
            f"native backend: its first start in a process loads SUMO's C++ library (libsumocpp); "
            f"cold − warm p50 {statistics.median(surplus):.0f} ms (included in native cold)"
        )

    print("\nbudget (measured / budget; > 1.00 is over):")
    budget_line("no SUMO", BUDGET_NO_SUMO_MS, res_plain)
    if res_native:
        budget_line("SUMO, native backend (default)", BUDGET_SUMO_MS, res_native)
    if res_python:
        budget_line("SUMO, python backend (libsumo)", BUDGET_SUMO_MS, res_python)
        # Its first env in a process also imports libsumo (which imports traci and sumolib).
        first = [r["cold_ms"] + r["import_libsumo_ms"] for r in res_python.values()]
        print(
            f"  {'  … + import libsumo (first in process)':34s} ≤ {BUDGET_SUMO_MS:3.0f} ms: cold max "
            f"{max(first):6.1f} ms = {max(first) / BUDGET_SUMO_MS:.2f}x, "
            f"p50 {statistics.median(first):6.1f} ms"
        )
    over = [f for f in files if res_plain[f]["cold_ms"] > BUDGET_NO_SUMO_MS]
    over += [f for f, r in {**res_native, **res_python}.items() if r["cold_ms"] > BUDGET_SUMO_MS]
    if over:
        print("  over budget (cold):")
        for f in dict.fromkeys(over):
            p, n, y = res_plain[f], res_native.get(f), res_python.get(f)
            parts = (
                f"no SUMO {p['cold_ms']:.0f} = map parse {p['parse_ms']:.0f} + first-env init "
                f"{p['init_ms']:.0f} + warm {p['warm_ms']:.0f}"
            )
            if n is not None:
                parts += f"; native {n['cold_ms']:.0f} (warm {n['warm_ms']:.0f})"
            if y is not None:
                start, warmup, other = y["cold_parts"]
                parts += (
                    f"; python {y['cold_ms']:.0f} = libsumo.start {start:.0f} + warm-up {warmup:.0f} "
                    f"+ other {other:.0f}"
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
    rows = [("no SUMO", res_plain), ("SUMO native", res_native), ("SUMO python", res_python)]
    for label, res in rows:
        if not res:
            continue
        cold = statistics.median(r["cold_ms"] for r in res.values())
        warm = statistics.median(r["warm_ms"] for r in res.values())
        print(
            f"ratio ours {label:11s} p50 / highway-v0: cold {cold / peer['cold_ms']:.2f}x, "
            f"warm {warm / peer['warm_ms']:.2f}x (< 1 = ours faster)"
        )
    sys.stdout.flush()


if __name__ == "__main__":
    main()
