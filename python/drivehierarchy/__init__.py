"""DriveHierarchy: a Rust-core benchmark and simulator for vision-language-model driving agents."""

from drivehierarchy._core import (
    ConfigError,
    DriveHierarchyError,
    RenderError,
    ScenarioError,
    SimulationError,
    __version__,
)

__all__ = [
    "ConfigError",
    "DriveHierarchyError",
    "RenderError",
    "ScenarioError",
    "SimulationError",
    "__version__",
]
