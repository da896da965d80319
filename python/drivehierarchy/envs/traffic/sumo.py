"""Deprecated alias of `drivehierarchy.envs.traffic.modes` (renamed: it holds the traffic
modes, not SUMO); it goes in the next release."""

import warnings

from drivehierarchy.envs.traffic.modes import TRAFFIC_MODES, resolve_traffic_mode

warnings.warn(
    "drivehierarchy.envs.traffic.sumo is deprecated: use drivehierarchy.envs.traffic.modes",
    DeprecationWarning,
    stacklevel=2,
)

__all__ = ["TRAFFIC_MODES", "resolve_traffic_mode"]
