"""SUMO co-simulation through libsumo, one simulation per process.

The Rust world calls `SumoTraffic.start` at reset and `SumoTraffic.tick` once per 0.05 s tick
(from inside the episode's tick loop; see `python/src/traffic.rs`). Each tick:

1. the ego and the mirrored scenario actors are placed with `vehicle.moveToXY` (the keepRoute
   flag comes with each mover: 1 = onto the ego route's edges while the ego is near its route,
   2 = the nearest lane anywhere, or off the network), so SUMO's drivers follow, queue behind
   and yield to them;
2. SUMO advances one step of 0.05 s;
3. vehicles that departed in this step get one subscription each (position, angle, speed,
   signals) and their type's size and class are looked up once;
4. the subscription results of all vehicles and the changed light states go back to Rust as
   libsumo returns them (no per-vehicle getters, no per-vehicle Python work).

libsumo holds one simulation per process: a second live `SumoTraffic` in the same process is an
error (vectorise SUMO envs over processes, e.g. `gymnasium.vector.AsyncVectorEnv`).
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
import weakref
from pathlib import Path
from typing import Any, ClassVar

from drivehierarchy._core import ConfigError, NativeSumo, SimulationError

TRAFFIC_MODES = ("sumo", "native", "none")
STEP_LENGTH_S = 0.05
EGO_ID = "dh_ego"
EGO_ROUTE = "dh_ego_route"
_MIRROR = "dh_actor_{}"


def resolve_traffic_mode(config_mode: str | None, scenario_mode: str) -> str:
    """The effective mode: the env config's `traffic=` if set, else the scenario's."""
    mode = config_mode if config_mode is not None else scenario_mode
    if mode not in TRAFFIC_MODES:
        raise ConfigError(f"config `traffic` = {mode!r}: expected one of {', '.join(TRAFFIC_MODES)}")
    return mode


def _libsumo() -> Any:
    try:
        import libsumo
    except ImportError as exc:  # pragma: no cover - a default dependency
        raise SimulationError(
            f"traffic mode 'sumo' needs the `libsumo` and `eclipse-sumo` packages: {exc}"
        ) from None
    return libsumo


class SumoTraffic:
    """The process's libsumo simulation, driven by the Rust world tick by tick."""

    _owner: ClassVar[weakref.ref[SumoTraffic] | None] = None

    def __init__(self, extra_args: tuple[str, ...] = ()) -> None:
        self.extra_args = tuple(extra_args)
        self._ls = _libsumo()
        self._tc = self._ls.constants
        self._running = False
        self._tmp: Path | None = None
        self._mirrors: set[int] = set()
        # Ego / mirror ids taken out of SUMO because moveToXY could not map them.
        self._out: set[str] = set()
        self._tls: tuple[str, ...] = ()
        self._type_info: dict[str, tuple[float, float, float, str, tuple[int, ...]]] = {}
        self._vars = (
            self._tc.VAR_POSITION,
            self._tc.VAR_ANGLE,
            self._tc.VAR_SPEED,
            self._tc.VAR_SIGNALS,
        )
        self.sumo_time_s = 0.0
        self.steps = 0

    # -- lifecycle ----------------------------------------------------------------------------
    def _claim(self) -> None:
        owner = SumoTraffic._owner() if SumoTraffic._owner is not None else None
        # The native backend (envs/traffic/native.py) shares the one simulation per process.
        if (owner is not None and owner is not self and owner._running) or NativeSumo.busy():
            raise SimulationError(
                "libsumo runs one simulation per process and another SUMO env in this process is "
                "running; close it first, or vectorise SUMO envs over processes "
                "(gymnasium.vector.AsyncVectorEnv)"
            )
        SumoTraffic._owner = weakref.ref(self)

    def start(
        self,
        net: str,
        routes_xml: str,
        seed: int,
        warmup_s: float,
        movers: list[tuple[int, float, float, float, float, int]],
        light_sync: list[tuple[str, int, float]] = (),  # type: ignore[assignment]
        programs: list[tuple[str, list[tuple[str, float]]]] = (),  # type: ignore[assignment]
    ) -> tuple[dict[str, Any], list[Any], dict[str, Any]]:
        """(Re)starts SUMO for an episode; runs the warm-up; returns the t = 0 frame.

        `programs` = (light, [(state, duration s), ...]) of the scenario's replacement light
        programs (`[[lights]] phases`), installed before the warm-up. `light_sync` = (light,
        phase, remaining s) of each light at episode t = 0 (the scenario's overrides included);
        set at the end of the warm-up (also without one) so SUMO's lights keep the timing the
        world's own light model has.
        """
        self.close()
        self._claim()
        ls, tc = self._ls, self._tc
        self._tmp = Path(tempfile.mkdtemp(prefix="dh_sumo_"))
        routes = self._tmp / "traffic.rou.xml"
        routes.write_text(routes_xml, encoding="utf-8")
        errlog = self._tmp / "sumo_errors.log"
        from drivehierarchy.scenarios import sumo_runtime_home

        binary = str(Path(sumo_runtime_home()) / "bin" / "sumo")
        cmd = [
            binary,
            "--net-file", net,
            "--route-files", str(routes),
            "--step-length", str(STEP_LENGTH_S),
            "--seed", str(int(seed) % 2**31),
            "--begin", "0",
            "--collision.action", "none",
            "--no-step-log", "true",
            "--no-warnings", "true",
            "--error-log", str(errlog),
            *self.extra_args,
        ]  # fmt: skip
        try:
            ls.start(cmd)
        except Exception as exc:
            said = errlog.read_text(encoding="utf-8", errors="replace").strip() if errlog.exists() else ""
            self._cleanup_tmp()
            raise SimulationError(
                f"SUMO failed to start on {net}: {exc}" + (f"\nSUMO said:\n{said}" if said else "")
            ) from None
        self._running = True
        self._mirrors = set()
        self._out = set()
        self._type_info = {}
        self.steps = 0
        ls.simulation.subscribe([tc.VAR_DEPARTED_VEHICLES_IDS])
        self._tls = tuple(ls.trafficlight.getIDList())
        for tl, phases in programs:
            if tl not in self._tls:
                raise SimulationError(f"light override: SUMO has no traffic light {tl!r}")
            logic = ls.trafficlight.Logic(
                "dh_override", 0, 0, [ls.trafficlight.Phase(float(d), state) for state, d in phases]
            )
            ls.trafficlight.setProgramLogic(tl, logic)
            ls.trafficlight.setProgram(tl, "dh_override")
        for tl in self._tls:
            ls.trafficlight.subscribe(tl, [tc.TL_RED_YELLOW_GREEN_STATE])
        ls.vehicle.add(EGO_ID, EGO_ROUTE, typeID="dh_ego", depart="now")
        new: list[Any] = []
        for _ in range(round(warmup_s / STEP_LENGTH_S)):
            self._move(movers)
            ls.simulationStep()
            self.steps += 1
            new.extend(self._departed())
        for tl, phase, remaining in light_sync:
            if tl in self._tls:
                ls.trafficlight.setPhase(tl, phase)
                ls.trafficlight.setPhaseDuration(tl, remaining)
        self.sumo_time_s = ls.simulation.getTime()
        # Read once here (the subscription results predate the light sync above).
        state = tc.TL_RED_YELLOW_GREEN_STATE
        lights = {tl: {state: ls.trafficlight.getRedYellowGreenState(tl)} for tl in self._tls}
        return ls.vehicle.getAllSubscriptionResults(), new, lights

    def tick(
        self, movers: list[tuple[int, float, float, float, float, int]]
    ) -> tuple[dict[str, Any], list[Any], dict[str, Any]]:
        """Places the movers, steps SUMO once, returns the subscription results."""
        ls = self._ls
        if not self._running:
            raise SimulationError("SUMO is not running (the traffic was closed); call reset()")
        self._move(movers)
        ls.simulationStep()
        self.steps += 1
        new = self._departed()
        return ls.vehicle.getAllSubscriptionResults(), new, ls.trafficlight.getAllSubscriptionResults()

    def close(self) -> None:
        """Stops SUMO (idempotent); the next `start` starts a fresh simulation."""
        if self._running:
            self._running = False
            # SUMO may already be gone (e.g. it failed mid-episode).
            with contextlib.suppress(Exception):
                self._ls.close()
        self._cleanup_tmp()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()

    def _cleanup_tmp(self) -> None:
        if self._tmp is not None:
            shutil.rmtree(self._tmp, ignore_errors=True)
            self._tmp = None

    @property
    def running(self) -> bool:
        return self._running

    # -- per tick -----------------------------------------------------------------------------
    def _move(self, movers: list[tuple[int, float, float, float, float, int]]) -> None:
        ls = self._ls
        if len(movers) - 1 != len(self._mirrors):
            # A scenario actor left the world: its SUMO double leaves too.
            gone = self._mirrors - {m[0] for m in movers}
            for ident in sorted(gone):
                vid = _MIRROR.format(ident)
                if vid in self._out:
                    self._out.discard(vid)
                else:
                    ls.vehicle.remove(vid)
                self._mirrors.discard(ident)
        for ident, x, y, angle, _speed, keep_route in movers:
            if ident == 0:
                vid, vtype = EGO_ID, EGO_ID
            else:
                vid = vtype = _MIRROR.format(ident)
                if ident not in self._mirrors:
                    ls.vehicle.add(vid, EGO_ROUTE, typeID=vtype, depart="now")
                    self._mirrors.add(ident)
            if vid in self._out:
                # Out of SUMO since it could not be mapped: try it again at its new place.
                try:
                    ls.vehicle.add(vid, EGO_ROUTE, typeID=vtype, depart="now")
                except self._ls.TraCIException:
                    continue
                self._out.discard(vid)
            # keepRoute=1 maps onto SUMO's copy of the route, which a keepRoute=2 placement
            # replaced; then the ego is placed anywhere.
            if not self._try_move(vid, x, y, angle, keep_route) and not (
                keep_route == 1 and self._try_move(vid, x, y, angle, 2)
            ):
                # SUMO cannot place it (off its network, too far from a lane its class may use):
                # it leaves SUMO until it can be mapped again; the world goes on without it there.
                with contextlib.suppress(self._ls.TraCIException):
                    ls.vehicle.remove(vid)
                self._out.add(vid)

    def _try_move(self, vid: str, x: float, y: float, angle: float, keep_route: int) -> bool:
        try:
            self._ls.vehicle.moveToXY(vid, "", -1, x, y, angle, keep_route)
        except self._ls.TraCIException:
            return False
        return True

    def _departed(self) -> list[tuple[str, float, float, float, str, tuple[int, ...]]]:
        ls, tc = self._ls, self._tc
        ids = ls.simulation.getSubscriptionResults()[tc.VAR_DEPARTED_VEHICLES_IDS]
        out = []
        for vid in ids:
            if vid.startswith("dh_"):
                continue
            ls.vehicle.subscribe(vid, self._vars)
            vtype = ls.vehicle.getTypeID(vid)
            info = self._type_info.get(vtype)
            if info is None:
                vt = ls.vehicletype
                info = (
                    vt.getLength(vtype),
                    vt.getWidth(vtype),
                    vt.getHeight(vtype),
                    vt.getVehicleClass(vtype),
                    tuple(vt.getColor(vtype)),
                )
                self._type_info[vtype] = info
            out.append((vid, *info))
        return out
