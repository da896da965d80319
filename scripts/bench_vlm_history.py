"""What VLM history and memory cost the harness per decision, with and without, side by side in one run.

One decision, as the harness does it: the env step (with the front camera and BEV rendered when
images are on), building the message (encoding the current frames, adding the history) and the
JSON body the transport sends. The reply is computed outside the timed part (the scripted route
driver: the server's work). The same episode is driven under every setting (same seed, same
replies), in alternating rounds; the best round of each setting is kept, so a busy machine
inflates all of them alike rather than one.

1. Without images (blind, nothing rendered): today's decision vs. `--ego-history K --memory K`,
   the history that costs something without images. Target: ≤ 10 % of today's decision.
2. With images: today's decision (front + BEV) vs. `--history N --history-bev --ego-history K
   --memory K`. Past frames are the data URLs sent when they were current, so history adds no
   encoding; its cost is the larger body (N more frame pairs to serialise and send). The overhead
   is printed as a share of today's decision with images and of the one without.
3. End to end: `r4 evaluate --agent vlm` on one scenario against the loopback scripted server
   (a separate process, no added latency), so a decision also holds the HTTP request through the
   SDK, the server's reply and the run's files: decisions/s without images, with and without
   history, then with images.

    python scripts/bench_vlm_history.py [--decisions 200] [--rounds 3] [--seeds 4] [--history 4] [--k 4]
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

SCENARIO = "03_turning/town01_03_right_turn_signalised"


@dataclass
class Setting:
    name: str
    images: bool
    history: Any  # HistoryOptions


def drive(setting: Setting, decisions: int) -> tuple[float, int, int]:
    """(seconds of timed work, decisions, mean body bytes) over `decisions` decisions."""
    from drivehierarchy import _core
    from drivehierarchy.agents.vlm.history import DecisionHistory
    from drivehierarchy.agents.vlm.payload import PayloadOptions, build_messages
    from drivehierarchy.agents.vlm.transport import encode_body
    from drivehierarchy.envs.config import R4Config
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env
    from drivehierarchy.testing.openai_server import parse_chat_request, route_driver

    config = R4Config() if setting.images else R4Config(front=None, bev=None)
    payload = PayloadOptions(blind=not setting.images)
    env = DriveHierarchyR4Env(scenario=SCENARIO, config=config)
    history = (
        DecisionHistory(setting.history, payload, _core.constants()["tick_s"])
        if setting.history.enabled
        else None
    )
    obs, info = env.reset(seed=0)
    timed, body_bytes, episode_n = 0.0, 0, 0
    for _ in range(decisions):
        episode_n += 1
        t0 = time.perf_counter()
        if history is None:
            messages = build_messages(obs, episode_n, payload)
        else:
            ego = env.sim.ego_array().tolist() if setting.history.ego else None
            messages = history.messages(obs, episode_n, int(info["tick"]), ego)
        # The bytes the transport sends (`transport.encode_body`).
        body = encode_body({"model": "m", "messages": messages, "temperature": 0.0, "max_tokens": 256})
        t1 = time.perf_counter()
        question = messages[0]["content"][-1]
        reply = route_driver(parse_chat_request({"messages": [{"role": "user", "content": [question]}]}))
        t2 = time.perf_counter()
        obs, _, terminated, truncated, info = env.step(reply)
        if history is not None:
            history.record_reply(episode_n, info.get("reply"))
        t3 = time.perf_counter()
        timed += (t1 - t0) + (t3 - t2)
        body_bytes += len(body)
        if terminated or truncated:
            obs, info = env.reset(seed=0)
            episode_n = 0
            if history is not None:
                history.reset(0)
    env.close()
    return timed, decisions, body_bytes // decisions


def best_of(settings: list[Setting], decisions: int, rounds: int) -> dict[str, tuple[float, int]]:
    """Per setting: (best seconds per decision over the rounds, mean body bytes)."""
    best: dict[str, tuple[float, int]] = {}
    for _ in range(rounds):
        for s in settings:
            timed, n, size = drive(s, decisions)
            per = timed / n
            if s.name not in best or per < best[s.name][0]:
                best[s.name] = (per, size)
    return best


def harness(url: str, setting: Setting, out: Path, seeds: int) -> tuple[float, float, int]:
    """(wall seconds, this process's CPU seconds, decisions) of `r4 evaluate --agent vlm` on the
    scenario with `seeds` seeds (several, so the run's fixed costs — the SDK client, the
    manifest's git call, loading the scenario — weigh little per decision)."""
    from drivehierarchy.agents.vlm import PayloadOptions, VLMOptions
    from drivehierarchy.benchmark.r4 import runner
    from drivehierarchy.scenarios import resolve_scenario

    vlm = VLMOptions(
        base_url=url,
        model="test-model",
        payload=PayloadOptions(blind=not setting.images),
        history=setting.history,
    )
    opts = runner.RunOptions(agent="vlm", vlm=vlm, seeds=seeds)
    t0, c0 = time.perf_counter(), time.process_time()
    results = runner.evaluate([Path(resolve_scenario(SCENARIO))], out, opts, log=lambda _: None)
    return (
        time.perf_counter() - t0,
        time.process_time() - c0,
        sum(int(r["vlm"]["decisions"]) for r in results),
    )


def end_to_end(settings: list[Setting], rounds: int, seeds: int) -> dict[str, tuple[float, float]]:
    """Per setting: (median wall decisions/s, median harness-CPU seconds per decision) over the
    rounds. The harness's CPU time (all its threads; the server is another process) is what
    history adds to; the wall rate also holds the server and whatever else the machine runs. The
    median, not the best: a whole run is long enough to be hit by the machine's other work."""
    port = _free_port()
    server = subprocess.Popen(
        [sys.executable, "-m", "drivehierarchy.testing.openai_server", "--port", str(port), "--driver"],
        stderr=subprocess.PIPE,
        text=True,
    )
    samples: dict[str, list[tuple[float, float]]] = {s.name: [] for s in settings}
    try:
        assert server.stderr is not None
        server.stderr.readline()  # "serving ..." once it listens
        url = f"http://127.0.0.1:{port}/v1"
        with tempfile.TemporaryDirectory() as tmp:
            harness(url, settings[0], Path(tmp) / "warm-up", 1)  # imports, first connection
            for r in range(rounds):
                for i, s in enumerate(settings):
                    wall, cpu, n = harness(url, s, Path(tmp) / f"{r}_{i}", seeds)
                    samples[s.name].append((n / wall, cpu / n))
    finally:
        server.terminate()
        server.wait(timeout=10)
    return {
        k: (statistics.median(r for r, _ in v), statistics.median(c for _, c in v))
        for k, v in samples.items()
    }


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def main() -> int:
    from drivehierarchy.agents.vlm.history import HistoryOptions

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--decisions", type=int, default=200, help="decisions per setting and round")
    ap.add_argument("--rounds", type=int, default=3, help="alternating rounds; the best is kept")
    ap.add_argument("--history", type=int, default=4, help="past frames (N)")
    ap.add_argument("--k", type=int, default=4, help="ego-history and memory length (K)")
    ap.add_argument("--seeds", type=int, default=4, help="seeds per end-to-end run (default 4)")
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 10 decisions, 1 round, 1 seed")
    args = ap.parse_args()
    if args.quick:
        args.decisions, args.rounds, args.seeds = 10, 1, 1

    k, n = args.k, args.history
    text = HistoryOptions(ego=k, memory=k)
    full = HistoryOptions(frames=n, bev=True, ego=k, memory=k)
    settings = [
        Setting("no images, today", False, HistoryOptions()),
        Setting(f"no images, ego-history {k} + memory {k}", False, text),
        Setting("images, today", True, HistoryOptions()),
        Setting(f"images, history {n} + BEV, ego-history {k} + memory {k}", True, full),
    ]
    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the start")
    print(f"{SCENARIO}, {args.decisions} decisions per setting, best of {args.rounds} round(s)\n")
    best = best_of(settings, args.decisions, args.rounds)
    width = max(len(s.name) for s in settings)
    print(f"{'setting':<{width}}  {'ms/decision':>11}  {'decisions/s':>11}  {'body':>9}")
    for s in settings:
        per, size = best[s.name]
        print(f"{s.name:<{width}}  {1e3 * per:11.3f}  {1 / per:11.1f}  {size / 1024:7.0f} kB")
    base_text, hist_text = best[settings[0].name][0], best[settings[1].name][0]
    base_img, hist_img = best[settings[2].name][0], best[settings[3].name][0]
    over_text, over_img = hist_text - base_text, hist_img - base_img
    print(
        f"\nwithout images: history costs {1e3 * over_text:+.3f} ms = {100 * over_text / base_text:+.1f} % "
        "of today's decision (target ≤ 10 %)"
    )
    print(
        f"with images:    history costs {1e3 * over_img:+.3f} ms = {100 * over_img / base_img:+.1f} % of "
        f"today's decision with images, {100 * over_img / base_text:+.1f} % of one without "
        f"(its body is {best[settings[3].name][1] / max(best[settings[2].name][1], 1):.1f} × larger; "
        "no frame is encoded twice)"
    )

    print(
        f"\nend to end (r4 evaluate, loopback scripted server, one scenario × {args.seeds} seeds, "
        f"median of {args.rounds}):"
    )
    rates = end_to_end(settings, args.rounds, args.seeds)
    print(f"{'setting':<{width}}  {'decisions/s':>11}  {'harness CPU ms/decision':>23}")
    for s in settings:
        rate, per = rates[s.name]
        print(f"{s.name:<{width}}  {rate:11.1f}  {1e3 * per:23.3f}")
    e_base, e_hist = rates[settings[0].name][1], rates[settings[1].name][1]
    e_img, e_img_hist = rates[settings[2].name][1], rates[settings[3].name][1]
    print(
        f"without images: history costs {1e3 * (e_hist - e_base):+.3f} ms of harness CPU = "
        f"{100 * (e_hist - e_base) / e_base:+.1f} % of today's decision (target ≤ 10 %)"
    )
    print(
        f"with images:    history costs {1e3 * (e_img_hist - e_img):+.3f} ms of harness CPU = "
        f"{100 * (e_img_hist - e_img) / e_img:+.1f} % of today's decision with images"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
