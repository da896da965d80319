"""R4 simulation speed, ours beside highway-env in the same run.

    python scripts/bench_r4.py [--seconds 5]

Prints ticks/s without images (30 actors), decisions/s with the protocol's front camera and BEV
rendered at every decision, and highway-env `intersection-v0` decisions/s (its default
Kinematics observation, 1 Hz policy, 15 Hz simulation), with ratios. Everything runs in this one
process on one core; wall and process-CPU rates are both printed because the machine may be
shared.
"""

from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np

import drivehierarchy  # noqa: F401  (registers DriveHierarchy-R4)
from drivehierarchy.scenarios import builtin_root

BENCH_SCENARIO = builtin_root() / "bench" / "town01_30_actors.toml"


def measure(run_for: float, body: Callable[[], int]) -> tuple[float, float, int]:
    """Calls `body` (returning work units done) until `run_for` seconds passed: (wall/s, cpu/s, units)."""
    units = 0
    w0, c0 = time.perf_counter(), time.process_time()
    while time.perf_counter() - w0 < run_for:
        units += body()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return units / wall, units / max(cpu, 1e-9), units


def ours_stepper(images: bool, expert: bool) -> Callable[[], int]:
    cfg: dict = {} if images else {"front": None, "bev": None}
    env = gym.make("DriveHierarchy-R4", scenario=str(BENCH_SCENARIO), **cfg).unwrapped
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    state = {"tick": 0}

    def body() -> int:
        action = env.expert_action() if expert else np.array([rng.uniform(-0.05, 0.05), 8.0], np.float32)
        _, _, terminated, truncated, info = env.step(action)
        done = info["tick"] - state["tick"]
        state["tick"] = info["tick"]
        if terminated or truncated:
            env.reset(seed=int(rng.integers(1 << 30)))
            state["tick"] = 0
        return done if not images else 1

    return body


def highway_stepper(env_id: str) -> Callable[[], int] | None:
    try:
        import highway_env  # noqa: F401
    except ImportError:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(env_id)
        env.reset(seed=0)
    rng = np.random.default_rng(0)

    def body() -> int:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset(seed=int(rng.integers(1 << 30)))
        return 1

    return body


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=5.0, help="measuring time per row")
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 0.2 s per row")
    args = ap.parse_args()
    if args.quick:
        args.seconds = 0.2
    if not BENCH_SCENARIO.exists():
        raise SystemExit(f"benchmark scenario missing: {BENCH_SCENARIO}")

    rows: list[tuple[str, str, float, float]] = []
    w, c, _ = measure(args.seconds, ours_stepper(images=False, expert=False))
    rows.append(("ours: ticks/s, no images, 30 actors, fixed policy", "ticks/s", w, c))
    w, c, _ = measure(args.seconds, ours_stepper(images=False, expert=True))
    rows.append(("ours: ticks/s, no images, 30 actors, expert policy", "ticks/s", w, c))
    ours_img = measure(args.seconds, ours_stepper(images=True, expert=True))
    rows.append(("ours: decisions/s, front 800x450 + BEV 800x800", "decisions/s", ours_img[0], ours_img[1]))
    peer = highway_stepper("intersection-v0")
    peer_rate = None
    if peer is not None:
        peer_rate = measure(args.seconds, peer)
        name = "highway-env intersection-v0 (Kinematics obs)"
        rows.append((name, "decisions/s", peer_rate[0], peer_rate[1]))

    print(f"{'what':58s} {'unit':12s} {'wall':>10s} {'cpu':>10s}")
    for name, unit, wall, cpu in rows:
        print(f"{name:58s} {unit:12s} {wall:10.1f} {cpu:10.1f}")
    print()
    print("targets: ≥ 5,000 ticks/s without images (30 actors); ≥ 100 decisions/s with images")
    if peer_rate is not None:
        print(
            f"ratio ours-with-images / highway-env intersection-v0 decisions/s: "
            f"{ours_img[0] / peer_rate[0]:.1f}x wall, {ours_img[1] / peer_rate[1]:.1f}x cpu"
        )
        print(
            f"ratio ours-without-images (decisions = ticks/5) / intersection-v0: "
            f"{rows[1][2] / 5 / peer_rate[0]:.0f}x wall, {rows[1][3] / 5 / peer_rate[1]:.0f}x cpu"
        )
    else:
        print("highway-env not installed: `pip install highway-env` for the side-by-side row")
    print(f"(scenario: {Path(BENCH_SCENARIO).relative_to(builtin_root().parent)})")


if __name__ == "__main__":
    main()
