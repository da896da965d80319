"""Infrastructure failures of one scenario (SUMO killed, a hung worker, an unexpected exception in
the scene or its agent): the failure line the results log records for it (the protocol's
`system_error` termination, not scored) and the `error.json` report in its folder.

An agent that raises is treated like any other scene fault: the scenario is recorded as failed
and redone on resume; the batch goes on. (An agent cannot hurt the score by raising: the failed
scenario is not scored, and the run exits non-zero until it is redone.) Model-server faults are
not scene faults: a failed request holds the previous control and is counted (`vlm_drive.py`)."""

from __future__ import annotations

import traceback
from typing import Any

from drivehierarchy._core import SimulationError
from drivehierarchy.benchmark.r4.jobs import Job, RunOptions
from drivehierarchy.benchmark.r4.workers import WorkerDied, WorkerTimeout


class ScenariosFailed(SimulationError):
    """Some scenarios failed with an infrastructure error (recorded, redone on resume); the others
    finished. `failed` holds their keys."""

    def __init__(self, message: str, failed: list[str]) -> None:
        super().__init__(message)
        self.failed = failed


def failure_kind(exc: BaseException) -> str:
    if isinstance(exc, WorkerTimeout):
        return "worker_timeout"
    if isinstance(exc, WorkerDied):
        return "worker_died"
    return "exception"


def error_report(job: Job, exc: BaseException) -> dict[str, Any]:
    """`error.json`: what failed the scenario, with the traceback (a worker's own traceback is
    attached to its exception as a note) and, for a worker, its pid and exit code."""
    report: dict[str, Any] = {
        "key": job.key,
        "scenario": str(job.scenario),
        "seed": job.seed,
        "kind": failure_kind(exc),
        "type": type(exc).__name__,
        "message": str(exc),
        "traceback": "".join(traceback.format_exception(exc)),
    }
    if isinstance(exc, WorkerDied):
        report["pid"] = exc.pid
        report["exit_code"] = exc.exit_code
    return report


def failure_line(job: Job, opts: RunOptions, exc: BaseException, wall: float) -> dict[str, Any]:
    """The results line of a failed scenario: ends with `system_error`, carries no score."""
    return {
        "key": job.key,
        "scenario": str(job.scenario),
        "category": job.category,
        "agent": opts.agent,
        "seed": job.seed,
        "status": "Failed",
        "termination_reason": "system_error",
        "system_error": {"kind": failure_kind(exc), "type": type(exc).__name__, "message": str(exc)},
        "wall_s": round(wall, 4),
    }
