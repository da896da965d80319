"""R4 evaluation: drive scenarios with an agent, write append-only results, resume after a crash.

Layout of an output directory:

    manifest.json                     version, git commit, agent, config, seeds, scenario hashes
    results.jsonl                     one scene score record per finished scenario (append-only)
    scenes/<category>__<name>/
        scene_score.json              the protocol's record (+ ours)
        episode_log.jsonl             header (route, start, destination, T_ref, parameters), one line
                                      per tick (pose, speed, on-road, contacts), end: the trajectory,
                                      enough to re-score offline
        events.json                   the scored events (collisions, timeouts, red lights, ...)
        frames/NNNN_front.png, NNNN_bev.png   (--frames)
        episode.gif                   (--video)
    summary.csv, summary.md           category means and the R4 score (mean of categories)

A scenario counts as done once its line is in results.jsonl (written last, flushed and synced), so
a run killed at any point resumes without redoing or losing finished scenarios.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivehierarchy import __version__, _core
from drivehierarchy._core import ConfigError
from drivehierarchy.agents.base import Agent, ConstantAgent
from drivehierarchy.agents.expert import ExpertAgent
from drivehierarchy.envs.config import CameraConfig, R4Config
from drivehierarchy.scenarios import builtin_scenarios


class AgentRegistry:
    """Named agent factories; registering a name twice is an error."""

    def __init__(self) -> None:
        self._factories: dict[str, Callable[[], Agent]] = {}
        # "prefix:ARG" names (e.g. "sb3:runs/ppo/model.zip") → factory(ARG)
        self._prefixes: dict[str, Callable[[str], Agent]] = {}

    def register(self, name: str, factory: Callable[[], Agent]) -> None:
        if name in self._factories:
            raise ValueError(f"agent {name!r} is already registered")
        self._factories[name] = factory

    def register_prefix(self, prefix: str, factory: Callable[[str], Agent]) -> None:
        if prefix in self._prefixes:
            raise ValueError(f"agent prefix {prefix!r} is already registered")
        self._prefixes[prefix] = factory

    def create(self, name: str) -> Agent:
        prefix, sep, arg = name.partition(":")
        if sep and prefix in self._prefixes:
            return self._prefixes[prefix](arg)
        try:
            return self._factories[name]()
        except KeyError:
            raise ConfigError(
                f"config `agent` = {name!r}: unknown agent (known: {', '.join(sorted(self._factories))})"
            ) from None

    def names(self) -> list[str]:
        return sorted(self._factories) + [f"{p}:..." for p in sorted(self._prefixes)]


# `--video`: the protocol's front camera at half size, one frame per decision (4 Hz).
VIDEO_CAMERA_JSON = json.dumps(dataclasses.asdict(CameraConfig(width=400, height=225)))

AGENTS = AgentRegistry()
AGENTS.register("expert", ExpertAgent)
AGENTS.register("zero", lambda: ConstantAgent([0.0, 0.0], name="zero"))
AGENTS.register("constant8", lambda: ConstantAgent([0.0, 8.0], name="constant8"))


def _sb3_agent(path: str) -> Agent:
    from drivehierarchy.agents.sb3 import Sb3Agent  # needs the `rl` extra; imported on use

    return Sb3Agent(path)


AGENTS.register_prefix("sb3", _sb3_agent)


@dataclass(frozen=True)
class Job:
    scenario: Path
    key: str  # "<category>__<name>", unique in a run


@dataclass
class RunOptions:
    agent: str = "expert"
    seed: int = 0
    frames: bool = False
    video: bool = False
    config: R4Config = field(default_factory=R4Config)


def scenario_key(path: Path) -> str:
    return f"{path.parent.name}__{path.stem}"


def jobs_for(scenarios: Iterable[Path]) -> list[Job]:
    jobs, seen = [], set()
    for p in scenarios:
        key = scenario_key(p)
        if key in seen:
            raise ConfigError(f"config `scenarios` = {p}: two scenarios share the key {key!r}")
        seen.add(key)
        jobs.append(Job(scenario=p, key=key))
    return jobs


def suite_scenarios(suite: str) -> list[Path]:
    """`builtin` (the shipped suite), a folder of `*/*.toml`, or a single file."""
    if suite == "builtin":
        return builtin_scenarios()
    root = Path(suite)
    if root.is_file():
        return [root]
    found = sorted(root.glob("*/*.toml")) + sorted(root.glob("*.toml"))
    if not found:
        raise ConfigError(f"config `suite` = {suite!r}: no scenario files (*.toml) found under {root}")
    return found


def read_results(out: Path) -> dict[str, dict[str, Any]]:
    """Finished scenarios of a run by key; a torn last line (killed mid-write) is ignored."""
    path = out / "results.jsonl"
    done: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return done
    with path.open("r", encoding="utf-8") as fh:
        for line in fh:
            if not line.endswith("\n"):
                break  # torn write: the scenario is redone
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            done.setdefault(rec["key"], rec)
    return done


def _append_line(path: Path, record: dict[str, Any]) -> None:
    data = json.dumps(record, sort_keys=True) + "\n"
    # A line torn by a kill is closed first (and then skipped as invalid JSON), never extended.
    if path.exists() and path.stat().st_size > 0:
        with path.open("rb") as fh:
            fh.seek(-1, os.SEEK_END)
            if fh.read(1) != b"\n":
                data = "\n" + data
    with path.open("a", encoding="utf-8") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def _write_json_atomic(path: Path, obj: Any) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _git_commit() -> str | None:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        )
    except OSError:
        return None
    return out.stdout.strip() or None


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_manifest(out: Path, jobs: list[Job], opts: RunOptions) -> None:
    manifest = {
        "drivehierarchy_version": __version__,
        "git_commit": _git_commit(),
        "agent": opts.agent,
        "seed": opts.seed,
        "config": json.loads(opts.config.to_json()),
        "scenarios": {j.key: {"path": str(j.scenario), "sha256": _sha256(j.scenario)} for j in jobs},
        "python": sys.version.split()[0],
        "started_unix": time.time(),
    }
    path = out / "manifest.json"
    if path.exists():
        old = json.loads(path.read_text(encoding="utf-8"))
        if old.get("agent") != opts.agent or old.get("seed") != opts.seed:
            raise ConfigError(
                f"{path}: field `agent`/`seed` = {old.get('agent')!r}/{old.get('seed')!r}: this output "
                f"directory belongs to another run (asked: {opts.agent!r}/{opts.seed!r}); use a new --out"
            )
        manifest["started_unix"] = old.get("started_unix", manifest["started_unix"])
        manifest["resumed_unix"] = time.time()
    _write_json_atomic(path, manifest)


def run_scene(job: Job, opts: RunOptions, out: Path) -> dict[str, Any]:
    """Drives one scenario to its end and writes its files; returns its results line."""
    from drivehierarchy.agents.base import run_episode
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    config = opts.config
    agent = AGENTS.create(opts.agent)
    if not opts.frames and not getattr(agent, "uses_images", True):
        # Agents that never look at images (the expert) drive much faster without them; the
        # video renders its own small frames.
        config = config.replace(front=None, bev=None)
    env = DriveHierarchyR4Env(scenario=job.scenario, config=config)
    scene_dir = out / "scenes" / job.key
    frames_dir = scene_dir / "frames"
    if opts.frames:
        frames_dir.mkdir(parents=True, exist_ok=True)
    scene_dir.mkdir(parents=True, exist_ok=True)
    gif = _core.GifWriter(str(scene_dir / "episode.gif"), fps=4) if opts.video else None

    def on_step(step: int, obs: dict[str, Any], reward: float, info: dict[str, Any]) -> None:
        if opts.frames:
            from PIL import Image

            for key in ("front", "bev"):
                if key in obs:
                    Image.fromarray(obs[key]).save(frames_dir / f"{step:04d}_{key}.png")
        if gif is not None:
            gif.push(env.sim.render_camera(VIDEO_CAMERA_JSON))

    t0 = time.perf_counter()
    try:
        result = run_episode(env, agent, seed=opts.seed, on_step=on_step)
    finally:
        if gif is not None:
            gif.close()
    wall = time.perf_counter() - t0
    record = dict(result.score)
    _write_json_atomic(scene_dir / "scene_score.json", record)
    (scene_dir / "episode_log.jsonl").write_text(env.unwrapped.sim.episode_log(), encoding="utf-8")
    _write_json_atomic(scene_dir / "events.json", record["events"])
    env.close()
    return {
        "key": job.key,
        "scenario": str(job.scenario),
        "category": job.scenario.parent.name,
        "agent": opts.agent,
        "seed": opts.seed,
        "steps": result.steps,
        "wall_s": round(wall, 4),
        "score": record,
    }


def evaluate(
    scenarios: Iterable[Path], out: Path, opts: RunOptions, *, log: Callable[[str], None] = print
) -> list[dict[str, Any]]:
    """Runs every scenario not yet in `out/results.jsonl`; returns all results in suite order."""
    out.mkdir(parents=True, exist_ok=True)
    jobs = jobs_for(scenarios)
    write_manifest(out, jobs, opts)
    done = read_results(out)
    for i, job in enumerate(jobs, 1):
        if job.key in done:
            log(f"[{i}/{len(jobs)}] {job.key}: done before, skipped")
            continue
        line = run_scene(job, opts, out)
        _append_line(out / "results.jsonl", line)
        done[job.key] = line
        s = line["score"]
        log(
            f"[{i}/{len(jobs)}] {job.key}: S_R4 {s['score_composed']:.2f} ({s['status']}, "
            f"{s['termination_reason']}) in {line['wall_s']:.2f} s"
        )
    results = [done[j.key] for j in jobs]
    write_summary(out, results)
    return results


def summarize(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Category means and the model's R4 score (mean of the categories present)."""
    by_cat: dict[str, list[float]] = {}
    for r in results:
        by_cat.setdefault(r["category"], []).append(float(r["score"]["score_composed"]))
    cats = {c: float(np.mean(v)) for c, v in sorted(by_cat.items())}
    return {
        "categories": cats,
        "counts": {c: len(v) for c, v in sorted(by_cat.items())},
        "r4_score": float(np.mean(list(cats.values()))) if cats else 0.0,
        "scenarios": len(results),
        "completed": sum(r["score"]["termination_reason"] == "destination_reached" for r in results),
    }


def write_summary(out: Path, results: list[dict[str, Any]]) -> dict[str, Any]:
    summary = summarize(results)
    _write_json_atomic(out / "summary.json", summary)
    rows = [
        "scenario,category,status,termination_reason,score_route,score_safety,score_efficiency,score_composed"
    ]
    for r in results:
        s = r["score"]
        rows.append(
            f"{r['key']},{r['category']},{s['status']},{s['termination_reason']},"
            f"{s['score_route']:.4f},{s['score_safety']:.4f},{s['score_efficiency']:.4f},{s['score_composed']:.4f}"
        )
    (out / "summary.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    (out / "summary.md").write_text(summary_table(results, summary), encoding="utf-8")
    return summary


def summary_table(results: list[dict[str, Any]], summary: dict[str, Any] | None = None) -> str:
    summary = summary or summarize(results)
    lines = [
        "| scenario | status | termination | route | safety | efficiency | S_R4 |",
        "|---|---|---|---:|---:|---:|---:|",
    ]
    for r in results:
        s = r["score"]
        lines.append(
            f"| {r['key']} | {s['status']} | {s['termination_reason']} | {s['score_route']:.1f} | "
            f"{s['score_safety']:.3f} | {s['score_efficiency']:.3f} | {s['score_composed']:.2f} |"
        )
    lines += ["", "| category | scenarios | mean S_R4 |", "|---|---:|---:|"]
    for c, v in summary["categories"].items():
        lines.append(f"| {c} | {summary['counts'][c]} | {v:.2f} |")
    lines.append(f"| **R4 (mean of categories)** | {summary['scenarios']} | **{summary['r4_score']:.2f}** |")
    return "\n".join(lines) + "\n"


def rescore_dir(out: Path) -> list[dict[str, Any]]:
    """Recomputes every scene score of a run from its episode logs, without simulating."""
    scenes = sorted((out / "scenes").glob("*/episode_log.jsonl"))
    if not scenes:
        single = out / "episode_log.jsonl"
        if single.exists():
            scenes = [single]
        else:
            raise ConfigError(f"{out}: no episode_log.jsonl found (expected scenes/*/episode_log.jsonl)")
    rescored = []
    for log_path in scenes:
        record = json.loads(_core.rescore(log_path.read_text(encoding="utf-8")))
        _write_json_atomic(log_path.parent / "scene_score.rescored.json", record)
        rescored.append({"key": log_path.parent.name, "score": record})
    return rescored
