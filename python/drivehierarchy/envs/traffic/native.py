"""Choosing the SUMO transport of an env's co-simulation (docs/traffic.md, "Backends").

The orchestration (command line, warm-up, light sync, mirrors, departures) runs in Rust
(`dh_env::world::sumo`) over one of three transports:

- "libsumo": libsumo's C++ API through the C++ shim (`_dh_sumo_shim.so`): SUMO in this process,
  a tick never enters Python;
- "traci": SUMO as a subprocess (the pinned `sumo` binary), spoken to over TraCI on 127.0.0.1
  through the same shim built against libtraci (`_dh_sumo_traci.so`): any number per process;
- "libsumo-python": the `libsumo` Python module (the fallback when the shims were not built).

libsumo holds one simulation per process (its state is global); TraCI does not.

`sumo_backend` (env config): "native" (the libsumo shim), "python" (the libsumo module),
"traci", or "auto": the libsumo shim when it is built and no other in-process SUMO runs, TraCI
when one does (a second env in the same process, e.g. `gymnasium.make_vec(...,
vectorization_mode="sync")`), the Python module when the shims are missing (logged once).
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

from drivehierarchy import _core
from drivehierarchy._core import ConfigError, SimulationError

SUMO_BACKENDS = ("auto", "native", "python", "traci")
_log = logging.getLogger(__name__)
_warned: set[str] = set()


def shim_paths(kind: str = "libsumo") -> tuple[Path, Path, Path]:
    """(shim, SUMO client library, sumo binary) of this installation for `kind` "libsumo"/"traci"."""
    from drivehierarchy.scenarios import sumo_runtime_home

    home = Path(sumo_runtime_home())
    name = "libsumocpp.so" if kind == "libsumo" else "libtracicpp.so"
    libs = [home / d / name for d in ("lib64", "lib")]
    lib = next((p for p in libs if p.exists()), libs[0])
    shim = _core.NATIVE_SUMO_SHIM if kind == "libsumo" else _core.TRACI_SUMO_SHIM
    return Path(_core.__file__).parent / shim, lib, home / "bin" / "sumo"


def native_sumo_paths() -> tuple[Path, Path, Path]:
    """(shim, libsumocpp, sumo binary) of this installation."""
    return shim_paths("libsumo")


def shim_session(kind: str, extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    """A session over the C++ shim; `SimulationError` saying why when it is unavailable."""
    if not sys.platform.startswith("linux"):
        raise SimulationError(f"{kind} SUMO transport unavailable: the shims are built on Linux only")
    try:
        shim, lib, binary = native_sumo_paths() if kind == "libsumo" else shim_paths(kind)
    except ImportError as exc:
        raise SimulationError(
            f"{kind} SUMO transport unavailable: no `eclipse-sumo` package ({exc})"
        ) from None
    return _core.SumoSession.shim(kind, str(shim), str(lib), str(binary), list(extra_args))


def native_sumo(extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    """The native backend (libsumo through the shim)."""
    return shim_session("libsumo", extra_args)


def python_sumo(extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    """The Python backend (the `libsumo` module as the transport)."""
    try:
        import libsumo
    except ImportError as exc:  # pragma: no cover - a default dependency
        raise SimulationError(
            f"traffic mode 'sumo' needs the `libsumo` and `eclipse-sumo` packages: {exc}"
        ) from None
    from drivehierarchy.scenarios import sumo_runtime_home

    binary = Path(sumo_runtime_home()) / "bin" / "sumo"
    return _core.SumoSession.libsumo_module(libsumo, str(binary), list(extra_args))


def make_sumo_traffic(backend: str = "auto", extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    """The session of an env's SUMO for `backend` (see the module docs)."""
    if backend not in SUMO_BACKENDS:
        raise ConfigError(f"config `sumo_backend` = {backend!r}: expected one of {', '.join(SUMO_BACKENDS)}")
    if backend == "python":
        return python_sumo(extra_args)
    if backend == "traci":
        return shim_session("traci", extra_args)
    if backend == "auto" and _core.SumoSession.in_process_busy():
        try:
            return shim_session("traci", extra_args)
        except SimulationError as exc:
            _warn(f"{exc}; a second SUMO env in this process cannot start")
            return native_sumo_or_python(extra_args)
    if backend == "native":
        return native_sumo(extra_args)
    return native_sumo_or_python(extra_args)


def native_sumo_or_python(extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    try:
        return native_sumo(extra_args)
    except SimulationError as exc:
        _warn(f"{exc}; SUMO mode uses the Python libsumo backend")
        return python_sumo(extra_args)


def needs_new_session(session: _core.SumoSession | None, backend: str) -> bool:
    """Whether an env must (re)choose its session before starting SUMO: it has none, or "auto"
    holds an in-process one that is idle while another env's in-process SUMO runs."""
    if session is None:
        return True
    return (
        backend == "auto"
        and session.transport != "traci"
        and not session.running
        and _core.SumoSession.in_process_busy()
    )


def _warn(msg: str) -> None:
    if msg not in _warned:
        _warned.add(msg)
        _log.warning("%s", msg)
