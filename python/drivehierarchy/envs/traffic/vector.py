"""SUMO envs vectorised over processes.

libsumo holds one simulation per process, so SUMO-mode envs vectorise with one process per env:
`gymnasium.vector.AsyncVectorEnv` works as is. `TrafficVectorEnv` adds one thing: when a worker
process dies (SUMO crashed, the process was killed), the next call raises a `SimulationError`
naming the worker and its exit code instead of a bare `BrokenPipeError` / `EOFError`. It never
waits on a dead worker.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym

from drivehierarchy._core import SimulationError

_PIPE_ERRORS = (BrokenPipeError, EOFError, ConnectionError)


class TrafficVectorEnv(gym.vector.AsyncVectorEnv):
    """`AsyncVectorEnv` that reports dead workers clearly (see the module docs)."""

    def _check_workers(self, cause: BaseException | None = None) -> None:
        for i, p in enumerate(self.processes):
            p.join(0)
            if not p.is_alive():
                raise SimulationError(
                    f"vector env worker {i} (pid {p.pid}) died with exit code {p.exitcode}; "
                    "its SUMO simulation is gone: close() this vector env and make a new one"
                ) from cause

    def _guarded(self, call: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        self._check_workers()
        try:
            return call(*args, **kwargs)
        except _PIPE_ERRORS as exc:
            self._check_workers(exc)
            raise

    def reset_async(self, *args: Any, **kwargs: Any) -> None:
        self._guarded(super().reset_async, *args, **kwargs)

    def reset_wait(self, *args: Any, **kwargs: Any) -> Any:
        return self._guarded(super().reset_wait, *args, **kwargs)

    def step_async(self, *args: Any, **kwargs: Any) -> None:
        self._guarded(super().step_async, *args, **kwargs)

    def step_wait(self, *args: Any, **kwargs: Any) -> Any:
        return self._guarded(super().step_wait, *args, **kwargs)


def sumo_vector_env(num_envs: int, **env_kwargs: Any) -> TrafficVectorEnv:
    """`num_envs` `DriveHierarchy-R4` envs (each with its own SUMO) in worker processes."""

    def make() -> gym.Env[Any, Any]:
        import drivehierarchy  # noqa: F401  (registers the env id in a spawned worker)

        return gym.make("DriveHierarchy-R4", **env_kwargs)

    return TrafficVectorEnv([make] * num_envs)
