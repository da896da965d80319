"""Regenerates the "One example per task" section of docs/openloop-generate.md.

Runs the documented command (`openloop generate --suite scenarios/r4 --per-task 20 --seed 0`)
into a temporary folder, takes the first record of each task file, writes its images scaled
down into docs/openloop-generate/<task>.jpg (several images side by side, labelled) and rewrites
the section between `<!-- examples:begin -->` and `<!-- examples:end -->`.

    python docs/_scripts/gen_openloop_examples.py
"""

from __future__ import annotations

import re
import sys
import tempfile
from pathlib import Path

from PIL import Image, ImageDraw

from drivehierarchy.benchmark.openloop.catalog import ImageRootMap, default_catalog, load_dataset
from drivehierarchy.benchmark.openloop.synthetic import oracle_answer
from drivehierarchy.cli import main

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "openloop-generate.md"
IMAGES = ROOT / "docs" / "openloop-generate"
COMMAND = ["openloop", "generate", "--suite", "scenarios/r4", "--per-task", "20", "--seed", "0"]
TILE_W, COLS = 400, 5


def _sheet(paths: list[Path], labels: list[str]) -> Image.Image:
    tiles = []
    for path, label in zip(paths, labels, strict=True):
        im = Image.open(path).convert("RGB")
        im = im.resize((TILE_W, round(im.height * TILE_W / im.width)))
        if label:
            d = ImageDraw.Draw(im)
            d.rectangle([0, 0, 8 * len(label) + 8, 16], fill=(0, 0, 0))
            d.text((4, 2), label, fill=(255, 255, 255))
        tiles.append(im)
    cols = min(COLS, len(tiles))
    rows = (len(tiles) + cols - 1) // cols
    h = tiles[0].height
    sheet = Image.new("RGB", (cols * TILE_W, rows * h), (255, 255, 255))
    for i, t in enumerate(tiles):
        sheet.paste(t, ((i % cols) * TILE_W, (i // cols) * h))
    return sheet


def main_() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "ex"
        if main([*COMMAND, "--out", str(out), "--no-progress"]) != 0:
            return 1
        cat = default_catalog(out)
        blocks = []
        for ds in cat.datasets:
            rec = load_dataset(cat, ds, ImageRootMap.parse([])).records[0]
            paths = [Path(p) for p in rec.image_paths]
            if rec.labelled_images:
                labels = [str(img.get("label", "")) for img in rec.raw.get("images", [])]
            elif len(paths) > 1:
                labels = [str(i + 1) for i in range(len(paths))]
            else:
                labels = [""]
            IMAGES.mkdir(exist_ok=True)
            _sheet(paths, labels).save(IMAGES / f"{rec.task}.jpg", quality=80)
            lines = [f"### {ds.name}", "", f"![{ds.name}](openloop-generate/{rec.task}.jpg)", ""]
            question = rec.question or "(none in the record; the runner asks the release's default)"
            lines += [f"**Question:** {question}", ""]
            if rec.options:
                lines += ["**Options:** " + " ".join(rec.options), ""]
            lines += [f"**Answer:** `{oracle_answer(rec)}`", "", ""]
            blocks.append("\n".join(lines))
    text = PAGE.read_text(encoding="utf-8")
    new, n = re.subn(
        r"(<!-- examples:begin -->\n).*?(<!-- examples:end -->)",
        lambda m: m.group(1) + "\n" + "".join(blocks).rstrip() + "\n\n" + m.group(2),
        text,
        flags=re.S,
    )
    if n != 1:
        print(f"{PAGE}: no examples block", file=sys.stderr)
        return 1
    PAGE.write_text(new, encoding="utf-8")
    print(f"{PAGE}: {len(blocks)} examples")
    return 0


if __name__ == "__main__":
    raise SystemExit(main_())
