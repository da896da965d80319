"""Scoring a run folder (`drivehierarchy openloop score DIR`).

Reads `DIR/predictions/<file_stem>.jsonl` (one `{"id", "task", "prediction", "record", "model"}`
object per line), scores every task in Rust (one call per file; exact PROTOCOL §1.2–1.3
scorers), runs the R1_4 judge when a model path is given (else R1_4 is `skipped` with the
reason), aggregates and writes:

- `DIR/evaluation/final_score.json`: the original's fields (`overall`, `per_task` micro means
  per scorer type, `per_file`, `config`, `skipped_files`) plus `tasks` (S_t per task id),
  `ranks` (S_r), `S_open` (frozen-weight headline; null unless all 14 tasks are scored),
  `S_open_partial`, `weights` and read diagnostics.
- `DIR/evaluation/per_record.jsonl`: `{"task", "id", "score", "parsed"}` per record.

Resume artefacts are tolerated: a repeated id keeps its first line; a truncated last line is
skipped with a warning.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError, _core

from .judge import DEFAULT_THRESHOLD, JudgeResult, JudgeSkipped, run_judge

JUDGE_TASK = "R1_4"
LINGO_JUDGE = "wayveai/Lingo-Judge"


class PredictionFileWarning(UserWarning):
    """A predictions file had lines that were skipped (truncated tail, malformed lines)."""


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def score_run(
    run_dir: str | Path,
    *,
    judge_model: str | Path | None = None,
    strict_order: bool = False,
    weights: Mapping[str, float] | None = None,
    judge_device: str | int = "auto",
    judge_threshold: float = DEFAULT_THRESHOLD,
) -> dict[str, Any]:
    """Scores a run folder, writes `evaluation/final_score.json` + `per_record.jsonl`, returns
    the final_score dict. `weights` overrides the frozen headline weights (task id → weight)."""
    run = Path(run_dir)
    pred_dir = run / "predictions"
    if not pred_dir.is_dir():
        raise ConfigError(f"{run}: no predictions/ folder (expected {pred_dir})")
    files = sorted(p for p in pred_dir.glob("*.jsonl") if p.is_file())
    skipped_files: list[dict[str, str]] = []
    outcomes: list[tuple[str, str, list[float], int, float | None]] = []
    per_record: list[str] = []
    diagnostics: dict[str, Any] = {}
    models: set[str] = set()
    judge_info: dict[str, Any] = {
        "enabled": False,
        "skip_reason": None,
        "model_name": str(judge_model) if judge_model is not None else LINGO_JUDGE,
        "device": judge_device,
        "threshold": judge_threshold,
    }
    judge_seen = False

    for path in files:
        try:
            task = _core.openloop_task_from_stem(path.stem)
        except ValueError:
            skipped_files.append({"source_file": path.name, "reason": "unknown_task_type"})
            continue
        res = _core.openloop_score_file(str(path), task, strict_order)
        models.update(res["models"])
        for line, message in res["issues"]:
            warnings.warn(f"{path}:{line}: skipped: {message}", PredictionFileWarning, stacklevel=2)
        diagnostics[path.name] = {
            "task": task,
            "records": len(res["ids"]),
            "duplicates_skipped": res["duplicates"],
            "lines_skipped": [{"line": ln, "reason": msg} for ln, msg in res["issues"]],
            "truncated_tail": res["truncated_tail"],
        }
        ids: list[str] = res["ids"]
        pass_rate: float | None = None
        passed: list[bool] | None = None
        if task == JUDGE_TASK:
            judge_seen = True
            if judge_model is None:
                judge_info["skip_reason"] = (
                    "no_judge_model: pass judge_model (--judge-model) = local path of " + LINGO_JUDGE
                )
                skipped_files.append({"source_file": path.name, "reason": "no_judge_model"})
                continue
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

    if not judge_seen and judge_info["skip_reason"] is None:
        judge_info["skip_reason"] = "l1_4_result_file_missing"

    summary = json.loads(_core.openloop_summarize(outcomes, dict(weights) if weights is not None else None))
    out_dir = run / "evaluation"
    out_dir.mkdir(parents=True, exist_ok=True)
    output_path = out_dir / "final_score.json"
    per_record_path = out_dir / "per_record.jsonl"
    params = _core.openloop_score_params()
    payload: dict[str, Any] = {
        "created_at": datetime.now(timezone.utc).isoformat(),
        "result_dir": str(run),
        "output_file": str(output_path),
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
