"""Choosing the SUMO backend: native (libsumo's C++ API driven from Rust) or Python (libsumo).

The native backend (`_core.NativeSumo`, `python/src/sumo_native.rs`) runs a co-simulated tick
without entering Python: the Rust world places the ego, steps SUMO and reads the vehicles and
lights through a small C++ shim around `libsumocpp.so` of the `eclipse-sumo` wheel. It is built
with the core when SUMO's headers are present (`python/build.rs`) and loaded only here, when a
SUMO-mode env starts. Both backends give the same traffic (tested).

`sumo_backend` (env config): "native", "python", or "auto" (native when available, else the
Python backend with one log line saying why).
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Any

from drivehierarchy import _core
from drivehierarchy._core import ConfigError, SimulationError
from drivehierarchy.envs.traffic.sumo import SumoTraffic

SUMO_BACKENDS = ("auto", "native", "python")
_log = logging.getLogger(__name__)
_warned: set[str] = set()
_ONE_PER_PROCESS = (
    "libsumo runs one simulation per process and another SUMO env in this process is running; "
    "close it first, or vectorise SUMO envs over processes (gymnasium.vector.AsyncVectorEnv)"
)


def native_sumo_paths() -> tuple[Path, Path, Path]:
    """(shim, libsumocpp, sumo binary) of this installation."""
    from drivehierarchy.scenarios import sumo_runtime_home

    home = Path(sumo_runtime_home())
    libs = [home / d / "libsumocpp.so" for d in ("lib64", "lib")]
    lib = next((p for p in libs if p.exists()), libs[0])
    return Path(_core.__file__).parent / _core.NATIVE_SUMO_SHIM, lib, home / "bin" / "sumo"


def native_sumo(extra_args: tuple[str, ...] = ()) -> _core.NativeSumo:
    """The native backend; `SimulationError` saying why when it is unavailable."""
    if not sys.platform.startswith("linux"):
        raise SimulationError("native SUMO backend unavailable: it is built on Linux only")
    try:
        shim, lib, binary = native_sumo_paths()
    except ImportError as exc:
        raise SimulationError(f"native SUMO backend unavailable: no `eclipse-sumo` package ({exc})") from None
    return _core.NativeSumo(str(shim), str(lib), str(binary), list(extra_args))


def make_sumo_traffic(backend: str = "auto") -> Any:
    """The object owning this env's SUMO: `NativeSumo` or `SumoTraffic` (see the module docs)."""
    if backend not in SUMO_BACKENDS:
        raise ConfigError(f"config `sumo_backend` = {backend!r}: expected one of {', '.join(SUMO_BACKENDS)}")
    if backend == "python":
        return SumoTraffic()
    try:
        return native_sumo()
    except SimulationError as exc:
        if backend == "native":
            raise
        if str(exc) not in _warned:
            _warned.add(str(exc))
            _log.warning("%s; SUMO mode uses the Python libsumo backend", exc)
        return SumoTraffic()


def check_python_sumo_free() -> None:
    """Before a native start: no Python-backend SUMO may run in this process (one per process)."""
    owner = SumoTraffic._owner() if SumoTraffic._owner is not None else None
    if owner is not None and owner.running:
        raise SimulationError(_ONE_PER_PROCESS)
