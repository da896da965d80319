"""R4 evaluation: drive scenarios with an agent, write append-only results, resume after a crash.

Layout of an output directory:

    manifest.json                     version, git commit, agent, model, decoding, controls,
                                      config, seeds, scenario hashes
    results.jsonl                     one results line (scene score record + run facts) per
                                      finished scenario, or a failure line (`system_error`) per
                                      scenario failed by infrastructure (append-only, synced; the
                                      last line of a key wins)
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
        error.json                    why the scenario failed (kind, exception type, message,
                                      traceback; a worker's pid and exit code), when it did
    summary.json, summary.csv, summary.md   category means (± bootstrap 95 % intervals when a
                                      category has several runs) and the R4 score
    table2.md, table2.csv, r4_summary.csv   the paper's Table 2 row and the `openloop report --r4` input

A scenario counts as done once its results line is in results.jsonl (written last), so a run killed
at any point resumes without redoing or losing finished scenarios; an unfinished or failed
scenario's directory is wiped and the scenario redone from scratch.

Faults (`faults.py`): SUMO killed or crashed, a worker that hangs past `worker_timeout_s`, or any
unexpected exception in one scenario (its env, its agent, its files; a `ConfigError` is not
unexpected: it stops the run) fail that scenario only: it is
recorded with the `system_error` termination (not scored) and an error.json, the batch goes on, the
summary lists it under `failed`, and the run raises `ScenariosFailed` naming it (`r4 evaluate`
exits 4); the same command redoes only the failed scenarios. A results write that fails (disk
full) stops the run with `ResultWriteError` and leaves no partial line.

Up to `jobs` scenarios are in flight at once (asyncio): a VLM agent's requests from all of them
go out from this process's one connection pool and reach the server together so it can batch
them, while each scenario's world stays frozen during its own request, as in the original. Env
steps and message building run in a thread pool (the Rust step releases the GIL); with several
jobs, scenarios with SUMO traffic run their env in a worker process each (`workers.py`: libsumo
runs one simulation per process). `ray_address` runs each scenario as a Ray task instead.

The code: `agents.py` (the registry), `jobs.py` (options, jobs, the suite), `store.py` (results
log, manifest, files), `drive.py` / `vlm_drive.py` (one scenario), `dispatch.py` (where a
scenario runs, progress), `summary.py` (statistics, tables, re-scoring); this module orchestrates.

Batch-abort rule (the original's: "scenarios that produce control traces without valid VLM
inference cause the batch to terminate immediately"): a VLM scenario that ends without a single
valid decision (every reply unparseable or lost) — or whose requests fail
`max_consecutive_transport_failures` decisions in a row (the server is gone) — is not scored. It is
logged to aborted.jsonl, no further scenario is started, the ones in flight finish, and the run
fails with `BatchAborted`; the same command resumes it, redoing the aborted scenarios.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from drivehierarchy._core import ConfigError, DriveHierarchyError
from drivehierarchy.benchmark.r4.agents import AGENTS, VLM_AGENT, AgentRegistry, ConstantAgent
from drivehierarchy.benchmark.r4.dispatch import Dispatch, Progress
from drivehierarchy.benchmark.r4.drive import VIDEO_CAMERA, run_scene
from drivehierarchy.benchmark.r4.faults import ScenariosFailed, SceneFailure
from drivehierarchy.benchmark.r4.jobs import (
    Job,
    RunOptions,
    expected_duration_s,
    jobs_for,
    scenario_key,
    suite_scenarios,
    uses_sumo,
)
from drivehierarchy.benchmark.r4.store import (
    ResultWriteError,
    append_line,
    changed_scenarios,
    check_manifest,
    read_failures,
    read_results,
    write_json_atomic,
    write_manifest,
)
from drivehierarchy.benchmark.r4.summary import (
    bootstrap_ci,
    rescore_dir,
    summarize,
    summary_table,
    write_summary,
)
from drivehierarchy.benchmark.r4.vlm_drive import VlmScene, drive_vlm_scene
from drivehierarchy.benchmark.r4.workers import WorkerDied, WorkerTimeout

__all__ = [
    "AGENTS",
    "VIDEO_CAMERA",
    "VLM_AGENT",
    "AgentRegistry",
    "BatchAborted",
    "ConstantAgent",
    "Job",
    "ResultWriteError",
    "RunOptions",
    "ScenariosFailed",
    "SceneFailure",
    "VlmScene",
    "WorkerDied",
    "WorkerTimeout",
    "bootstrap_ci",
    "drive_vlm_scene",
    "evaluate",
    "evaluate_async",
    "expected_duration_s",
    "jobs_for",
    "read_failures",
    "read_results",
    "rescore_dir",
    "run_scene",
    "scenario_key",
    "suite_scenarios",
    "summarize",
    "summary_table",
    "uses_sumo",
    "write_summary",
]


class BatchAborted(DriveHierarchyError):
    """The batch-abort rule stopped the run (see the module doc); rerun the command to resume."""


async def evaluate_async(
    scenarios: Iterable[Path], out: Path, opts: RunOptions, *, log: Callable[[str], None] = print
) -> list[dict[str, Any]]:
    """Runs every job not yet finished in `out/results.jsonl`, up to `opts.jobs` at once; returns
    all results in suite order. Raises `BatchAborted` under the batch-abort rule and
    `ScenariosFailed` (after writing the summary of the others) when scenarios failed."""
    if opts.jobs < 1:
        raise ConfigError(f"config `jobs` = {opts.jobs!r}: expected ≥ 1")
    is_vlm = opts.agent == VLM_AGENT
    if is_vlm and opts.vlm is None:
        raise ConfigError("config `agent` = 'vlm': needs a server (--base-url and --model)")
    if not is_vlm:
        AGENTS.create(opts.agent)  # unknown names fail before anything is written
    if opts.action_level != "control" and not (
        is_vlm or opts.agent == "expert" or opts.agent.startswith("sb3:")
    ):
        raise ConfigError(
            f"config `agent` = {opts.agent!r}: decides at the control level only; --action-level "
            f"{opts.action_level} takes expert, vlm or an sb3: policy trained at that level"
        )
    if opts.agent.startswith("sb3:"):
        from drivehierarchy.agents.sb3 import model_level

        # A policy drives at the level it was trained at: refused here, before anything is written.
        _, mode = model_level(opts.agent.removeprefix("sb3:"), opts.action_level)
        if opts.config.action_mode != mode:
            raise ConfigError(
                f"config `action_mode` = {opts.config.action_mode!r}: the model {opts.agent} "
                f"drives in action mode {mode!r}"
            )
    jobs = jobs_for(scenarios, opts.seed_list())
    # Every scenario is loaded (a bad file fails here, before anything is written) and its traffic
    # resolved as the env will run it.
    sumo = frozenset(p for p in {j.scenario for j in jobs} if uses_sumo(p, opts.config))
    old_manifest = check_manifest(out, opts)  # a directory of another run is refused before any request
    done = read_results(out) if out.is_dir() and not opts.force else {}
    changed = changed_scenarios(old_manifest, jobs, done)
    if changed:
        raise ConfigError(
            f"{out / 'manifest.json'}: field `scenarios` = {changed!r}: scenario file(s) changed since "
            "they were run here; add --force to redo them (or use a new --out)"
        )
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
    index = {j.key: i for i, j in enumerate(jobs, 1)}
    todo = []
    for job in jobs:
        if job.key in done:
            i = index[job.key]
            log(f"[{i}/{len(jobs)}] {job.key}: done before, skipped (scenario unchanged; --force redoes it)")
        else:
            todo.append(job)
    if opts.jobs > 1:
        # Longest first (by the scenario's reference duration): the suite's end is not held up by
        # long scenarios started last. Results do not depend on the order.
        length = {p: expected_duration_s(p) for p in {j.scenario for j in todo}}
        todo.sort(key=lambda j: -length[j.scenario])
    progress = Progress(len(jobs), len(jobs) - len(todo), opts.progress, done)
    sem = asyncio.Semaphore(opts.jobs)
    aborted: list[dict[str, Any]] = []
    dispatch = Dispatch(opts, out, driver, sumo)
    failed: list[tuple[Job, BaseException]] = []

    async def one(job: Job) -> None:
        async with sem:
            if aborted:
                return  # the batch is stopping: start nothing new
            t0 = time.perf_counter()
            try:
                line = await dispatch.run(job)
            except (ResultWriteError, ConfigError):
                # Nothing more can be recorded / the run's configuration is wrong (every scenario
                # would fail alike): the run stops with the error.
                raise
            except Exception as exc:
                # Infrastructure failed this scenario (SUMO killed, a hung worker, an exception in
                # the scene or its agent): recorded as failed, redone on resume; the others go on.
                fail(job, exc, time.perf_counter() - t0)
                return
            record(job, line)

    def fail(job: Job, exc: BaseException, wall: float) -> None:
        failed.append((job, exc))
        scene_dir = out / "scenes" / job.key
        scene_dir.mkdir(parents=True, exist_ok=True)
        failure = SceneFailure.of(exc)
        write_json_atomic(scene_dir / "error.json", failure.report(job))
        append_line(out / "results.jsonl", failure.line(job, opts, wall))
        log(f"[{index[job.key]}/{len(jobs)}] {job.key}: FAILED, system_error ({type(exc).__name__}: {exc})")
        progress.fail()

    def record(job: Job, line: dict[str, Any]) -> None:
        i = index[job.key]
        if "aborted" in line:
            aborted.append(line)
            append_line(out / "aborted.jsonl", line)
            log(f"[{i}/{len(jobs)}] {job.key}: ABORTED ({line['aborted']}; {line.get('last_error')})")
        else:
            append_line(out / "results.jsonl", line)
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
        dispatch.close(clean=clean)
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
    results = [done[j.key] for j in jobs if j.key in done]
    failed_keys = sorted(j.key for j, _ in failed)
    if results or not failed:
        write_summary(
            out,
            results,
            model=opts.model_name(),
            failed=failed_keys,
            facts=opts.run_facts(),
            controls=opts.controls(),
        )
    if failed:
        job, exc = failed[0]
        more = ", ".join(j.key for j, _ in failed[1:])
        raise ScenariosFailed(
            f"scenario {job.key}: {type(exc).__name__}: {exc}"
            + (f" (and {len(failed) - 1} more: {more})" if more else "")
            + f". {len(done)}/{len(jobs)} scenarios finished; the failed ones are recorded as "
            "system_error (see their error.json); run the same command again to redo only them.",
            failed_keys,
        ) from exc
    return results


def evaluate(
    scenarios: Iterable[Path], out: Path, opts: RunOptions, *, log: Callable[[str], None] = print
) -> list[dict[str, Any]]:
    """Blocking `evaluate_async`."""
    return asyncio.run(evaluate_async(scenarios, out, opts, log=log))
