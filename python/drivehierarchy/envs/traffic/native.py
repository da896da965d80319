"""Deprecated alias of `drivehierarchy.envs.traffic.transport` (renamed: it picks the SUMO
transport); it goes in the next release."""

import warnings

from drivehierarchy.envs.traffic.transport import (
    SUMO_BACKENDS,
    libsumo_or_python,
    libsumo_paths,
    libsumo_python_session,
    libsumo_session,
    make_sumo_traffic,
    needs_new_session,
    shim_paths,
    shim_session,
)

warnings.warn(
    "drivehierarchy.envs.traffic.native is deprecated: use drivehierarchy.envs.traffic.transport",
    DeprecationWarning,
    stacklevel=2,
)

native_sumo_paths = libsumo_paths
native_sumo = libsumo_session
python_sumo = libsumo_python_session
native_sumo_or_python = libsumo_or_python

__all__ = [
    "SUMO_BACKENDS",
    "make_sumo_traffic",
    "native_sumo",
    "native_sumo_or_python",
    "native_sumo_paths",
    "needs_new_session",
    "python_sumo",
    "shim_paths",
    "shim_session",
]
