"""Import the original release's scenarios into our scenario format (`scenario import-official`).

The original release describes each scene twice: `entity.json` as its web editor exported it
and `entity_sumo.json` as converted for its CARLA–SUMO runtime (hero, background vehicles and
pedestrians with SUMO routes, departures, reference points and estimated durations). We read
`entity_sumo.json` for everything the runtime used and `entity.json` for what it adds: the
editor's participant list (to catch actors the conversion lost), actor kinds and names, and
the editor's triggers, obstacles and light settings, which the original runtime ignores (so do
we; the report says so).

Mapping (docs/protocol.md#r4-categories): hero → `[ego]`; `slave` vehicles → `[[traffic.vehicles]]` driven
by SUMO, departing at t = 0 from rest on their lane and position; pedestrians → scripted
pedestrian actors walking point to point at each target point's speed (default 1.2 m/s).
Positions come from the CARLA coordinates and the user's network offset (CARLA x = SUMO x −
off_x, CARLA y = off_y − SUMO y), so a network rebuilt with another offset still fits.

Nothing is dropped silently: an actor that cannot be represented is listed in the scene's
report with the reason.

The network, and all geometry on it (projection onto lanes, poses along them, footprint
overlap), is the simulator's own (`_core.Network`); the files are written with tomlkit.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import TYPE_CHECKING, Any

import tomlkit
from tomlkit.items import InlineTable, Table
from tomlkit.toml_document import TOMLDocument

from drivehierarchy import _core
from drivehierarchy._core import ConfigError, Network, OrientedBox, ScenarioError

if TYPE_CHECKING:
    from drivehierarchy._core import _Edge, _Lane

# The original tongji network's offset (docs/protocol.md#r4-categories), used when a file gives none.
DEFAULT_NET_OFFSET = (761.28, 488.05)
DEFAULT_PEDESTRIAN_SPEED_MPS = 1.2
VTYPES_DEFAULT_NAME = "carlavtypes13.rou.xml"
REPORT_NAME = "import_report.json"
# Two coordinate sources of one point disagreeing by more than this are reported.
COORD_TOLERANCE_M = 0.05
# A start or destination moved by more than this to land on its lane is reported.
SNAP_REPORT_M = 0.5

# Our categories (`_core.constants()`) by the original's folder number; the original's folder
# names differ (`01_pedestrain_recognition`, `03_right_turn`, ...).
CATEGORY_BY_NUMBER = {c.split("_", 1)[0]: c for c in _core.constants()["categories"]}

# Our shipped vehicle types (scenarios/traffic/vtypes.add.xml) by SUMO class, used only when no
# vehicle-type file of the original is available.
_BUILTIN_TYPE_BY_VCLASS = {
    "bus": "bus",
    "coach": "bus",
    "truck": "truck",
    "trailer": "truck",
    "delivery": "van",
    "motorcycle": "motorcycle",
    "moped": "motorcycle",
    "bicycle": "bicycle",
}


# --------------------------------------------------------------------------------------------
# Coordinate frames


def carla_to_sumo(x: float, y: float, offset: Sequence[float] = DEFAULT_NET_OFFSET) -> tuple[float, float]:
    """CARLA (left-handed, y south) → SUMO network frame (x east, y north)."""
    return x + offset[0], offset[1] - y


def sumo_to_carla(x: float, y: float, offset: Sequence[float] = DEFAULT_NET_OFFSET) -> tuple[float, float]:
    """SUMO network frame → CARLA."""
    return x - offset[0], offset[1] - y


def carla_yaw_to_heading_deg(yaw: float) -> float:
    """CARLA yaw (degrees, clockwise seen from above) → heading counter-clockwise from east,
    in (−180, 180]."""
    h = -yaw % 360.0
    return h - 360.0 if h > 180.0 else h


def category_for(folder: str) -> str:
    """Our category for an original category folder (`01_pedestrain_recognition` → `01_pedestrian`)."""
    m = re.match(r"^(\d{1,2})(?:_|$)", folder)
    if not m or f"{int(m.group(1)):02d}" not in CATEGORY_BY_NUMBER:
        raise ScenarioError(
            f"category folder {folder!r}: expected a name starting with a category number 01–10 "
            f"(docs/protocol.md#r4-categories), e.g. 01_pedestrain_recognition"
        )
    return CATEGORY_BY_NUMBER[f"{int(m.group(1)):02d}"]


# --------------------------------------------------------------------------------------------
# Report


@dataclass
class Unmapped:
    actor: str
    reason: str


@dataclass
class SceneReport:
    source: str
    scene_id: str = ""
    original_category: str = ""
    category: str = ""
    out: str | None = None
    actors_in_file: int = 0
    ego: bool = False
    vehicles: int = 0
    pedestrians: int = 0
    notes: list[str] = field(default_factory=list)
    unmapped: list[Unmapped] = field(default_factory=list)
    error: str | None = None
    validation: str | None = None

    @property
    def imported(self) -> bool:
        return self.error is None and self.out is not None

    def to_json(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "scene_id": self.scene_id,
            "original_category": self.original_category,
            "category": self.category,
            "out": self.out,
            "imported": self.imported,
            "actors_in_file": self.actors_in_file,
            "mapped": {"ego": self.ego, "vehicles": self.vehicles, "pedestrians": self.pedestrians},
            "unmapped": [{"actor": u.actor, "reason": u.reason} for u in self.unmapped],
            "notes": self.notes,
            "error": self.error,
            "validation": self.validation,
        }


@dataclass
class ImportReport:
    source: str
    net: str
    out: str
    vtypes: str | None
    scenes: list[SceneReport] = field(default_factory=list)

    @property
    def failed(self) -> list[SceneReport]:
        return [s for s in self.scenes if not s.imported]

    @property
    def unmapped_count(self) -> int:
        return sum(len(s.unmapped) for s in self.scenes)

    def to_json(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "net": self.net,
            "out": self.out,
            "vtypes": self.vtypes,
            "scenes": [s.to_json() for s in self.scenes],
            "imported": sum(s.imported for s in self.scenes),
            "failed": len(self.failed),
            "unmapped_actors": self.unmapped_count,
        }

    def lines(self) -> list[str]:
        out = []
        for s in self.scenes:
            head = f"{'ok  ' if s.imported else 'FAIL'} {s.source}"
            if s.imported:
                head += (
                    f" -> {s.out} (ego, {s.vehicles} SUMO vehicles, {s.pedestrians} pedestrians"
                    f" of {s.actors_in_file} actors)"
                )
            out.append(head)
            if s.error:
                out.append(f"     error: {s.error}")
            out.extend(f"     NOT MAPPED {u.actor}: {u.reason}" for u in s.unmapped)
            out.extend(f"     note: {n}" for n in s.notes)
        out.append(
            f"{sum(s.imported for s in self.scenes)} of {len(self.scenes)} scenes imported, "
            f"{len(self.failed)} failed, {self.unmapped_count} actors not mapped"
        )
        return out


# --------------------------------------------------------------------------------------------
# The user's network and the TOML output


def _normal_edge(net: Network, edge_id: str) -> _Edge | None:
    """The edge `edge_id` if it is one a route can list (not inside a junction), else None."""
    edge = net.edge(edge_id)
    return edge if edge is not None and edge["function"] in ("normal", "connector") else None


def _open_lanes(net: Network, edge_id: str, vclass: str) -> list[_Lane]:
    """Lanes of `edge_id` open to `vclass` (a vehicle class SUMO does not know is unmappable)."""
    try:
        return net.lanes(edge=edge_id, vclass=vclass)
    except ConfigError as exc:
        raise _Unmappable(f"vehicle class {vclass!r} is not a SUMO vehicle class") from exc


def _rounded(v: Any) -> Any:
    """`v` with every float rounded to 0.1 mm (no sub-millimetre noise from the projections in
    the files; no negative zero)."""
    if isinstance(v, int):  # bool too
        return v
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"non-finite number {v}")
        r = round(v, 4)
        return r + 0.0 if r != 0 else 0.0
    if isinstance(v, dict):
        return {k: _rounded(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_rounded(x) for x in v]
    return v


def _inline(d: dict[str, Any]) -> InlineTable:
    """An inline table in the style of the shipped scenarios: `{ lane = "a", s = 1.0 }`."""
    t = tomlkit.inline_table()
    t.append(None, tomlkit.ws(" "))
    for k, v in d.items():
        t.append(k, _item(v))
    t.append(None, tomlkit.ws(" "))
    return t


def _item(v: Any) -> Any:
    if isinstance(v, dict):
        return _inline(v)
    if isinstance(v, list):
        arr = tomlkit.array()
        if len(v) > 1 and all(isinstance(x, dict) for x in v):
            # One table per line, indented by two spaces as in the shipped scenarios.
            for x in v:
                arr.add_line(_inline(x), indent="  ")
            arr.add_line(indent="")
        else:
            arr.extend(_item(x) for x in v)
        return arr
    return v


def _table(items: dict[str, Any], into: Table | TOMLDocument | None = None) -> Any:
    """`items` (keys whose value is None left out) as a TOML table."""
    t = tomlkit.table() if into is None else into
    for k, v in _rounded(items).items():
        if v is not None:
            t.add(k, _item(v))
    return t


# --------------------------------------------------------------------------------------------
# Vehicle types


def read_vtypes(path: Path) -> dict[str, dict[str, str]]:
    """`<vType>` attributes by id from a SUMO route / additional file."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ScenarioError(f"{path}: cannot read the vehicle-type file: {exc}") from exc
    types = {vt.get("id", ""): dict(vt.attrib) for vt in root.iter("vType")}
    if not types:
        raise ScenarioError(f"{path}: no <vType> elements (expected e.g. carlavtypes13.rou.xml)")
    return types


# --------------------------------------------------------------------------------------------
# The importer


def _f(v: Any) -> float | None:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


class OfficialImporter:
    """Converts the original's scenes onto one road network; see the module docstring."""

    def __init__(
        self,
        net: Path,
        out: Path,
        *,
        vtypes: Path | None = None,
        copy_net: bool = False,
        validate: bool = True,
    ) -> None:
        self.net_path = Path(net)
        if not self.net_path.is_file():
            raise ConfigError(f"--net {net}: file not found")
        self.out = Path(out)
        # A file that cannot be read or parsed raises ScenarioError naming it and what is wrong.
        self.net = Network.load(self.net_path)
        self.validate = validate
        self.copy_net = copy_net
        if vtypes is None:
            beside = self.net_path.parent / VTYPES_DEFAULT_NAME
            vtypes = beside if beside.is_file() else None
        elif not Path(vtypes).is_file():
            raise ConfigError(f"--vtypes {vtypes}: file not found")
        self.vtypes_src = Path(vtypes) if vtypes else None
        self.vtypes = read_vtypes(self.vtypes_src) if self.vtypes_src else None

    # -- files ------------------------------------------------------------------------------

    def _prepare_out(self) -> tuple[Path, Path | None]:
        self.out.mkdir(parents=True, exist_ok=True)
        net = self.net_path.resolve()
        if self.copy_net:
            dst = self.out / self.net_path.name
            if dst.resolve() != net:
                shutil.copyfile(net, dst)
            net = dst.resolve()
        vt = None
        if self.vtypes_src is not None:
            vt = self.out / self.vtypes_src.name
            if vt.resolve() != self.vtypes_src.resolve():
                shutil.copyfile(self.vtypes_src, vt)
        return net, vt

    @staticmethod
    def _rel(target: Path, start: Path) -> str:
        try:
            return Path(os.path.relpath(target.resolve(), start.resolve())).as_posix()
        except ValueError:  # another drive (Windows)
            return target.resolve().as_posix()

    # -- entry points -----------------------------------------------------------------------

    def import_dir(self, src: Path) -> ImportReport:
        src = Path(src)
        files = sorted(src.rglob("entity_sumo.json")) if src.is_dir() else []
        if src.is_file() and src.name.endswith(".json"):
            files = [src]
        if not files:
            raise ConfigError(
                f"{src}: no entity_sumo.json found (expected <category>/<scene id>/entity_sumo.json)"
            )
        net_file, vt_file = self._prepare_out()
        report = ImportReport(
            source=str(src),
            net=str(self.net_path),
            out=str(self.out),
            vtypes=str(vt_file) if vt_file else None,
        )
        seen: dict[Path, str] = {}
        for f in files:
            scene = SceneReport(source=Path(os.path.relpath(f, src if src.is_dir() else f.parent)).as_posix())
            try:
                self._import_scene(f, scene, net_file, vt_file, seen)
            except (ScenarioError, ConfigError, KeyError, TypeError, ValueError) as exc:
                scene.error = _describe(exc)
                scene.out = None
            report.scenes.append(scene)
        (self.out / REPORT_NAME).write_text(
            json.dumps(report.to_json(), indent=2, ensure_ascii=False) + "\n", encoding="utf-8"
        )
        return report

    def _import_scene(
        self, path: Path, rep: SceneReport, net_file: Path, vt_file: Path | None, seen: dict[Path, str]
    ) -> None:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise ScenarioError(f"{path}: cannot read: {exc}") from exc
        if not isinstance(data, dict) or not isinstance(data.get("hero"), dict):
            raise ScenarioError(f"{path}: field `hero`: missing (not an entity_sumo.json of the original)")
        rep.scene_id = str(path.parent.name)
        rep.original_category = path.parent.parent.name
        rep.category = category_for(rep.original_category)
        editor = _read_entity(path.parent / "entity.json", rep)
        toml_text = self.convert(data, rep, editor=editor, net_file=net_file, vt_file=vt_file, path=path)
        out = self.out / rep.category / f"{rep.scene_id}.toml"
        if out in seen:
            raise ScenarioError(f"{path}: scene id {rep.scene_id} already imported from {seen[out]}")
        seen[out] = rep.source
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(
            toml_text.replace("@MAP@", self._rel(net_file, out.parent)).replace(
                "@VTYPES@", self._rel(vt_file, out.parent) if vt_file else ""
            ),
            encoding="utf-8",
        )
        rep.out = out.as_posix()
        if self.validate:
            from drivehierarchy import DriveHierarchyError, _core
            from drivehierarchy.scenarios import sumo_home

            try:
                _core.validate_scenario(str(out), sumo_home())
                rep.validation = "ok"
            except DriveHierarchyError as exc:
                rep.validation = str(exc)
                rep.error = f"the written file does not validate: {exc}"

    # -- conversion -------------------------------------------------------------------------

    def convert(
        self,
        data: dict[str, Any],
        rep: SceneReport,
        *,
        editor: dict[str, Any] | None = None,
        net_file: Path | None = None,
        vt_file: Path | None = None,
        path: Path | None = None,
    ) -> str:
        """The scenario TOML of one `entity_sumo.json` (map and vtypes paths as @MAP@/@VTYPES@)."""
        where = str(path) if path else "entity_sumo.json"
        file_offset = data.get("map", {}).get("net_offset") if isinstance(data.get("map"), dict) else None
        self._file_offset = (
            (float(file_offset[0]), float(file_offset[1])) if file_offset else DEFAULT_NET_OFFSET
        )
        if any(abs(a - b) > 1e-6 for a, b in zip(self._file_offset, self.net.offset, strict=True)):
            rep.notes.append(
                f"the scene's net offset {list(self._file_offset)} differs from the network's "
                f"{list(self.net.offset)}: positions placed from their CARLA coordinates with the "
                "network's offset"
            )
        hero = data["hero"]
        others = data.get("background_vehicles") or []
        if not isinstance(others, list):
            raise ScenarioError(f"{where}: field `background_vehicles`: expected a list")
        rep.actors_in_file = 1 + len(others)
        editor_parts = _editor_participants(editor, rep)

        self._ego_box: OrientedBox | None = None
        ego = self._ego(hero, rep, where, editor_parts.get(str(hero.get("actor_id"))))
        rep.ego = True
        actors: list[dict[str, Any]] = []
        vehicles: list[dict[str, Any]] = []
        slave_speeds: set[float] = set()
        for i, a in enumerate(others):
            aid = str(a.get("actor_id", f"#{i}"))
            role = a.get("role")
            label = f"{role or 'actor'} {aid}" + (f" ({a['name']})" if a.get("name") else "")
            ed = editor_parts.get(aid)
            if ed is not None and ed.get("type") and role and ed["type"] != role:
                rep.notes.append(
                    f"{label}: role {role!r} in entity_sumo.json, {ed['type']!r} in entity.json; "
                    f"used entity_sumo.json's"
                )
            try:
                if role == "pedestrian":
                    actors.append(self._pedestrian(a, label, rep))
                    rep.pedestrians += 1
                elif role == "slave":
                    vehicles.append(self._vehicle(a, aid, label, rep))
                    rep.vehicles += 1
                    slave_speeds.update(
                        float(p["speed_kmh"])
                        for p in a.get("reference_points", [])[1:]
                        if _f(p.get("speed_kmh"))
                    )
                elif role == "main":
                    raise _Unmappable("a second hero (role main): a scenario has one ego")
                else:
                    raise _Unmappable(
                        f"role {role!r} is not one the original runtime spawns (main, slave, pedestrian)"
                    )
            except _Unmappable as exc:
                rep.unmapped.append(Unmapped(label, str(exc)))
        sumo_ids = {str(hero.get("actor_id"))} | {str(a.get("actor_id")) for a in others}
        for pid, p in editor_parts.items():
            if pid not in sumo_ids:
                rep.unmapped.append(
                    Unmapped(
                        f"{p.get('type', 'actor')} {pid}" + (f" ({p['name']})" if p.get("name") else ""),
                        "in entity.json but not in entity_sumo.json: the original's conversion lost it "
                        "(no SUMO route or departure to import)",
                    )
                )
        if slave_speeds:
            rep.notes.append(
                "background vehicles' reference-point speeds ("
                + ", ".join(f"{s:g}" for s in sorted(slave_speeds))
                + " km/h) not imported: SUMO drives them at its own speeds, as in the original runtime"
            )

        ref = _f(hero.get("estimated_duration_seconds"))
        dur = _f(data.get("scenario_duration_seconds"))
        if dur is None:
            ests = [_f(a.get("estimated_duration_seconds")) for a in [hero, *others]]
            known = [e for e in ests if e]
            dur = max(known) if known else None
            rep.notes.append(
                "no scenario_duration_seconds: duration_s = the longest actor estimate"
                if dur
                else "no durations: duration_s left to our default"
            )
        top: dict[str, Any] = {
            "version": 1,
            "id": f"official_{rep.scene_id}" if rep.scene_id else "official_scene",
            "name": f"{rep.original_category}/{rep.scene_id}",
            "category": rep.category,
            "description": _description(rep, editor),
            "map": "@MAP@",
            "reference_duration_s": ref if ref and ref > 0 else None,
            "duration_s": dur if dur and dur > 0 else None,
            "seed": int(data["random_seed"])
            if isinstance(data.get("random_seed"), int) and data["random_seed"] >= 0
            else None,
        }
        if ref is None or ref <= 0:
            rep.notes.append(
                "hero has no estimated_duration_seconds: reference duration = our default (L / 5.56 m/s)"
            )
        for w in data.get("conversion_warnings") or []:
            rep.notes.append(f"the original's conversion warned: {w}")
        if data.get("weather"):
            rep.notes.append("weather not imported (our renderer has one lighting)")

        doc = tomlkit.document()
        doc.add(tomlkit.comment("Imported from the original DriveHierarchy release by"))
        doc.add(tomlkit.comment("`drivehierarchy scenario import-official`."))
        doc.add(tomlkit.comment(f"Source: {rep.source}"))
        _table(top, into=doc)
        ego_vehicle = ego.pop("vehicle", None)
        doc.add(tomlkit.nl())
        ego_table = doc.setdefault("ego", _table(ego))
        if ego_vehicle:
            ego_table.add(tomlkit.nl())
            ego_table.add("vehicle", _table(ego_vehicle))
        if actors:
            doc.add(tomlkit.nl())
            doc.add("actors", tomlkit.aot())
            for a in actors:
                doc["actors"].append(_table(a))
        if vehicles:
            traffic = {
                "mode": "sumo",
                "vtypes": "@VTYPES@" if self.vtypes is not None else None,
                "warmup_s": 0.0,
            }
            doc.add(tomlkit.nl())
            traffic_table = doc.setdefault("traffic", _table(traffic))
            traffic_table.add(tomlkit.nl())
            traffic_table.add("vehicles", tomlkit.aot())
            for v in vehicles:
                traffic_table["vehicles"].append(_table(v))
        return tomlkit.dumps(doc)

    # -- points -----------------------------------------------------------------------------

    def _point(self, p: dict[str, Any], what: str, rep: SceneReport) -> tuple[float, float]:
        """A reference point in the network frame: from its CARLA coordinates and the network's
        offset; else its SUMO coordinates; else its longitude / latitude through the network's
        projection."""
        cx, cy = _f(p.get("carla_x")), _f(p.get("carla_y"))
        sx, sy = _f(p.get("sumo_x")), _f(p.get("sumo_y"))
        if cx is not None and cy is not None:
            x, y = carla_to_sumo(cx, cy, self.net.offset)
            if sx is not None and sy is not None:
                fx, fy = carla_to_sumo(cx, cy, self._file_offset)
                if math.hypot(fx - sx, fy - sy) > COORD_TOLERANCE_M:
                    rep.notes.append(
                        f"{what}: CARLA ({cx:.2f}, {cy:.2f}) and SUMO ({sx:.2f}, {sy:.2f}) "
                        "coordinates disagree "
                        f"by {math.hypot(fx - sx, fy - sy):.2f} m; used CARLA's"
                    )
            return x, y
        if sx is not None and sy is not None:
            return sx - self._file_offset[0] + self.net.offset[0], sy - self._file_offset[
                1
            ] + self.net.offset[1]
        lon, lat = _f(p.get("longitude")), _f(p.get("latitude"))
        if lon is not None and lat is not None:
            return self._lon_lat(lon, lat, what)
        raise _Unmappable(f"{what}: no coordinates (carla_x/y, sumo_x/y or longitude/latitude)")

    def _lon_lat(self, lon: float, lat: float, what: str) -> tuple[float, float]:
        """A longitude / latitude in the network frame: the network's PROJ projection plus its
        offset, as SUMO converts them."""
        if self.net.proj_parameter.strip() in ("", "!"):
            raise _Unmappable(
                f"{what}: only longitude/latitude given and the network {self.net_path.name} has no "
                "geo-projection (projParameter)"
            )
        try:
            import pyproj  # type: ignore[import-not-found, unused-ignore]
        except ImportError as exc:
            raise _Unmappable(
                f"{what}: only longitude/latitude given; converting them needs pyproj (pip install pyproj)"
            ) from exc
        try:
            x, y = pyproj.Proj(self.net.proj_parameter)(lon, lat)
        except Exception as exc:  # pyproj raises its own CRSError / ProjError
            raise _Unmappable(
                f"{what}: longitude/latitude ({lon}, {lat}) cannot be projected with the network's "
                f"projParameter {self.net.proj_parameter!r}: {exc}"
            ) from exc
        return float(x) + self.net.offset[0], float(y) + self.net.offset[1]

    def _edge(self, edge_id: str) -> _Edge | None:
        return _normal_edge(self.net, edge_id)

    def _place_on_edge(
        self, edge_id: str, lane_id: str | None, xy: tuple[float, float], vclass: str
    ) -> tuple[_Lane, float, float, float]:
        """(lane, s, signed offset, distance) of `xy` on `lane_id` if it is open to `vclass`,
        else on the nearest lane of `edge_id` open to it."""
        if self._edge(edge_id) is None:
            raise _Unmappable(f"edge {edge_id!r} is not in the network {self.net_path.name}")
        lanes = _open_lanes(self.net, edge_id, vclass)
        lanes = [ln for ln in lanes if ln["id"] == lane_id] or lanes
        if not lanes:
            raise _Unmappable(f"edge {edge_id!r} has no lane open to class {vclass}")
        best = None
        for ln in lanes:
            s, off = self.net.project(ln["id"], *xy)
            if best is None or abs(off) < abs(best[2]):
                best = (ln, s, off)
        assert best is not None
        ln, s, off = best
        # SUMO's lane length may differ from its shape's (ours checks s against the former).
        length = min(ln["shape_length_m"], ln["length_m"])
        s = min(max(s, 0.0), math.floor(length * 1e4) / 1e4)
        return ln, s, off, abs(off)

    # -- actors -----------------------------------------------------------------------------

    def _ego(
        self, hero: dict[str, Any], rep: SceneReport, where: str, ed: dict[str, Any] | None
    ) -> dict[str, Any]:
        try:
            edges = [str(e) for e in hero.get("route_edges") or []]
            if not edges:
                raise _Unmappable("no route_edges")
            missing = [e for e in edges if self._edge(e) is None]
            if missing:
                raise _Unmappable(f"route edges {missing} are not in the network {self.net_path.name}")
            vclass = hero.get("vclass") or "passenger"
            pts = hero.get("reference_points") or []
            depart = hero.get("depart") or {}
            lane_id = depart.get("lane_id")
            if pts:
                start_xy = self._point(pts[0], "hero start", rep)
                ln, s, off, _ = self._place_on_edge(edges[0], lane_id, start_xy, vclass)
            else:
                known = self.net.lane(lane_id) if lane_id else None
                if known is None or known["function"] not in ("normal", "connector"):
                    raise _Unmappable("neither reference points nor a known depart lane")
                ln = known
                s, off = float(depart.get("lane_pos") or 0.0), 0.0
                rep.notes.append("hero start from its depart lane and position (no reference points)")
            width = self._type_dims(hero.get("sumo_type_id"))[1] if self.vtypes else 2.0
            # The original spawns the ego at the editor's point. Where that point lies on the road
            # (on any lane of the edge but a sidewalk, e.g. a narrow lane closed to cars) it is
            # kept exactly; elsewhere (on a kerb) the ego is moved into its lane.
            max_off = max(0.0, ln["width_m"] / 2 - width / 2)
            on_road = pts and self._on_road(edges[0], start_xy)
            start_off = off if on_road else max(-max_off, min(max_off, off))
            if on_road and abs(off) > max_off + SNAP_REPORT_M:
                rep.notes.append(
                    f"ego starts at the editor's point, {abs(off):.2f} m off the centre of lane "
                    f"{ln['id']} (on another lane of the road)"
                )
            if abs(start_off - off) > SNAP_REPORT_M:
                rep.notes.append(
                    f"ego start moved {abs(start_off - off):.2f} m sideways into lane {ln['id']} "
                    f"(the editor's point is {abs(off):.2f} m off its centre)"
                )
            start = {"lane": ln["id"], "s": s, "offset_m": start_off}
            elen, ewid, _eh = self._type_dims(hero.get("sumo_type_id")) if self.vtypes else (4.9, 2.0, 1.5)
            self._ego_box = self.net.lane_box(ln["id"], s, start_off, elen, ewid)
            spawn = hero.get("carla_spawn") or {}
            if _f(spawn.get("yaw")) is not None:
                lane_heading = math.degrees(self.net.position(ln["id"], s)[2])
                diff = abs((carla_yaw_to_heading_deg(float(spawn["yaw"])) - lane_heading + 180) % 360 - 180)
                if diff > 15:
                    rep.notes.append(
                        f"ego spawn yaw differs from its lane's heading by {diff:.0f}°: "
                        "started along the lane"
                    )
            if len(pts) >= 2:
                end_xy = self._point(pts[-1], "hero end", rep)
                eln, es, _eoff, edist = self._place_on_edge(edges[-1], None, end_xy, vclass)
                if edist > SNAP_REPORT_M * 4:
                    rep.notes.append(
                        f"ego destination is {edist:.2f} m from the nearest drivable lane of its last edge "
                        f"{edges[-1]}: placed on {eln['id']} at s = {es:.1f}"
                    )
                destination = {"lane": eln["id"], "s": es}
            else:
                destination = None
                rep.notes.append("hero has no end point: destination = end of the last route edge")
            speed = (_f(depart.get("speed_kmh")) or 0.0) / 3.6
            out: dict[str, Any] = {
                "route_edges": edges,
                "start": start,
                "destination": destination,
                "speed_mps": speed,
            }
            if self.vtypes is not None and hero.get("sumo_type_id") in self.vtypes:
                length, wid, height = self._type_dims(hero["sumo_type_id"])
                out["vehicle"] = {"length_m": length, "width_m": wid, "height_m": height}
            elif hero.get("sumo_type_id"):
                rep.notes.append(
                    f"ego type {hero['sumo_type_id']!r} has no dimensions here: our default ego size"
                )
            return out
        except _Unmappable as exc:
            raise ScenarioError(f"{where}: hero: {exc}") from exc

    def _on_road(self, edge_id: str, xy: tuple[float, float]) -> bool:
        """Whether `xy` lies on a lane of the edge other than a sidewalk."""
        for ln in self.net.lanes(edge=edge_id) if self._edge(edge_id) is not None else []:
            if set(ln["allow"]) <= {"pedestrian", "wheelchair"}:
                continue
            _s, off = self.net.project(ln["id"], *xy)
            if abs(off) <= ln["width_m"] / 2:
                return True
        return False

    def _type_dims(self, type_id: str | None) -> tuple[float, float, float]:
        vt = (self.vtypes or {}).get(type_id or "", {})
        return (
            _f(vt.get("length")) or 4.9,
            _f(vt.get("width")) or 2.0,
            _f(vt.get("height")) or 1.5,
        )

    def _vehicle(self, a: dict[str, Any], aid: str, label: str, rep: SceneReport) -> dict[str, Any]:
        edges = [str(e) for e in a.get("route_edges") or []]
        if not edges:
            raise _Unmappable("no route_edges")
        missing = [e for e in edges if self._edge(e) is None]
        if missing:
            raise _Unmappable(f"route edges {missing} are not in the network {self.net_path.name}")
        type_id = a.get("sumo_type_id")
        if self.vtypes is not None:
            if type_id not in self.vtypes:
                raise _Unmappable(f"vehicle type {type_id!r} is not in the vehicle-type file")
            vtype = str(type_id)
            vclass = self.vtypes[vtype].get("vClass", "passenger")
        else:
            vclass = str(a.get("vclass") or "passenger")
            vtype = _BUILTIN_TYPE_BY_VCLASS.get(vclass, "car")
            rep.notes.append(f"{label}: type {type_id!r} drawn as our {vtype!r} (no vehicle-type file given)")
        depart = a.get("depart") or {}
        if depart.get("edge_id") not in (None, edges[0]):
            raise _Unmappable(
                f"departs on edge {depart.get('edge_id')!r}, not on its route's first edge {edges[0]!r}"
            )
        lanes = self.net.lanes(edge=edges[0])
        idx = depart.get("lane_index")
        if isinstance(idx, int) and not 0 <= idx < len(lanes):
            raise _Unmappable(f"depart lane index {idx} but edge {edges[0]!r} has {len(lanes)} lanes")
        open_idx = [ln["index"] for ln in _open_lanes(self.net, edges[0], vclass)]
        if isinstance(idx, int) and idx not in open_idx:
            # SUMO refuses the whole route file over such a vehicle ("Invalid departLane"); the
            # nearest lane open to its class keeps it where the editor put it, give or take a lane.
            if not open_idx:
                raise _Unmappable(f"no lane of its first edge {edges[0]!r} is open to its class {vclass}")
            want: int = idx
            new = min(open_idx, key=lambda i: (abs(i - want), i))
            rep.notes.append(
                f"CHANGED {label}: depart lane {lanes[idx]['id']} is closed to its class {vclass} "
                f"(SUMO cannot insert it there): departs on {lanes[new]['id']}"
            )
            idx = new
        for e in edges:
            if not _open_lanes(self.net, e, vclass):
                raise _Unmappable(f"route edge {e!r} has no lane open to its class {vclass}")
        for e0, e1 in pairwise(edges):
            a0 = self._edge(e0)
            if a0 is not None and e1 not in a0["successors"]:
                rep.notes.append(f"{label}: route gap {e0} → {e1} filled by shortest-path routing")
        pos = _f(depart.get("lane_pos"))
        # SUMO's length of an edge is that of its first lane.
        length = lanes[0]["length_m"]
        if pos is not None and not 0.0 <= pos <= length:
            rep.notes.append(
                f"{label}: depart position {pos:.2f} m clamped to edge {edges[0]} (0 … {length:.2f} m)"
            )
            pos = min(max(pos, 0.0), length)
        if self._ego_box is not None and isinstance(idx, int):
            lane = lanes[idx]
            front = pos if pos is not None else 0.0
            vlen, vwid, _h = self._type_dims(type_id) if self.vtypes else (4.5, 1.9, 1.5)
            box = self.net.lane_box(lane["id"], front - vlen / 2, 0.0, vlen, vwid)
            if box.overlaps(self._ego_box):
                # The original's CARLA bridge spawns each vehicle SUMO inserts; CARLA refuses a
                # spawn that collides, so this vehicle never appeared in the original's world.
                raise _Unmappable(
                    f"departs overlapping the ego's start ({lane['id']} at {front:.2f} m): the "
                    "original's CARLA spawn of it would collide and fail, so it never appeared there"
                )
        t = _f(depart.get("time_seconds")) or 0.0
        if t != 0.0:
            rep.notes.append(
                f"{label}: depart time {t:g} s replaced by 0 (the original runtime departs all at t = 0)"
            )
        return {
            "id": "slave_" + re.sub(r"[^\w.#-]", "_", aid),
            "vtype": vtype,
            "route": edges,
            "depart_s": 0.0,
            "depart_lane": idx if isinstance(idx, int) else None,
            "depart_pos_m": pos,
            "depart_speed": (_f(depart.get("speed_kmh")) or 0.0) / 3.6,
        }

    def _pedestrian(self, a: dict[str, Any], label: str, rep: SceneReport) -> dict[str, Any]:
        pts = a.get("reference_points") or []
        if len(pts) < 2:
            raise _Unmappable(f"{len(pts)} reference point(s): a walk needs a start and a target point")
        waypoints: list[dict[str, Any]] = []
        for k, p in enumerate(pts):
            x, y = self._point(p, f"{label} point {k}", rep)
            if waypoints and math.hypot(x - waypoints[-1]["x"], y - waypoints[-1]["y"]) < 0.01:
                rep.notes.append(f"{label}: point {k} repeats the previous one; dropped")
                continue
            wp: dict[str, Any] = {"x": x, "y": y}
            if waypoints:
                kmh = _f(p.get("speed_kmh"))
                wp["speed_mps"] = kmh / 3.6 if kmh and kmh > 0 else DEFAULT_PEDESTRIAN_SPEED_MPS
                if not (kmh and kmh > 0):
                    rep.notes.append(f"{label}: point {k} has no speed: {DEFAULT_PEDESTRIAN_SPEED_MPS} m/s")
            waypoints.append(wp)
        if len(waypoints) < 2:
            raise _Unmappable("all reference points coincide: nowhere to walk")
        return {
            "name": label,
            "kind": "pedestrian",
            "waypoints": waypoints,
            "at_end": "stop",
        }


class _Unmappable(Exception):
    """An actor we cannot represent (listed in the report, never dropped silently)."""


def _describe(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        return f"missing field {exc}"
    return str(exc)


def _read_entity(path: Path, rep: SceneReport) -> dict[str, Any] | None:
    if not path.is_file():
        rep.notes.append("no entity.json beside it: the editor's participant list was not cross-checked")
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            raise ValueError("not an object")
        for key in ("trajectoryInfo", "customizedParams"):
            if isinstance(data.get(key), str) and data[key]:
                data[key] = json.loads(data[key])
    except (OSError, ValueError) as exc:
        rep.notes.append(f"entity.json unreadable ({exc}): not cross-checked")
        return None
    params = data.get("customizedParams") or {}
    if isinstance(params, dict):
        for key, what in (
            ("obstacles", "obstacles"),
            ("trigger", "triggers"),
            ("trafficLight", "traffic-light settings"),
        ):
            items = params.get(key) or []
            if items:
                rep.notes.append(
                    f"entity.json: {len(items)} editor {what} not imported "
                    "(the original runtime ignores them)"
                )
        if params.get("sceneTrigger"):
            rep.notes.append(
                "entity.json: the editor's scene triggers not imported "
                "(the original runtime starts every actor at t = 0)"
            )
    return data


def _editor_participants(editor: dict[str, Any] | None, rep: SceneReport) -> dict[str, dict[str, Any]]:
    if not editor:
        return {}
    info = editor.get("trajectoryInfo")
    parts = info.get("participantTrajectories") if isinstance(info, dict) else None
    if not isinstance(parts, list):
        return {}
    return {str(p.get("id")): p for p in parts if isinstance(p, dict)}


def _description(rep: SceneReport, editor: dict[str, Any] | None) -> str:
    desc = f"Original R4 scene {rep.scene_id} ({rep.original_category}) on the user's network"
    if editor and isinstance(editor.get("testSceneDesc"), str) and editor["testSceneDesc"].strip():
        desc += f"; editor note: {editor['testSceneDesc'].strip()}"
    return desc


def import_official(
    src: Path,
    net: Path,
    out: Path,
    *,
    vtypes: Path | None = None,
    copy_net: bool = False,
    validate: bool = True,
) -> ImportReport:
    """Imports every `entity_sumo.json` under `src` into `out/<category>/<scene id>.toml`."""
    out = Path(out)
    # The original's data stays the user's: never write it into the package or its checkout.
    package = Path(__file__).resolve().parent
    checkout = package.parents[1]
    guarded = [package]
    if (checkout / "pyproject.toml").is_file() and (checkout / "python" / "drivehierarchy").is_dir():
        guarded.append(checkout)
    for root in guarded:
        if out.resolve().is_relative_to(root):
            raise ConfigError(
                f"--out {out}: inside {root} (the drivehierarchy package or its checkout); "
                "write imported scenes to a folder of your own"
            )
    return OfficialImporter(net, out, vtypes=vtypes, copy_net=copy_net, validate=validate).import_dir(src)


def iter_scenes(src: Path) -> Iterable[Path]:
    """The `entity_sumo.json` files under `src`, sorted."""
    return sorted(Path(src).rglob("entity_sumo.json"))
