"""Hand-written contract of the Rust extension module (checked by `mypy.stubtest`)."""

from collections.abc import Mapping, Sequence
from os import PathLike
from typing import Any, Final, TypedDict, final

import numpy as np
from numpy.typing import NDArray

from drivehierarchy.core_types import (
    ActorView,
    BevConfigDict,
    Calibration,
    CalibrationDefaults,
    CameraConfigDict,
    OpenloopTask,
    ProjectedActor,
    ScenarioSummary,
    ScoredFile,
    SimConfigDict,
)
from drivehierarchy.envs.config import BevConfig, CameraConfig

# Settings go in as the package's frozen dataclasses or as dicts of the same fields.
_Camera = CameraConfig | CameraConfigDict | Mapping[str, Any]
_Bev = BevConfig | BevConfigDict | Mapping[str, Any]

__version__: Final[str]
STATE_FIELDS: list[str]
OPENLOOP_UNICODE_VERSION: Final[str]

class DriveHierarchyError(Exception): ...
class SimulationError(DriveHierarchyError): ...
class RenderError(DriveHierarchyError): ...

class ScenarioError(DriveHierarchyError, ValueError):
    """Bad scenario input; the attributes say where (None where the core error does not know)."""

    file: str | None
    line: int | None
    column: int | None
    field: str | None
    value: str | None
    reason: str | None

class ConfigError(DriveHierarchyError, ValueError):
    """Bad runtime setting or action (same attributes as `ScenarioError`)."""

    file: str | None
    line: int | None
    column: int | None
    field: str | None
    value: str | None
    reason: str | None

class _Constants(TypedDict):
    tick_s: float
    ticks_per_decision: int
    decision_hz: float
    warmup_ticks: int
    scenario_version: int
    categories: list[str]
    termination_reasons: list[str]
    openloop_tasks: list[str]
    kinds: list[str]
    actor_kinds: list[str]
    obstacle_kinds: list[str]
    vclass_of: dict[str, str]
    actor_keys: list[str]
    behaviors: list[str]
    at_end: list[str]
    chain_events: list[str]
    start_triggers: list[str]
    brake_triggers: list[str]
    sign_kinds: list[str]
    depart_lanes: list[str]
    depart_speeds: list[str]
    times_of_day: list[str]
    weathers: list[str]
    camera_faults: list[str]
    traffic_modes: list[str]
    deprecated_traffic_modes: dict[str, str]
    ego_vclass: str
    builtin_vtypes: dict[str, str]
    default_vtype: str
    of_rules: list[_OfRule]

class _OfRule(TypedDict):
    table: str
    key: str
    actor_self: bool
    required: bool

def constants() -> _Constants:
    """The Rust facts (step length, categories, scenario enums, ...) as one plain dict."""

@final
class Frame:
    """One moment of an episode as the renderers see it (`Sim.frame_snapshot`)."""

    def render_camera(self, config: _Camera) -> NDArray[np.uint8]: ...
    def render_bev(self, config: _Bev) -> NDArray[np.uint8]: ...

@final
class Sim:
    """One R4 episode: world, route tracker, actuation bridge, score tracker and renderers."""

    def __new__(
        cls,
        scenario: str,
        config: SimConfigDict | Mapping[str, Any],
        sumo_home: str | PathLike[str] | None = None,
        text: str | None = None,
    ) -> Sim: ...
    @property
    def scenario_id(self) -> str: ...
    @property
    def category(self) -> str: ...
    @property
    def route_length_m(self) -> float: ...
    @property
    def trajectory_hash(self) -> str: ...
    def reset(self, seed: int, variation: int | None = None) -> tuple[dict[str, Any], dict[str, Any]]: ...
    def step(
        self, action: NDArray[np.float64]
    ) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]: ...
    def step_reply(self, reply: str | None) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]: ...
    def decision_log(self) -> list[dict[str, Any]]: ...
    def expert_action(self) -> NDArray[np.float64]: ...
    def render(self, kind: str) -> NDArray[np.uint8]: ...
    def render_camera(self, config: _Camera) -> NDArray[np.uint8]: ...
    def render_bev(self, config: _Bev) -> NDArray[np.uint8]: ...
    def frame_snapshot(self) -> Frame: ...
    def render_surround(self) -> dict[str, NDArray[np.uint8]]: ...
    def project_actors(self, config: _Camera) -> list[ProjectedActor]: ...
    def render_and_project(self, config: _Camera) -> tuple[NDArray[np.uint8], list[ProjectedActor]]: ...
    def score(self) -> dict[str, Any]: ...
    def episode_log(self) -> list[dict[str, Any]]: ...
    def write_episode_log(self, path: str | PathLike[str]) -> None: ...
    # Background traffic (docs/traffic.md).
    def set_traffic(self, mode: str, sumo: Any | None = None) -> None: ...
    @property
    def scenario_traffic_mode(self) -> str: ...
    @property
    def traffic(self) -> str | None: ...
    def traffic_routes(self, seed: int, variation: int | None = None) -> str: ...
    def actors_array(self) -> NDArray[np.float64]: ...
    def actor_views(self) -> list[ActorView]: ...
    @property
    def time_s(self) -> float: ...
    def ego_array(self) -> NDArray[np.float64]: ...
    def light_states(self) -> list[tuple[str, str, str]]: ...

LIBSUMO_SUMO_SHIM: Final[str]
TRACI_SUMO_SHIM: Final[str]

@final
class SimBatch:
    """N R4 episodes stepped on a rayon pool with the GIL released (the native vector env)."""

    def __new__(
        cls,
        scenarios: list[str],
        config: Mapping[str, Any] | SimConfigDict,
        traffic: str | None = None,
        sumo_home: str | PathLike[str] | None = None,
        threads: int = 0,
    ) -> SimBatch: ...
    def load(self, index: int, path: str) -> None: ...
    def __len__(self) -> int: ...
    @property
    def scenario_ids(self) -> list[str]: ...
    @property
    def traffic(self) -> list[str | None]: ...
    def score(self, index: int) -> dict[str, Any]: ...
    def run(
        self,
        resets: list[tuple[int, int] | None],
        actions: NDArray[np.float64] | None = None,
    ) -> tuple[dict[str, Any], NDArray[np.float64], NDArray[np.bool_], list[dict[str, Any]]]: ...
    def reset_some(
        self, resets: list[tuple[int, int] | None]
    ) -> tuple[dict[str, Any], list[dict[str, Any]]]: ...

@final
class SumoSession:
    """One SUMO co-simulation's session: its transport and SUMO's lifecycle."""

    @staticmethod
    def shim(
        kind: str, shim: str, library: str, sumo_binary: str, extra_args: list[str] = ...
    ) -> SumoSession: ...
    @staticmethod
    def libsumo_module(module: Any, sumo_binary: str, extra_args: list[str] = ...) -> SumoSession: ...
    def close(self) -> None: ...
    @property
    def transport(self) -> str: ...
    @property
    def running(self) -> bool: ...
    @property
    def sumo_time_s(self) -> float: ...
    @property
    def steps(self) -> int: ...
    @staticmethod
    def in_process_busy() -> bool: ...

@final
class GifWriter:
    def __new__(cls, path: str | PathLike[str], fps: int = 4) -> GifWriter: ...
    def push(self, frame: NDArray[np.uint8]) -> None: ...
    def close(self) -> None: ...
    @property
    def frames(self) -> int: ...

def rescore(log: Sequence[Mapping[str, Any]]) -> dict[str, Any]: ...
def rescore_file(path: str | PathLike[str]) -> dict[str, Any]: ...
def validate_scenario(path: str, sumo_home: str | PathLike[str] | None = None) -> ScenarioSummary: ...
def scenario_json_schema() -> dict[str, Any]: ...
def default_sim_config() -> SimConfigDict: ...
def set_builtin_maps_dir(path: str | PathLike[str]) -> bool: ...
def map_summary(map: str, sumo_home: str | PathLike[str] | None = None) -> dict[str, Any]: ...
def sumo_home() -> str | None: ...

# The scenario editor (python/drivehierarchy/editor).
def map_geometry(map: str, sumo_home: str | PathLike[str] | None = None) -> dict[str, Any]: ...
def snap_to_lane(
    map: str,
    x: float,
    y: float,
    max_dist_m: float = 10.0,
    vclass: str | None = None,
    internal: bool = False,
    sumo_home: str | PathLike[str] | None = None,
) -> tuple[str, float, float] | None: ...
def scenario_geometry(
    path: str, text: str, sumo_home: str | PathLike[str] | None = None
) -> dict[str, Any]: ...

# A road network as the world reads it (python/src/network.rs): lanes, snapping, projection,
# poses along lanes and footprint overlap, for tools such as the official-scene importer.
class _Edge(TypedDict):
    id: str
    function: str
    lanes: list[str]
    successors: list[str]

class _Lane(TypedDict):
    id: str
    edge: str
    function: str
    index: int
    width_m: float
    length_m: float
    shape_length_m: float
    speed_mps: float
    allow: list[str]
    shape: list[tuple[float, float]]

@final
class Network:
    """A SUMO road network (`.net.xml` or `.net.xml.gz`)."""

    @staticmethod
    def load(path: str | PathLike[str]) -> Network: ...
    @property
    def path(self) -> str: ...
    @property
    def offset(self) -> tuple[float, float]: ...
    @property
    def proj_parameter(self) -> str: ...
    def edge(self, id: str) -> _Edge | None: ...
    def lane(self, id: str) -> _Lane | None: ...
    def lanes(
        self, edge: str | None = None, vclass: str | None = None, internal: bool = False
    ) -> list[_Lane]: ...
    def project(self, lane: str, x: float, y: float) -> tuple[float, float]: ...
    def position(self, lane: str, s: float, offset: float = 0.0) -> tuple[float, float, float]: ...
    def lane_box(self, lane: str, s: float, offset: float, length: float, width: float) -> OrientedBox: ...
    def snap(
        self,
        x: float,
        y: float,
        max_dist_m: float = 10.0,
        vclass: str | None = None,
        internal: bool = False,
    ) -> tuple[str, float, float] | None: ...

@final
class OrientedBox:
    """A rectangle on the ground: centre, heading (radians from east), length, width."""

    def __new__(cls, x: float, y: float, heading: float, length: float, width: float) -> OrientedBox: ...
    @property
    def x(self) -> float: ...
    @property
    def y(self) -> float: ...
    @property
    def heading(self) -> float: ...
    @property
    def length(self) -> float: ...
    @property
    def width(self) -> float: ...
    def corners(self) -> list[tuple[float, float]]: ...
    def overlaps(self, other: OrientedBox) -> bool: ...

# Open-loop R1–R3 scoring
def colour_palette() -> list[dict[str, Any]]: ...
def colour_name(rgb: tuple[int, int, int]) -> str: ...
def colour_name_of_pixels(pixels: list[tuple[int, int, int]]) -> str | None: ...
def openloop_tasks() -> list[OpenloopTask]: ...
def openloop_task_from_stem(stem: str) -> str: ...
def openloop_task_from_record(record: Mapping[str, Any]) -> str: ...
def openloop_task_from_original_file(name: str) -> str: ...
def openloop_score_answer(
    task_id: str, ground_truth: object, prediction: str, strict_order: bool = False
) -> tuple[float, bool]: ...
def openloop_score_task(
    task_id: str, records: Sequence[Mapping[str, Any]], predictions: list[str], strict_order: bool = False
) -> tuple[list[float], list[bool]]: ...
def openloop_score_file(
    path: str | PathLike[str],
    task_id: str | None = None,
    strict_order: bool = False,
    layout: str = "drivehierarchy",
) -> ScoredFile: ...
def openloop_summarize(
    outcomes: list[tuple[str, str, list[float], int, float | None]],
    weights: dict[str, float] | None = None,
) -> dict[str, Any]: ...
def openloop_score_params() -> dict[str, float]: ...
def openloop_frozen_weights() -> dict[str, float]: ...
def openloop_calibrate(
    tasks: list[str],
    scores: list[list[float]],
    lambda_same: float | None = None,
    lambda_cross: float | None = None,
    gamma: float | None = None,
    budgets: dict[str, float] | None = None,
) -> Calibration: ...
def openloop_calibration_defaults() -> CalibrationDefaults: ...
def openloop_spearman(x: list[float], y: list[float]) -> float: ...
