"""The `drivehierarchy` command: each area adds its own sub-commands."""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys

# Area modules, each with `register(subparsers)` adding its commands; every command sets
# `func(args) -> int` on its parser.
_AREAS = (
    "drivehierarchy.baselines.cli",
    "drivehierarchy.benchmark.openloop.cli",
    "drivehierarchy.benchmark.r4.cli",
    "drivehierarchy.benchmark.hierarchy",
    "drivehierarchy.scenario_cli",
    "drivehierarchy.map_cli",
    "drivehierarchy.editor.cli",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="drivehierarchy", description=__doc__)
    from drivehierarchy import __version__

    parser.add_argument("--version", action="version", version=f"drivehierarchy {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for name in _AREAS:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    from drivehierarchy import DriveHierarchyError

    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except DriveHierarchyError as exc:
        print(f"drivehierarchy: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader went away (`drivehierarchy scenario list | head`): stop quietly, as a Unix
        # tool killed by SIGPIPE would, and keep the interpreter's final flush from raising again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 128 + signal.SIGPIPE
    except KeyboardInterrupt:
        print("drivehierarchy: interrupted", file=sys.stderr)
        return 128 + signal.SIGINT


if __name__ == "__main__":
    sys.exit(main())
