"""Choosing the SUMO transport of an env's co-simulation (docs/traffic.md, "Backends").

The orchestration (command line, warm-up, light sync, mirrors, departures) runs in Rust
(`dh_env::world::sumo`) over one of three transports:

- "libsumo": libsumo's C++ API through the C++ shim (`_dh_sumo_shim.so`): SUMO in this process,
  a tick never enters Python;
- "traci": SUMO as a subprocess (the pinned `sumo` binary), spoken to over TraCI on 127.0.0.1
  through the same shim built against libtraci (`_dh_sumo_traci.so`): any number per process;
- "libsumo-python": the `libsumo` Python module (the fallback when the shims were not built).

libsumo holds one simulation per process (its state is global); TraCI does not.

`sumo_backend` (env config): one of the transports above, or "auto": the libsumo shim when it
is built and no other in-process SUMO runs, TraCI when one does (a second env in the same
process, e.g. `gymnasium.make_vec(..., vectorization_mode="sync")`), the Python module when the
shims are missing (logged once). The old names "native" (= "libsumo") and "python"
(= "libsumo-python") are accepted for one release with a `DeprecationWarning`.
"""

from __future__ import annotations

import logging
import sys
import warnings
from pathlib import Path

from drivehierarchy import _core
from drivehierarchy._core import ConfigError, SimulationError

SUMO_BACKENDS = ("auto", "libsumo", "traci", "libsumo-python")
DEPRECATED_SUMO_BACKENDS = {"native": "libsumo", "python": "libsumo-python"}
_log = logging.getLogger(__name__)
_warned: set[str] = set()


def shim_paths(kind: str = "libsumo") -> tuple[Path, Path, Path]:
    """(shim, SUMO client library, sumo binary) of this installation for `kind` "libsumo"/"traci"."""
    from drivehierarchy.scenarios import sumo_runtime_home

    home = Path(sumo_runtime_home())
    name = "libsumocpp.so" if kind == "libsumo" else "libtracicpp.so"
    libs = [home / d / name for d in ("lib64", "lib")]
    lib = next((p for p in libs if p.exists()), libs[0])
    shim = _core.LIBSUMO_SUMO_SHIM if kind == "libsumo" else _core.TRACI_SUMO_SHIM
    return Path(_core.__file__).parent / shim, lib, home / "bin" / "sumo"


def canonical_sumo_backend(backend: str, stacklevel: int = 2) -> str:
    """`backend` under its current name (a `DeprecationWarning` for an old one); `ConfigError`
    for an unknown one."""
    new = DEPRECATED_SUMO_BACKENDS.get(backend) if isinstance(backend, str) else None
    if new is not None:
        warnings.warn(
            f"config `sumo_backend` = {backend!r} is deprecated and will be removed in the next "
            f"release: use {new!r}",
            DeprecationWarning,
            stacklevel=stacklevel + 1,
        )
        return new
    if backend not in SUMO_BACKENDS:
        raise ConfigError(f"config `sumo_backend` = {backend!r}: expected one of {', '.join(SUMO_BACKENDS)}")
    return backend


def libsumo_paths() -> tuple[Path, Path, Path]:
    """(shim, libsumocpp, sumo binary) of this installation."""
    return shim_paths("libsumo")


def shim_session(kind: str, extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    """A session over the C++ shim; `SimulationError` saying why when it is unavailable."""
    if not sys.platform.startswith("linux"):
        raise SimulationError(f"{kind} SUMO transport unavailable: the shims are built on Linux only")
    try:
        shim, lib, binary = libsumo_paths() if kind == "libsumo" else shim_paths(kind)
    except ImportError as exc:
        raise SimulationError(
            f"{kind} SUMO transport unavailable: no `eclipse-sumo` package ({exc})"
        ) from None
    return _core.SumoSession.shim(kind, str(shim), str(lib), str(binary), list(extra_args))


def libsumo_session(extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    """The "libsumo" transport (libsumo's C++ API through the shim)."""
    return shim_session("libsumo", extra_args)


def libsumo_python_session(extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    """The "libsumo-python" transport (the `libsumo` Python module)."""
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
    backend = canonical_sumo_backend(backend)
    if backend == "libsumo-python":
        return libsumo_python_session(extra_args)
    if backend == "traci":
        return shim_session("traci", extra_args)
    if backend == "auto" and _core.SumoSession.in_process_busy():
        try:
            return shim_session("traci", extra_args)
        except SimulationError as exc:
            _warn(f"{exc}; a second SUMO env in this process cannot start")
            return libsumo_or_python(extra_args)
    if backend == "libsumo":
        return libsumo_session(extra_args)
    return libsumo_or_python(extra_args)


def libsumo_or_python(extra_args: tuple[str, ...] = ()) -> _core.SumoSession:
    try:
        return libsumo_session(extra_args)
    except SimulationError as exc:
        _warn(f"{exc}; SUMO mode uses the libsumo-python transport")
        return libsumo_python_session(extra_args)


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
