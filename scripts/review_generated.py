"""A review sheet for a generated open-loop set: N random records as one HTML page, each with its
images, the pixel points and boxes its question names drawn on them, the question, the options
and the ground-truth answer, so a person can check every answer against what the images show.
Beside the sheet, `verdicts.json` holds one verdict per record (correct / wrong / ambiguous /
unanswerable, with a reason), recorded with `--verdict` and summed up with `--table`.

    drivehierarchy openloop generate --suite scenarios/r4 --out generated
    python scripts/review_generated.py generated --n 100 --seed 0 --out review
    # open review/index.html (or the images under review/img/), then per record:
    python scripts/review_generated.py generated --out review --verdict R1_1_A_12 correct
    python scripts/review_generated.py generated --out review --verdict R2_3_4 wrong "subject is Front-Left"
    python scripts/review_generated.py generated --out review --table
"""

from __future__ import annotations

import argparse
import collections
import html
import json
import random
import re
from pathlib import Path

from PIL import Image, ImageDraw

from drivehierarchy.benchmark.openloop.catalog import ImageRootMap, default_catalog, load_dataset
from drivehierarchy.benchmark.openloop.synthetic import oracle_answer

POINT = re.compile(r"\[\s*(\d+(?:\.\d+)?)\s*,\s*(\d+(?:\.\d+)?)\s*\]")
BOX = re.compile(
    r"\[\s*(\d+(?:\.\d+)?)\s*,\s*(\d+(?:\.\d+)?)\s*,\s*(\d+(?:\.\d+)?)\s*,\s*(\d+(?:\.\d+)?)\s*\]"
)
WIDTH = 800


def _marked(src: Path, dest: Path, question: str, answer_box: list[float] | None) -> None:
    im = Image.open(src).convert("RGB")
    d = ImageDraw.Draw(im)
    for m in BOX.finditer(question):
        d.rectangle([float(v) for v in m.groups()], outline=(255, 0, 255), width=4)
    for m in POINT.finditer(question):
        x, y = (float(v) for v in m.groups())
        d.ellipse([x - 14, y - 14, x + 14, y + 14], outline=(255, 0, 0), width=4)
    if answer_box:
        d.rectangle(answer_box, outline=(0, 255, 0), width=4)
    im.resize((WIDTH, round(im.height * WIDTH / im.width))).save(dest, quality=85)


VERDICTS = ("correct", "wrong", "ambiguous", "unanswerable")


def _load_verdicts(path: Path) -> dict[str, object]:
    if not path.is_file():
        raise SystemExit(f"{path}: no verdict file (write the sheet first: without --verdict/--table)")
    data = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(data, dict) or not isinstance(data.get("records"), list):
        raise SystemExit(f"{path}: field 'records': expected a list")
    return data


def _save(path: Path, data: dict[str, object]) -> None:
    path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")


def record_verdict(path: Path, rid: str, verdict: str, reason: str) -> None:
    """Sets the verdict of record `rid` in the verdict file."""
    if verdict not in VERDICTS:
        raise SystemExit(f"--verdict {rid} {verdict!r}: expected one of {', '.join(VERDICTS)}")
    if verdict != "correct" and not reason:
        raise SystemExit(f"--verdict {rid} {verdict}: give the reason (a third value)")
    data = _load_verdicts(path)
    recs = data["records"]
    assert isinstance(recs, list)
    hit = next((r for r in recs if r["id"] == rid), None)
    if hit is None:
        raise SystemExit(f"{path}: record {rid!r} is not on the sheet")
    hit["verdict"], hit["reason"] = verdict, reason
    _save(path, data)


def table(path: Path) -> str:
    """Markdown table of the verdicts per task, with the sheet's data folder, seed and size."""
    data = _load_verdicts(path)
    recs = data["records"]
    assert isinstance(recs, list)
    by: dict[str, collections.Counter[str]] = collections.defaultdict(collections.Counter)
    for r in recs:
        by[r["task"]][r.get("verdict") or "unreviewed"] += 1
        by["all"][r.get("verdict") or "unreviewed"] += 1
    cols = [*VERDICTS, "unreviewed"]
    lines = [
        f"Sheet: {data.get('n')} random records of `{data.get('data_dir')}` "
        f"(review seed {data.get('seed')}).",
        "",
        "| task | " + " | ".join(cols) + " |",
        "|---|" + "---|" * len(cols),
    ]
    for task in [*sorted(k for k in by if k != "all"), "all"]:
        lines.append(f"| {task} | " + " | ".join(str(by[task][c]) for c in cols) + " |")
    notes = [f"- {r['id']} ({r['verdict']}): {r['reason']}" for r in recs if r.get("reason")]
    return "\n".join([*lines, *(["", *notes] if notes else [])])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data_dir", type=Path, help="a folder written by `openloop generate`")
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("review"))
    ap.add_argument(
        "--verdict",
        nargs="+",
        metavar=("ID", "VERDICT"),
        help=f"record a verdict: ID VERDICT [REASON], VERDICT one of {', '.join(VERDICTS)}",
    )
    ap.add_argument("--table", action="store_true", help="print the verdicts per task (Markdown)")
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 3 records")
    args = ap.parse_args()
    if args.quick:
        args.n = 3
    vpath = args.out / "verdicts.json"
    if args.verdict:
        if len(args.verdict) not in (2, 3):
            raise SystemExit("--verdict: expected ID VERDICT [REASON]")
        record_verdict(
            vpath, args.verdict[0], args.verdict[1], args.verdict[2] if len(args.verdict) > 2 else ""
        )
        return 0
    if args.table:
        print(table(vpath))
        return 0
    cat = default_catalog(args.data_dir)
    records = [r for ds in cat.datasets for r in load_dataset(cat, ds, ImageRootMap.parse([])).records]
    if not records:
        raise SystemExit(f"{args.data_dir}: no records")
    pick = random.Random(args.seed).sample(records, min(args.n, len(records)))
    (args.out / "img").mkdir(parents=True, exist_ok=True)
    parts = ["<!doctype html><meta charset=utf-8><title>review</title><body style='font-family:sans-serif'>"]
    parts.append(
        "<p>Red circles: points named in the question; magenta: boxes in it; green: the answer box. "
        "Record verdicts with <code>--verdict ID VERDICT [REASON]</code> (verdicts.json).</p>"
    )
    for k, rec in enumerate(pick):
        gt = rec.ground_truth
        box = gt.get("bbox") if isinstance(gt, dict) else None
        parts.append(f"<h3>{k + 1}. {html.escape(rec.id)} ({html.escape(rec.task)})</h3>")
        for i, path in enumerate(rec.image_paths):
            name = f"{k:03d}_{i}.jpg"
            _marked(Path(path), args.out / "img" / name, rec.question, box if i == 0 else None)
            parts.append(f"<img src='img/{name}' width={WIDTH // 2 if len(rec.image_paths) > 1 else WIDTH}>")
        parts.append(f"<p><b>Q:</b> {html.escape(rec.question or '(default question)')}</p>")
        if rec.options:
            parts.append(f"<p><b>Options:</b> {html.escape(' | '.join(rec.options))}</p>")
        parts.append(f"<p><b>Answer:</b> <code>{html.escape(oracle_answer(rec))}</code></p>")
        meta = rec.raw.get("meta_data", {})
        meta_text = html.escape(json.dumps(meta, indent=1))
        parts.append(f"<details><summary>meta_data</summary><pre>{meta_text}</pre></details>")
    (args.out / "index.html").write_text("\n".join(parts), encoding="utf-8")
    # Verdicts of records already reviewed on an earlier sheet of the same set are kept.
    old = {}
    if vpath.is_file():
        prev = json.loads(vpath.read_text(encoding="utf-8"))
        old = {r["id"]: r for r in prev.get("records", []) if r.get("verdict")}
    rows = [
        old.get(rec.id)
        or {
            "id": rec.id,
            "task": rec.task,
            "images": [f"img/{k:03d}_{i}.jpg" for i in range(len(rec.image_paths))],
            "answer": oracle_answer(rec),
            "verdict": None,
            "reason": "",
        }
        for k, rec in enumerate(pick)
    ]
    _save(vpath, {"data_dir": args.data_dir.as_posix(), "seed": args.seed, "n": len(pick), "records": rows})
    print(f"{args.out / 'index.html'}: {len(pick)} records; verdicts in {vpath}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
