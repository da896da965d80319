"""Balancing and quality checks of generated records (the paper's appendix rules).

Balancing (selection from candidates, deterministic given the rng): yes/no answers half and
half, multiple-choice answer letters uniform, counts not dominated by 0, groups (classes,
statuses) as even as the candidates allow. Checks (`check`): unique ids and questions per
image set, boxes inside the image, valid orders, images present, every answer among its
options.
"""

from __future__ import annotations

import json
import random
import string
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")
# At most this share of a count task's answers may be 0.
MAX_ZERO_SHARE = 0.2


def _dedup(items: Sequence[Any]) -> list[Any]:
    """Drops candidates with the same question on the same images (first kept)."""
    seen: set[str] = set()
    out = []
    for item in items:
        rec = item[0]
        key = json.dumps(
            [rec.get("question"), rec.get("image_path"), rec.get("image_paths"), rec.get("images")]
        )
        if key not in seen:
            seen.add(key)
            out.append(item)
    return out


def balance_groups(groups: dict[Any, list[T]], n: int, rng: random.Random) -> list[T]:
    """Up to `n` items drawn round-robin over the groups (sorted keys), each group shuffled:
    groups end up as even as their sizes allow."""
    pools = {k: _dedup(v) for k, v in sorted(groups.items(), key=lambda kv: str(kv[0]))}
    for v in pools.values():
        rng.shuffle(v)
    out: list[T] = []
    while len(out) < n and any(pools.values()):
        for k in list(pools):
            if pools[k] and len(out) < n:
                out.append(pools[k].pop())
    rng.shuffle(out)
    return out


def balance_binary(yes: list[T], no: list[T], n: int, rng: random.Random) -> list[T]:
    """Exactly half yes and half no (one more of one when `n` is odd): at most twice the
    smaller side, so the balance never degrades when one side runs short."""
    yes, no = _dedup(yes), _dedup(no)
    rng.shuffle(yes)
    rng.shuffle(no)
    k = min(len(yes), len(no), n // 2)
    extra = 1 if n % 2 and k < min(len(yes), len(no)) else 0
    out = yes[: k + extra] + no[:k]
    rng.shuffle(out)
    return out


def balance_counts(by_count: dict[int, list[T]], n: int, rng: random.Random) -> list[T]:
    """Round-robin over the answer values, with 0 capped at `MAX_ZERO_SHARE`."""
    nonzero = {k: v for k, v in by_count.items() if k != 0}
    picked = balance_groups(nonzero, n, rng)
    zeros = _dedup(by_count.get(0, []))
    rng.shuffle(zeros)
    n_zero = min(
        len(zeros), int(MAX_ZERO_SHARE * max(len(picked), 1) / (1 - MAX_ZERO_SHARE)), n - len(picked)
    )
    # Keep the share when `picked` already fills n: swap some in for the largest groups' extras.
    out = picked + zeros[:n_zero]
    out = out[:n] if len(out) > n else out
    rng.shuffle(out)
    return out


def letter_options(recs: list[dict[str, Any]], rng: random.Random, answer_style: str = "letter") -> None:
    """Turns each record's `options` (plain values, the answer among them) into lettered
    options ("A. moving.") and its `answer` into the letter (`letter`) or the full option
    (`option`). The correct letters cycle through the letters so they are uniform."""
    order = list(range(len(recs)))
    rng.shuffle(order)
    for turn, i in enumerate(order):
        rec = recs[i]
        opts = list(rec["options"])
        answer = rec["answer"]
        others = [o for o in opts if o != answer]
        rng.shuffle(others)
        pos = turn % len(opts)
        opts = [*others[:pos], answer, *others[pos:]]
        lettered = [f"{string.ascii_uppercase[j]}. {o}." for j, o in enumerate(opts)]
        rec["options"] = lettered
        rec["answer"] = string.ascii_uppercase[pos] if answer_style == "letter" else lettered[pos]


# -- checks ---------------------------------------------------------------------------------------
class QualityError(ValueError):
    """A generated record breaks a quality rule (names task, record and rule)."""


def _images(rec: dict[str, Any]) -> list[str]:
    if "images" in rec:
        return [i["path"] for i in rec["images"]]
    if "image_paths" in rec:
        return list(rec["image_paths"])
    return [rec["image_path"]]


def check(task: str, recs: Sequence[dict[str, Any]], out_dir: Path, image_size: tuple[int, int]) -> None:
    """Raises `QualityError` on the first broken rule."""
    from drivehierarchy.benchmark.openloop.records import TASK_KIND, record_id

    kind = TASK_KIND[task]
    ids: set[str] = set()
    seen: set[str] = set()
    for rec in recs:
        rid = record_id(rec)
        where = f"{task} record {rid}"
        if not rid or rid in ids:
            raise QualityError(f"{where}: missing or duplicate id")
        ids.add(rid)
        key = json.dumps([rec.get("question"), _images(rec)])
        if key in seen:
            raise QualityError(f"{where}: duplicate question on the same images")
        seen.add(key)
        for p in _images(rec):
            if Path(p).is_absolute() or not (out_dir / p).is_file():
                raise QualityError(f"{where}: image {p!r} is not a file relative to the output folder")
        if kind == "bbox":
            x0, y0, x1, y1 = rec["ground_truth"]["bbox"]
            w, h = image_size
            if not (0 <= x0 < x1 < w and 0 <= y0 < y1 < h):
                raise QualityError(f"{where}: box {rec['ground_truth']['bbox']} not inside {w}x{h}")
        elif kind == "sequence_order":
            labels = [i["label"] for i in rec["images"]]
            order = rec["ground_truth_order"]
            if sorted(order) != sorted(labels) or len(set(order)) != len(order) or not 3 <= len(order) <= 5:
                raise QualityError(f"{where}: ground_truth_order {order} is not an order of {labels}")
        elif kind == "multi_choice":
            opts = rec.get("options") or []
            letters = [o.split(".", 1)[0] for o in opts]
            ans = str(rec["answer"])
            if ans not in letters and ans not in opts:
                raise QualityError(f"{where}: answer {ans!r} is not one of the options {opts}")
        elif kind == "yes_no" and rec["answer"] not in ("Yes", "No"):
            raise QualityError(f"{where}: yes/no answer {rec['answer']!r}")
        elif kind == "numeric":
            float(str(rec["answer"]).split()[0])
