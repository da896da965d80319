"""Decision cost at each action level and with VLM history, side by side in one run
(docs/r4.md#action-levels, docs/vlm.md#history-and-memory).

    python scripts/bench_action_levels.py [--seconds 6] [--rounds 6] [--k 4] [--quick]

Drives the bench scenario (town01, 30 scripted actors) without images at the control level
(`[steer, target speed]` through the protocol's bridge), the waypoint level (8 points for the
waypoint tracker, which computes a control at each of the decision's 5 ticks) and the meta level
(a path action resolved on the lane graph, then the same tracker), with the same fixed driving at
every level (straight on along the lane at 8 m/s: at the meta level FOLLOW_LANE with ACCELERATE up
to 8 m/s, then KEEP, so that its episodes run as long as the others'). The levels take turns in
short windows (`--rounds` of `--seconds / rounds` each) so that load from other jobs on a shared
machine hits them alike; the resets between episodes are timed apart and left out (a reset builds
a new world, several milliseconds that would otherwise swamp a decision's tens of microseconds).
Prints decisions/s (wall and process CPU) and each level's overhead per decision over the control
level; must hold: ≤ 10 % for the waypoint and meta levels.

Two more rows are a VLM's decision at the control level without images, as the harness makes it
(the message, the JSON body the transport sends, and the step on the reply text, which the
protocol's parser reads): `vlm` is today's message, `vlm+hist` adds `--ego-history K --memory K`
(the history that costs something without images; past frames need images). Their overhead is
`vlm+hist` over `vlm`; must hold: ≤ 10 %. The reply's round trip to a server (the SDK's HTTP
request, the server) is left out, so this is the smallest decision there is and the overhead's
largest share of one; scripts/bench_vlm_history.py also measures it end to end.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import drivehierarchy  # noqa: F401  (registers DriveHierarchy-R4)
from drivehierarchy.scenarios import builtin_root

BENCH_SCENARIO = builtin_root() / "bench" / "town01_30_actors.toml"
SPEED_MPS = 8.0
LEVELS = ("control", "waypoints", "meta")
VLM_ROWS = ("vlm", "vlm+hist")
# The route driver's usual reply (the same every decision, so both VLM rows parse the same text).
REPLY = "steer: 0.000\ntarget_speed_mps: 8.0"


def stepper(level: str) -> Callable[[], tuple[float, float]]:
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
        action = np.array([0, 1], np.int64)  # FOLLOW_LANE, ACCELERATE (KEEP from 8 m/s on)
    seed = [0]

    def body() -> int:
        _, _, terminated, truncated, info = env.step(action)
        if level == "meta":
            # KEEP holds the speed it is given: at rest it would stand until the blocked limit
            # and the level would time resets instead of decisions.
            action[1] = 0 if info["speed_mps"] >= SPEED_MPS - 0.5 else 1
        if terminated or truncated:
            w0, c0 = time.perf_counter(), time.process_time()
            seed[0] += 1
            env.reset(seed=seed[0])
            if level == "meta":
                action[1] = 1
            return time.perf_counter() - w0, time.process_time() - c0
        return 0.0, 0.0

    return body


def vlm_stepper(history_k: int) -> Callable[[], tuple[float, float]]:
    """One VLM decision without images: the message (today's, or with ego history and memory of
    `history_k` decisions), its request body, the step on the reply and the history's bookkeeping."""
    from drivehierarchy import _core
    from drivehierarchy.agents.vlm.history import DecisionHistory, HistoryOptions
    from drivehierarchy.agents.vlm.payload import PayloadOptions, build_messages
    from drivehierarchy.agents.vlm.transport import encode_body

    env = gym.make("DriveHierarchy-R4", scenario=str(BENCH_SCENARIO), front=None, bev=None).unwrapped
    payload = PayloadOptions(blind=True)
    options = HistoryOptions(ego=history_k, memory=history_k)
    history = DecisionHistory(options, payload, _core.constants()["tick_s"]) if history_k else None
    state: dict[str, Any] = {"seed": 0, "decision": 0}
    state["obs"], state["info"] = env.reset(seed=0)

    def body() -> tuple[float, float]:
        state["decision"] += 1
        n, obs, info = state["decision"], state["obs"], state["info"]
        if history is None:
            messages = build_messages(obs, n, payload)
        else:
            messages = history.messages(obs, n, int(info["tick"]), env.sim.ego_array().tolist())
        encode_body({"model": "m", "messages": messages, "temperature": 0.0, "max_tokens": 256})
        obs, _, terminated, truncated, info = env.step(REPLY)
        if history is not None:
            history.record_reply(n, info.get("reply"))
        state["obs"], state["info"] = obs, info
        if terminated or truncated:
            w0, c0 = time.perf_counter(), time.process_time()
            state["seed"] += 1
            state["obs"], state["info"] = env.reset(seed=state["seed"])
            state["decision"] = 0
            if history is not None:
                history.reset(state["seed"])
            return time.perf_counter() - w0, time.process_time() - c0
        return 0.0, 0.0

    return body


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=6.0, help="total seconds per level (default 6)")
    ap.add_argument("--rounds", type=int, default=6, help="turns each level takes (default 6)")
    ap.add_argument("--k", type=int, default=4, help="ego-history and memory length of vlm+hist (default 4)")
    ap.add_argument("--quick", action="store_true", help="a tiny run (the figures mean nothing)")
    args = ap.parse_args()
    if args.quick:
        args.seconds, args.rounds = 0.3, 2
    if args.k < 1:
        ap.error(f"--k = {args.k}: expected ≥ 1")
    rows = (*LEVELS, *VLM_ROWS)
    bodies = {lv: stepper(lv) for lv in LEVELS}
    bodies["vlm"], bodies["vlm+hist"] = vlm_stepper(0), vlm_stepper(args.k)
    totals = {lv: [0, 0.0, 0.0] for lv in rows}  # decisions, wall s, cpu s
    window = args.seconds / max(args.rounds, 1)
    for _ in range(max(args.rounds, 1)):
        for lv in rows:
            w0, c0 = time.perf_counter(), time.process_time()
            n, reset_wall, reset_cpu = 0, 0.0, 0.0
            while time.perf_counter() - w0 < window:
                rw, rc = bodies[lv]()
                n, reset_wall, reset_cpu = n + 1, reset_wall + rw, reset_cpu + rc
            # Resets (a new world every episode) are no decision's cost: they are left out.
            totals[lv][0] += n
            totals[lv][1] += time.perf_counter() - w0 - reset_wall
            totals[lv][2] += time.process_time() - c0 - reset_cpu

    def cost(row: str) -> float:
        n, _, cpu = totals[row]
        return cpu / max(n, 1)

    print(f"bench scenario {BENCH_SCENARIO.name}, no images, {args.rounds} rounds of {window:.2f} s per row")
    print(
        f"{'row':<10} {'decisions':>9} {'dec/s wall':>11} {'dec/s cpu':>10} "
        f"{'ms/dec cpu':>11} {'overhead':>9}  over"
    )
    for lv in rows:
        n, wall, cpu = totals[lv]
        base = "vlm" if lv == "vlm+hist" else "control" if lv in LEVELS else None
        over = f"{(cost(lv) / cost(base) - 1.0) * 100.0:>+8.1f}%" if base and cost(base) > 0 else "—"
        print(
            f"{lv:<10} {n:>9} {n / max(wall, 1e-9):>11.1f} {n / max(cpu, 1e-9):>10.1f} "
            f"{cost(lv) * 1e3:>11.4f} {over:>9}  {base or '(today: the VLM baseline)'}"
        )
    print(
        f"history (ego-history {args.k} + memory {args.k}): "
        f"{(cost('vlm+hist') - cost('vlm')) * 1e3:+.4f} ms per decision over today's VLM decision; "
        f"the waypoint tracker: {(cost('waypoints') - cost('control')) * 1e3:+.4f} ms over the control level"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
