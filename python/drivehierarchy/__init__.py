"""DriveHierarchy: a Rust-core benchmark and simulator for vision-language-model driving agents.

`import drivehierarchy` registers the Gymnasium id `DriveHierarchy-R4` (idempotently);
`gym.make("drivehierarchy:DriveHierarchy-R4")` works without the import.
"""

from drivehierarchy._core import (
    ConfigError,
    DriveHierarchyError,
    RenderError,
    ScenarioError,
    SimulationError,
    __version__,
)

R4_ENV_ID = "DriveHierarchy-R4"


def register_envs() -> None:
    """Registers the package's Gymnasium ids; calling it again is a no-op."""
    from gymnasium.envs.registration import register, registry

    if R4_ENV_ID not in registry:
        register(id=R4_ENV_ID, entry_point="drivehierarchy.envs.r4:DriveHierarchyR4Env")


register_envs()

__all__ = [
    "R4_ENV_ID",
    "ConfigError",
    "DriveHierarchyError",
    "RenderError",
    "ScenarioError",
    "SimulationError",
    "__version__",
    "register_envs",
]
