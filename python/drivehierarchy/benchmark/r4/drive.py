"""One scenario driven by a registry agent, and what every scene driver writes at its end (the
record, events, logs, the results line)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from drivehierarchy import _core
from drivehierarchy.benchmark.r4.agents import AGENTS
from drivehierarchy.benchmark.r4.jobs import Job, RunOptions
from drivehierarchy.benchmark.r4.store import fresh_scene_dir, write_json_atomic, write_text_atomic
from drivehierarchy.envs.config import CameraConfig

# `--video`: the protocol's front camera at half size, one frame per decision (4 Hz).
VIDEO_CAMERA = CameraConfig(width=400, height=225)


def save_frames(frames_dir: Path, step: int, obs: dict[str, Any]) -> None:
    from PIL import Image

    for key in ("front", "bev"):
        if key in obs:
            Image.fromarray(obs[key]).save(frames_dir / f"{step:04d}_{key}.png")


def finish_scene(
    env: Any, job: Job, opts: RunOptions, scene_dir: Path, steps: int, wall: float, extra: dict[str, Any]
) -> dict[str, Any]:
    """Writes the scene's record, events and logs; returns its results line."""
    sim = env.unwrapped.sim
    record = dict(env.unwrapped.score())
    write_json_atomic(scene_dir / "scene_score.json", record)
    sim.write_episode_log(scene_dir / "episode_log.jsonl")
    write_json_atomic(scene_dir / "events.json", record["events"])
    if not (scene_dir / "decisions.jsonl").exists() and hasattr(sim, "decision_log"):
        lines = "".join(json.dumps(d, sort_keys=True) + "\n" for d in sim.decision_log())
        write_text_atomic(scene_dir / "decisions.jsonl", lines)
    return {
        "key": job.key,
        "scenario": str(job.scenario),
        "category": job.category,
        "agent": opts.agent,
        "seed": job.seed,
        "steps": steps,
        "wall_s": round(wall, 4),
        "score": record,
        **opts.run_facts(),
        **extra,
    }


def run_scene(job: Job, opts: RunOptions, out: Path) -> dict[str, Any]:
    """Drives one scenario with a registry agent to its end and writes its files; returns its
    results line."""
    from drivehierarchy.agents.base import run_episode
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    config = opts.config
    agent = AGENTS.create(opts.agent)
    if not opts.frames and not getattr(agent, "uses_images", True):
        # Agents that never look at images (the expert) drive much faster without them; the
        # video renders its own small frames.
        config = config.replace(front=None, bev=None)
    env = DriveHierarchyR4Env(scenario=job.scenario, config=config)
    gif = None
    try:  # the env (and its SUMO) is closed however the scene ends: the next one may need libsumo
        scene_dir = fresh_scene_dir(out, job, opts.frames)
        gif = _core.GifWriter(str(scene_dir / "episode.gif"), fps=4) if opts.video else None

        def on_step(step: int, obs: dict[str, Any], reward: float, info: dict[str, Any]) -> None:
            if opts.frames:
                save_frames(scene_dir / "frames", step, obs)
            if gif is not None:
                gif.push(env.sim.render_camera(VIDEO_CAMERA))

        t0 = time.perf_counter()
        result = run_episode(env, agent, seed=job.seed, on_step=on_step)
        wall = time.perf_counter() - t0
        if gif is not None:
            gif.close()
            gif = None
        return finish_scene(env, job, opts, scene_dir, result.steps, wall, {})
    finally:
        if gif is not None:
            gif.close()
        env.close()
