"""`drivehierarchy r4 ...`: run, evaluate and re-score closed-loop episodes."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.scenarios import resolve_scenario


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    r4 = sub.add_parser("r4", help="closed-loop R4 episodes")
    cmds = r4.add_subparsers(dest="r4_command", required=True)

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("--agent", default="expert", help=f"agent name ({', '.join(runner.AGENTS.names())})")
        p.add_argument("--out", type=Path, required=True, help="output directory (resumable)")
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--frames", action="store_true", help="save front and BEV PNGs of every decision")
        p.add_argument("--video", action="store_true", help="save an animated GIF of the front camera")

    run = cmds.add_parser("run", help="drive one scenario")
    run.add_argument("--scenario", required=True, help="scenario file or built-in id")
    common(run)
    run.set_defaults(func=_run)

    ev = cmds.add_parser("evaluate", help="drive a whole suite and print the summary table")
    ev.add_argument("--suite", default="builtin", help="'builtin', a folder of scenarios, or one file")
    common(ev)
    ev.set_defaults(func=_evaluate)

    rs = cmds.add_parser("rescore", help="recompute scores from episode logs, without simulating")
    rs.add_argument("dir", type=Path)
    rs.set_defaults(func=_rescore)

    gal = cmds.add_parser("gallery", help="rewrite the rendering gallery (start frame of every scenario)")
    gal.add_argument("--out", type=Path, default=Path("docs/gallery"), help="output directory")
    gal.add_argument("--seed", type=int, default=0)
    gal.set_defaults(func=_gallery)


def _opts(args: argparse.Namespace) -> runner.RunOptions:
    return runner.RunOptions(agent=args.agent, seed=args.seed, frames=args.frames, video=args.video)


def _run(args: argparse.Namespace) -> int:
    path = Path(resolve_scenario(args.scenario))
    results = runner.evaluate([path], args.out, _opts(args), log=lambda m: print(m, file=sys.stderr))
    print(json.dumps(results[0]["score"], indent=2, sort_keys=True))
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    results = runner.evaluate(runner.suite_scenarios(args.suite), args.out, _opts(args))
    print()
    print(runner.summary_table(results))
    return 0


def _rescore(args: argparse.Namespace) -> int:
    for r in runner.rescore_dir(args.dir):
        s = r["score"]
        print(f"{r['key']}: S_R4 {s['score_composed']:.4f} ({s['termination_reason']})")
    return 0


def _gallery(args: argparse.Namespace) -> int:
    from drivehierarchy.benchmark.r4 import gallery

    entries = gallery.write_gallery(args.out, seed=args.seed)
    print(f"{len(entries)} scenarios written to {args.out}")
    return 0
