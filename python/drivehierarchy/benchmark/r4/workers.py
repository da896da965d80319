"""Worker processes for scenarios with SUMO traffic in a concurrent `r4 evaluate`.

libsumo runs one simulation per process, so scenarios with SUMO background traffic cannot share
the harness's process. Each `SceneWorker` is a fresh interpreter (`python -m` this module: like a
spawn-context process, but without re-running the caller's `__main__`, so a script calling
`evaluate` needs no `if __name__ == "__main__"` guard) owning at most one env (and so one
libsumo) at a time, talking over a socket pair with `multiprocessing.connection` framing. The
async harness drives it call by call (reset, build the message, step) while the scenario's VLM
requests stay in the harness's process and its one `AsyncOpenAI` pool, so the server still
batches across every scenario in flight. A scenario keeps its worker from start to end; between
calls its world waits, frozen, as in the original. The observation stays in the worker: only
the built message (two JPEG data URLs), the step's info and the final record travel.

A worker that dies (killed, SUMO crashed) is reported as `WorkerDied` for the scenario it was
driving — on the next call, or within `POLL_S` of the death while a call is waiting — never a hang.
A worker that does not answer a call within the pool's `timeout_s` (hung: SUMO stuck, a deadlock,
the process stopped) is killed and reported as `WorkerTimeout`. The pool then starts a fresh
worker for later scenarios. Workers exit when the harness's end of
the socket closes (including when the harness itself is killed).
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import pickle
import socket
import subprocess
import sys
import time
import traceback
from collections.abc import AsyncIterator, Callable
from concurrent.futures import Executor
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from drivehierarchy._core import SimulationError

WORKER_NAME = "r4-sumo-worker"
POLL_S = 0.2  # how often a waiting call checks that its worker is still alive


class WorkerDied(SimulationError):
    """The worker process driving a scenario died; the scenario is redone on resume."""

    def __init__(self, message: str, *, pid: int | None = None, exit_code: int | None = None) -> None:
        super().__init__(message)
        self.pid = pid
        self.exit_code = exit_code

    def __reduce__(self) -> tuple[Any, ...]:  # keeps pid and exit code across pickling
        return (_rebuild, (type(self), str(self), self.pid, self.exit_code))


class WorkerTimeout(WorkerDied):
    """The worker did not answer a call in time and was killed; the scenario is redone on resume."""


def _rebuild(cls: type[WorkerDied], message: str, pid: int | None, exit_code: int | None) -> WorkerDied:
    return cls(message, pid=pid, exit_code=exit_code)


def _serve(conn: Any) -> None:
    """The worker's loop: `("new", factory, args, kwargs)` makes the worker's object (closing the
    previous one), `("call", method, ...)` calls it, `("run", fn, ...)` runs a function,
    `("exit", ...)` ends. Replies `("ok", result)` or `("err", exception, traceback text)`."""
    obj: Any = None
    while True:
        try:
            op, target, args, kwargs = conn.recv()
        except (EOFError, OSError):
            return  # the harness is gone
        try:
            if op == "exit":
                _close(obj)
                return
            if op == "new":
                _close(obj)
                obj = None
                obj = target(*args, **kwargs)
                result = None
            elif op == "call":
                result = getattr(obj, target)(*args, **kwargs)
            elif op == "run":
                result = target(*args, **kwargs)
            else:
                raise ValueError(f"unknown worker operation {op!r}")
            reply: tuple[Any, ...] = ("ok", result)
        except BaseException as exc:
            tb = traceback.format_exc()
            try:
                pickle.dumps(exc)
            except Exception:
                exc = SimulationError(f"{type(exc).__name__}: {exc}")
            reply = ("err", exc, tb)
        try:
            conn.send(reply)
        except (OSError, ValueError):
            return


def _close(obj: Any) -> None:
    if obj is not None and hasattr(obj, "close"):
        with contextlib.suppress(Exception):
            obj.close()


class SceneWorker:
    """One worker process and the harness's end of its socket. `request` blocks (run it in a
    thread); `call` is its async form."""

    def __init__(self, index: int, timeout_s: float | None = None) -> None:
        # The longest one call may take (None: no limit); a hung worker is killed after it.
        self.timeout_s = timeout_s
        here, there = socket.socketpair()
        # The worker imports this very package (not whatever `drivehierarchy` its path finds first).
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[3])
        env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
        self.name = f"{WORKER_NAME}-{index}"
        with there:
            self.process = subprocess.Popen(
                [sys.executable, "-m", __name__, str(there.fileno()), self.name],
                pass_fds=[there.fileno()],
                env=env,
                stdin=subprocess.DEVNULL,
            )
        # Only the worker holds its end now: its death reads as EOF here.
        self.conn = Connection(here.detach())
        self.scene: str | None = None  # the scenario it drives, for error messages
        _LIVE.add(self.process)

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def _died(self, cause: BaseException | None = None) -> WorkerDied:
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.process.wait(5)
        code = self.process.returncode
        what = f"exit code {code}" if code is not None else "lost its socket"
        return WorkerDied(
            f"worker process {self.name} (pid {self.process.pid}) driving "
            f"{self.scene or 'a scenario'} died ({what}); the scenario's SUMO simulation is gone",
            pid=self.process.pid,
            exit_code=code,
        )

    def _timed_out(self, op: str, target: Any) -> WorkerTimeout:
        self.kill()
        what = target if isinstance(target, str) else getattr(target, "__name__", repr(target))
        return WorkerTimeout(
            f"worker process {self.name} (pid {self.process.pid}) driving "
            f"{self.scene or 'a scenario'} did not answer `{op} {what}` within {self.timeout_s:g} s "
            "(hung); killed it, the scenario's SUMO simulation is gone",
            pid=self.process.pid,
            exit_code=self.process.returncode,
        )

    def request(self, op: str, target: Any, *args: Any, **kwargs: Any) -> Any:
        deadline = None if self.timeout_s is None else time.monotonic() + self.timeout_s
        try:
            self.conn.send((op, target, args, kwargs))
            while not self.conn.poll(POLL_S):
                if not self.alive:
                    raise self._died()
                if deadline is not None and time.monotonic() >= deadline:
                    raise self._timed_out(op, target)
            reply = self.conn.recv()
        except (EOFError, OSError) as exc:
            raise self._died(exc) from None
        if reply[0] == "ok":
            return reply[1]
        error: BaseException = reply[1]
        if hasattr(error, "add_note"):  # Python ≥ 3.11: the worker's traceback in the report
            error.add_note(f"in {self.name} (pid {self.process.pid}):\n{reply[2]}")
        raise error

    async def call(self, pool: Executor, op: str, target: Any, *args: Any, **kwargs: Any) -> Any:
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(pool, lambda: self.request(op, target, *args, **kwargs))

    def stop(self, timeout: float = 5.0) -> None:
        """Asks the worker to exit; kills it if it does not within `timeout`."""
        if self.alive:
            with contextlib.suppress(OSError, ValueError):
                self.conn.send(("exit", None, (), {}))
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.process.wait(timeout)
        self.kill()
        self.conn.close()

    def kill(self) -> None:
        if self.alive:
            self.process.kill()
        self.process.wait()
        _LIVE.discard(self.process)


_LIVE: set[subprocess.Popen[bytes]] = set()


def running_workers() -> list[int]:
    """Pids of this process's live worker processes (diagnostics and tests)."""
    return sorted(p.pid for p in _LIVE if p.poll() is None)


class WorkerPool:
    """Workers started on demand (at most as many as scenarios using them at once)
    and reused across scenarios; a dead one is replaced."""

    def __init__(self, timeout_s: float | None = None) -> None:
        self.timeout_s = timeout_s
        self._idle: list[SceneWorker] = []
        self._all: list[SceneWorker] = []
        self.started = 0

    @contextlib.asynccontextmanager
    async def worker(self, scene: str) -> AsyncIterator[SceneWorker]:
        while self._idle and not self._idle[-1].alive:
            self._idle.pop().stop(0)
        w = self._idle.pop() if self._idle else self._start()
        w.scene = scene
        ok = False
        try:
            yield w
            ok = True
        finally:
            w.scene = None
            if ok and w.alive:
                self._idle.append(w)
            else:
                # Dead, or left mid-call by an error: its state is unknown, it is not reused.
                w.kill()
                w.stop(0)
                self._all.remove(w)

    def _start(self) -> SceneWorker:
        w = SceneWorker(self.started, self.timeout_s)
        self.started += 1
        self._all.append(w)
        return w

    def close(self, *, kill: bool = False) -> None:
        """Stops every worker (`kill`: at once, e.g. when the run is being torn down)."""
        for w in self._all:
            if kill:
                w.kill()
            w.stop()
        self._all.clear()
        self._idle.clear()


def make_remote(worker: SceneWorker, pool: Executor) -> Callable[..., Any]:
    """`await remote(method, *args)` calls the worker's object (see `_serve`)."""

    async def remote(method: str, *args: Any, **kwargs: Any) -> Any:
        return await worker.call(pool, "call", method, *args, **kwargs)

    return remote


def main(argv: list[str] | None = None) -> int:
    """`python -m drivehierarchy.benchmark.r4.workers FD NAME`: serve the harness on socket FD."""
    args = sys.argv[1:] if argv is None else argv
    conn = Connection(int(args[0]))
    _serve(conn)
    return 0


if __name__ == "__main__":
    sys.exit(main())
