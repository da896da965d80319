#!/usr/bin/env python3
"""Rendering speed through the Python bindings, beside highway-env's `rgb_array` renderer, in one run.

Measures, on one process pinned to one core (the renderer itself uses no threads):

* front 800×450 + BEV 800×800 frame pairs/s (the protocol's VLM observation),
* front 400×225 frames/s (videos, cheap observations),
* BEV 128×128 frames/s (RL observations),

each including the hand-off of an owned numpy array, on a built-in scenario mid-episode (the
expert drives a few decisions first so traffic is in view), and on the official tongji net when
`../shared/official` is present (a throw-away scenario built from one official hero route);
then highway-env's `highway-v0` at 800×450. Wall time and process CPU time are both printed
because the machine may be shared: CPU-time rates are what the renderer costs.

    python scripts/bench_render.py [--seconds 2] [--scenario 04_intersection/...] [--no-highway]
    python scripts/bench_render.py --baseline DIR   # before/after: DIR holds another build's
                                                    # `drivehierarchy` package (e.g. main's)

Also measures R4 decisions/s with both protocol images rendered at every decision (the 30-actor
bench scenario, expert driver). With `--baseline`, the decisions/s and pair rates of the build in
DIR are measured in a child process in the same run, alternating rounds with this build, and
printed beside ours with ratios (the machine may be shared, so only same-run ratios compare).

Targets (issue 3): pairs ≥ 150/s, front 400×225 ≥ 600/s, BEV 128 ≥ 2,000/s; issue 34:
≥ 600 decisions/s with front 800×450 + BEV 800×800.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
OFFICIAL = REPO / "../shared/official/Close_Loop_Evaluation"
TONGJI = OFFICIAL / "Carla_Simulation/Co-Simulation/Sumo/tongji/tongji.net.xml"
ONSITE = OFFICIAL / "Scenario_Onsite"
TARGETS = {"pair": 150.0, "front400": 600.0, "bev128": 2000.0}
DECISIONS_TARGET = 600.0


@dataclasses.dataclass
class Rate:
    frames: int
    wall_s: float
    cpu_s: float

    @property
    def per_wall(self) -> float:
        return self.frames / self.wall_s

    @property
    def per_cpu(self) -> float:
        return self.frames / max(self.cpu_s, 1e-9)


def measure(fn: Callable[[], Any], seconds: float, min_frames: int = 20) -> Rate:
    fn()  # warm the renderer's scratch buffers
    n = 0
    w0, c0 = time.perf_counter(), time.process_time()
    while True:
        fn()
        n += 1
        if n >= min_frames and time.perf_counter() - w0 >= seconds:
            break
    return Rate(n, time.perf_counter() - w0, time.process_time() - c0)


def pin_one_core() -> str:
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (no sched_setaffinity)"
    cpu = min(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {cpu})
    return f"pinned to CPU {cpu}"


def camera_config(**kw: Any) -> Any:
    from drivehierarchy.envs.config import CameraConfig

    return CameraConfig(**kw)


def bev_config(**kw: Any) -> Any:
    from drivehierarchy.envs.config import BevConfig

    return BevConfig(**kw)


def bench_sim(sim: Any, seconds: float) -> dict[str, Rate]:
    front = camera_config()
    front400 = camera_config(width=400, height=225)
    bev = bev_config()
    bev128 = bev_config(size_px=128, px_per_m=2.0)  # the RL view (BevConfig::rl)

    def pair() -> None:
        a = sim.render_camera(front)
        b = sim.render_bev(bev)
        assert a.shape == (450, 800, 3) and b.shape == (800, 800, 3)

    return {
        "pair": measure(pair, seconds),
        "front": measure(lambda: sim.render_camera(front), seconds),
        "bev": measure(lambda: sim.render_bev(bev), seconds),
        "front400": measure(lambda: sim.render_camera(front400), seconds),
        "bev128": measure(lambda: sim.render_bev(bev128), seconds),
    }


def drive_to_mid_episode(scenario: str, decisions: int) -> tuple[Any, Any, int]:
    """An env (no observation images, so stepping is cheap) after `decisions` expert steps."""
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    env = DriveHierarchyR4Env(scenario=scenario, front=None, bev=None, prompt=False)
    env.reset(seed=0)
    done = 0
    for _ in range(decisions):
        _, _, term, trunc, _ = env.step(env.expert_action())
        done += 1
        if term or trunc:
            break
    return env, env.sim, done


def bench_decisions(seconds: float, conditions: str | None = None) -> Rate:
    """R4 decisions/s with the protocol's front camera and BEV rendered at every decision, under
    the scenario's conditions or the `conditions` override."""
    import gymnasium as gym

    from drivehierarchy.scenarios import builtin_root

    scenario = str(builtin_root() / "bench" / "town01_30_actors.toml")
    extra = {} if conditions is None else {"conditions": conditions}
    env = gym.make("DriveHierarchy-R4", scenario=scenario, **extra).unwrapped
    env.reset(seed=0)
    seed = [0]

    def step() -> None:
        _, _, term, trunc, _ = env.step(env.expert_action())
        if term or trunc:
            seed[0] += 1
            env.reset(seed=seed[0])

    rate = measure(step, seconds)
    env.close()
    return rate


def child_rates(seconds: float, scenario: str, decisions: int) -> dict[str, Rate]:
    """The rows `--baseline` compares, measured in this process (run as the child)."""
    import drivehierarchy  # noqa: F401  (registers DriveHierarchy-R4)

    env, sim, _ = drive_to_mid_episode(scenario, decisions)
    front, bev = camera_config(), bev_config()
    out = {"pair": measure(lambda: (sim.render_camera(front), sim.render_bev(bev)), seconds)}
    env.close()
    out["decisions"] = bench_decisions(seconds)
    return out


def run_child(pythonpath: str | None, args: argparse.Namespace) -> dict[str, Rate]:
    import subprocess

    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, __file__, "--child", "--seconds", str(args.seconds), "--scenario", args.scenario]
    cmd += ["--decisions", str(args.decisions)] + (["--no-pin"] if args.no_pin else [])
    out = subprocess.run(cmd, env=env, check=True, capture_output=True, text=True).stdout
    return {k: Rate(**v) for k, v in json.loads(out.strip().splitlines()[-1]).items()}


def compare(args: argparse.Namespace) -> int:
    """Before/after in one run: alternate baseline and this build, keep each side's best round."""
    best: dict[str, dict[str, Rate]] = {"before": {}, "after": {}}
    for _ in range(args.rounds):
        for side, path in (("before", args.baseline), ("after", None)):
            for k, r in run_child(path, args).items():
                if k not in best[side] or r.per_cpu > best[side][k].per_cpu:
                    best[side][k] = r
    print(f"before = {args.baseline}, after = this checkout; best of {args.rounds} alternating rounds")
    print(f"  {'':44} {'before':>10} {'after':>10} {'after/before':>13}   (per CPU second; wall in brackets)")
    labels = (("decisions", "R4 decisions/s, front 800×450 + BEV 800×800"), ("pair", "front + BEV pairs/s"))
    for k, label in labels:
        b, a = best["before"][k], best["after"][k]
        print(
            f"  {label:44} {b.per_cpu:10.1f} {a.per_cpu:10.1f} {a.per_cpu / b.per_cpu:12.2f}×"
            f"   ({b.per_wall:.1f} → {a.per_wall:.1f} wall)"
        )
    dec = best["after"]["decisions"].per_cpu
    verdict = "ok" if dec >= DECISIONS_TARGET else "MISSED"
    print(f"decisions/s target {DECISIONS_TARGET:.0f}: {verdict} ({dec:.1f})")
    return 0


def in_view(sim: Any) -> int:
    return sum(1 for a in sim.project_actors(camera_config()) if a["pixel_count"] > 0)


def tongji_scenario(tmp: Path) -> Path | None:
    """A throw-away scenario on the official tongji net: the first official hero route that loads,
    with those of its background vehicles whose routes our format can express (others dropped)."""
    from drivehierarchy import DriveHierarchyError, _core

    if not TONGJI.is_file() or not ONSITE.is_dir():
        return None
    path = tmp / "tongji.toml"

    def loads(lines: list[str]) -> bool:
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
        try:
            _core.validate_scenario(str(path))
        except DriveHierarchyError:
            return False
        return True

    for entity in sorted(ONSITE.glob("*/*/entity_sumo.json")):
        d = json.loads(entity.read_text(encoding="utf-8"))
        dep = d["hero"]["depart"]
        lines = [
            "version = 1",
            f'id = "bench_tongji_{entity.parent.name}"',
            'category = "06_traffic_flow"',
            f"map = {json.dumps(str(TONGJI.resolve()))}",
            "[ego]",
            f'start = {{ lane = "{dep["lane_id"]}", s = {float(dep["lane_pos"]):.2f} }}',
            f"route_edges = {json.dumps(d['hero']['route_edges'])}",
        ]
        if not loads(lines):
            continue
        for v in d.get("background_vehicles", [])[:12]:
            dep = v["depart"]
            kind = "pedestrian" if v.get("role") == "pedestrian" else "car"
            actor = [
                "[[actors]]",
                f'kind = "{kind}"',
                f"route = {{ edges = {json.dumps(v['route_edges'])}, start_lane = "
                f'"{dep["lane_id"]}", start_s = {float(dep["lane_pos"]):.2f} }}',
                f"speed_mps = {max(float(dep.get('speed_kmh', 0.0)) / 3.6, 5.0):.2f}",
                'at_end = "remove"',
            ]
            if loads(lines + actor):
                lines += actor
        if loads(lines):
            return path
    return None


def _scenario_id(path: Path) -> str:
    import tomllib

    return str(tomllib.loads(path.read_text(encoding="utf-8"))["id"])


def bench_highway(seconds: float) -> Rate | None:
    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
    os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
    try:
        import gymnasium as gym
        import highway_env  # noqa: F401  (registers highway-v0)
    except ImportError as exc:
        print(f"highway-env not installed ({exc}); `pip install highway-env` for the comparison")
        return None
    env = gym.make("highway-v0", render_mode="rgb_array", config={"screen_width": 800, "screen_height": 450})
    env.reset(seed=0)
    for _ in range(5):
        env.step(env.action_space.sample())
    frame = env.render()
    assert isinstance(frame, np.ndarray) and frame.shape == (450, 800, 3), getattr(frame, "shape", None)
    rate = measure(env.render, seconds)
    env.close()
    return rate


def row(label: str, r: Rate, target: float | None = None, peer: Rate | None = None) -> str:
    s = f"  {label:<34} {r.per_wall:9.1f}/s wall  {r.per_cpu:9.1f}/s CPU  ({r.frames} in {r.wall_s:.2f} s)"
    if target is not None:
        s += f"  target {target:,.0f}: {'ok' if r.per_cpu >= target else 'MISSED'} (CPU)"
    if peer is not None:
        s += f"  ours/highway-env {r.per_cpu / peer.per_cpu:.1f}× (CPU)"
    return s


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=2.0, help="time per measurement")
    ap.add_argument("--scenario", default="04_intersection/town01_04_straight_cross_traffic")
    ap.add_argument("--decisions", type=int, default=24, help="expert decisions before measuring")
    ap.add_argument("--no-highway", action="store_true")
    ap.add_argument("--no-pin", action="store_true", help="do not pin the process to one core")
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 0.1 s per measurement")
    ap.add_argument("--baseline", help="directory holding another build's drivehierarchy package")
    ap.add_argument("--rounds", type=int, default=2, help="alternating rounds with --baseline")
    ap.add_argument(
        "--conditions",
        default="night,rain,fog",
        help="also measure decisions/s under these conditions overrides, comma-separated "
        "(default night,rain,fog; '' for none)",
    )
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.quick:
        args.seconds, args.decisions = 0.1, 4

    pinned = "not pinned" if args.no_pin else pin_one_core()
    if args.child:
        rates = child_rates(args.seconds, args.scenario, args.decisions)
        print(json.dumps({k: dataclasses.asdict(r) for k, r in rates.items()}))
        return 0
    if args.baseline:
        return compare(args)
    import drivehierarchy

    print(f"drivehierarchy {drivehierarchy.__version__}, {pinned}, {args.seconds:.1f} s per measurement")
    results: dict[str, dict[str, Rate]] = {}

    env, sim, k = drive_to_mid_episode(args.scenario, args.decisions)
    print(f"{args.scenario}: after {k} expert decisions, {in_view(sim)} actors in the front camera")
    results["builtin"] = bench_sim(sim, args.seconds)
    env.close()
    decisions = bench_decisions(args.seconds)
    by_conditions = {c: bench_decisions(args.seconds, c) for c in args.conditions.split(",") if c}

    with tempfile.TemporaryDirectory() as tmp:
        path = tongji_scenario(Path(tmp))
        if path is None:
            print("tongji: skipped (../shared/official not present or no usable hero route)")
        else:
            env, sim, k = drive_to_mid_episode(str(path), 8)
            print(f"tongji ({_scenario_id(path)}): after {k} expert decisions, {in_view(sim)} actors in view")
            results["tongji"] = bench_sim(sim, args.seconds)
            env.close()

    peer = None if args.no_highway else bench_highway(args.seconds)

    print()
    for name, r in results.items():
        print(f"ours — {name}")
        print(row("front 800×450 + BEV 800×800 pairs", r["pair"], TARGETS["pair"], peer))
        print(row("front 800×450", r["front"], None, peer))
        print(row("BEV 800×800", r["bev"]))
        print(row("front 400×225", r["front400"], TARGETS["front400"]))
        print(row("BEV 128×128", r["bev128"], TARGETS["bev128"]))
    if peer is not None:
        print("highway-env highway-v0 rgb_array")
        print(row("800×450", peer))
    print("R4 — town01_30_actors, expert")
    print(row("decisions/s, front 800×450 + BEV 800×800", decisions, DECISIONS_TARGET))
    for c, r in by_conditions.items():
        print(row(f"  … --conditions {c}", r) + f"  ×{r.per_cpu / decisions.per_cpu:.2f} of default (CPU)")
    missed = [f"{name}/{k}" for name, r in results.items() for k, t in TARGETS.items() if r[k].per_cpu < t]
    if decisions.per_cpu < DECISIONS_TARGET:
        missed.append("decisions")
    print()
    print("all targets met (CPU time)" if not missed else f"targets missed (CPU time): {', '.join(missed)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
