"""Synthetic stand-ins for the unreleased images, and an oracle policy for the test server.

Used by the tests and the runner benchmark, and handy to smoke-test a setup end to end without
the datasets: `write_images` creates a small, unique JPEG/PNG at every (remapped) image path of
the given records; `OraclePolicy` answers each request with its record's ground truth (or with a
scripted wrong answer), recognising the record by its question text and image bytes.
"""

from __future__ import annotations

import hashlib
import io
import json
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from .prompts import user_parts
from .records import BBOX, MULTI_CHOICE, NUMERIC, SEQUENCE_ORDER, TASKS, YES_NO, Record


def synthetic_image_bytes(key: str, fmt: str, size: tuple[int, int] = (16, 12)) -> bytes:
    """A tiny image whose pixels derive from `key`, so different keys give different files."""
    from PIL import Image

    digest = hashlib.sha256(key.encode("utf-8")).digest()
    w, h = size
    im = Image.new("RGB", (w, h))
    px = im.load()
    assert px is not None
    for y in range(h):
        for x in range(w):
            b = digest[(x // 4 + 4 * (y // 4)) % len(digest)]
            px[x, y] = (b, (b * 7) % 256, (b * 13) % 256)
    buf = io.BytesIO()
    im.save(buf, format=fmt)
    return buf.getvalue()


def write_images(records: Iterable[Record], skip: Callable[[str], bool] | None = None) -> int:
    """Create every image file the records reference (format from the extension); returns how
    many were written. `skip(path)` leaves chosen paths absent (to test missing images)."""
    n = 0
    for rec in records:
        for img in rec.images:
            path = Path(img.path)
            if path.exists() or (skip is not None and skip(img.path)):
                continue
            fmt = "PNG" if path.suffix.lower() == ".png" else "JPEG"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(synthetic_image_bytes(img.path, fmt))
            n += 1
    return n


def oracle_answer(record: Record) -> str:
    """The ground truth written as a well-behaved model would answer."""
    gt = record.ground_truth
    if record.kind == BBOX and isinstance(gt, dict):
        return json.dumps(gt.get("bbox"))
    if record.kind == SEQUENCE_ORDER:
        return json.dumps(gt)
    if isinstance(gt, str):
        return gt
    return json.dumps(gt)


def wrong_answer(record: Record) -> str:
    """An answer that scores 0 on the exact-match tasks and parses on every task."""
    gt = record.ground_truth
    if record.kind == YES_NO:
        return "no" if str(gt).strip().lower().startswith("y") else "yes"
    if record.kind == MULTI_CHOICE:
        letters = [o.strip()[0] for o in record.options if o.strip()]
        good = oracle_answer(record).strip()[:1].upper()
        return next((c for c in letters if c.upper() != good), "Z")
    if record.kind == NUMERIC:
        return "1000"
    if record.kind == BBOX:
        return "[0, 0, 1, 1]"
    if record.kind == SEQUENCE_ORDER and isinstance(gt, list):
        return json.dumps(list(reversed(gt)))
    return "I cannot tell."


def request_key(texts: Sequence[str], image_hashes: Sequence[str | None]) -> str:
    h = hashlib.sha256()
    for t in texts:
        h.update(b"T" + t.encode("utf-8") + b"\0")
    for d in image_hashes:
        h.update(b"I" + (d or "").encode("ascii") + b"\0")
    return h.hexdigest()


def record_key(record: Record) -> str:
    """The key the oracle computes from a request for this record (needs its image files)."""
    texts = [v for k, v in user_parts(record) if k == "text"]
    hashes = [hashlib.sha256(Path(img.path).read_bytes()).hexdigest() for img in record.images]
    return request_key(texts, hashes)


class OraclePolicy:
    """Policy for `ScriptedOpenAIServer`: answers from the ground truth of the matching record.

    `answer(record)` picks the reply (default: the oracle answer); it may return a `Fault` too.
    Requests that match no record get `unknown_reply`. Records that share question and images
    must share the answer (checked at construction).
    """

    def __init__(
        self,
        records: Iterable[Record],
        answer: Callable[[Record], Any] = oracle_answer,
        unknown_reply: str = "unknown",
    ):
        self.answer = answer
        self.unknown_reply = unknown_reply
        self.by_key: dict[str, Record] = {}
        for rec in records:
            key = record_key(rec)
            other = self.by_key.get(key)
            if other is not None and oracle_answer(other) != oracle_answer(rec):
                raise ValueError(f"records {other.id} and {rec.id} look identical but differ in answer")
            self.by_key.setdefault(key, rec)
        self.unmatched = 0

    def __call__(self, req: Any) -> Any:
        key = request_key(req.user_texts, [img.sha256 for img in req.images])
        rec = self.by_key.get(key)
        if rec is None:
            self.unmatched += 1
            return self.unknown_reply
        return self.answer(rec)


def make_synthetic_records(root: Path, per_task: int, image_dir: Path) -> Path:
    """Write a data folder of `per_task` synthetic records for each of the 14 task files (with
    images under `image_dir`); returns the data folder. Records follow each task's real schema."""
    root.mkdir(parents=True, exist_ok=True)
    for tid, stem, kind, _ in TASKS:
        lines = []
        for i in range(per_task):
            rid = f"{tid}_{i}"
            img = str(image_dir / tid / f"{i}.jpg")
            rec: dict[str, Any] = {"Question_id": rid, "question": f"Synthetic question {i} of {tid}?"}
            if kind == YES_NO:
                rec.update(answer="Yes" if i % 2 else "No", image_path=img)
            elif kind == NUMERIC:
                rec.update(answer=str(i % 7), image_path=img)
            elif kind == MULTI_CHOICE:
                rec.update(
                    options=["A. left.", "B. right.", "C. straight."], answer="ABC"[i % 3], image_path=img
                )
            elif kind == BBOX:
                rec = {"task_id": rid, "image_path": img, "question": rec["question"]}
                rec["ground_truth"] = {"bbox": [10, 20, 30 + i % 5, 40], "format": "xyxy"}
            elif kind == SEQUENCE_ORDER:
                rec = {"Question_id": rid, "task_id": rid}
                rec["images"] = [{"label": c, "path": img.replace(".jpg", f"_{c}.jpg")} for c in "ABC"]
                rec["ground_truth_order"] = ["B", "A", "C"] if i % 2 else ["A", "B", "C"]
            else:
                rec.update(answer=f"Answer {i}.", image_paths=[img, img.replace(".jpg", "_b.jpg")])
            lines.append(json.dumps(rec))
        (root / f"{stem}.jsonl").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return root
