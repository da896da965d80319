"""Typed, frozen configuration of the R4 environment (unknown keys are rejected)."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any, Literal

from drivehierarchy import _core
from drivehierarchy._core import ConfigError

ActionMode = Literal["decision", "raw", "waypoints", "meta"]
ACTION_MODES: tuple[str, ...] = ("decision", "raw", "waypoints", "meta")
# `r4 run/evaluate --action-level`: the levels a driver (VLM, expert, policy) decides at.
ACTION_LEVELS: dict[str, ActionMode] = {"control": "decision", "waypoints": "waypoints", "meta": "meta"}

# Every default the Rust core also has is read from it (`SimConfig::default()`): one definition.
# tests/envs/test_config_parity.py checks that the dataclasses below agree with it field by field.
_RUST_DEFAULTS = _core.default_sim_config()


def _rust_default(*keys: str) -> Any:
    value: Any = _RUST_DEFAULTS
    for key in keys:
        value = value[key]
    return value


_DEFAULT_ACTION_MODE: ActionMode = _rust_default("action_mode")


@dataclass(frozen=True)
class CameraConfig:
    """Pinhole front camera; defaults are the protocol's (docs/protocol.md#r4-loop)."""

    width: int = _rust_default("front", "width")
    height: int = _rust_default("front", "height")
    fov_deg: float = _rust_default("front", "fov_deg")
    mount_forward_m: float = _rust_default("front", "mount_forward_m")
    mount_left_m: float = _rust_default("front", "mount_left_m")
    mount_height_m: float = _rust_default("front", "mount_height_m")
    pitch_deg: float = _rust_default("front", "pitch_deg")
    yaw_deg: float = _rust_default("front", "yaw_deg")
    supersample: int = _rust_default("front", "supersample")
    draw_ego: bool = _rust_default("front", "draw_ego")
    draw_distance_m: float = _rust_default("front", "draw_distance_m")


@dataclass(frozen=True)
class BevConfig:
    """Top-down view centred on the ego, forward up; defaults are the protocol's 800×800 at 8 px/m."""

    size_px: int = _rust_default("bev", "size_px")
    px_per_m: float = _rust_default("bev", "px_per_m")


@dataclass(frozen=True)
class R4Config:
    """Settings of one `DriveHierarchy-R4` environment.

    `action_mode="decision"`: actions are `[steer, target_speed_mps]` sent through the protocol's
    actuation bridge (what a VLM outputs). `"raw"`: `[throttle, brake, steer]` applied directly
    (for RL). `"waypoints"`: `waypoints` ego-frame points (x forward, y left, metres)
    `waypoint_dt_s` apart, driven by the waypoint tracker; `"meta"`: `[path, speed]` indices of a
    path action and a speed action, resolved on the lane graph for the same tracker (both this
    project's extension of the protocol, docs/r4.md#action-levels). Images can be switched off
    (`front=None`, `bev=None`) for fast state-only runs.
    """

    scenario: str | None = None
    action_mode: ActionMode = _DEFAULT_ACTION_MODE
    decision_interval_ticks: int = _rust_default("decision_interval_ticks")
    # The original applies zero control on ticks 1–4 and first asks at tick 5 with the state
    # after tick 4: reset plays these ticks. 0 asks at t = 0.
    warmup_ticks: int = _rust_default("warmup_ticks")
    front: CameraConfig | None = field(default_factory=CameraConfig)
    bev: BevConfig | None = field(default_factory=BevConfig)
    prompt: bool = _rust_default("prompt")
    # Waypoint level (and the meta level's plan): points per plan and seconds between them.
    waypoints: int = _rust_default("waypoints")
    waypoint_dt_s: float = _rust_default("waypoint_dt_s")
    # Background traffic: "sumo" | "idm" | "none"; None = the scenario's `[traffic]` mode.
    traffic: str | None = None
    # SUMO mode's transport: "libsumo" (libsumo's C++ API through the shim, no Python per tick),
    # "libsumo-python" (the libsumo module), "traci" (SUMO as a subprocess), "auto" = libsumo for
    # the process's first SUMO env, TraCI for further ones, libsumo-python without the shims
    # (docs/traffic.md).
    sumo_backend: str = "auto"
    # Robustness controls (docs/rendering.md#conditions): light and weather for every episode,
    # overriding the scenario's `[conditions]` ("night", "fog", "dusk+rain", ...; None = the
    # scenario's), and a fault of the observation's front camera ("frozen" | "dropped" | "dirty").
    conditions: str | None = _rust_default("conditions")
    camera_fault: str | None = _rust_default("camera_fault")

    def __post_init__(self) -> None:
        from drivehierarchy.envs.traffic.modes import canonical_traffic_mode
        from drivehierarchy.envs.traffic.transport import canonical_sumo_backend

        # Old names (traffic "native", sumo_backend "native"/"python") warn and are stored new.
        object.__setattr__(self, "sumo_backend", canonical_sumo_backend(self.sumo_backend, stacklevel=3))
        if self.traffic is not None:
            object.__setattr__(self, "traffic", canonical_traffic_mode(self.traffic, stacklevel=3))
        if self.conditions is not None:
            object.__setattr__(self, "conditions", canonical_conditions(self.conditions))
        faults = _core.constants()["camera_faults"]
        if self.camera_fault is not None and self.camera_fault not in faults:
            raise ConfigError(
                f"config `camera_fault` = {self.camera_fault!r}: expected one of {', '.join(faults)}"
            )
        if self.action_mode not in ACTION_MODES:
            raise ConfigError(
                f"config `action_mode` = {self.action_mode!r}: expected one of "
                f"{', '.join(map(repr, ACTION_MODES))}"
            )
        if (
            not isinstance(self.waypoints, int)
            or isinstance(self.waypoints, bool)
            or not 1 <= self.waypoints <= 64
        ):
            raise ConfigError(f"config `waypoints` = {self.waypoints!r}: expected an integer in 1..=64")
        dt = self.waypoint_dt_s
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not 0.0 < dt <= 10.0:
            raise ConfigError(f"config `waypoint_dt_s` = {dt!r}: expected seconds in (0, 10]")
        if not isinstance(self.decision_interval_ticks, int) or self.decision_interval_ticks < 1:
            raise ConfigError(
                f"config `decision_interval_ticks` = {self.decision_interval_ticks!r}: "
                "expected an integer ≥ 1"
            )
        if (
            not isinstance(self.warmup_ticks, int)
            or isinstance(self.warmup_ticks, bool)
            or self.warmup_ticks < 0
        ):
            raise ConfigError(f"config `warmup_ticks` = {self.warmup_ticks!r}: expected an integer ≥ 0")

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> R4Config:
        """Builds a config from plain values, rejecting unknown keys with the key named."""
        config: R4Config = _from_dict(cls, data, "")
        return config

    def to_core(self) -> dict[str, Any]:
        """The settings the Rust core reads (`_core.Sim`; the scenario travels separately)."""
        d = dataclasses.asdict(self)
        d.pop("scenario")
        d.pop("traffic")  # handled by the Python env (envs/traffic), not the Rust config
        d.pop("sumo_backend")
        return d

    def to_json(self) -> str:
        """`to_core()` as JSON text (what a run's manifest records)."""
        return json.dumps(self.to_core())

    def replace(self, **changes: Any) -> R4Config:
        return dataclasses.replace(self, **changes)


def canonical_conditions(name: str) -> str:
    """The canonical name of a conditions override (`rain+night` → `night+rain`, `noon+clear` →
    `noon`): a time of day, a weather, or both joined by `+`; ConfigError naming the bad part."""
    facts = _core.constants()
    times, weathers = facts["times_of_day"], facts["weathers"]
    time, weather = times[0], weathers[0]
    seen: set[str] = set()
    parts = name.split("+") if isinstance(name, str) else [name]
    for part in parts:
        kind = "time" if part in times else "weather" if part in weathers else None
        if kind is None or kind in seen:
            why = (
                f"names two {'times of day' if kind == 'time' else 'weathers'}"
                if kind
                else f"expected a time of day ({', '.join(times)}), a weather ({', '.join(weathers)}) "
                "or time+weather, e.g. night+rain"
            )
            raise ConfigError(f"config `conditions` = {name!r}: {why}")
        seen.add(kind)
        if kind == "time":
            time = part
        else:
            weather = part
    if weather == weathers[0]:
        return str(time)
    return str(weather) if time == times[0] else f"{time}+{weather}"


def _from_dict(cls: type, data: Any, prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"config `{prefix or cls.__name__}` = {data!r}: expected a table of settings")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(
            f"config `{prefix}{unknown[0]}` = {data[unknown[0]]!r}: unknown setting "
            f"(known: {', '.join(sorted(fields))})"
        )
    kwargs: dict[str, Any] = {}
    nested = {"front": CameraConfig, "bev": BevConfig}
    for key, value in data.items():
        sub = nested.get(key) if cls is R4Config else None
        if sub is not None and isinstance(value, dict):
            kwargs[key] = _from_dict(sub, value, f"{prefix}{key}.")
        else:
            kwargs[key] = value
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(f"config `{prefix or cls.__name__}`: {exc}") from None
