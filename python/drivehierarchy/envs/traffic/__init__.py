"""Live background traffic for `DriveHierarchy-R4` (see `docs/traffic.md`).

Mode `sumo`: the Rust orchestration (`dh_env::world::sumo`) runs SUMO on the scenario's own
network in lockstep with the world over one of its transports (`transport.make_sumo_traffic`).
Mode `idm` needs nothing from here: it lives in the Rust world (`dh_env::world::idm`).
"""

from drivehierarchy.envs.traffic.modes import TRAFFIC_MODES, resolve_traffic_mode
from drivehierarchy.envs.traffic.vector import TrafficVectorEnv, sumo_vector_env

__all__ = ["TRAFFIC_MODES", "TrafficVectorEnv", "resolve_traffic_mode", "sumo_vector_env"]
