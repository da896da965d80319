"""Where a scenario runs: in the harness's thread pool, in a worker process (SUMO traffic with
several jobs: libsumo runs one simulation per process), or as a Ray task; and the progress bar."""

from __future__ import annotations

import asyncio
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from drivehierarchy.benchmark.r4.agents import VLM_AGENT
from drivehierarchy.benchmark.r4.drive import run_scene
from drivehierarchy.benchmark.r4.jobs import Job, RunOptions
from drivehierarchy.benchmark.r4.vlm_drive import drive_vlm_scene
from drivehierarchy.benchmark.r4.workers import WorkerPool


class Dispatch:
    """Runs one job where it belongs and returns its results line (or an `aborted` line). Owns the
    thread pool, the worker processes and the Ray handle of a run; `close` releases them."""

    def __init__(self, opts: RunOptions, out: Path, driver: Any, sumo: frozenset[Path] = frozenset()) -> None:
        self.opts = opts
        self.sumo = sumo  # the scenarios with SUMO traffic (`jobs.uses_sumo`)
        self.out = out
        self.driver = driver
        ray = _ray_init(opts.ray_address) if opts.ray_address else None
        self.remote = ray.remote(_ray_scene) if ray is not None else None
        self.pool = ThreadPoolExecutor(max_workers=max(2, opts.jobs), thread_name_prefix="r4")
        # libsumo runs one simulation per process: with several jobs, scenarios with SUMO traffic
        # run in worker processes (one libsumo each; Ray tasks have their own processes anyway).
        self.workers = WorkerPool(opts.worker_timeout_s) if self.remote is None and opts.jobs > 1 else None

    async def run(self, job: Job) -> dict[str, Any]:
        opts, out, driver, pool = self.opts, self.out, self.driver, self.pool
        if self.remote is not None:
            line: dict[str, Any] = await self.remote.remote(job, opts, out)
            return line
        if self.workers is not None and job.scenario in self.sumo:
            async with self.workers.worker(job.key) as w:
                if driver is not None:
                    return await drive_vlm_scene(job, opts, out, driver, pool, worker=w)
                line = await w.call(pool, "run", run_scene, job, opts, out)
                return line
        if driver is not None:
            return await drive_vlm_scene(job, opts, out, driver, pool)
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(pool, run_scene, job, opts, out)

    def close(self, *, clean: bool) -> None:
        if self.workers is not None:
            # Torn down by an error: kill the workers so no thread waits on one.
            self.workers.close(kill=not clean)
        self.pool.shutdown(wait=True)


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


class Progress:
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
