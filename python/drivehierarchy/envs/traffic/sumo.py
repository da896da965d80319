"""Traffic modes and the SUMO constants shared with the Rust orchestration.

SUMO co-simulation itself runs in Rust (`dh_env::world::sumo`: command line, warm-up, light sync,
mirrors, departures) over a transport chosen in `envs/traffic/native.py`.
"""

from __future__ import annotations

from drivehierarchy._core import ConfigError

TRAFFIC_MODES = ("sumo", "native", "none")
STEP_LENGTH_S = 0.05
EGO_ID = "dh_ego"
EGO_ROUTE = "dh_ego_route"


def resolve_traffic_mode(config_mode: str | None, scenario_mode: str) -> str:
    """The effective mode: the env config's `traffic=` if set, else the scenario's."""
    mode = config_mode if config_mode is not None else scenario_mode
    if mode not in TRAFFIC_MODES:
        raise ConfigError(f"config `traffic` = {mode!r}: expected one of {', '.join(TRAFFIC_MODES)}")
    return mode
