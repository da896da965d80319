"""`drivehierarchy map ...`: road networks for scenarios.

`map import-osm FILE.osm --out NET` runs SUMO's `netconvert` (from the `eclipse-sumo` package)
on an OpenStreetMap extract with options that give a drivable, routable network (below), then
loads the result with our own map reader and routes across it, so a network that our simulator
cannot use is an error here rather than at the first `reset`.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path
from typing import Any

from drivehierarchy import _core
from drivehierarchy._core import ConfigError, ScenarioError

# netconvert options for OSM (SUMO docs, "Importing OpenStreetMap" recommendations): simplify
# geometry, recognise roundabouts and ramps, merge the clusters of junctions OSM draws at big
# crossings, place lights where OSM marks signals (dropping lights on plain through-roads and
# joining the ones of one crossing), sidewalks and crossings from OSM's tags, and keep only
# edges open to cars (footways, rails, tracks and private driveways go; OSM's access rules
# stay: a raceway is open to SUMO's `vip` class only and is dropped with them).
NETCONVERT_OSM_OPTIONS = (
    "--geometry.remove",
    "--roundabouts.guess",
    "--ramps.guess",
    "--junctions.join",
    "--tls.guess-signals",
    "--tls.discard-simple",
    "--tls.join",
    "--tls.default-type",
    "static",
    "--output.original-names",
    "--osm.sidewalks",
    "--crossings.guess",
    "--keep-edges.by-vclass",
    "passenger",
)

# Countries driving on the left, as coarse (min_lon, min_lat, max_lon, max_lat) boxes: only used
# when the extract has no `driving_side` tags (override with --driving-side).
LEFT_HAND_BOXES = {
    "United Kingdom / Ireland": (-10.7, 49.8, 1.8, 60.9),
    "Japan": (122.9, 24.0, 146.0, 45.6),
    "Australia": (112.9, -43.7, 153.7, -10.6),
    "New Zealand": (166.3, -47.3, 178.6, -34.4),
    "India": (68.1, 6.7, 97.4, 35.5),
    "South Africa": (16.4, -34.9, 32.9, -22.1),
    "Hong Kong": (113.8, 22.15, 114.45, 22.57),
    "Singapore / Malaysia": (99.6, 1.1, 119.3, 7.4),
    "Thailand": (97.3, 5.6, 105.7, 20.5),
    "Indonesia (Java)": (105.0, -8.9, 114.7, -5.8),
}


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    mp = sub.add_parser("map", help="road networks")
    cmds = mp.add_subparsers(dest="map_command", required=True)
    osm = cmds.add_parser(
        "import-osm",
        help="build a SUMO network from an OpenStreetMap extract (netconvert) and check it",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    osm.add_argument("osm", type=Path, help="OpenStreetMap extract (.osm / .osm.xml, optionally .gz)")
    osm.add_argument("--out", type=Path, required=True, help="network to write (.net.xml)")
    osm.add_argument(
        "--driving-side",
        choices=("auto", "left", "right"),
        default="auto",
        help="traffic side (auto: the extract's driving_side tags, else its location)",
    )
    osm.add_argument(
        "--netconvert-option",
        action="append",
        default=[],
        metavar="OPT",
        help="extra netconvert argument (repeatable), e.g. --netconvert-option=--no-turnarounds",
    )
    osm.add_argument("--json", action="store_true", help="print the summary as JSON")
    osm.set_defaults(func=_import_osm)

    show = cmds.add_parser(
        "show",
        help="list a network's edges and lanes (ids, lengths, speed limits, allowed classes)",
        description="NET is what a scenario's `map` key takes: a .net.xml path, `sumo:PATH` (a net "
        "shipped with eclipse-sumo) or `builtin:NAME` (a map shipped with drivehierarchy).",
    )
    show.add_argument("net", help="network: path, sumo:PATH or builtin:NAME (e.g. builtin:town01)")
    show.add_argument("--all", action="store_true", help="also internal, crossing and walking-area edges")
    show.add_argument("--edge", action="append", default=[], metavar="ID", help="only this edge (repeatable)")
    show.add_argument("--json", action="store_true", help="print everything as JSON")
    show.set_defaults(func=_show)


def netconvert_binary() -> Path:
    """`netconvert` of the installed eclipse-sumo package."""
    try:
        import sumo
    except ImportError as exc:
        raise ConfigError(
            "netconvert: the eclipse-sumo package is not installed (pip install eclipse-sumo)"
        ) from exc
    exe = Path(sumo.SUMO_HOME) / "bin" / ("netconvert.exe" if os.name == "nt" else "netconvert")
    if not exe.is_file():
        raise ConfigError(f"netconvert: not found at {exe}")
    return exe


def _osm_root(path: Path) -> ET.Element:
    import gzip

    try:
        if path.suffix == ".gz":
            with gzip.open(path, "rb") as fh:
                return ET.parse(fh).getroot()
        return ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"{path}: not a readable OpenStreetMap XML file: {exc}") from exc


def detect_driving_side(root: ET.Element) -> tuple[str, str]:
    """("left" | "right", why) from `driving_side` tags, else from the extract's location."""
    tags = Counter(t.get("v") for t in root.iter("tag") if t.get("k") == "driving_side")
    if tags:
        side = "left" if tags.get("left", 0) > tags.get("right", 0) else "right"
        return side, f"driving_side tags {dict(tags)}"
    b = root.find("bounds")
    if b is not None:
        lon = (float(b.get("minlon", 0)) + float(b.get("maxlon", 0))) / 2
        lat = (float(b.get("minlat", 0)) + float(b.get("maxlat", 0))) / 2
    else:
        nodes = [(float(n.get("lon", 0)), float(n.get("lat", 0))) for n in root.iter("node")]
        if not nodes:
            return "right", "no nodes (default right)"
        lon = sum(p[0] for p in nodes) / len(nodes)
        lat = sum(p[1] for p in nodes) / len(nodes)
    for name, (x0, y0, x1, y1) in LEFT_HAND_BOXES.items():
        if x0 <= lon <= x1 and y0 <= lat <= y1:
            return "left", f"centre ({lat:.4f}, {lon:.4f}) lies in {name}"
    return "right", f"centre ({lat:.4f}, {lon:.4f}) is not in a left-hand-traffic region"


def netconvert_command(osm: Path, out: Path, *, lefthand: bool, extra: list[str] | None = None) -> list[str]:
    import sumo

    typemap = Path(sumo.SUMO_HOME) / "data" / "typemap" / "osmNetconvert.typ.xml"
    cmd = [
        str(netconvert_binary()),
        "--osm-files",
        str(osm),
        "--output-file",
        str(out),
        "--type-files",
        str(typemap),
        *NETCONVERT_OSM_OPTIONS,
    ]
    if lefthand:
        cmd.append("--lefthand")
    return cmd + list(extra or [])


def check_network(net: Path) -> dict[str, Any]:
    """Loads `net` with our map reader and routes across it (the two farthest-apart ends of its
    longest car route, found with sumolib); returns counts and the route our reader found."""
    import sumolib

    snet = sumolib.net.readNet(str(net))
    drivable = [e for e in snet.getEdges() if any(ln.allows("passenger") for ln in e.getLanes())]
    if not drivable:
        raise ScenarioError(f"{net}: no edge open to cars (class passenger)")
    # The longest edge, then the reachable edge farthest from it by route length.
    start = max(drivable, key=lambda e: e.getLength())
    best: tuple[float, list[Any]] = (0.0, [start])
    for e in sorted(drivable, key=lambda e: -e.getLength())[:400]:
        path, cost = snet.getShortestPath(start, e, vClass="passenger")
        if path and cost is not None and cost > best[0]:
            best = (cost, path)
    cost, path = best
    probe = {
        "version": 1,
        "id": "osm_probe",
        "category": "06_traffic_flow",
        "map": str(net.resolve().as_posix()),
    }
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "probe.toml"
        edges = json.dumps([path[0].getID(), path[-1].getID()])
        f.write_text(
            "\n".join(f"{k} = {json.dumps(v)}" for k, v in probe.items())
            + f"\n\n[ego]\nroute_edges = {edges}\n",
            encoding="utf-8",
        )
        summary = _core.validate_scenario(str(f), None)
    tls = {j.getID() for j in snet.getNodes() if j.getType() == "traffic_light"}
    return {
        "net": str(net),
        "edges": len(snet.getEdges()),
        "drivable_edges": len(drivable),
        "drivable_km": round(
            sum(e.getLength() * sum(ln.allows("passenger") for ln in e.getLanes()) for e in drivable) / 1000,
            3,
        ),
        "junctions": len(snet.getNodes()),
        "traffic_light_junctions": len(tls),
        "roundabouts": len(snet.getRoundabouts()),
        "lefthand": bool(_lefthand_of(net)),
        "probe_route": {
            "from": path[0].getID(),
            "to": path[-1].getID(),
            "sumolib_edges": len(path),
            "sumolib_length_m": round(cost, 2),
            "our_edges": len(summary["route_edges"]),
            "our_length_m": round(summary["route_length_m"], 2),
        },
    }


def _lefthand_of(net: Path) -> bool:
    for _, el in ET.iterparse(net, events=("start",)):
        if el.tag == "net":
            return el.get("lefthand", "false") == "true"
    return False


def import_osm(
    osm: Path, out: Path, *, driving_side: str = "auto", extra: list[str] | None = None
) -> dict[str, Any]:
    if not osm.is_file():
        raise ConfigError(f"{osm}: file not found")
    side, why = (driving_side, "given") if driving_side != "auto" else detect_driving_side(_osm_root(osm))
    out.parent.mkdir(parents=True, exist_ok=True)
    cmd = netconvert_command(osm, out, lefthand=side == "left", extra=extra)
    import sumo

    # netconvert's PROJ finds its database through PROJ_DATA (PROJ_LIB before PROJ 9.1).
    proj = str(Path(sumo.SUMO_HOME) / "data" / "proj")
    env = {**os.environ, "PROJ_DATA": proj, "PROJ_LIB": proj}
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
    if proc.returncode != 0 or not out.is_file():
        msg = (proc.stderr or proc.stdout).strip().splitlines()
        raise ConfigError(f"{osm}: netconvert failed (exit {proc.returncode}): " + " | ".join(msg[-5:]))
    summary = check_network(out)
    summary["driving_side"] = side
    summary["driving_side_reason"] = why
    summary["netconvert"] = [Path(cmd[0]).name, *cmd[1:]]
    warnings = [ln for ln in proc.stderr.splitlines() if ln.startswith("Warning")]
    summary["netconvert_warnings"] = len(warnings)
    return summary


def _import_osm(args: argparse.Namespace) -> int:
    s = import_osm(args.osm, args.out, driving_side=args.driving_side, extra=args.netconvert_option)
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    r = s["probe_route"]
    print(f"wrote {s['net']}")
    print(f"  driving side: {s['driving_side']} ({s['driving_side_reason']})")
    print(
        f"  {s['edges']} edges ({s['drivable_edges']} open to cars, {s['drivable_km']} lane-km), "
        f"{s['junctions']} junctions, {s['traffic_light_junctions']} with lights, "
        f"{s['roundabouts']} roundabouts"
    )
    print(
        f"  checked: our map reader routes {r['from']} → {r['to']} over {r['our_edges']} edges, "
        f"{r['our_length_m']:.1f} m (sumolib: {r['sumolib_edges']} edges, {r['sumolib_length_m']:.1f} m)"
    )
    print(f"  netconvert warnings: {s['netconvert_warnings']}")
    return 0


def _classes(allow: list[str], everything: list[str]) -> str:
    """The shorter of "a, b" and "all but x, y" (a lane open to all but pedestrians reads so)."""
    if set(allow) >= set(everything):
        return "all"
    if not allow:
        return "none"
    missing = [c for c in everything if c not in allow]
    return ", ".join(allow) if len(allow) <= len(missing) else "all but " + ", ".join(missing)


def _show(args: argparse.Namespace) -> int:
    from drivehierarchy.scenarios import sumo_home

    if not args.net.startswith(("sumo:", "builtin:")) and not Path(args.net).exists():
        raise ConfigError(f"map `{args.net}`: {args.net} does not exist")
    net = _core.map_summary(args.net, sumo_home())
    edges = [e for e in net["edges"] if args.all or e["function"] == "normal"]
    if args.edge:
        unknown = sorted(set(args.edge) - {e["id"] for e in net["edges"]})
        if unknown:
            from drivehierarchy._suggest import did_you_mean

            ids = [e["id"] for e in net["edges"]]
            raise ConfigError(f"map `{args.net}`: no edge `{unknown[0]}`{did_you_mean(unknown[0], ids)}")
        edges = [e for e in net["edges"] if e["id"] in args.edge]
    if args.json:
        print(json.dumps({**net, "edges": edges}, indent=2))
        return 0
    everything = net["vclasses"]
    x0, y0, x1, y1 = net["bounds"]
    print(f"{net['path']}")
    print(
        f"  {len(net['edges'])} edges ({sum(e['function'] == 'normal' for e in net['edges'])} normal), "
        f"{net['junctions']} junctions, {len(net['traffic_lights'])} traffic lights, "
        f"{x1 - x0:.0f} m × {y1 - y0:.0f} m"
    )
    for e in edges:
        ends = f"{e['from'] or '?'} → {e['to'] or '?'}"
        kind = "" if e["function"] == "normal" else f" [{e['function']}]"
        name = f" “{e['name']}”" if e.get("name") else ""
        print(f"edge {e['id']}{kind}{name}: {ends}, {len(e['lanes'])} lane(s)")
        for lane in e["lanes"]:
            print(
                f"  lane {lane['id']:<24} {lane['length_m']:8.1f} m  {lane['speed_mps']:5.1f} m/s  "
                f"{lane['width_m']:4.1f} m wide  {_classes(lane['allow'], everything)}"
            )
    return 0
