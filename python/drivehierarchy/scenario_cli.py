"""`drivehierarchy scenario ...`: validate and list scenario files."""

from __future__ import annotations

import argparse
import json

from drivehierarchy import DriveHierarchyError, _core
from drivehierarchy.scenarios import builtin_scenarios, scenario_id, sumo_home


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    sc = sub.add_parser("scenario", help="scenario files")
    cmds = sc.add_subparsers(dest="scenario_command", required=True)
    v = cmds.add_parser("validate", help="check scenario files; exit 1 if any is invalid")
    v.add_argument("files", nargs="+")
    v.set_defaults(func=_validate)
    ls = cmds.add_parser("list", help="list the built-in scenarios")
    ls.set_defaults(func=_list)


def _validate(args: argparse.Namespace) -> int:
    bad = 0
    for f in args.files:
        try:
            summary = json.loads(_core.validate_scenario(f, sumo_home()))
        except DriveHierarchyError as exc:
            bad += 1
            print(f"INVALID {exc}")
            continue
        print(f"ok {f}: {json.dumps(summary, sort_keys=True)}")
    return 1 if bad else 0


def _list(args: argparse.Namespace) -> int:
    for p in builtin_scenarios():
        print(scenario_id(p))
    return 0
