"""`drivehierarchy r4 ...`: run, evaluate and re-score closed-loop episodes."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from drivehierarchy import _core
from drivehierarchy._core import ConfigError
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.scenarios import resolve_scenario


def register(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    r4 = sub.add_parser("r4", help="closed-loop R4 episodes")
    cmds = r4.add_subparsers(dest="r4_command", required=True)

    def common(p: argparse.ArgumentParser) -> None:
        names = ", ".join([*runner.AGENTS.names(), runner.VLM_AGENT])
        p.add_argument(
            "--agent",
            default="expert",
            help=f"agent name ({names}). sb3:PATH loads a Stable-Baselines3 archive, which unpickles "
            "Python objects and so can run arbitrary code: only load model files you trust",
        )
        p.add_argument("--out", type=Path, required=True, help="output directory (resumable)")
        p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
        p.add_argument(
            "--action-level",
            choices=["control", "waypoints", "meta"],
            default=None,
            help="what the agent decides: control = the paper's [steer, target speed] (default); "
            "waypoints = 8 ego-frame points 0.5 s apart for the waypoint tracker; meta = a path "
            "action x a speed action. waypoints and meta are this project's extension of the "
            "protocol (docs/r4.md#action-levels). An sb3: model drives at the level it was "
            "trained at (default), and another level is refused",
        )
        p.add_argument("--frames", action="store_true", help="save front and BEV PNGs of every decision")
        p.add_argument("--video", action="store_true", help="save an animated GIF of the front camera")
        p.add_argument("--progress", action="store_true", help="progress bar on stderr (default: on a TTY)")
        p.add_argument(
            "--force",
            action="store_true",
            help="redo scenarios that --out already has results for (needed when a scenario file changed)",
        )
        c = p.add_argument_group("robustness controls (any agent; docs/rendering.md#conditions)")
        c.add_argument(
            "--conditions",
            metavar="NAME",
            help="control: draw every episode at this time of day and weather, overriding the "
            "scenarios' [conditions]: noon, dusk, night, overcast, rain, fog or TIME+WEATHER "
            "(e.g. night+rain)",
        )
        c.add_argument(
            "--camera-fault",
            choices=_core.constants()["camera_faults"],
            help="control: a fault of the front camera: frozen (stops updating), dropped (about one "
            "frame in four repeats the previous), dirty (smudged lens)",
        )
        v = p.add_argument_group("VLM agent (--agent vlm; docs/vlm.md)")
        v.add_argument("--base-url", help="OpenAI-compatible server, e.g. http://localhost:8000/v1")
        v.add_argument("--model", help="served model id, or a preset key (drivehierarchy r4 models)")
        v.add_argument("--api-key-env", help="environment variable holding the API key")
        v.add_argument("--temperature", type=float, default=0.0)
        v.add_argument("--max-tokens", type=int, default=256, help="bound on reply tokens (default 256)")
        v.add_argument("--timeout", type=float, default=60.0, help="seconds per request (default 60)")
        v.add_argument("--max-retries", type=int, default=2, help="retries per request (default 2)")
        v.add_argument(
            "--max-transport-failures",
            type=int,
            default=3,
            help="abort a scenario after this many decisions in a row without a reply (default 3)",
        )
        v.add_argument("--blind", action="store_true", help="control: text only, no images")
        v.add_argument("--no-bev", action="store_true", help="control: front image only")
        v.add_argument("--corrupt", choices=["noise", "blur", "dark"], help="control: degrade both images")
        v.add_argument(
            "--latency-aware",
            action="store_true",
            help="control: the world keeps moving for each reply's latency (previous control held)",
        )
        h = p.add_argument_group(
            "VLM history and memory (this project's extension of the protocol, docs/vlm.md)"
        )
        h.add_argument("--history", type=int, default=0, metavar="N", help="send the last N front frames too")
        h.add_argument(
            "--stride", type=int, default=1, metavar="S", help="decisions between two past frames (default 1)"
        )
        h.add_argument("--history-bev", action="store_true", help="send the past frames' BEVs too")
        h.add_argument(
            "--ego-history",
            type=int,
            default=0,
            metavar="K",
            help="the ego's last K positions and speeds as text",
        )
        h.add_argument(
            "--memory", type=int, default=0, metavar="K", help="the model's own last K decisions as text"
        )
        h.add_argument(
            "--history-shuffle",
            action="store_true",
            help="control: the past frames in a seeded random order (their labels stay in place)",
        )
        h.add_argument(
            "--history-freeze", action="store_true", help="control: every past frame is the current one"
        )

    run = cmds.add_parser("run", help="drive one scenario")
    run.add_argument("--scenario", required=True, help="scenario file or built-in id")
    run.add_argument("--json", action="store_true", help="print the scene score record as JSON")
    common(run)
    run.set_defaults(func=_run)

    ev = cmds.add_parser("evaluate", help="drive a whole suite and print the summary table")
    ev.add_argument("--suite", default="builtin", help="'builtin', a folder of scenarios, or one file")
    ev.add_argument("--jobs", type=int, default=1, help="scenarios in flight at once (default 1)")
    ev.add_argument("--seeds", type=int, default=1, help="run every scenario with K seeds (default 1)")
    ev.add_argument("--ray", metavar="ADDRESS", help="run scenarios as Ray tasks ('local' starts one)")
    ev.add_argument(
        "--worker-timeout",
        type=float,
        default=600.0,
        metavar="S",
        help="kill a SUMO worker process that does not answer a call within S seconds; its scenario "
        "fails, the others go on (default 600; 0: no limit). For a non-VLM agent one call is the "
        "whole scenario",
    )
    common(ev)
    ev.set_defaults(func=_evaluate)

    rs = cmds.add_parser("rescore", help="recompute scores from episode logs, without simulating")
    rs.add_argument("dir", type=Path)
    rs.set_defaults(func=_rescore)

    rep = cmds.add_parser(
        "report",
        help="Table 2, the (model, action level, inputs) comparison in S_R4 and the CARLA dialect, plots "
        "and r4_summary.csv of runs",
    )
    rep.add_argument("runs", nargs="+", type=Path, help="r4 evaluate output directories")
    rep.add_argument("--out", type=Path, required=True)
    rep.add_argument("--paper", action="store_true", help="add the paper's rows of preset models")
    rep.add_argument("--no-plot", action="store_true")
    rep.set_defaults(func=_report)

    mod = cmds.add_parser("models", help="the paper's 15 model presets")
    mod.set_defaults(func=_models)

    gal = cmds.add_parser("gallery", help="rewrite the rendering gallery (start frame of every scenario)")
    gal.add_argument("--out", type=Path, default=Path("docs/gallery"), help="output directory")
    gal.add_argument("--seed", type=int, default=0)
    gal.set_defaults(func=_gallery)


_HISTORY_FLAGS = ("history", "history_bev", "ego_history", "memory", "history_shuffle", "history_freeze")


def _vlm_options(args: argparse.Namespace) -> object | None:
    vlm_flags = [f for f in ("base_url", "model", "api_key_env", *_HISTORY_FLAGS) if getattr(args, f)]
    if args.stride != 1:
        vlm_flags.append("stride")
    if args.agent != runner.VLM_AGENT:
        if vlm_flags:
            raise ConfigError(f"--{vlm_flags[0].replace('_', '-')}: only for --agent vlm")
        return None
    if not args.base_url or not args.model:
        raise ConfigError("--agent vlm: needs --base-url and --model")
    from drivehierarchy.agents.vlm import PayloadOptions, VLMOptions
    from drivehierarchy.agents.vlm.history import HistoryOptions
    from drivehierarchy.agents.vlm.transport import DecodingConfig

    return VLMOptions(
        base_url=args.base_url,
        model=args.model,
        api_key_env=args.api_key_env,
        decoding=DecodingConfig(
            temperature=args.temperature, max_tokens=args.max_tokens, repetition_penalty=None
        ),
        payload=PayloadOptions(blind=args.blind, no_bev=args.no_bev, corrupt=args.corrupt),
        timeout_s=args.timeout,
        max_retries=args.max_retries,
        max_consecutive_transport_failures=args.max_transport_failures,
        latency_aware=args.latency_aware,
        history=HistoryOptions(
            frames=args.history,
            stride=args.stride,
            bev=args.history_bev,
            ego=args.ego_history,
            memory=args.memory,
            shuffle=args.history_shuffle,
            freeze=args.history_freeze,
        ),
    )


def _opts(args: argparse.Namespace) -> runner.RunOptions:
    from drivehierarchy.envs.config import R4Config

    level, mode = args.action_level or "control", None
    if args.agent.startswith("sb3:"):
        from drivehierarchy.agents.sb3 import model_level

        # The model's level (a raw-control model: the control level in action mode raw).
        level, mode = model_level(args.agent.removeprefix("sb3:"), args.action_level)
    config = R4Config(conditions=args.conditions, camera_fault=args.camera_fault)
    if mode is not None:
        config = config.replace(action_mode=mode)
    return runner.RunOptions(
        agent=args.agent,
        config=config,
        seed=args.seed,
        frames=args.frames,
        video=args.video,
        seeds=getattr(args, "seeds", 1),
        jobs=getattr(args, "jobs", 1),
        vlm=_vlm_options(args),
        ray_address=getattr(args, "ray", None),
        progress=args.progress or sys.stderr.isatty(),
        worker_timeout_s=_worker_timeout(getattr(args, "worker_timeout", 600.0)),
        force=args.force,
        action_level=level,
    )


def _worker_timeout(value: float) -> float | None:
    if value < 0:
        raise ConfigError(f"--worker-timeout = {value!r}: expected ≥ 0 seconds (0: no limit)")
    return value or None


def _run(args: argparse.Namespace) -> int:
    path = Path(resolve_scenario(args.scenario))
    try:
        results = runner.evaluate([path], args.out, _opts(args), log=lambda m: print(m, file=sys.stderr))
    except runner.BatchAborted as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except runner.ScenariosFailed as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 4
    result = results[0]
    s = result["score"]
    if args.json:
        print(json.dumps(s, indent=2, sort_keys=True))
        return 0
    scene = args.out / "scenes" / result["key"]
    print(
        f"{result['key']}: S_R4 {s['score_composed']:.2f} ({s['status']}, {s['termination_reason']}); "
        f"route {s['score_route']:.3f}, safety {s['score_safety']:.3f}, "
        f"efficiency {s['score_efficiency']:.3f}"
    )
    artifacts = [("score record", scene / "scene_score.json"), ("episode log", scene / "episode_log.jsonl")]
    artifacts += [("decisions", scene / "decisions.jsonl"), ("events", scene / "events.json")]
    if args.frames:
        artifacts.append(("frames", scene / "frames"))
    if args.video:
        artifacts.append(("video", scene / "episode.gif"))
    for what, path in artifacts:
        if path.exists():
            print(f"  {what + ':':<14}{path}")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    opts = _opts(args)
    log = (lambda m: None) if opts.progress else print
    try:
        results = runner.evaluate(runner.suite_scenarios(args.suite), args.out, opts, log=log)
    except runner.BatchAborted as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except runner.ScenariosFailed as exc:
        summary = args.out / "summary.md"
        if summary.exists():  # the scenarios that finished
            print()
            print(summary.read_text(encoding="utf-8"))
        print(f"error: {len(exc.failed)} scenario(s) failed: {', '.join(exc.failed)}: {exc}", file=sys.stderr)
        return 4
    print()
    print(runner.summary_table(results))
    return 0


def _report(args: argparse.Namespace) -> int:
    from drivehierarchy.benchmark.r4 import report

    for path in report.build_report(args.runs, args.out, paper=args.paper, plot=not args.no_plot):
        print(path)
    return 0


def _models(args: argparse.Namespace) -> int:
    from drivehierarchy.agents.vlm.presets import PRESETS

    print(f"{'key':<18} {'paper name':<20} {'served model id':<42} images  paper R4")
    for p in PRESETS.values():
        print(
            f"{p.key:<18} {p.paper_name:<20} {p.served_model_id:<42} {p.images_per_prompt:>6}  "
            f"{p.paper_r4_average:.3f}"
        )
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
