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


def _register_builtin_maps() -> None:
    # `map = "builtin:town01"` in a scenario anywhere resolves to the maps this package ships.
    from pathlib import Path

    from drivehierarchy import _core

    _core.set_builtin_maps_dir(str(Path(__file__).resolve().parent / "_data" / "scenarios" / "maps"))


_register_builtin_maps()


def register_envs() -> None:
    """Registers the package's Gymnasium ids; calling it again is a no-op."""
    from gymnasium.envs.registration import register, registry

    if R4_ENV_ID not in registry:
        register(
            id=R4_ENV_ID,
            entry_point="drivehierarchy.envs.r4:DriveHierarchyR4Env",
            # gymnasium.make_vec(..., vectorization_mode="vector_entry_point"): N worlds in Rust.
            vector_entry_point="drivehierarchy.envs.vector_native:DriveHierarchyR4VectorEnv",
        )


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
