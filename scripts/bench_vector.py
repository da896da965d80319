"""Native vector env vs the faster of Gymnasium's AsyncVectorEnv and SB3's SubprocVecEnv.

    python scripts/bench_vector.py [--num-envs 4] [--seconds 5] [--quick]

Prints decisions/s (env steps summed over the N envs, autoresets included) of
`gymnasium.make_vec("DriveHierarchy-R4", vectorization_mode="vector_entry_point")` beside the
two subprocess vector envs with the same N, scenario and actions, state only and with a 128×128
BEV, with ratios. All rows come from this one run (the machine may be shared: compare ratios, not
absolute numbers across runs). `--quick` measures the BEV row only, briefly, with 2 envs, to check
the script runs (the state row is the same code without the BEV).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import drivehierarchy  # noqa: F401  (registers DriveHierarchy-R4)

SCENARIO = "07_sudden_brake/town01_07_lead_brakes"
# Fresh worker processes: forking a process that has run thread pools (ours, BLAS) can deadlock.
START_METHOD = "spawn"


def env_kwargs(bev: bool) -> dict[str, Any]:
    return {
        "scenario": SCENARIO,
        "front": None,
        "bev": {"size_px": 128} if bev else None,
        "traffic": "idm",
    }


def make_single(bev: bool) -> Callable[[], gym.Env[Any, Any]]:
    def make() -> gym.Env[Any, Any]:
        # Imported here: the package registers the id in a spawned worker.
        from drivehierarchy.envs.vector_native import DropNoneInfo

        # The infos the native env returns (and what Gymnasium needs to batch them).
        return DropNoneInfo(gym.make("DriveHierarchy-R4", **env_kwargs(bev)))

    return make


def actions(rng: np.random.Generator, n: int) -> np.ndarray:
    a = np.empty((n, 2), np.float32)
    a[:, 0] = rng.uniform(-0.05, 0.05, n)
    a[:, 1] = rng.uniform(4.0, 10.0, n)
    return a


def time_loop(step: Callable[[np.ndarray], Any], n: int, seconds: float, warmup: int = 3) -> float:
    rng = np.random.default_rng(0)
    for _ in range(warmup):
        step(actions(rng, n))
    steps = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        step(actions(rng, n))
        steps += 1
    return steps * n / (time.perf_counter() - t0)


def bench_native(n: int, bev: bool, seconds: float) -> float:
    env = gym.make_vec(
        "DriveHierarchy-R4", num_envs=n, vectorization_mode="vector_entry_point", **env_kwargs(bev)
    )
    env.reset(seed=0)
    try:
        return time_loop(env.step, n, seconds)
    finally:
        env.close()


def bench_async(n: int, bev: bool, seconds: float) -> float:
    env = gym.vector.AsyncVectorEnv([make_single(bev)] * n, context=START_METHOD)
    env.reset(seed=0)
    try:
        return time_loop(env.step, n, seconds)
    finally:
        env.close()


def bench_subproc(n: int, bev: bool, seconds: float) -> float | None:
    try:
        from stable_baselines3.common.vec_env import SubprocVecEnv
    except ImportError:
        return None
    env = SubprocVecEnv([make_single(bev)] * n, start_method=START_METHOD)
    env.seed(0)
    env.reset()
    try:
        return time_loop(lambda a: env.step(a), n, seconds)
    finally:
        env.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--num-envs", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=5.0, help="timed seconds per row")
    ap.add_argument("--quick", action="store_true", help="the BEV row, 2 envs, 0.5 s: checks the script runs")
    args = ap.parse_args()
    n, seconds = (2, 0.5) if args.quick else (args.num_envs, args.seconds)
    print(f"N = {n} envs, scenario {SCENARIO}, Rust IDM traffic, {seconds:g} s per row")
    print(f"{'observation':<18}{'native':>12}{'Async':>12}{'SubprocVecEnv':>15}{'native/best':>13}")
    rows = [("state", False), ("state + BEV 128", True)]
    for label, bev in rows[1:] if args.quick else rows:
        ours = bench_native(n, bev, seconds)
        asy = bench_async(n, bev, seconds)
        sub = bench_subproc(n, bev, seconds)
        best = max(asy, sub or 0.0)
        sub_txt = f"{sub:>15.0f}" if sub is not None else f"{'n/a':>15}"
        print(f"{label:<18}{ours:>12.0f}{asy:>12.0f}{sub_txt}{ours / best:>12.2f}x")
    print("(decisions/s: env steps summed over the N envs; ratio against the faster subprocess env)")


if __name__ == "__main__":
    main()
