"""Scoring a results folder (`drivehierarchy openloop score DIR`).

Two layouts are read, detected from the folder (or forced with `layout=`):

- ours: `DIR/predictions/<file_stem>.jsonl` (e.g. `R1_1_A_Existence.jsonl`), lines
  `{"id", "task", "prediction", "record", "model", ...}`; a repeated id (crash-resume) keeps
  its first line;
- the original runner's: `DIR/<file_stem>_pred.jsonl` (its exact names, released or legacy
  stems), lines `{"Question_id" (or "task_id"), "question", "ground_truth",
  "model_prediction"[, "ground_truth_order"]}`; every line counts, as in the original scorer.

Our runner's lines carry both sets of fields. Every task is scored in Rust (one call per file;
exact scorers of docs/protocol.md#answer-parsing and #record-scores, the original's formulas), the
R1_4 judge runs when a model
path is given (else R1_4 is `skipped` with the reason; `skip_l1_4` skips it as the original's
`--skip-l1-4`), then aggregated and written:

- `DIR/evaluation/final_score.json`: the original's fields (`overall`, `per_task` micro means
  per scorer type, `per_file`, `config`, `scored_files`, `skipped_files`) plus `layout`,
  `tasks` (S_t per task id), `ranks` (S_r), `S_open` (frozen-weight headline; null unless all
  14 tasks are scored), `S_open_partial`, `weights` and read diagnostics (`read`); each
  `per_file` entry also has `skipped_lines` and `first_skip` (null when none).
- `DIR/evaluation/per_record.jsonl`: `{"task", "id", "score", "parsed"}` per record.

Nothing is ever a silent 0: a folder with no prediction file or no scored record, a prediction
file of unknown task, and a file none of whose lines can be scored raise `ConfigError` naming
the file and the first reason. An empty file (every request of that task failed) leaves its
task unscored and listed in `skipped_files`. Lines that are skipped (invalid JSON, a line cut
by a kill, missing fields) are counted, warned about and reported per file.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError, _core

from .judge import DEFAULT_THRESHOLD, JudgeResult, JudgeSkipped, run_judge

JUDGE_TASK = "R1_4"
LINGO_JUDGE = "wayveai/Lingo-Judge"
LAYOUTS = ("auto", "drivehierarchy", "original")
ORIGINAL_SUFFIX = "_pred.jsonl"


class PredictionFileWarning(UserWarning):
    """A predictions file had lines that were skipped (truncated tail, malformed lines)."""


def detect_layout(run: Path, layout: str = "auto") -> tuple[str, list[Path]]:
    """(layout, prediction files) of a results folder; ConfigError when there are none."""
    if layout not in LAYOUTS:
        raise ConfigError(f"layout must be one of {', '.join(LAYOUTS)}, got {layout!r}")
    if not run.exists():
        raise ConfigError(f"{run}: no such folder")
    if not run.is_dir():
        raise ConfigError(f"{run}: not a results folder (a file, not a folder)")
    flat = sorted(p for p in run.glob("*" + ORIGINAL_SUFFIX) if p.is_file())
    pred_dir = run / "predictions"
    ours = sorted(p for p in pred_dir.glob("*.jsonl") if p.is_file()) if pred_dir.is_dir() else []
    if layout == "auto":
        if flat and ours:
            raise ConfigError(
                f"{run}: holds both the original layout ({flat[0].name}, ...) and predictions/; "
                "choose one with --layout original|drivehierarchy"
            )
        layout = "original" if flat else "drivehierarchy"
        if not flat and not pred_dir.is_dir():
            raise ConfigError(
                f"{run}: no prediction files: expected the original runner's <task>_pred.jsonl "
                f"(e.g. R1_1_A_Existence_pred.jsonl) or predictions/<task>.jsonl"
            )
    files = flat if layout == "original" else ours
    if not files:
        where = f"{run}/*{ORIGINAL_SUFFIX}" if layout == "original" else f"{pred_dir}/*.jsonl"
        raise ConfigError(f"{run}: no prediction files ({where})")
    return layout, files


def _task_of(path: Path, layout: str) -> str:
    try:
        if layout == "original":
            return _core.openloop_task_from_original_file(path.name)
        return _core.openloop_task_from_stem(path.stem)
    except ConfigError:
        expected = (
            "the original runner writes <task file stem>_pred.jsonl, e.g. R1_1_A_Existence_pred.jsonl"
            if layout == "original"
            else "expected predictions/<task file stem>.jsonl, e.g. R1_1_A_Existence.jsonl"
        )
        raise ConfigError(f"{path}: unknown task file ({expected})") from None


def _is_empty(path: Path) -> bool:
    size = path.stat().st_size
    return size == 0 or (size < 4096 and not path.read_bytes().strip())


def _skip_note(issues: list[tuple[int, str]]) -> str | None:
    return f"line {issues[0][0]}: {issues[0][1]}" if issues else None


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def score_run(
    run_dir: str | Path,
    *,
    judge_model: str | Path | None = None,
    skip_l1_4: bool = False,
    strict_order: bool = False,
    weights: Mapping[str, float] | None = None,
    judge_device: str | int = "auto",
    judge_threshold: float = DEFAULT_THRESHOLD,
    layout: str = "auto",
) -> dict[str, Any]:
    """Scores a results folder, writes `evaluation/final_score.json` + `per_record.jsonl`,
    returns the final_score dict. `weights` overrides the frozen headline weights (task id →
    weight); `layout` is `auto`, `original` or `drivehierarchy`."""
    run = Path(run_dir)
    layout, files = detect_layout(run, layout)
    tasks = [(path, _task_of(path, layout)) for path in files]  # all names checked first
    skipped_files: list[dict[str, str]] = []
    outcomes: list[tuple[str, str, list[float], int, float | None]] = []
    per_record: list[str] = []
    diagnostics: dict[str, Any] = {}
    skips: dict[str, tuple[int, str | None]] = {}
    models: set[str] = set()
    judge_info: dict[str, Any] = {
        "enabled": False,
        "skip_reason": None,
        "model_name": str(judge_model) if judge_model is not None else LINGO_JUDGE,
        "device": judge_device,
        "threshold": judge_threshold,
    }
    judge_seen = False

    for path, task in tasks:
        if _is_empty(path):
            # A task whose every request failed leaves an empty file: the task is missing
            # (listed here, S_open stays null), not scored 0.
            warnings.warn(f"{path}: empty prediction file, not scored", PredictionFileWarning, stacklevel=2)
            skipped_files.append({"source_file": path.name, "reason": "empty_file"})
            continue
        if task == JUDGE_TASK:
            judge_seen = True
            skip: tuple[str, str] | None = None  # (skipped_files reason, config.l1_4.skip_reason)
            if skip_l1_4:
                skip = ("skip_l1_4_flag", "skip_l1_4_flag")
            elif judge_model is None:
                skip = (
                    "no_judge_model",
                    "no_judge_model: pass judge_model (--judge-model) = local path of " + LINGO_JUDGE,
                )
            if skip is not None:
                skipped_files.append({"source_file": path.name, "reason": skip[0]})
                judge_info["skip_reason"] = skip[1]
                continue
        res = _core.openloop_score_file(str(path), task, strict_order, layout)
        models.update(res["models"])
        issues: list[tuple[int, str]] = res["issues"]
        if issues:
            warnings.warn(
                f"{path}: skipped {len(issues)} of {res['lines']} lines; first: {_skip_note(issues)}",
                PredictionFileWarning,
                stacklevel=2,
            )
        diagnostics[path.name] = {
            "task": task,
            "formats": res["formats"],
            "lines": res["lines"],
            "records": len(res["ids"]),
            "duplicates_skipped": res["duplicates"],
            "duplicate_ids_counted": res["duplicate_ids"],
            "lines_skipped": [{"line": ln, "reason": msg} for ln, msg in issues],
            "truncated_tail": res["truncated_tail"],
        }
        skips[path.name] = (len(issues), _skip_note(issues))
        ids: list[str | None] = res["ids"]
        pass_rate: float | None = None
        passed: list[bool] | None = None
        if task == JUDGE_TASK:
            result = run_judge(
                res["judge_items"], judge_model, threshold=judge_threshold, device=judge_device
            )
            if isinstance(result, JudgeSkipped):
                judge_info["skip_reason"] = result.reason
                skipped_files.append({"source_file": path.name, "reason": result.reason})
                continue
            assert isinstance(result, JudgeResult)
            judge_info["enabled"] = True
            scores, parse_fail = result.scores, result.parse_fail
            parsed = [bool(q.strip() and a.strip() and p.strip()) for q, a, p in res["judge_items"]]
            pass_rate, passed = result.pass_rate, result.passed
        else:
            scores, parsed = res["scores"], res["parsed"]
            parse_fail = parsed.count(False)
        outcomes.append((task, path.name, scores, parse_fail, pass_rate))
        dumps = json.dumps
        for k, (rid, s, ok) in enumerate(zip(ids, scores, parsed, strict=True)):
            extra = f', "passed": {"true" if passed[k] else "false"}' if passed is not None else ""
            per_record.append(
                f'{{"task": "{task}", "id": {dumps(rid, ensure_ascii=False)}, "score": {s!r}, '
                f'"parsed": {"true" if ok else "false"}{extra}}}'
            )

    if not outcomes:
        why = "; ".join(f"{f['source_file']}: {f['reason']}" for f in skipped_files)
        raise ConfigError(f"{run}: nothing to score ({why or 'no prediction files'})")
    if not judge_seen and not skip_l1_4:
        judge_info["skip_reason"] = "l1_4_result_file_missing"

    summary = _core.openloop_summarize(outcomes, dict(weights) if weights is not None else None)
    for item in summary["per_file"]:
        n_skipped, first = skips.get(item["source_file"], (0, None))
        item["skipped_lines"] = n_skipped
        item["first_skip"] = first
    out_dir = run / "evaluation"
    out_dir.mkdir(parents=True, exist_ok=True)
    output_path = out_dir / "final_score.json"
    per_record_path = out_dir / "per_record.jsonl"
    params = _core.openloop_score_params()
    payload: dict[str, Any] = {
        "created_at": datetime.now(UTC).isoformat(),
        "result_dir": str(run),
        "output_file": str(output_path),
        "layout": layout,
        "config": {**params, "strict_order": strict_order, "l1_4": judge_info},
        "scored_files": len(outcomes),
        "skipped_files": skipped_files,
        "overall": summary["overall"],
        "per_task": summary["per_task"],
        "per_file": summary["per_file"],
        "tasks": summary["tasks"],
        "ranks": summary["ranks"],
        "S_open": summary["S_open"],
        "S_open_partial": summary["S_open_partial"],
        "weights": summary["weights"],
        "models": sorted(models),
        "read": diagnostics,
        "per_record_file": str(per_record_path),
    }
    _write_atomic(per_record_path, "".join(line + "\n" for line in per_record))
    _write_atomic(output_path, json.dumps(payload, ensure_ascii=False, indent=2))
    return payload
