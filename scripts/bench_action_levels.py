"""Decision cost at each action level, side by side in one run (docs/r4.md#action-levels).

    python scripts/bench_action_levels.py [--seconds 6] [--rounds 6] [--quick]

Drives the bench scenario (town01, 30 scripted actors) without images at the control level
(`[steer, target speed]` through the protocol's bridge), the waypoint level (8 points for the
waypoint tracker, which computes a control at each of the decision's 5 ticks) and the meta level
(a path action resolved on the lane graph, then the same tracker), with the same fixed driving at
every level (straight on along the lane at 8 m/s). The levels take turns in short windows
(`--rounds` of `--seconds / rounds` each) so that load from other jobs on a shared machine hits
them alike. Prints decisions/s (wall and process CPU) and each level's overhead per decision over
the control level; must hold: ≤ 10 % for the waypoint level.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import drivehierarchy  # noqa: F401  (registers DriveHierarchy-R4)
from drivehierarchy.scenarios import builtin_root

BENCH_SCENARIO = builtin_root() / "bench" / "town01_30_actors.toml"
SPEED_MPS = 8.0
LEVELS = ("control", "waypoints", "meta")


def stepper(level: str) -> Callable[[], int]:
    mode = {"control": "decision", "waypoints": "waypoints", "meta": "meta"}[level]
    env = gym.make(
        "DriveHierarchy-R4", scenario=str(BENCH_SCENARIO), front=None, bev=None, action_mode=mode
    ).unwrapped
    env.reset(seed=0)
    if level == "control":
        action = np.array([0.0, SPEED_MPS], np.float32)
    elif level == "waypoints":
        k = env.config.waypoints
        dt = env.config.waypoint_dt_s
        action = np.array([[SPEED_MPS * dt * (i + 1), 0.0] for i in range(k)], np.float32)
    else:
        action = np.array([0, 0], np.int64)  # FOLLOW_LANE, KEEP
    seed = [0]

    def body() -> int:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            seed[0] += 1
            env.reset(seed=seed[0])
        return 1

    return body


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=6.0, help="total seconds per level (default 6)")
    ap.add_argument("--rounds", type=int, default=6, help="turns each level takes (default 6)")
    ap.add_argument("--quick", action="store_true", help="a tiny run (the figures mean nothing)")
    args = ap.parse_args()
    if args.quick:
        args.seconds, args.rounds = 0.3, 2
    bodies = {lv: stepper(lv) for lv in LEVELS}
    totals = {lv: [0, 0.0, 0.0] for lv in LEVELS}  # decisions, wall s, cpu s
    window = args.seconds / max(args.rounds, 1)
    for _ in range(max(args.rounds, 1)):
        for lv in LEVELS:
            w0, c0 = time.perf_counter(), time.process_time()
            n = 0
            while time.perf_counter() - w0 < window:
                n += bodies[lv]()
            totals[lv][0] += n
            totals[lv][1] += time.perf_counter() - w0
            totals[lv][2] += time.process_time() - c0
    base = totals["control"]
    base_cpu_cost = base[2] / max(base[0], 1)
    print(
        f"bench scenario {BENCH_SCENARIO.name}, no images, {args.rounds} rounds of {window:.2f} s per level"
    )
    print(
        f"{'level':<10} {'decisions':>9} {'dec/s wall':>11} {'dec/s cpu':>10} "
        f"{'ms/dec cpu':>11} {'overhead':>9}"
    )
    for lv in LEVELS:
        n, wall, cpu = totals[lv]
        cost = cpu / max(n, 1)
        over = (cost / base_cpu_cost - 1.0) * 100.0 if base_cpu_cost > 0 else float("nan")
        print(
            f"{lv:<10} {n:>9} {n / max(wall, 1e-9):>11.1f} {n / max(cpu, 1e-9):>10.1f} "
            f"{cost * 1e3:>11.3f} {over:>+8.1f}%"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
