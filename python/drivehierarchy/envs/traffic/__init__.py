"""Live background traffic for `DriveHierarchy-R4` (see `docs/traffic.md`).

`SumoTraffic` owns libsumo: it runs SUMO on the scenario's own network in lockstep with the
Rust world (one batched exchange per 0.05 s tick). The native mode needs nothing from here: it
lives in the Rust world (`dh_env::world::idm`).
"""

from drivehierarchy.envs.traffic.sumo import TRAFFIC_MODES, SumoTraffic, resolve_traffic_mode
from drivehierarchy.envs.traffic.vector import TrafficVectorEnv, sumo_vector_env

__all__ = ["TRAFFIC_MODES", "SumoTraffic", "TrafficVectorEnv", "resolve_traffic_mode", "sumo_vector_env"]
