"""R4 evaluation: drive scenarios with an agent, write append-only results, resume after a crash.

Layout of an output directory:

    manifest.json                     version, git commit, agent, model, decoding, controls,
                                      config, seeds, scenario hashes
    results.jsonl                     one results line (scene score record + run facts) per
                                      finished scenario (append-only, flushed and synced)
    aborted.jsonl                     scenarios aborted by the batch-abort rule (append-only log)
    scenes/<category>__<name>[__s<seed>]/
        scene_score.json              the protocol's record (+ ours)
        episode_log.jsonl             header (route, start, destination, T_ref, parameters), one line
                                      per tick (pose, speed, on-road, contacts), end: the trajectory,
                                      enough to re-score offline
        events.json                   the scored events (collisions, timeouts, red lights, ...)
        decisions.jsonl               one line per decision: index, tick, prompt hash, raw reply,
                                      parsed action or failure kind, latency, attempts, control
        frames/NNNN_front.png, NNNN_bev.png   (--frames)
        episode.gif                   (--video)
    summary.json, summary.csv, summary.md   category means (± bootstrap 95 % intervals when a
                                      category has several runs) and the R4 score
    table2.md, table2.csv, r4_summary.csv   the paper's Table 2 row and the `openloop report --r4` input

A scenario counts as done once its line is in results.jsonl (written last), so a run killed at any
point resumes without redoing or losing finished scenarios; an unfinished scenario's directory is
wiped and the scenario redone from scratch.

Up to `jobs` scenarios are in flight at once (asyncio): a VLM agent's requests from all of them
go out from this process's one connection pool and reach the server together so it can batch
them, while each scenario's world stays frozen during its own request, as in the original. Env
steps and message building run in a thread pool (the Rust step releases the GIL); with several
jobs, scenarios with SUMO traffic run their env in a worker process each (`workers.py`: libsumo
runs one simulation per process). A worker that dies fails its scenario with `WorkerDied` (the
others go on; the run then fails naming it and a rerun redoes it). `ray_address` runs each
scenario as a Ray task instead.

Batch-abort rule (the original's: "scenarios that produce control traces without valid VLM
inference cause the batch to terminate immediately"): a VLM scenario that ends without a single
valid decision (every reply unparseable or lost) — or whose requests fail
`max_consecutive_transport_failures` decisions in a row (the server is gone) — is not scored. It is
logged to aborted.jsonl, no further scenario is started, the ones in flight finish, and the run
fails with `BatchAborted`; the same command resumes it, redoing the aborted scenarios.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import functools
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivehierarchy import __version__, _core
from drivehierarchy._core import ConfigError, DriveHierarchyError, SimulationError
from drivehierarchy.agents.base import Agent, ConstantAgent
from drivehierarchy.agents.expert import ExpertAgent
from drivehierarchy.benchmark.r4.workers import WorkerDied, WorkerPool
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

# The VLM agent needs a server (`RunOptions.vlm`) and is driven by the async harness, not a factory.
VLM_AGENT = "vlm"


class BatchAborted(DriveHierarchyError):
    """The batch-abort rule stopped the run (see the module doc); rerun the command to resume."""


@dataclass(frozen=True)
class Job:
    scenario: Path
    key: str  # "<category>__<name>[__s<seed>]", unique in a run
    seed: int = 0

    @property
    def category(self) -> str:
        return self.scenario.parent.name


@dataclass
class RunOptions:
    agent: str = "expert"
    seed: int = 0  # the first seed; `seeds` runs seed, seed + 1, ...
    frames: bool = False
    video: bool = False
    config: R4Config = field(default_factory=R4Config)
    seeds: int = 1
    jobs: int = 1
    vlm: Any = None  # VLMOptions when agent == "vlm"
    ray_address: str | None = None
    progress: bool = False

    def seed_list(self) -> list[int]:
        if self.seeds < 1:
            raise ConfigError(f"config `seeds` = {self.seeds!r}: expected ≥ 1")
        return [self.seed + i for i in range(self.seeds)]

    def identity(self) -> dict[str, Any]:
        """What must match for a run directory to be resumed."""
        ident: dict[str, Any] = {"agent": self.agent, "seeds": self.seed_list()}
        if self.vlm is not None:
            m = self.vlm.manifest()
            ident["vlm"] = {k: m[k] for k in ("model", "decoding", "payload", "latency_aware")}
        return ident


def scenario_key(path: Path) -> str:
    return f"{path.parent.name}__{path.stem}"


def jobs_for(scenarios: Iterable[Path], seeds: list[int] | None = None) -> list[Job]:
    """One job per scenario and seed; with several seeds the key carries `__s<seed>`."""
    seeds = seeds if seeds is not None else [0]
    jobs, seen = [], set()
    for p in scenarios:
        base = scenario_key(p)
        if base in seen:
            raise ConfigError(f"config `scenarios` = {p}: two scenarios share the key {base!r}")
        seen.add(base)
        for sd in seeds:
            jobs.append(Job(scenario=p, key=base if len(seeds) == 1 else f"{base}__s{sd}", seed=sd))
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
    return _read_jsonl_by_key(out / "results.jsonl")


def _read_jsonl_by_key(path: Path) -> dict[str, dict[str, Any]]:
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


def _write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
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
        "seeds": opts.seed_list(),
        "identity": opts.identity(),
        "vlm": opts.vlm.manifest() if opts.vlm is not None else None,
        "jobs": opts.jobs,
        "ray_address": opts.ray_address,
        "config": json.loads(opts.config.to_json()),
        "scenarios": {
            j.key: {"path": str(j.scenario), "sha256": _sha256(j.scenario), "seed": j.seed} for j in jobs
        },
        "python": sys.version.split()[0],
        "started_unix": time.time(),
    }
    path = out / "manifest.json"
    old = check_manifest(out, opts)
    if old is not None:
        manifest["started_unix"] = old.get("started_unix", manifest["started_unix"])
        manifest["resumed_unix"] = time.time()
    _write_json_atomic(path, manifest)


def check_manifest(out: Path, opts: RunOptions) -> dict[str, Any] | None:
    """The existing manifest of `out`, if any; refuses a directory of another run."""
    path = out / "manifest.json"
    if not path.exists():
        return None
    old: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    old_ident = old.get("identity", {"agent": old.get("agent"), "seeds": [old.get("seed")]})
    ident = opts.identity()
    if old_ident != ident:
        a, b = _flatten(old_ident), _flatten(ident)
        diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        raise ConfigError(
            f"{path}: field `{'/'.join(diff)}` = {[a.get(k) for k in diff]!r}: this output "
            f"directory belongs to another run (asked: {[b.get(k) for k in diff]!r}); use a new --out"
        )
    return old


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _fresh_scene_dir(out: Path, job: Job, frames: bool) -> Path:
    """The scenario's directory, emptied: an interrupted scenario is redone from scratch."""
    scene_dir = out / "scenes" / job.key
    if scene_dir.exists():
        shutil.rmtree(scene_dir)
    scene_dir.mkdir(parents=True)
    if frames:
        (scene_dir / "frames").mkdir()
    return scene_dir


def _save_frames(frames_dir: Path, step: int, obs: dict[str, Any]) -> None:
    from PIL import Image

    for key in ("front", "bev"):
        if key in obs:
            Image.fromarray(obs[key]).save(frames_dir / f"{step:04d}_{key}.png")


def _finish_scene(
    env: Any, job: Job, opts: RunOptions, scene_dir: Path, steps: int, wall: float, extra: dict[str, Any]
) -> dict[str, Any]:
    """Writes the scene's record, events and logs; returns its results line."""
    sim = env.unwrapped.sim
    record = dict(env.unwrapped.score())
    _write_json_atomic(scene_dir / "scene_score.json", record)
    _write_text_atomic(scene_dir / "episode_log.jsonl", sim.episode_log())
    _write_json_atomic(scene_dir / "events.json", record["events"])
    if not (scene_dir / "decisions.jsonl").exists() and hasattr(sim, "decision_log"):
        lines = "".join(json.dumps(d, sort_keys=True) + "\n" for d in sim.decision_log())
        _write_text_atomic(scene_dir / "decisions.jsonl", lines)
    return {
        "key": job.key,
        "scenario": str(job.scenario),
        "category": job.category,
        "agent": opts.agent,
        "seed": job.seed,
        "steps": steps,
        "wall_s": round(wall, 4),
        "score": record,
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
    scene_dir = _fresh_scene_dir(out, job, opts.frames)
    gif = _core.GifWriter(str(scene_dir / "episode.gif"), fps=4) if opts.video else None

    def on_step(step: int, obs: dict[str, Any], reward: float, info: dict[str, Any]) -> None:
        if opts.frames:
            _save_frames(scene_dir / "frames", step, obs)
        if gif is not None:
            gif.push(env.sim.render_camera(VIDEO_CAMERA_JSON))

    t0 = time.perf_counter()
    try:
        result = run_episode(env, agent, seed=job.seed, on_step=on_step)
    finally:
        if gif is not None:
            gif.close()
    line = _finish_scene(env, job, opts, scene_dir, result.steps, time.perf_counter() - t0, {})
    env.close()
    return line


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
        self, scenario: Path, config: R4Config, scene_dir: Path, payload: Any, frames: bool, video: bool
    ) -> None:
        from drivehierarchy.envs.r4 import DriveHierarchyR4Env

        self.env = DriveHierarchyR4Env(scenario=scenario, config=config)
        self.scene_dir = scene_dir
        self.payload = payload
        self.frames = frames
        self.gif = _core.GifWriter(str(scene_dir / "episode.gif"), fps=4) if video else None
        self.obs: dict[str, Any] = {}

    def reset(self, seed: int) -> dict[str, Any]:
        self.obs, info = self.env.reset(seed=seed)
        return dict(info)

    def messages(self, decision: int, seed: int) -> list[dict[str, Any]]:
        from drivehierarchy.agents.vlm.payload import build_messages

        return build_messages(self.obs, decision, self.payload, seed=seed)

    def step(self, raw: str | None, decision: int) -> tuple[bool, bool, dict[str, Any]]:
        self.obs, _reward, terminated, truncated, info = self.env.step(raw)
        self._record(decision)
        return terminated, truncated, dict(info)

    def step_latency_aware(
        self, raw: str | None, held: int, interval: int, decision: int
    ) -> tuple[bool, bool, dict[str, Any], dict[str, Any]]:
        self.obs, terminated, truncated, info, rep = _step_latency_aware(self.env, raw, held, interval)
        self._record(decision)
        return terminated, truncated, dict(info), rep

    def _record(self, decision: int) -> None:
        if self.frames:
            _save_frames(self.scene_dir / "frames", decision, self.obs)
        if self.gif is not None:
            self.gif.push(self.env.sim.render_camera(VIDEO_CAMERA_JSON))

    def finish(
        self, job: Job, opts: RunOptions, steps: int, wall: float, extra: dict[str, Any]
    ) -> dict[str, Any]:
        self._close_gif()
        return _finish_scene(self.env, job, opts, self.scene_dir, steps, wall, extra)

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
    scene_dir = _fresh_scene_dir(out, job, opts.frames)
    args = (job.scenario, config, scene_dir, driver.payload, opts.frames, opts.video)
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
                    **reply.log_fields(),
                }
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
            _write_json_atomic(scene_dir / "aborted.json", line)
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
            _write_json_atomic(scene_dir / "scene_score.json", record)
        await remote("close")
        closed = True
        return line
    finally:
        if not closed:
            # Aborted, or failed: the env (and its SUMO) goes now, whatever state it is in.
            with contextlib.suppress(Exception):
                await remote("close")


TICK_S = 0.05  # the protocol's simulation step


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


def _ray_scene(job: Job, opts: RunOptions, out: Path) -> dict[str, Any]:
    """A Ray task: one scenario, driven as locally (the output directory must be shared)."""
    if opts.agent != VLM_AGENT:
        return run_scene(job, opts, out)

    async def main() -> dict[str, Any]:
        from drivehierarchy.agents.vlm.agent import VLMDriver

        driver = VLMDriver(opts.vlm)
        try:
            with ThreadPoolExecutor(max_workers=2) as pool:
                return await drive_vlm_scene(job, opts, out, driver, pool)
        finally:
            await driver.transport.aclose()

    return asyncio.run(main())


def _ray_init(address: str) -> Any:
    import ray

    if not ray.is_initialized():
        ray.init(
            address=None if address == "local" else address,
            include_dashboard=False,
            log_to_driver=False,
            ignore_reinit_error=True,
        )
    return ray


class _Progress:
    """tqdm bar with the running mean S_R4 and failure counts (stderr; off when not asked)."""

    def __init__(self, total: int, initial: int, enabled: bool, done: dict[str, dict[str, Any]]):
        self.bar = None
        self.scores = [float(r["score"]["score_composed"]) for r in done.values()]
        self.parse = sum(int((r.get("vlm") or {}).get("parse_failures", 0)) for r in done.values())
        self.transport = sum(int((r.get("vlm") or {}).get("transport_errors", 0)) for r in done.values())
        self.aborted = 0
        self.failed = 0
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(
                total=total, initial=initial, unit="scenario", file=sys.stderr, dynamic_ncols=True
            )
            self._postfix()

    def _postfix(self) -> None:
        if self.bar is not None:
            mean = float(np.mean(self.scores)) if self.scores else float("nan")
            extra = {"failed": self.failed} if self.failed else {}
            self.bar.set_postfix(
                mean_S_R4=f"{mean:.2f}",
                parse_fail=self.parse,
                transport=self.transport,
                aborted=self.aborted,
                **extra,
            )

    def update(self, line: dict[str, Any]) -> None:
        vlm = line.get("vlm") or {}
        self.parse += int(vlm.get("parse_failures", 0))
        self.transport += int(vlm.get("transport_errors", 0))
        if "aborted" in line:
            self.aborted += 1
        else:
            self.scores.append(float(line["score"]["score_composed"]))
        if self.bar is not None:
            self.bar.update(1)
            self._postfix()

    def fail(self) -> None:
        """A scenario that failed with an error (its worker died); redone on resume."""
        self.failed += 1
        if self.bar is not None:
            self.bar.update(1)
            self._postfix()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


async def evaluate_async(
    scenarios: Iterable[Path], out: Path, opts: RunOptions, *, log: Callable[[str], None] = print
) -> list[dict[str, Any]]:
    """Runs every job not yet in `out/results.jsonl`, up to `opts.jobs` at once; returns all
    results in suite order. Raises `BatchAborted` under the batch-abort rule."""
    if opts.jobs < 1:
        raise ConfigError(f"config `jobs` = {opts.jobs!r}: expected ≥ 1")
    is_vlm = opts.agent == VLM_AGENT
    if is_vlm and opts.vlm is None:
        raise ConfigError("config `agent` = 'vlm': needs a server (--base-url and --model)")
    if not is_vlm:
        AGENTS.create(opts.agent)  # unknown names fail before anything is written
    jobs = jobs_for(scenarios, opts.seed_list())
    check_manifest(out, opts)  # a directory of another run is refused before any request
    driver = None
    if is_vlm:
        from drivehierarchy.agents.vlm.agent import VLMDriver

        driver = VLMDriver(opts.vlm)
        try:
            await driver.transport.health_check()  # a clear error before anything is written
        except BaseException:
            await driver.transport.aclose()
            raise
    out.mkdir(parents=True, exist_ok=True)
    write_manifest(out, jobs, opts)
    done = read_results(out)
    index = {j.key: i for i, j in enumerate(jobs, 1)}
    todo = []
    for job in jobs:
        if job.key in done:
            log(f"[{index[job.key]}/{len(jobs)}] {job.key}: done before, skipped")
        else:
            todo.append(job)
    if opts.jobs > 1:
        # Longest first (by the scenario's reference duration): the suite's end is not held up by
        # long scenarios started last. Results do not depend on the order.
        length = {p: expected_duration_s(p) for p in {j.scenario for j in todo}}
        todo.sort(key=lambda j: -length[j.scenario])
    progress = _Progress(len(jobs), len(jobs) - len(todo), opts.progress, done)
    sem = asyncio.Semaphore(opts.jobs)
    aborted: list[dict[str, Any]] = []
    ray = _ray_init(opts.ray_address) if opts.ray_address else None
    remote = ray.remote(_ray_scene) if ray is not None else None
    pool = ThreadPoolExecutor(max_workers=max(2, opts.jobs), thread_name_prefix="r4")
    loop = asyncio.get_running_loop()

    # libsumo runs one simulation per process: with several jobs, scenarios with SUMO traffic run
    # in worker processes (one libsumo each; Ray tasks have their own processes anyway).
    workers = WorkerPool() if remote is None and opts.jobs > 1 else None
    failed: list[tuple[Job, BaseException]] = []

    async def one(job: Job) -> None:
        async with sem:
            if aborted:
                return  # the batch is stopping: start nothing new
            try:
                await run_one(job)
            except WorkerDied as exc:
                # That scenario is lost (redone from scratch on resume); the others go on.
                failed.append((job, exc))
                scene_dir = out / "scenes" / job.key
                scene_dir.mkdir(parents=True, exist_ok=True)
                _write_json_atomic(scene_dir / "error.json", {"key": job.key, "error": str(exc)})
                log(f"[{index[job.key]}/{len(jobs)}] {job.key}: FAILED ({exc})")
                progress.fail()

    async def run_one(job: Job) -> None:
        in_worker = workers is not None and uses_sumo(job.scenario, opts.config)
        if remote is not None:
            line = await remote.remote(job, opts, out)
        elif in_worker:
            assert workers is not None
            async with workers.worker(job.key) as w:
                if driver is not None:
                    line = await drive_vlm_scene(job, opts, out, driver, pool, worker=w)
                else:
                    line = await w.call(pool, "run", run_scene, job, opts, out)
        elif driver is not None:
            line = await drive_vlm_scene(job, opts, out, driver, pool)
        else:
            line = await loop.run_in_executor(pool, run_scene, job, opts, out)
        i = index[job.key]
        if "aborted" in line:
            aborted.append(line)
            _append_line(out / "aborted.jsonl", line)
            log(f"[{i}/{len(jobs)}] {job.key}: ABORTED ({line['aborted']}; {line.get('last_error')})")
        else:
            _append_line(out / "results.jsonl", line)
            done[job.key] = line
            s = line["score"]
            log(
                f"[{i}/{len(jobs)}] {job.key}: S_R4 {s['score_composed']:.2f} ({s['status']}, "
                f"{s['termination_reason']}) in {line['wall_s']:.2f} s"
            )
        progress.update(line)

    clean = False
    try:
        await asyncio.gather(*(one(j) for j in todo))
        clean = True
    finally:
        progress.close()
        if workers is not None:
            # Torn down by an error: kill the workers so no thread waits on one.
            workers.close(kill=not clean)
        pool.shutdown(wait=True)
        if driver is not None:
            await driver.transport.aclose()
    if aborted:
        first = aborted[0]
        v = first.get("vlm", {})
        raise BatchAborted(
            f"scenario {first['key']}: {first['aborted']} ({v.get('decisions')} decisions, "
            f"{v.get('transport_errors')} transport errors, {v.get('parse_failures')} unparseable; "
            f"last error: {first.get('last_error')}). Batch aborted as the original does: "
            f"{len(done)}/{len(jobs)} scenarios finished; run the same command again to resume."
        )
    if failed:
        job, exc = failed[0]
        more = ", ".join(j.key for j, _ in failed[1:])
        raise SimulationError(
            f"scenario {job.key}: {exc}"
            + (f" (and {len(failed) - 1} more: {more})" if more else "")
            + f". {len(done)}/{len(jobs)} scenarios finished; run the same command again to resume "
            "(failed scenarios are redone from scratch)."
        ) from exc
    results = [done[j.key] for j in jobs]
    write_summary(out, results, model=_model_name(opts))
    return results


_SUMO_MODE = re.compile(r'^\s*\[traffic\][^\[]*?^\s*mode\s*=\s*"sumo"', re.MULTILINE | re.DOTALL)


def uses_sumo(scenario: Path, config: R4Config) -> bool:
    """Whether the scenario runs SUMO background traffic (config override, else its `[traffic]`)."""
    mode = getattr(config, "traffic", None)
    if mode is not None:
        return bool(mode == "sumo")
    return bool(_SUMO_MODE.search(scenario.read_text(encoding="utf-8")))


_REFERENCE_DURATION = re.compile(r"^\s*reference_duration_s\s*=\s*([0-9.eE+-]+)", re.MULTILINE)


def expected_duration_s(scenario: Path) -> float:
    """The scenario's `reference_duration_s` (0 when it has none): a proxy for its length."""
    m = _REFERENCE_DURATION.search(scenario.read_text(encoding="utf-8"))
    try:
        return float(m.group(1)) if m else 0.0
    except ValueError:
        return 0.0


def evaluate(
    scenarios: Iterable[Path], out: Path, opts: RunOptions, *, log: Callable[[str], None] = print
) -> list[dict[str, Any]]:
    """Blocking `evaluate_async`."""
    return asyncio.run(evaluate_async(scenarios, out, opts, log=log))


def _model_name(opts: RunOptions) -> str:
    return opts.vlm.served_model if opts.vlm is not None else opts.agent


BOOTSTRAP_RESAMPLES = 2000


def bootstrap_ci(values: list[float], seed: int = 0) -> tuple[float, float] | None:
    """Percentile bootstrap 95 % interval of the mean (fixed seed: the summary is reproducible);
    None with fewer than two values."""
    if len(values) < 2:
        return None
    rng = np.random.default_rng(seed)
    arr = np.asarray(values, dtype=np.float64)
    means = arr[rng.integers(0, len(arr), (BOOTSTRAP_RESAMPLES, len(arr)))].mean(axis=1)
    lo, hi = np.percentile(means, [2.5, 97.5])
    return float(lo), float(hi)


def summarize(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Category means (± bootstrap 95 % intervals over the category's runs: scenarios × seeds)
    and the model's R4 score (mean of the categories present, with an interval from resampling
    within every category)."""
    by_cat: dict[str, list[float]] = {}
    for r in results:
        by_cat.setdefault(r["category"], []).append(float(r["score"]["score_composed"]))
    by_cat = dict(sorted(by_cat.items()))
    cats = {c: float(np.mean(v)) for c, v in by_cat.items()}
    ci = {c: bootstrap_ci(v) for c, v in by_cat.items()}
    r4_ci = None
    if by_cat and any(len(v) > 1 for v in by_cat.values()):
        rng = np.random.default_rng(0)
        cat_means = [
            np.asarray(v)[rng.integers(0, len(v), (BOOTSTRAP_RESAMPLES, len(v)))].mean(axis=1)
            for v in by_cat.values()
        ]
        lo, hi = np.percentile(np.mean(cat_means, axis=0), [2.5, 97.5])
        r4_ci = [float(lo), float(hi)]
    vlm = [r["vlm"] for r in results if r.get("vlm")]
    out: dict[str, Any] = {
        "categories": cats,
        "categories_ci95": {c: list(v) if v is not None else None for c, v in ci.items()},
        "counts": {c: len(v) for c, v in by_cat.items()},
        "r4_score": float(np.mean(list(cats.values()))) if cats else 0.0,
        "r4_score_ci95": r4_ci,
        "scenarios": len(results),
        "seeds": sorted({int(r.get("seed", 0)) for r in results}),
        "completed": sum(r["score"]["termination_reason"] == "destination_reached" for r in results),
    }
    if vlm:
        out["decisions"] = sum(v["decisions"] for v in vlm)
        out["parse_failures"] = sum(v["parse_failures"] for v in vlm)
        out["transport_errors"] = sum(v["transport_errors"] for v in vlm)
    return out


def write_summary(out: Path, results: list[dict[str, Any]], model: str | None = None) -> dict[str, Any]:
    from drivehierarchy.benchmark.r4 import report

    if not results:
        raise ConfigError(f"{out}: no finished scenario to summarize")
    summary = summarize(results)
    if model is not None:
        summary["model"] = model
    _write_json_atomic(out / "summary.json", summary)
    rows = [
        "scenario,category,seed,status,termination_reason,score_route,score_safety,score_efficiency,"
        "score_composed"
    ]
    for r in results:
        s = r["score"]
        rows.append(
            f"{r['key']},{r['category']},{r.get('seed', 0)},{s['status']},{s['termination_reason']},"
            f"{s['score_route']:.4f},{s['score_safety']:.4f},{s['score_efficiency']:.4f},{s['score_composed']:.4f}"
        )
    _write_text_atomic(out / "summary.csv", "\n".join(rows) + "\n")
    _write_text_atomic(out / "summary.md", summary_table(results, summary))
    report.write_run_tables(out, summary, model or "model")
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
    lines += ["", "| category | runs | mean S_R4 | 95 % CI |", "|---|---:|---:|---|"]
    for c, v in summary["categories"].items():
        ci = summary.get("categories_ci95", {}).get(c)
        ci_text = f"[{ci[0]:.2f}, {ci[1]:.2f}]" if ci else "–"
        lines.append(f"| {c} | {summary['counts'][c]} | {v:.2f} | {ci_text} |")
    r4_ci = summary.get("r4_score_ci95")
    r4_ci_text = f"[{r4_ci[0]:.2f}, {r4_ci[1]:.2f}]" if r4_ci else "–"
    lines.append(
        f"| **R4 (mean of categories)** | {summary['scenarios']} | **{summary['r4_score']:.2f}** "
        f"| {r4_ci_text} |"
    )
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
