"""Infrastructure failures of one scenario (SUMO killed, a hung worker, an unexpected exception in
the scene or its agent): the failure line the results log records for it (the protocol's
`system_error` termination, not scored) and the `error.json` report in its folder.

An agent that raises is treated like any other scene fault: the scenario is recorded as failed
and redone on resume; the batch goes on. (An agent cannot dodge a bad scenario by raising: the
run exits non-zero and its summary lists the scenario until a rerun scores it.) A `ConfigError`
is not a scene fault: the run's configuration is wrong and the run stops. Model-server faults are
not scene faults either: a failed request holds the previous control and is counted
(`vlm_drive.py`)."""

from __future__ import annotations

import dataclasses
import traceback
from dataclasses import dataclass
from typing import Any, Literal

from drivehierarchy._core import SimulationError
from drivehierarchy.benchmark.r4.jobs import Job, RunOptions
from drivehierarchy.benchmark.r4.workers import WorkerDied, WorkerTimeout


class ScenariosFailed(SimulationError):
    """Some scenarios failed with an infrastructure error (recorded, redone on resume); the others
    finished. `failed` holds their keys."""

    def __init__(self, message: str, failed: list[str]) -> None:
        super().__init__(message)
        self.failed = failed


FailureKind = Literal["worker_died", "worker_timeout", "exception"]


@dataclass(frozen=True)
class SceneFailure:
    """Why infrastructure failed one scenario (typed; serialised into its results line and its
    `error.json`)."""

    kind: FailureKind
    type: str  # the exception's class name
    message: str
    traceback: str  # a worker's own traceback is attached to its exception as a note
    pid: int | None = None  # the worker process, for worker faults
    exit_code: int | None = None  # the worker's exit status (-N: killed by signal N)

    @classmethod
    def of(cls, exc: BaseException) -> SceneFailure:
        kind: FailureKind = "exception"
        pid = code = None
        if isinstance(exc, WorkerDied):
            kind = "worker_timeout" if isinstance(exc, WorkerTimeout) else "worker_died"
            pid, code = exc.pid, exc.exit_code
        tb = "".join(traceback.format_exception(exc))
        return cls(kind, type(exc).__name__, str(exc), tb, pid, code)

    def report(self, job: Job) -> dict[str, Any]:
        """`error.json`."""
        fields = {k: v for k, v in dataclasses.asdict(self).items() if v is not None}
        return {"key": job.key, "scenario": str(job.scenario), "seed": job.seed, **fields}

    def line(self, job: Job, opts: RunOptions, wall: float) -> dict[str, Any]:
        """The results line of the failed scenario: ends with `system_error`, carries no score."""
        return {
            "key": job.key,
            "scenario": str(job.scenario),
            "category": job.category,
            "agent": opts.agent,
            "seed": job.seed,
            "status": "Failed",
            "termination_reason": "system_error",
            "system_error": {"kind": self.kind, "type": self.type, "message": self.message},
            "wall_s": round(wall, 4),
        }
