"""`drivehierarchy openloop ...`: predict, score, generate, calibrate, report, deficit, export-sft."""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("openloop", help="open-loop R1–R3 benchmark (predict, score, report, ...)")
    sub = parser.add_subparsers(dest="openloop_command", required=True)

    p = sub.add_parser("predict", help="query an OpenAI-compatible VLM on the task files (resumable)")
    p.add_argument(
        "--base-url", required=True, help="OpenAI-compatible API base, e.g. http://localhost:8000/v1"
    )
    p.add_argument("--model", required=True, help="model name sent in each request")
    p.add_argument("--out", required=True, type=Path, help="run folder (created; resumed when present)")
    _add_data_args(p)
    p.add_argument("--concurrency", type=int, default=64, help="requests in flight (default 64)")
    p.add_argument("--limit", type=int, default=None, help="first N records of each task file")
    p.add_argument("--api-key-env", default=None, help="name of the environment variable holding the API key")
    p.add_argument("--timeout", type=float, default=300.0, help="seconds per HTTP attempt (default 300)")
    p.add_argument("--retries", type=int, default=6, help="retries on 429/5xx/timeouts (default 6)")
    p.add_argument("--max-tokens", type=int, default=256, help="max new tokens (protocol: 256)")
    p.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    p.set_defaults(func=_cmd_predict)

    p = sub.add_parser(
        "score",
        help="score a results folder (ours or the original runner's); writes DIR/evaluation/final_score.json",
    )
    p.add_argument(
        "run_dir", type=Path, help="our run folder (predictions/) or the original's result_dir (*_pred.jsonl)"
    )
    p.add_argument("--judge-model", default=None, help="local path of the Lingo-Judge model for R1_4")
    p.add_argument(
        "--skip-l1-4", action="store_true", help="skip R1_4 (judge) scoring, as the original's flag"
    )
    p.add_argument("--strict-order", action="store_true", help="R3_2 without the original's label-fill quirk")
    p.add_argument(
        "--layout",
        choices=("auto", "original", "drivehierarchy"),
        default="auto",
        help="folder layout (default: detected)",
    )
    p.set_defaults(func=_cmd_score)

    p = sub.add_parser(
        "generate",
        help="generate R1–R3 question files (+ images) from the R4 suite's scenes, exact ground truth",
    )
    p.add_argument(
        "--suite", required=True, type=Path, help="scenario folder (e.g. scenarios/r4) or one file"
    )
    p.add_argument("--out", required=True, type=Path, help="output folder (the 14 task files + images/)")
    p.add_argument("--per-task", type=int, default=200, help="records per task (default 200)")
    p.add_argument("--seed", type=int, default=0, help="seed of every choice (default 0)")
    p.add_argument(
        "--split",
        choices=("eval", "train"),
        default="eval",
        help="eval: the R4 scenes (seeds 0-4); train: other seeds/traffic on the same maps",
    )
    p.add_argument("--tasks", default=None, help="comma-separated task ids (default: all)")
    p.add_argument("--jobs", type=int, default=2, help="rollout worker processes (default 2)")
    p.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=_cmd_generate)

    p = sub.add_parser("calibrate", help="recompute task weights from a pool of models' task scores")
    p.add_argument(
        "--scores", required=True, type=Path, help="CSV: a 'model' column + one column per task id"
    )
    p.add_argument("--out", type=Path, default=None, help="write the weights as JSON here")
    p.set_defaults(func=_cmd_calibrate)

    p = sub.add_parser(
        "report", help="Table 1 (Markdown + CSV), radar plots, Spearman heatmaps, R4 correlations"
    )
    p.add_argument("run_dirs", nargs="*", type=Path, help="scored run folders")
    p.add_argument(
        "--scores", type=Path, default=None, help="also read task scores from a CSV (model + task ids)"
    )
    p.add_argument("--r4", type=Path, default=None, help="CSV with columns model, r4_score")
    p.add_argument("--out", type=Path, default=Path("openloop_report"), help="output folder")
    p.add_argument("--no-plots", action="store_true", help="tables only (no matplotlib)")
    p.set_defaults(func=_cmd_report)

    p = sub.add_parser(
        "deficit", help="a model's relative deficit to the task-wise best of a pool (Table 3 row 1)"
    )
    p.add_argument("--scores", required=True, type=Path, help="CSV: model + task ids (e.g. from `report`)")
    p.add_argument("--model", required=True)
    p.add_argument("--threshold", type=float, default=0.25, help="select tasks at least this far behind")
    p.set_defaults(func=_cmd_deficit)

    p = sub.add_parser("export-sft", help="write chosen tasks' records as ms-swift SFT JSONL")
    p.add_argument("--tasks", required=True, help="comma-separated task ids, e.g. R1_2_A,R1_2_B,R1_3")
    p.add_argument("--out", required=True, type=Path, help="output .jsonl")
    _add_data_args(p, datasets=False)
    p.add_argument("--limit", type=int, default=None, help="first N records of each task file")
    p.add_argument("--require-images", action="store_true", help="skip records whose images are missing")
    p.set_defaults(func=_cmd_export_sft)


def _add_data_args(p: argparse.ArgumentParser, datasets: bool = True) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--data-dir", type=Path, help="folder holding the 14 released task JSONL files")
    src.add_argument("--catalog", type=Path, help="catalog JSON (original open_loop_all.json format)")
    if datasets:
        p.add_argument("--datasets", default="all", help="'all' or comma-separated task ids / names")
    p.add_argument(
        "--image-root",
        action="append",
        default=[],
        metavar="OLD=NEW",
        help="rewrite image paths starting with OLD to NEW (repeatable), e.g. /data/sets=/mnt/datasets",
    )


def _cmd_predict(args: argparse.Namespace) -> int:
    from .client import DecodingConfig
    from .runner import RunConfig, predict

    config = RunConfig(
        base_url=args.base_url,
        model=args.model,
        out=args.out,
        datasets=args.datasets,
        data_dir=args.data_dir,
        catalog=args.catalog,
        image_roots=tuple(args.image_root),
        concurrency=args.concurrency,
        limit=args.limit,
        api_key_env=args.api_key_env,
        decoding=DecodingConfig(max_tokens=args.max_tokens),
        timeout_s=args.timeout,
        max_retries=args.retries,
        progress=not args.no_progress,
    )
    try:
        s = predict(config)
    except KeyboardInterrupt:
        print("interrupted; run the same command again to resume", file=sys.stderr)
        return 130
    print(
        f"{s.out}: {s.total} records, {s.already_done} already done, {s.written} predicted, "
        f"{s.failed} failed (see errors.jsonl) in {s.elapsed_s:.1f} s"
        + ("" if s.complete else "; incomplete — run again to retry failures")
    )
    return 0 if s.complete else 1


def _cmd_score(args: argparse.Namespace) -> int:
    from .scoring import PredictionFileWarning, score_run

    with warnings.catch_warnings():
        # Skipped lines are reported once, in the printed summary below.
        warnings.simplefilter("ignore", PredictionFileWarning)
        result = score_run(
            args.run_dir,
            judge_model=args.judge_model,
            skip_l1_4=args.skip_l1_4,
            strict_order=args.strict_order,
            layout=args.layout,
        )
    print(json.dumps(_headline(result), indent=2, ensure_ascii=False))
    for f in result["per_file"]:
        if f["skipped_lines"]:
            print(
                f"warning: {f['source_file']}: skipped {f['skipped_lines']} lines "
                f"(scored {f['n']}); first: {f['first_skip']}",
                file=sys.stderr,
            )
    for name, read in result["read"].items():
        if read["duplicate_ids_counted"]:
            print(
                f"note: {name}: {read['duplicate_ids_counted']} repeated ids, each line counted "
                "(as the original scorer does)",
                file=sys.stderr,
            )
    print(f"wrote {args.run_dir / 'evaluation' / 'final_score.json'}", file=sys.stderr)
    return 0


def _headline(result: dict[str, Any]) -> dict[str, Any]:
    """The short summary printed after scoring (the full result is in the file)."""
    keep = {k: v for k, v in result.items() if not isinstance(v, list | dict) or k in ("ranks", "weighted")}
    from .report import extract_task_scores

    keep["tasks"] = extract_task_scores(result)
    keep["skipped_files"] = result["skipped_files"]
    skipped = {
        f["source_file"]: {
            "skipped_lines": f["skipped_lines"],
            "first_skip": f["first_skip"],
            "scored": f["n"],
        }
        for f in result["per_file"]
        if f["skipped_lines"]
    }
    if skipped:
        keep["skipped_lines"] = skipped
    return keep


def _cmd_generate(args: argparse.Namespace) -> int:
    from .generate.writer import generate

    summary = generate(
        args.suite,
        args.out,
        per_task=args.per_task,
        seed=args.seed,
        split=args.split,
        tasks=[t.strip() for t in args.tasks.split(",") if t.strip()] if args.tasks else None,
        jobs=args.jobs,
        progress=not args.no_progress,
    )
    from .generate.quality import format_table

    for task, info in summary["tasks"].items():
        print(f"{task}\t{info['records']}\t{info['file']}")
    print(format_table(summary["quality"]), file=sys.stderr)
    print(f"wrote {args.out} ({summary['images']} images)", file=sys.stderr)
    return 0


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from .calibration import calibrate, read_scores_csv, write_weights

    pool = read_scores_csv(args.scores)
    weights = calibrate(pool)
    if args.out is not None:
        write_weights(args.out, weights)
        print(f"wrote {args.out}", file=sys.stderr)
    items = weights.items() if isinstance(weights, dict) else getattr(weights, "weights", {}).items()
    for task, w in items:
        print(f"{task}\t{w:.3f}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from .report import build_report, load_pool

    if not args.run_dirs and args.scores is None:
        raise ConfigError("report: give scored run folders and/or --scores CSV")
    pool = load_pool(args.run_dirs, scores_csv=args.scores)
    written = build_report(pool, args.out, r4_csv=args.r4, plots=not args.no_plots)
    for path in written:
        print(path)
    return 0


def _cmd_deficit(args: argparse.Namespace) -> int:
    from .finetune import deficit_table, read_pool_csv, select_targets

    pool = read_pool_csv(args.scores)
    row = deficit_table(pool, args.model)
    print("\t".join(row))
    print("\t".join(f"{v:+.2f}" for v in row.values()))
    groups = select_targets(row, threshold=args.threshold)
    for rank, tasks in groups.items():
        print(f"{rank}: {', '.join(tasks) if tasks else '-'}")
    return 0


def _cmd_export_sft(args: argparse.Namespace) -> int:
    from .finetune import export_sft

    n, skipped = export_sft(
        tasks=[t.strip() for t in args.tasks.split(",") if t.strip()],
        out=args.out,
        data_dir=args.data_dir,
        catalog=args.catalog,
        image_roots=tuple(args.image_root),
        limit=args.limit,
        require_images=args.require_images,
    )
    print(f"wrote {n} samples to {args.out}" + (f" ({skipped} skipped: missing images)" if skipped else ""))
    return 0
