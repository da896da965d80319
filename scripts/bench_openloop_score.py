"""Speed of `score_run` on 14,000 and 76,798 synthetic predictions, beside a pure-Python
reference of the same scorers (written from docs/protocol.md#answer-parsing, #record-scores). Both
must give identical
per-record scores, which also cross-checks the Rust parsers on varied and odd replies.

Usage: python scripts/bench_openloop_score.py [--sizes 14000 76798] [--strict-time]
Targets (excluding the R1_4 judge): 14,000 ≤ 1 s, 76,798 ≤ 5 s.
"""

from __future__ import annotations

import argparse
import json
import math
import random
import re
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from drivehierarchy import _core
from drivehierarchy.benchmark.openloop.scoring import score_run

REPO = Path(__file__).resolve().parents[1]
OFFICIAL = REPO.parent / "shared" / "official" / "Open_Loop_Evaluation"
TASKS = {t["id"]: t for t in _core.openloop_tasks()}
TARGETS = {14000: 1.0, 76798: 5.0}

# --- pure-Python reference scorer ---------------------------------------------------------------
NUM = re.compile(r"[-+]?(?:\d+\.\d+|\d+|\.\d+)(?:[eE][-+]?\d+)?")
LEAD = re.compile(r'^\s*["\'\(\[\{]*\s*([A-Z])(?:\s*[\)\]\}"\'\.,:;-]|$)')
HINT = re.compile(r"\b(?:OPTION|ANSWER|CHOICE)\s*[:\-]?\s*([A-Z])\b")
PREFIX1 = re.compile(r"^\s*[A-Za-z]\s*[\.\):\-]\s*")
PREFIX2 = re.compile(r"^\s*(?:option|answer|choice)\s*[:\-]?\s*[A-Za-z]\s*", re.IGNORECASE)
SIGMA_COUNT = (0.20 - 0.05) / math.log(2.0)
SIGMA_DIST = (math.log(2.0) - 0.0) / math.log(2.0)


def ref_number(v: Any) -> float | None:
    if v is None or isinstance(v, bool):
        return None
    if isinstance(v, int | float):
        try:
            return float(v)
        except OverflowError:
            return math.inf if v > 0 else -math.inf
    if isinstance(v, str):
        m = NUM.search(v.replace(",", " "))
        return float(m.group(0)) if m else None
    return None


def ref_norm(v: Any) -> str:
    t = re.sub(r"\s+", " ", str(v).strip().lower())
    return re.sub(r"[^a-z0-9 ]+", "", t).strip()


def ref_letter(v: Any) -> str | None:
    if v is None:
        return None
    t = str(v).strip().upper()
    if not t:
        return None
    if len(t) == 1 and t.isalpha():
        return t
    m = LEAD.search(t) or HINT.search(t)
    return m.group(1) if m else None


def ref_yes_no(v: Any) -> str | None:
    t = ref_norm(v)
    if not t:
        return None
    if t in {"yes", "y", "true"} or t.startswith("yes"):
        return "yes"
    if t in {"no", "n", "false"} or t.startswith("no"):
        return "no"
    return None


def ref_decay(e: float, tau: float, sigma: float) -> float:
    return 100.0 if e <= tau else max(0.0, min(100.0, 100.0 * math.exp(-(e - tau) / sigma)))


def ref_round(v: float) -> float:
    # Half away from zero; ±inf stays infinite (the original would raise here).
    if math.isinf(v):
        return v
    return float(math.floor(v + 0.5) if v >= 0 else math.ceil(v - 0.5))


def ref_loads(text: str) -> tuple[bool, Any]:
    try:
        return True, json.loads(text)
    except (json.JSONDecodeError, RecursionError):
        return False, None


def ref_box(v: Any) -> list[float] | None:
    def canon(n: list[float]) -> list[float]:
        a, c = sorted((n[0], n[2]))
        b, d = sorted((n[1], n[3]))
        return [a, b, c, d]

    if isinstance(v, dict):
        return ref_box(v["bbox"]) if "bbox" in v else None
    if isinstance(v, list):
        if len(v) >= 4:
            nums = [ref_number(x) for x in v[:4]]
            if all(x is not None for x in nums):
                return canon(nums)  # type: ignore[arg-type]
        return ref_box(v[0]) if v and isinstance(v[0], list) else None
    if isinstance(v, str):
        t = v.strip()
        if not t:
            return None
        ok, parsed = ref_loads(t)
        if ok and (b := ref_box(parsed)) is not None:
            return b
        nums = [float(x) for x in NUM.findall(t)]
        return canon(nums[:4]) if len(nums) >= 4 else None
    return None


def ref_iou(g: list[float], p: list[float]) -> float:
    iw = max(0.0, min(g[2], p[2]) - max(g[0], p[0]))
    ih = max(0.0, min(g[3], p[3]) - max(g[1], p[1]))
    inter = iw * ih
    union = (
        max(0.0, g[2] - g[0]) * max(0.0, g[3] - g[1]) + max(0.0, p[2] - p[0]) * max(0.0, p[3] - p[1]) - inter
    )
    return 0.0 if union <= 0 else inter / union


def ref_labels(v: Any) -> list[str]:
    if isinstance(v, list):
        items = list(v)
    elif isinstance(v, str):
        t = v.strip()
        if not t:
            return []
        ok, parsed = ref_loads(t)
        items = (
            (parsed if isinstance(parsed, list) else [parsed])
            if ok
            else re.findall(r"\b([A-Z])\b", t.upper())
        )
    else:
        return []
    out: list[str] = []
    for it in items:
        lab = ref_letter(it)
        if lab is None:
            tok = str(it).strip().upper()
            lab = tok if len(tok) == 1 and tok.isalpha() else None
        if lab and lab not in out:
            out.append(lab)
    return out


def ref_score(scorer: str, gt: Any, pred: str) -> tuple[float, bool]:
    if scorer == "yes_no":
        g, p = ref_yes_no(gt), ref_yes_no(pred)
        return (0.0, False) if g is None or p is None else (100.0 if g == p else 0.0, True)
    if scorer == "multi_choice":
        gl, pl = ref_letter(gt), ref_letter(pred)
        if gl is not None and pl is not None:
            return 100.0 if gl == pl else 0.0, True
        strip = lambda x: PREFIX2.sub("", PREFIX1.sub("", str(x).strip())).strip()  # noqa: E731
        g, p = ref_norm(strip(gt)), ref_norm(strip(pred))
        return (0.0, False) if not g or not p else (100.0 if g == p else 0.0, True)
    if scorer in ("numeric_count", "numeric_distance"):
        g, p = ref_number(gt), ref_number(pred)
        if g is None or p is None:
            return 0.0, False
        if scorer == "numeric_count":
            gc, pc = max(0.0, ref_round(g)), max(0.0, ref_round(p))
            return ref_decay(abs(pc - gc) / max(gc, 1.0), 0.05, SIGMA_COUNT), True
        e = abs(math.log((max(0.0, p) + 0.1) / (max(0.0, g) + 0.1)))
        return ref_decay(e, 0.0, SIGMA_DIST), True
    if scorer == "bbox":
        g, p = ref_box(gt), ref_box(pred)
        return (0.0, False) if g is None or p is None else (max(0.0, min(100.0, 100.0 * ref_iou(g, p))), True)
    if scorer == "sequence_order":
        g, p = ref_labels(gt), ref_labels(pred)
        if not g or not p:
            return 0.0, False
        order = [x for x in p if x in g]
        order += [x for x in g if x not in order]
        if len(g) == 1:
            return (100.0 if order[0] == g[0] else 0.0), True
        pos = {x: i for i, x in enumerate(order)}
        inv = sum(1 for i in range(len(g)) for j in range(i + 1, len(g)) if pos[g[i]] > pos[g[j]])
        return max(0.0, min(100.0, 100.0 * (1.0 - inv / (len(g) * (len(g) - 1) // 2)))), True
    raise ValueError(scorer)


def ref_score_run(run: Path) -> dict[tuple[str, str], tuple[float, bool]]:
    out: dict[tuple[str, str], tuple[float, bool]] = {}
    for path in sorted((run / "predictions").glob("*.jsonl")):
        task = _core.openloop_task_from_stem(path.stem)
        scorer = TASKS[task]["scorer"]
        if scorer == "text_lingo_judge":
            continue
        field = {"sequence_order": "ground_truth_order", "bbox": "ground_truth"}.get(scorer, "answer")
        for line in path.read_text(encoding="utf-8").splitlines():
            obj = json.loads(line)
            if (task, obj["id"]) not in out:
                out[(task, obj["id"])] = ref_score(scorer, obj["record"].get(field), obj["prediction"])
    return out


# --- synthetic predictions ---------------------------------------------------------------------
ODD = [
    "",
    "  ",
    "N/A",
    "Ⓐ",
    "١٢",
    "NaN",
    "[NaN, 1, 2, 3]",
    "1e999",
    "-1e999",
    "ANſWER: b",
    " ' a",
    "\x1cyes",
    "İ",
    "ß",
    "I don't know",
    '{"bbox": "[1, 2, 3, 4]"}',
    '"\\"[5, 5, 9, 9]\\""',
    "[[[1,2,3,4]]]",
    "[true, 1, 2, 3]",
    "Option: C",
    "OPTIONS A",
    "The answer is: B",
    "(b) parked",
    "yes, no",
    "none",
    "0.49999999999999994",
    "2.5",
    "-0.5",
    ".5e1",
    "1,5",
    "Infinity",
    "[1, 2, 3, 4",
    "['A', 'B']",
    '["C", "A", "B", "A"]',
    '"B"',
    "{'a': 1}",
    '[{"x": "B"}, ["A"]]',
    "C -> A -> B",
    "٣ meters",
    "𝟗",
    "a) left",
    "Choice-d",
    "yes\u3000no",
]


def sample_records() -> dict[str, list[dict[str, Any]]]:
    if OFFICIAL.is_dir():
        out = {}
        for tid, t in TASKS.items():
            text = (OFFICIAL / f"{t['stem']}.jsonl").read_text(encoding="utf-8")
            out[tid] = [json.loads(x) for x in text.splitlines() if x.strip()]
        return out
    print(f"note: {OFFICIAL} absent; using minimal synthetic records", file=sys.stderr)
    opts = ["A. moving.", "B. parked.", "C. stopped."]
    base = {
        "R1_1_A": {"answer": "Yes"},
        "R1_1_B": {"answer": "3"},
        "R1_1_C": {"answer": "B", "options": opts},
        "R1_2_A": {"answer": "52.54 m"},
        "R1_2_B": {"answer": "17.78 m"},
        "R1_2_C": {"answer": "1"},
        "R1_3": {"ground_truth": {"bbox": [1452, 738, 1560, 960], "format": "xyxy"}},
        "R1_4": {"answer": "I am turning left."},
        "R2_1": {"answer": "5"},
        "R2_2_A": {"answer": "1"},
        "R2_2_B": {"answer": "C. stopped.", "options": opts},
        "R2_3": {"answer": "C", "options": opts},
        "R3_1": {"answer": "A. moving.", "options": opts},
        "R3_2": {"ground_truth_order": ["A", "B", "C"], "images": [{"label": x, "path": x} for x in "ABC"]},
    }
    return {
        t: [{"Question_id": f"{t}_0", "question": "q?", "image_path": "x.jpg", **b}] for t, b in base.items()
    }


def vary(rng: random.Random, task: str, rec: dict[str, Any]) -> str:
    scorer = TASKS[task]["scorer"]
    if rng.random() < 0.12:
        return rng.choice(ODD)
    if scorer == "yes_no":
        return rng.choice(["yes", "no", "Yes.", "No, there is not.", "true", "maybe", str(rec["answer"])])
    if scorer == "numeric_count":
        g = float(rec["answer"])
        return rng.choice(
            [str(int(g)), f"{g + rng.randint(-3, 3)}", f"{rng.randint(0, 12)} vehicles", f"{g * 1.5:.2f}"]
        )
    if scorer == "numeric_distance":
        g = float(str(rec["answer"]).split()[0])
        return rng.choice(
            [f"{g * rng.uniform(0.3, 2.5):.2f}", f"{g:.1f} m", f"about {rng.randint(1, 90)} meters"]
        )
    if scorer == "multi_choice":
        letters = [o[0] for o in rec.get("options", [])] or ["A", "B", "C"]
        ans = str(rec["answer"])
        return rng.choice(
            [
                rng.choice(letters),
                ans,
                ans[2:].strip() if len(ans) > 2 else ans,
                f"Answer: {rng.choice(letters)}",
                f"({rng.choice(letters).lower()})",
                rng.choice(rec.get("options") or ["A"]),
            ]
        )
    if scorer == "bbox":
        b = rec["ground_truth"]["bbox"]
        j = [x + rng.randint(-80, 80) for x in b]
        return rng.choice(
            [
                json.dumps(j),
                f"[{j[2]}, {j[3]}, {j[0]}, {j[1]}]",
                json.dumps([j]),
                json.dumps(json.dumps(j)),
                f"x1={j[0]}, y1={j[1]}",
                f"({j[0]}, {j[1]}), ({j[2]}, {j[3]})",
            ]
        )
    if scorer == "sequence_order":
        labels = list(rec["ground_truth_order"])
        rng.shuffle(labels)
        return rng.choice(
            [
                json.dumps(labels),
                ", ".join(labels),
                " -> ".join(labels),
                json.dumps(labels[:1]),
                json.dumps([*labels, labels[0]]),
            ]
        )
    return "The car ahead is stopped, so I wait."


def build_run(run: Path, n: int, seed: int = 0) -> None:
    rng = random.Random(seed)
    recs = sample_records()
    tasks = list(TASKS)
    (run / "predictions").mkdir(parents=True)
    (run / "manifest.json").write_text(json.dumps({"model": "synthetic"}), encoding="utf-8")
    per_task = {t: n // len(tasks) + (1 if i < n % len(tasks) else 0) for i, t in enumerate(tasks)}
    for t in tasks:
        with (run / "predictions" / f"{TASKS[t]['stem']}.jsonl").open("w", encoding="utf-8") as f:
            for k in range(per_task[t]):
                rec = dict(rng.choice(recs[t]))
                rid = f"{t}_syn_{k}"
                rec["Question_id" if "Question_id" in rec else "task_id"] = rid
                pred = vary(rng, t, rec).strip()
                f.write(
                    json.dumps(
                        {"id": rid, "task": t, "prediction": pred, "record": rec, "model": "synthetic"},
                        ensure_ascii=False,
                    )
                    + "\n"
                )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[14000, 76798])
    ap.add_argument("--strict-time", action="store_true", help="exit 1 when a time target is missed")
    ap.add_argument("--quick", action="store_true", help="smoke run (CI): 1,400 predictions, no time target")
    args = ap.parse_args()
    if args.quick:
        args.sizes, args.strict_time = [1400], False
    failed = False
    for n in args.sizes:
        with tempfile.TemporaryDirectory() as tmp:
            run = Path(tmp) / "run"
            build_run(run, n)
            best = math.inf
            for _ in range(3):
                t0 = time.perf_counter()
                result = score_run(run)
                best = min(best, time.perf_counter() - t0)
            t0 = time.perf_counter()
            ref = ref_score_run(run)
            t_ref = time.perf_counter() - t0
            ours = {}
            for line in (run / "evaluation" / "per_record.jsonl").read_text(encoding="utf-8").splitlines():
                o = json.loads(line)
                ours[(o["task"], o["id"])] = (o["score"], o["parsed"])
            mismatches = [(k, ours.get(k), v) for k, v in ref.items() if ours.get(k) != v]
            total = sum(1 for _ in run.glob("predictions/*.jsonl") for _ in _.open(encoding="utf-8"))
            target = TARGETS.get(n)
            verdict = ""
            if target is not None:
                verdict = f" (target ≤ {target:.0f} s: {'ok' if best <= target else 'MISSED'})"
            same = len(ref) - len(mismatches)
            print(
                f"{total:>6} predictions: score_run {best:.3f} s{verdict}; "
                f"pure-Python reference {t_ref:.3f} s ({t_ref / best:.1f}× slower); "
                f"rule-scored records {len(ref)}, identical: {same}; "
                f"overall mean {result['overall']['mean']:.4f}, parse_fail {result['overall']['parse_fail']}"
            )
            for k, a, b in mismatches[:10]:
                print(f"  MISMATCH {k}: rust {a} vs python {b}")
            if mismatches or (args.strict_time and target is not None and best > target):
                failed = True
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
