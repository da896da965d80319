"""Typed view of the released open-loop records (R1–R3), read unchanged.

The release's schemas differ per task (docs/protocol.md#open-loop-tasks): ids in `Question_id` or
`task_id`, the
target in `answer`, `ground_truth.bbox` or `ground_truth_order`, images in `image_path`,
`image_paths` (or `meta_data.image_paths`) or labelled `images[]`. A `Record` keeps the original
object untouched in `raw` and exposes the fields the runner, prompts and exports need.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from drivehierarchy import _core

# Answer kinds, spelled as in the original catalog's `task` field.
YES_NO = "yes_no"
NUMERIC = "numeric"
MULTI_CHOICE = "multi_choice"
BBOX = "bbox"
TEXT = "text"
SEQUENCE_ORDER = "sequence_order"
ANSWER_KINDS = (YES_NO, NUMERIC, MULTI_CHOICE, BBOX, TEXT, SEQUENCE_ORDER)

# The task table, ranks and frozen weights are the Rust core's (`dh-benchmark`'s `TASKS`), read
# once here so every Python module shares the one definition. A record's answer kind follows
# from the task's scorer (numeric count and distance tasks are both `numeric` in the catalog).
_KIND_OF_SCORER: dict[str, str] = {
    "yes_no": YES_NO,
    "numeric_count": NUMERIC,
    "numeric_distance": NUMERIC,
    "multi_choice": MULTI_CHOICE,
    "bbox": BBOX,
    "text_lingo_judge": TEXT,
    "sequence_order": SEQUENCE_ORDER,
}


def _task_table() -> tuple[tuple[str, str, str, str], ...]:
    rows = []
    for t in _core.openloop_tasks():
        kind = _KIND_OF_SCORER.get(t["scorer"])
        if kind is None:
            raise RuntimeError(
                f"open-loop task {t['id']}: scorer {t['scorer']!r} has no answer kind in "
                f"records._KIND_OF_SCORER (known: {sorted(_KIND_OF_SCORER)})"
            )
        rows.append((t["id"], t["stem"], kind, t["rank"]))
    return tuple(rows)


# (task id, file stem, answer kind, rank) of the 14 released tasks, in the paper's column order.
TASKS: tuple[tuple[str, str, str, str], ...] = _task_table()
TASK_IDS: tuple[str, ...] = tuple(t[0] for t in TASKS)
TASK_FILE_STEM: dict[str, str] = {t[0]: t[1] for t in TASKS}
TASK_KIND: dict[str, str] = {t[0]: t[2] for t in TASKS}
TASK_RANK: dict[str, str] = {t[0]: t[3] for t in TASKS}
RANKS: tuple[str, ...] = tuple(dict.fromkeys(t[3] for t in TASKS))

# Frozen headline weights (paper Table 1, docs/protocol.md#aggregation).
FROZEN_WEIGHTS: dict[str, float] = dict(_core.openloop_frozen_weights())

_TASK_ID_RE = re.compile(r"^(R\d_\d(?:_[A-Z](?=_|$))?)")


def task_id_from_name(name: str) -> str | None:
    """`R2_2_A_Temporal_Counting` → `R2_2_A`; None when the name starts with no task id."""
    m = _TASK_ID_RE.match(name)
    return m.group(1) if m else None


@dataclass(frozen=True)
class ImageRef:
    """One input image: its (remapped) path and, for R3_2, its option label."""

    path: str
    label: str | None = None


@dataclass(frozen=True)
class Record:
    """One open-loop item. `raw` is the original JSON object, unchanged."""

    id: str
    task: str  # task id such as "R1_1_A" (or the dataset name for a non-standard file)
    kind: str  # answer kind, one of ANSWER_KINDS
    dataset: str  # catalog dataset name (file stem)
    question: str  # the record's own question text ("" when absent)
    options: tuple[str, ...]
    images: tuple[ImageRef, ...]
    ground_truth: Any
    raw: dict[str, Any]
    line: int  # 1-based line number in its file

    @property
    def labelled_images(self) -> bool:
        """R3_2-style records whose images carry option labels (`Image A` before each)."""
        return self.kind == SEQUENCE_ORDER

    @property
    def image_paths(self) -> tuple[str, ...]:
        return tuple(img.path for img in self.images)


class RecordError(ValueError):
    """A record cannot be used (no id, wrong types). Carries the reason for the error log."""


def _text(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    import json

    if isinstance(value, list | dict):
        return json.dumps(value, ensure_ascii=False)
    return str(value)


def record_id(raw: dict[str, Any]) -> str | None:
    """`Question_id`, else `task_id`, else `id` (the original harness's order)."""
    for key in ("Question_id", "task_id", "id"):
        if key in raw:
            value = raw[key]
            if value is None:
                return None
            return str(value)
    return None


def ground_truth(raw: dict[str, Any], kind: str) -> Any:
    if kind == SEQUENCE_ORDER:
        return raw.get("ground_truth_order")
    if kind == BBOX:
        return raw.get("ground_truth")
    return raw.get("answer")


def image_refs(raw: dict[str, Any], kind: str) -> list[ImageRef]:
    """The record's images in input order (labelled for sequence ordering)."""
    if kind == SEQUENCE_ORDER:
        items = raw.get("images") or []
        if not isinstance(items, list):
            raise RecordError(f"field 'images' must be a list, got {type(items).__name__}")
        out = []
        for i, item in enumerate(items):
            if not isinstance(item, dict) or not isinstance(item.get("path"), str) or not item["path"]:
                raise RecordError(f"field 'images[{i}]' has no string 'path'")
            label = item.get("label")
            out.append(ImageRef(item["path"], str(label) if label else None))
        return out
    paths = raw.get("image_paths")
    if not paths:
        meta = raw.get("meta_data")
        paths = meta.get("image_paths") if isinstance(meta, dict) else None
    if paths:
        if not isinstance(paths, list) or not all(isinstance(p, str) and p for p in paths):
            raise RecordError("field 'image_paths' must be a list of non-empty strings")
        return [ImageRef(p) for p in paths]
    path = raw.get("image_path")
    if path:
        if not isinstance(path, str):
            raise RecordError(f"field 'image_path' must be a string, got {type(path).__name__}")
        return [ImageRef(path)]
    return []


def parse_record(raw: Any, *, task: str, kind: str, dataset: str, line: int) -> Record:
    """Build a `Record` from one parsed JSON line; raises `RecordError` naming the field."""
    if not isinstance(raw, dict):
        raise RecordError(f"line is a JSON {type(raw).__name__}, not an object")
    if kind not in ANSWER_KINDS:
        raise RecordError(f"unknown answer kind {kind!r}")
    rid = record_id(raw)
    if rid is None or rid == "":
        raise RecordError("no 'Question_id', 'task_id' or 'id' field")
    options_raw = raw.get("options") or []
    if not isinstance(options_raw, list):
        raise RecordError(f"field 'options' must be a list, got {type(options_raw).__name__}")
    question = _text(raw.get("question") or raw.get("prompt") or "")
    return Record(
        id=rid,
        task=task,
        kind=kind,
        dataset=dataset,
        question=question,
        options=tuple(str(o) for o in options_raw),
        images=tuple(image_refs(raw, kind)),
        ground_truth=ground_truth(raw, kind),
        raw=raw,
        line=line,
    )
