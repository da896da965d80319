"""Shapes of the plain data that crosses the `_core` seam: the settings it reads and the dicts it
returns. They type the package (mypy) and document the contract; at run time they are dicts."""

from __future__ import annotations

from typing import Literal, TypedDict


class CameraConfigDict(TypedDict):
    """A `CameraConfig` as a dict (what `dataclasses.asdict(CameraConfig())` gives)."""

    width: int
    height: int
    fov_deg: float
    mount_forward_m: float
    mount_left_m: float
    mount_height_m: float
    pitch_deg: float
    yaw_deg: float
    supersample: int
    draw_ego: bool
    draw_distance_m: float


class BevConfigDict(TypedDict):
    size_px: int
    px_per_m: float


class SimConfigDict(TypedDict):
    """The core's settings of one episode (`R4Config.to_core()`, `_core.default_sim_config()`)."""

    action_mode: Literal["decision", "raw"]
    decision_interval_ticks: int
    warmup_ticks: int
    front: CameraConfigDict | None
    bev: BevConfigDict | None
    prompt: bool


class ScenarioSummary(TypedDict):
    """What `drivehierarchy scenario validate FILE` prints (`_core.validate_scenario`)."""

    file: str
    id: str
    name: str
    category: str
    map: str
    route_edges: list[str]
    route_length_m: float
    reference_duration_s: float
    actors: int
    obstacles: int
    signs: int
    traffic_lights: int
    traffic: str


class ProjectedActor(TypedDict):
    """An actor as one camera sees it (`Sim.project_actors`)."""

    id: int
    bbox_px: list[float]
    center_px: list[float]
    distance_m: float
    visible_fraction: float
    pixel_count: int


class ActorView(TypedDict):
    """An active actor with what `Sim.actors_array` leaves out (`Sim.actor_views`)."""

    id: int
    kind: str
    x: float
    y: float
    yaw: float
    speed_mps: float
    length_m: float
    width_m: float
    height_m: float
    color: list[int]
    braking: bool
    blinkers: int
    beacon: bool
    motion: str


class OpenloopTask(TypedDict):
    """One open-loop task (`_core.openloop_tasks`)."""

    id: str
    stem: str
    legacy_stem: str
    rank: str
    answer_kind: str | None
    scorer: str
    metric: str
    weight: float


class ScoredFile(TypedDict):
    """One scored predictions file (`_core.openloop_score_file`)."""

    task: str
    ids: list[str | None]
    scores: list[float]
    parsed: list[bool]
    judge_items: list[tuple[str, str, str]]
    models: list[str]
    formats: list[str]
    lines: int
    duplicates: int
    duplicate_ids: int
    issues: list[tuple[int, str]]
    truncated_tail: bool


class CalibrationDefaults(TypedDict):
    lambda_same: float
    lambda_cross: float
    gamma: float
    budgets: dict[str, float]


class Calibration(TypedDict):
    """Calibrated task weights (`_core.openloop_calibrate`)."""

    tasks: list[str]
    weights: dict[str, float]
    rho: list[list[float]]
    load: list[float]
    uniqueness: list[float]
