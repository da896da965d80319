"""One scenario driven by the VLM driver, decision by decision: the env in the harness's thread
pool or in a worker process (`workers.py`), the requests from the harness's one connection pool."""

from __future__ import annotations

import asyncio
import contextlib
import functools
import json
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drivehierarchy import _core
from drivehierarchy.benchmark.r4.drive import VIDEO_CAMERA, finish_scene, save_frames
from drivehierarchy.benchmark.r4.jobs import Job, RunOptions
from drivehierarchy.benchmark.r4.store import fresh_scene_dir, write_json_atomic
from drivehierarchy.envs.config import R4Config

if TYPE_CHECKING:
    from drivehierarchy.agents.vlm.history import HistoryOptions


TICK_S: float = _core.constants()["tick_s"]  # the protocol's simulation step


@dataclass
class _VlmStats:
    decisions: int = 0
    valid: int = 0
    parse_failures: int = 0
    transport_errors: int = 0
    consecutive_transport: int = 0
    latency_s: float = 0.0
    held_ticks: int = 0

    def line(self) -> dict[str, Any]:
        return {
            "decisions": self.decisions,
            "valid": self.valid,
            "parse_failures": self.parse_failures,
            "transport_errors": self.transport_errors,
            "mean_latency_s": round(self.latency_s / self.decisions, 4) if self.decisions else None,
        }


class VlmScene:
    """One VLM scenario's env, driven decision by decision: in the harness's thread pool, or in a
    worker process (`workers.py`) for scenarios with SUMO traffic. The observation stays here;
    only the built message, the step's info and the final record travel."""

    def __init__(
        self,
        scenario: Path,
        config: R4Config,
        scene_dir: Path,
        payload: Any,
        frames: bool,
        video: bool,
        history: HistoryOptions | None = None,
    ) -> None:
        from drivehierarchy.envs.r4 import DriveHierarchyR4Env

        self.env = DriveHierarchyR4Env(scenario=scenario, config=config)
        self.scene_dir = scene_dir
        self.payload = payload
        self.frames = frames
        self.gif = _core.GifWriter(str(scene_dir / "episode.gif"), fps=4) if video else None
        self.obs: dict[str, Any] = {}
        self.tick = 0
        from drivehierarchy.agents.vlm.history import DecisionHistory

        # The episode's past frames and decisions: rebuilt from the start whenever the scenario is
        # (re)driven, so a resumed run sends what an uninterrupted one sends.
        self.history = (
            DecisionHistory(history, payload, TICK_S) if history is not None and history.enabled else None
        )

    def reset(self, seed: int) -> dict[str, Any]:
        self.obs, info = self.env.reset(seed=seed)
        self.tick = int(info.get("tick", 0))
        if self.history is not None:
            self.history.reset(seed)
        return dict(info)

    def messages(self, decision: int, seed: int) -> list[dict[str, Any]]:
        from drivehierarchy.agents.vlm.payload import build_messages

        if self.history is None:
            return build_messages(self.obs, decision, self.payload, seed=seed)
        ego = self.env.sim.ego_array().tolist() if self.history.options.ego else None
        return self.history.messages(self.obs, decision, self.tick, ego)

    def messages_logged(self, decision: int, seed: int) -> tuple[list[dict[str, Any]], dict[str, Any]]:
        """`messages` and the decision log's history fields (the past frames' offsets)."""
        messages = self.messages(decision, seed)
        if self.history is None or not self.history.options.frames:
            return messages, {}
        return messages, {"history_offsets_s": list(self.history.last_offsets_s)}

    def step(self, raw: str | None, decision: int) -> tuple[bool, bool, dict[str, Any]]:
        self.obs, _reward, terminated, truncated, info = self.env.step(raw)
        self._after(decision, info, info.get("reply"))
        return terminated, truncated, dict(info)

    def step_latency_aware(
        self, raw: str | None, held: int, interval: int, decision: int
    ) -> tuple[bool, bool, dict[str, Any], dict[str, Any]]:
        self.obs, terminated, truncated, info, rep = _step_latency_aware(self.env, raw, held, interval)
        self._after(decision, info, rep)
        return terminated, truncated, dict(info), rep

    def _after(self, decision: int, info: dict[str, Any], reply: Any) -> None:
        self.tick = int(info.get("tick", self.tick))
        if self.history is not None:
            self.history.record_reply(decision, reply if isinstance(reply, dict) and reply else None)
        self._record(decision)

    def _record(self, decision: int) -> None:
        if self.frames:
            save_frames(self.scene_dir / "frames", decision, self.obs)
        if self.gif is not None:
            self.gif.push(self.env.sim.render_camera(VIDEO_CAMERA))

    def finish(
        self, job: Job, opts: RunOptions, steps: int, wall: float, extra: dict[str, Any]
    ) -> dict[str, Any]:
        self._close_gif()
        return finish_scene(self.env, job, opts, self.scene_dir, steps, wall, extra)

    def _close_gif(self) -> None:
        if self.gif is not None:
            self.gif.close()
            self.gif = None

    def close(self) -> None:
        self._close_gif()
        self.env.close()


async def drive_vlm_scene(
    job: Job,
    opts: RunOptions,
    out: Path,
    driver: Any,
    pool: ThreadPoolExecutor,
    worker: Any = None,
) -> dict[str, Any]:
    """Drives one scenario with the VLM driver; returns its results line, or an `aborted` line
    (with `"aborted": reason`) under the batch-abort rule. The env runs in `pool` or, given a
    `workers.SceneWorker`, in that worker process; the requests are sent from here either way."""
    loop = asyncio.get_running_loop()
    vopts = driver.options
    config = opts.config
    images = driver.payload.images
    # Only render what the message carries (frames need both).
    if not opts.frames:
        config = config.replace(
            front=config.front if "front" in images else None,
            bev=config.bev if "bev" in images else None,
        )
    interval = config.decision_interval_ticks
    if vopts.latency_aware:
        # One env step per tick, so a decision can start late; `_step_latency_aware` keeps the
        # decision cadence.
        config = config.replace(decision_interval_ticks=1)
    scene_dir = fresh_scene_dir(out, job, opts.frames)
    args = (job.scenario, config, scene_dir, driver.payload, opts.frames, opts.video, vopts.history)
    scene: VlmScene | None = None
    if worker is not None:
        from drivehierarchy.benchmark.r4.workers import make_remote

        await worker.call(pool, "new", VlmScene, *args)
        remote = make_remote(worker, pool)
    else:
        scene = await loop.run_in_executor(pool, functools.partial(VlmScene, *args))

        async def remote(method: str, *a: Any) -> Any:
            return await loop.run_in_executor(pool, functools.partial(getattr(scene, method), *a))

    stats = _VlmStats()
    aborted: str | None = None
    t0 = time.perf_counter()
    closed = False
    try:
        info = await remote("reset", job.seed)
        with (scene_dir / "decisions.jsonl").open("w", encoding="utf-8") as dlog:
            while True:
                stats.decisions += 1
                n = stats.decisions
                asked_tick = info.get("tick")
                history_log: dict[str, Any] = {}
                if vopts.history.enabled:
                    messages, history_log = await remote("messages_logged", n, job.seed)
                else:
                    messages = await remote("messages", n, job.seed)
                reply = await driver.request(messages)
                stats.latency_s += reply.latency_s
                held = 0
                if vopts.latency_aware:
                    held = round(reply.latency_s / TICK_S)
                    stats.held_ticks += held
                    terminated, truncated, info, rep = await remote(
                        "step_latency_aware", reply.raw, held, interval, n
                    )
                else:
                    terminated, truncated, info = await remote("step", reply.raw, n)
                    rep = info.get("reply") or {}
                applied = bool(rep)  # False: the episode ended while the reply was still "in flight"
                failure = rep.get("failure")
                if reply.error is not None:
                    stats.transport_errors += 1
                    stats.consecutive_transport += 1
                else:
                    stats.consecutive_transport = 0
                    if applied and failure is None:
                        stats.valid += 1
                    elif failure is not None:
                        stats.parse_failures += 1
                entry = {
                    "decision": n,
                    "tick": rep.get("tick", asked_tick) if not vopts.latency_aware else asked_tick,
                    "raw": reply.raw,
                    "parsed": rep.get("parsed"),
                    "failure": failure,
                    "control": rep.get("control"),
                    "images": reply.images,
                    "held_ticks": held,
                    "applied": applied,
                    **history_log,
                    **reply.log_fields(),
                }
                # Waypoint and meta levels: the plan applied and how the tracker followed it.
                entry.update({k: rep[k] for k in ("plan", "tracking") if k in rep})
                dlog.write(json.dumps(entry, sort_keys=True) + "\n")
                dlog.flush()
                if stats.consecutive_transport >= vopts.max_consecutive_transport_failures:
                    aborted = "server_unavailable"
                    break
                if terminated or truncated:
                    break
        if aborted is None and stats.valid == 0:
            aborted = "no_valid_decision"
        wall = time.perf_counter() - t0
        line: dict[str, Any]
        if aborted is not None:
            line = {
                "key": job.key,
                "scenario": str(job.scenario),
                "category": job.category,
                "seed": job.seed,
                "aborted": aborted,
                "last_error": reply.error_detail,
                "wall_s": round(wall, 4),
                "vlm": stats.line(),
            }
            write_json_atomic(scene_dir / "aborted.json", line)
            return line
        extra: dict[str, Any] = {"vlm": stats.line()}
        if vopts.latency_aware:
            extra["vlm"]["held_ticks"] = stats.held_ticks
        line = await remote("finish", job, opts, stats.decisions, wall, extra)
        if vopts.latency_aware:
            # The env counted every held tick as a decision without a reply; the record keeps the
            # real decisions and failures (the episode log's end line keeps the env's counts).
            record = line["score"]
            record["decisions"] = stats.decisions
            record["parse_failures"] = stats.parse_failures + stats.transport_errors
            record["latency_aware"] = {"held_ticks": stats.held_ticks, "decision_interval_ticks": interval}
            write_json_atomic(scene_dir / "scene_score.json", record)
        await remote("close")
        closed = True
        return line
    finally:
        if not closed:
            # Aborted, or failed: the env (and its SUMO) goes now, whatever state it is in.
            with contextlib.suppress(Exception):
                await remote("close")


def _step_latency_aware(
    env: Any, raw: str | None, held: int, interval: int
) -> tuple[dict[str, Any], bool, bool, dict[str, Any], dict[str, Any]]:
    """One decision on a one-tick env: the previous control held (`None`) for `held` ticks, then
    the reply applied and held for the decision interval. Returns (obs, terminated, truncated,
    info, the reply step's `info["reply"]`, empty if the episode ended first)."""
    obs: dict[str, Any] = {}
    info: dict[str, Any] = {}
    for _ in range(held):
        obs, _, terminated, truncated, info = env.step(None)
        if terminated or truncated:
            return obs, terminated, truncated, info, {}
    obs, _, terminated, truncated, info = env.step(raw)
    rep = info.get("reply") or {}
    for _ in range(interval - 1):
        if terminated or truncated:
            break
        obs, _, terminated, truncated, info = env.step(None)
    return obs, terminated, truncated, info, rep
