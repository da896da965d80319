"""A review sheet for a generated open-loop set: N random records as one HTML page, each with its
images, the pixel points and boxes its question names drawn on them, the question, the options
and the ground-truth answer, so a person can check every answer against what the images show.

    drivehierarchy openloop generate --suite scenarios/r4 --out generated
    python scripts/review_generated.py generated --n 50 --seed 0 --out review
    # open review/index.html
"""

from __future__ import annotations

import argparse
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("data_dir", type=Path, help="a folder written by `openloop generate`")
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("review"))
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 3 records")
    args = ap.parse_args()
    if args.quick:
        args.n = 3
    cat = default_catalog(args.data_dir)
    records = [r for ds in cat.datasets for r in load_dataset(cat, ds, ImageRootMap.parse([])).records]
    if not records:
        raise SystemExit(f"{args.data_dir}: no records")
    pick = random.Random(args.seed).sample(records, min(args.n, len(records)))
    (args.out / "img").mkdir(parents=True, exist_ok=True)
    parts = ["<!doctype html><meta charset=utf-8><title>review</title><body style='font-family:sans-serif'>"]
    parts.append(
        "<p>Red circles: points named in the question; magenta: boxes in it; green: the answer box.</p>"
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
    print(f"{args.out / 'index.html'}: {len(pick)} records")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
