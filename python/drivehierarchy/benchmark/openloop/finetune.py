"""Benchmark-guided fine-tuning helpers (paper §4.5).

- `deficit_table`: a model's relative deficit to the task-wise best of a pool,
  (S_model − S_best) / S_best per task and for the weighted score — the first row of Table 3.
- `select_targets`: the task groups (per rank) at least `threshold` behind; on the paper's
  Table 1 pool with the default 0.25 this picks exactly the paper's interventions for
  Qwen3-VL(8B): R1 {R1_2_A, R1_2_B, R1_3}, R2 {R2_1, R2_3}, R3 {R3_1}.
- `export_sft`: chosen tasks' records as ms-swift JSONL (`messages` + `images`), with the
  same system prompt and user turn as evaluation and the target in the requested output format.
  Export from the split you train on: exporting the evaluation files trains on the test set.
"""

from __future__ import annotations

import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError

from .catalog import ImageRootMap, default_catalog, load_catalog, load_dataset, select_datasets
from .prompts import swift_user_text, system_prompt
from .records import BBOX, MULTI_CHOICE, NUMERIC, RANKS, SEQUENCE_ORDER, TASK_IDS, TASK_RANK, YES_NO, Record
from .report import Pool, read_scores_table, weighted_score

read_pool_csv = read_scores_table

AVG = "Avg.Score"
# The protocol's number pattern (docs/protocol.md#answer-parsing), so "52.54 m" exports as "52.54".
_NUMBER_RE = re.compile(r"[-+]?(?:\d+\.\d+|\d+|\.\d+)(?:[eE][-+]?\d+)?")


def deficit_table(pool: Pool, model: str) -> dict[str, float]:
    """`{Avg.Score: d, R1_1_A: d, ...}` with d = (S_model − max_pool S) / max_pool S (≤ 0).

    Tasks the model lacks are left out; the Avg entry needs all 14 tasks for every model.
    """
    if model not in pool:
        raise ConfigError(f"model {model!r} is not in the pool ({', '.join(pool)})")
    own = pool[model]
    out: dict[str, float] = {}
    avgs = {m: weighted_score(s) for m, s in pool.items()}
    if avgs[model] is not None:
        best_avg = max(v for v in avgs.values() if v is not None)
        out[AVG] = _rel(avgs[model], best_avg)  # type: ignore[arg-type]
    for tid in TASK_IDS:
        if tid not in own:
            continue
        best = max(s[tid] for s in pool.values() if tid in s)
        out[tid] = _rel(own[tid], best)
    return out


def _rel(value: float, best: float) -> float:
    return 0.0 if best <= 0 else (value - best) / best


def select_targets(
    deficits: Mapping[str, float], threshold: float = 0.25, top_k: int | None = None
) -> dict[str, list[str]]:
    """Per rank, the tasks whose deficit is at least `threshold` (relative, e.g. 0.25 = 25 %
    behind the best), worst first; `top_k` keeps at most k per rank."""
    if not 0 <= threshold <= 1:
        raise ConfigError(f"threshold must be in [0, 1], got {threshold}")
    groups: dict[str, list[str]] = {}
    for rank in RANKS:
        tasks = [t for t in TASK_IDS if TASK_RANK[t] == rank and t in deficits and deficits[t] <= -threshold]
        tasks.sort(key=lambda t: deficits[t])
        groups[rank] = tasks[:top_k] if top_k is not None else tasks
    return groups


# --- SFT export ----------------------------------------------------------------------------------


def _number_text(value: Any) -> str | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        v = float(value)
    elif isinstance(value, str):
        m = _NUMBER_RE.search(value.replace(",", " "))
        if not m:
            return None
        v = float(m.group(0))
    else:
        return None
    if not math.isfinite(v):
        return None
    return str(int(v)) if v == int(v) and abs(v) < 1e15 else repr(v)


def _letter_of(record: Record) -> str | None:
    gt = record.ground_truth
    if not isinstance(gt, str) or not gt.strip():
        return None
    text = gt.strip()
    if len(text) == 1 and text.isalpha():
        return text.upper()
    for opt in record.options:
        if opt.strip() == text and len(opt) > 1 and opt[0].isalpha() and opt[1] in ".):-":
            return opt[0].upper()
    if text[0].isalpha() and len(text) > 1 and text[1] in ".):":
        return text[0].upper()
    return None


def target_text(record: Record) -> str | None:
    """The assistant turn: the ground truth written in the output format the prompt asks for
    (lower-case yes/no, a bare number, an option letter, `[x1, y1, x2, y2]`, `["A", ...]`)."""
    gt = record.ground_truth
    if record.kind == YES_NO:
        t = str(gt).strip().lower() if gt is not None else ""
        return t if t in ("yes", "no") else None
    if record.kind == NUMERIC:
        return _number_text(gt)
    if record.kind == MULTI_CHOICE:
        return _letter_of(record)
    if record.kind == BBOX:
        box = gt.get("bbox") if isinstance(gt, dict) else gt
        if isinstance(box, list) and len(box) == 4 and all(_number_text(v) is not None for v in box):
            return "[" + ", ".join(_number_text(v) or "" for v in box) + "]"
        return None
    if record.kind == SEQUENCE_ORDER:
        if isinstance(gt, list) and gt and all(isinstance(x, str) for x in gt):
            return json.dumps(gt)
        return None
    return str(gt).strip() if isinstance(gt, str) and gt.strip() else None


def sft_sample(record: Record) -> dict[str, Any] | None:
    """One ms-swift sample, or None when the record has no usable target."""
    answer = target_text(record)
    if answer is None:
        return None
    return {
        "messages": [
            {"role": "system", "content": system_prompt(record.kind)},
            {"role": "user", "content": swift_user_text(record)},
            {"role": "assistant", "content": answer},
        ],
        "images": list(record.image_paths),
    }


def export_sft(
    tasks: Sequence[str],
    out: Path,
    *,
    data_dir: Path | None = None,
    catalog: Path | None = None,
    image_roots: Sequence[str] = (),
    limit: int | None = None,
    require_images: bool = False,
) -> tuple[int, int]:
    """Write the chosen tasks' records to `out`; returns (written, skipped). Records without a
    usable target are skipped, and so are records with missing images when `require_images`."""
    if (data_dir is None) == (catalog is None):
        raise ConfigError("give exactly one of --data-dir DIR or --catalog FILE")
    if not tasks:
        raise ConfigError("--tasks: no task given")
    cat = load_catalog(catalog) if catalog is not None else default_catalog(data_dir)  # type: ignore[arg-type]
    specs = select_datasets(cat, list(tasks))
    roots = ImageRootMap.parse(image_roots)
    out.parent.mkdir(parents=True, exist_ok=True)
    written = skipped = 0
    tmp = out.with_suffix(out.suffix + ".tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        for spec in specs:
            for rec in load_dataset(cat, spec, roots, limit).records:
                if require_images and not all(os.path.isfile(p) for p in rec.image_paths):
                    skipped += 1
                    continue
                sample = sft_sample(rec)
                if sample is None:
                    skipped += 1
                    continue
                fh.write(json.dumps(sample, ensure_ascii=False) + "\n")
                written += 1
    os.replace(tmp, out)
    return written, skipped
