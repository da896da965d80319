"""`drivehierarchy scenario ...`: validate, list, show, preview and import scenario files."""

from __future__ import annotations

import argparse
import json
import sys
import tomllib
from pathlib import Path
from typing import Any

from drivehierarchy import DriveHierarchyError, _core
from drivehierarchy._core import ConfigError
from drivehierarchy.envs.traffic.modes import TRAFFIC_MODES, deprecated_scenario_mode, traffic_mode_arg
from drivehierarchy.scenarios import builtin_scenarios, resolve_scenario, scenario_id, sumo_home
from drivehierarchy.suite_probe import SWEEP


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    sc = sub.add_parser("scenario", help="scenario files")
    cmds = sc.add_subparsers(dest="scenario_command", required=True)
    v = cmds.add_parser("validate", help="check scenario files; exit 1 if any is invalid")
    v.add_argument("files", nargs="+", help="scenario files or folders (every */*.toml and *.toml)")
    v.set_defaults(func=_validate)

    js = cmds.add_parser(
        "schema",
        help="print the JSON Schema of scenario files (docs/scenario.schema.json)",
        description=(
            "The JSON Schema generated from the Rust types that read scenario files: for editors "
            "(Taplo / Even Better TOML `#:schema` directive) and other tools. `validate` remains "
            "the full check (it also needs the map)."
        ),
    )
    js.add_argument("--out", type=Path, help="write it to this file instead of stdout")
    js.set_defaults(func=_schema)

    ls = cmds.add_parser("list", help="list the built-in scenarios, or those of a folder")
    ls.add_argument("dir", nargs="?", type=Path, help="a folder of <category>/<name>.toml files")
    ls.add_argument("--json", action="store_true", help="one JSON object per line")
    ls.set_defaults(func=_list)

    sh = cmds.add_parser("show", help="print a scenario's resolved summary (route, actors, traffic)")
    sh.add_argument("scenario", help="scenario file or built-in id")
    sh.add_argument("--json", action="store_true")
    sh.set_defaults(func=_show)

    pv = cmds.add_parser(
        "preview",
        help="write the front camera and BEV as PNGs (the start state, or at --time)",
        description=(
            "Writes OUT/<category>__<name>_front.png (800×450, 2× supersampled) and _bev.png "
            "(800×800). Without --time: the start state after reset. With --time T: the scene at "
            "the last decision at or before T seconds, the ego driven by the expert (what the "
            "editor's preview shows, byte for byte)."
        ),
    )
    pv.add_argument("scenario", help="scenario file or built-in id")
    pv.add_argument("--out", type=Path, default=Path("."), help="output folder (default: .)")
    pv.add_argument("--seed", type=int, default=0)
    pv.add_argument("--time", type=float, metavar="T", help="seconds into the episode (expert driving)")
    pv.set_defaults(func=_preview)

    pr = cmds.add_parser(
        "probe",
        help="sweep reference drivers (expert, late expert, blind follower / constant / light-obeying "
        "at several speeds) over scenarios",
        description=(
            "Measures how discriminating a suite is: S_R4 of reference drivers per scenario and per "
            "category over seeds (state-only episodes in worker processes). A cell is expert, "
            "late_expert, zero, or follower|constant|lights@<m/s>; a bare family name means all its "
            "sweep speeds. --results merges the episodes into a committed results file (rows of the "
            "same scenario, cell and seed are replaced); --update-doc regenerates the table between "
            "<!-- probe:begin --> and <!-- probe:end --> from the results file (or from this run). "
            "Exit 2 when no scenario is found."
        ),
    )
    pr.add_argument("files", nargs="+", help="scenario files or folders (every */*.toml and *.toml)")
    pr.add_argument("--out", type=Path, help="also write OUT/probe.csv (every episode) and OUT/probe.md")
    pr.add_argument(
        "--policies",
        default="expert,late_expert,zero,follower,constant,lights",
        help="comma-separated cells (default: the full sweep: " + ",".join(SWEEP) + ")",
    )
    pr.add_argument("--seeds", default="0-4", help="seeds, e.g. 0-4 (default) or 0,3")
    pr.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    pr.add_argument(
        "--traffic",
        type=traffic_mode_arg,
        metavar="{" + ",".join(TRAFFIC_MODES) + "}",
        help="override every scenario's traffic mode",
    )
    pr.add_argument(
        "--results", type=Path, help="merge the episodes into this CSV (e.g. docs/suite_probe.csv)"
    )
    pr.add_argument(
        "--update-doc",
        type=Path,
        help="rewrite the part of this Markdown file between <!-- probe:begin --> and <!-- probe:end -->",
    )
    pr.add_argument("--quiet", action="store_true", help="no per-task progress lines")
    pr.set_defaults(func=_probe)

    im = cmds.add_parser(
        "import-official",
        help="convert the original release's scenes (entity_sumo.json) into scenario files",
        description=(
            "Converts every <category>/<scene id>/entity_sumo.json under DIR (with entity.json "
            "beside it) into OUT/<category>/<scene id>.toml on your copy of the road network, "
            "copies the vehicle-type file into OUT, and writes OUT/import_report.json. Exit 1 if "
            "a scene cannot be imported (or, with --strict, if any actor could not be mapped)."
        ),
    )
    im.add_argument("dir", type=Path, help="folder of the original scenes (e.g. Scenario_Onsite)")
    im.add_argument("--net", type=Path, required=True, help="the road network (tongji.net.xml)")
    im.add_argument("--out", type=Path, required=True, help="output folder (yours; files are overwritten)")
    im.add_argument(
        "--vtypes",
        type=Path,
        help="SUMO vehicle types (carlavtypes13.rou.xml; default: that file beside --net, if present)",
    )
    im.add_argument("--copy-net", action="store_true", help="copy the network into OUT (self-contained)")
    im.add_argument("--strict", action="store_true", help="exit 1 when any actor could not be mapped")
    im.add_argument("--json", action="store_true", help="print the report as JSON")
    im.set_defaults(func=_import_official)


def _expand(items: list[str]) -> list[Path]:
    out: list[Path] = []
    for it in items:
        p = Path(it)
        if p.is_dir():
            found = sorted(p.glob("*/*.toml")) + sorted(p.glob("*.toml"))
            if not found:
                raise ConfigError(f"{p}: no scenario files (*.toml) in this folder")
            out.extend(found)
        else:
            out.append(p)
    return out


def _validate(args: argparse.Namespace) -> int:
    bad = 0
    for f in _expand(args.files):
        try:
            summary = _core.validate_scenario(str(f), sumo_home())
        except DriveHierarchyError as exc:
            bad += 1
            print(f"INVALID {exc}")
            continue
        print(f"ok {f}: {json.dumps(summary, sort_keys=True)}", flush=True)
        old = deprecated_scenario_mode(str(f))
        if old is not None:
            print(f"warning: {old}", file=sys.stderr)
    return 1 if bad else 0


def schema_text() -> str:
    """The scenario JSON Schema as docs/scenario.schema.json holds it."""
    return json.dumps(_core.scenario_json_schema(), indent=2, ensure_ascii=False) + "\n"


def _schema(args: argparse.Namespace) -> int:
    text = schema_text()
    if args.out is None:
        print(text, end="")
        return 0
    try:
        args.out.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"--out {args.out}: cannot write: {exc}") from exc
    print(args.out)
    return 0


def _probe(args: argparse.Namespace) -> int:
    import csv
    import time

    from drivehierarchy import suite_probe

    cells = suite_probe.expand_cells(args.policies)
    seeds = suite_probe.parse_seeds(args.seeds)
    files = _expand(args.files)
    t0 = time.perf_counter()
    rows = suite_probe.probe(
        files, cells, seeds=seeds, jobs=args.jobs, traffic=args.traffic, progress=not args.quiet
    )
    wall = time.perf_counter() - t0
    cpu = sum(r["wall_s"] for r in rows)
    print(f"{len(rows)} episodes in {wall:.0f} s wall ({cpu:.0f} s in episodes, {args.jobs} workers)")
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        with (args.out / "probe.csv").open("w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            for r in rows:
                w.writerow({**r, "events": ";".join(r["events"])})
        (args.out / "probe.md").write_text(
            suite_probe.markdown(suite_probe.summarize(rows)), encoding="utf-8"
        )
    table_rows = rows
    if args.results is not None:
        old = suite_probe.read_results(args.results) if args.results.exists() else []
        table_rows = suite_probe.merge(old, rows)
        suite_probe.write_results(args.results, table_rows)
    summary = suite_probe.summarize(table_rows)
    text = suite_probe.markdown(summary)
    if args.update_doc is not None:
        suite_probe.update_doc(args.update_doc, text)
    print(text.split("\n\n| scenario |")[0])
    return 0


def _toml(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError):
        return {}


def _list(args: argparse.Namespace) -> int:
    if args.dir is None:
        paths = builtin_scenarios()
        ids = [scenario_id(p) for p in paths]
    else:
        if not args.dir.is_dir():
            raise ConfigError(f"{args.dir}: not a folder")
        paths = sorted(args.dir.glob("*/*.toml"))
        if not paths:
            raise ConfigError(f"{args.dir}: no scenario files (<category>/<name>.toml)")
        ids = [str(p) for p in paths]
    for sid, p in zip(ids, paths, strict=True):
        doc = _toml(p)
        if args.json:
            row = {
                "id": sid,
                "category": doc.get("category"),
                "map": doc.get("map"),
                "description": doc.get("description", ""),
            }
            print(json.dumps(row, ensure_ascii=False))
        else:
            print(f"{sid}\t{doc.get('description', '')}")
    return 0


def _show(args: argparse.Namespace) -> int:
    path = Path(resolve_scenario(args.scenario))
    summary: dict[str, Any] = dict(_core.validate_scenario(str(path), sumo_home()))
    doc = _toml(path)
    summary["description"] = doc.get("description", "")
    summary["duration_s"] = doc.get("duration_s")
    summary["ego"] = {k: doc.get("ego", {}).get(k) for k in ("start", "destination")}
    summary["scripted_actors"] = [
        {
            "name": a.get("name"),
            "kind": a.get("kind"),
            "start": a.get("start", {"time_s": 0}),
            "lanes": (a.get("route") or {}).get("lanes") if isinstance(a.get("route"), dict) else None,
        }
        for a in doc.get("actors", [])
    ]
    if args.json:
        print(json.dumps(summary, indent=2, ensure_ascii=False, sort_keys=True))
        return 0
    print(f"{summary['id']}  ({summary['category']})  {summary['name']}")
    if summary["description"]:
        print(f"  {summary['description']}")
    print(f"  file: {path}")
    print(f"  map: {summary['map']}  ({summary['traffic_lights']} signal heads)")
    print(f"  ego: from {_place(summary['ego']['start'])} to {_place(summary['ego']['destination'])}")
    print(f"  route: {len(summary['route_edges'])} edges, {summary['route_length_m']:.1f} m")
    print(f"    edges: {' → '.join(summary['route_edges'])}")
    dur = summary["duration_s"]
    print(
        f"  T_ref: {summary['reference_duration_s']:.1f} s"
        + (f", scenario duration {dur:.1f} s (timeout {2 * dur:.1f} s)" if dur else "")
    )
    print(f"  actors: {summary['actors']}, obstacles: {summary['obstacles']}, signs: {summary['signs']}")
    for a in summary["scripted_actors"]:
        print(f"    - {a['kind']}: {a['name'] or ''}  start {json.dumps(a['start'])}")
        if a["lanes"]:
            print(f"      lanes: {', '.join(a['lanes'])}")
    print(f"  traffic: {summary['traffic']}")
    return 0


def _place(place: object) -> str:
    """`lane C2T_1 at s = 20.0 m` for a lane place, else the place as written."""
    if isinstance(place, dict) and "lane" in place:
        return f"lane {place['lane']} at s = {place.get('s', 0.0)} m"
    return json.dumps(place)


def _preview(args: argparse.Namespace) -> int:
    from drivehierarchy.benchmark.r4.gallery import render_start

    path = Path(resolve_scenario(args.scenario))
    args.out.mkdir(parents=True, exist_ok=True)
    if args.time is not None:
        from drivehierarchy.benchmark.r4.gallery import scenario_key
        from drivehierarchy.editor.scene import preview_frames

        if not args.time >= 0:
            raise ConfigError(f"--time {args.time}: must be a number of seconds ≥ 0")
        pngs = preview_frames(str(path), args.time, seed=args.seed)
        for view, data in pngs.items():
            out = args.out / f"{scenario_key(path)}_{view}.png"
            out.write_bytes(data)
            print(out)
        return 0
    entry = render_start(path, args.out, seed=args.seed)
    for view in ("front", "bev"):
        print(args.out / entry.files[view])
    return 0


def _import_official(args: argparse.Namespace) -> int:
    from drivehierarchy.scenario_import import import_official

    report = import_official(args.dir, args.net, args.out, vtypes=args.vtypes, copy_net=args.copy_net)
    if args.json:
        print(json.dumps(report.to_json(), indent=2, ensure_ascii=False))
    else:
        for line in report.lines():
            print(line)
        print(f"report: {Path(report.out) / 'import_report.json'}")
    if report.failed or (args.strict and report.unmapped_count):
        return 1
    return 0
