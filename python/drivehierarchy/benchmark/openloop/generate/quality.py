"""Balancing and quality checks of generated records (the paper's appendix rules).

Balancing (selection from candidates, deterministic given the rng): yes/no answers half and
half, multiple-choice answer letters uniform, counts not dominated by 0, groups (classes,
statuses) as even as the candidates allow. Checks (`check`): unique ids and questions per
image set, boxes inside the image, valid orders, images present, every answer among its
options.
"""

from __future__ import annotations

import hashlib
import json
import random
import re
import string
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

from drivehierarchy import DriveHierarchyError

T = TypeVar("T")
# At most this share of a count task's answers may be 0.
MAX_ZERO_SHARE = 0.2


# -- why candidates were dropped -------------------------------------------------------------------
# While a task is built (`tracking`), its builder counts the candidates each rule removes
# (`dropped`) and those that passed every rule (`passed`): a short or empty task then names the
# rules that emptied it.
_FUNNEL: Counter[str] | None = None
PASSED = "passed every rule"


def dropped(rule: str, k: int = 1) -> None:
    """Counts `k` candidates removed by `rule` (a short phrase) of the task being built."""
    if _FUNNEL is not None and k:
        _FUNNEL[rule] += k


def passed(k: int) -> None:
    """Counts `k` candidates that passed every rule of the task being built (before balancing)."""
    dropped(PASSED, k)


@contextmanager
def tracking() -> Iterator[Counter[str]]:
    """Collects `dropped`/`passed` counts of the builder run inside it."""
    global _FUNNEL
    outer, _FUNNEL = _FUNNEL, Counter()
    try:
        yield _FUNNEL
    finally:
        _FUNNEL = outer


def why_short(funnel: Mapping[str, int], asked: int, got: int) -> str:
    """The message of a task that yields `got` < `asked` records: how many candidates passed
    the rules and which rules removed the most."""
    ok = int(funnel.get(PASSED, 0))
    rules = sorted(((k, r) for r, k in funnel.items() if r != PASSED and k), key=lambda kr: (-kr[0], kr[1]))
    removed = ", ".join(f"{r} ({k})" for k, r in rules[:4]) or "no candidate moment at all"
    if ok == 0:
        return f"{got} of {asked} records: no candidate passed the rules; removed by: {removed}"
    return (
        f"{got} of {asked} records: {ok} candidates passed the rules (removed by: {removed}), "
        "and the balance and diversity rules (per-class balance, option share, 2 records per "
        "image, one record per description) kept only these"
    )


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


def _take(pool: list[Any], used: Counter[str] | None) -> Any:
    """Pops the last item of `pool` whose images each serve fewer than MAX_RECORDS_PER_IMAGE
    records so far (counted in `used`), or None (the pool is then emptied)."""
    for i in range(len(pool) - 1, -1, -1):
        keys = set(_image_keys(pool[i][0])) if used is not None else set()
        if all(used[k] < MAX_RECORDS_PER_IMAGE for k in keys):  # type: ignore[index]
            item = pool.pop(i)
            for k in keys:
                used[k] += 1  # type: ignore[index]
            return item
    pool.clear()
    return None


def balance_groups(
    groups: dict[Any, list[T]],
    n: int,
    rng: random.Random,
    used: Counter[str] | None = None,
    max_share: float | None = None,
) -> list[T]:
    """Up to `n` items drawn round-robin over the groups (sorted keys), each group shuffled:
    groups end up as even as their sizes allow; no image serves more than
    MAX_RECORDS_PER_IMAGE of them. With `max_share` no group gives more than that share of the
    items (fewer than `n` when the other groups run short)."""
    used = Counter() if used is None else used
    if max_share is not None and groups:
        # (With k groups no share can be below 1/k.)
        max_share = max(max_share, 1.0 / len(groups))
        # The largest total at which every group's draw stays within the share.
        sizes = sorted(len(_dedup(v)) for v in groups.values())
        cap_total = n
        for total in range(n, 0, -1):
            # (One record of each option fits any share: a set of 1–2 records is never empty.)
            per = max(1, int(max_share * total + 1e-9))
            if sum(min(sz, per) for sz in sizes) >= total:
                cap_total = total
                break
        else:
            cap_total = 0
        n = cap_total
    pools = {k: _dedup(v) for k, v in sorted(groups.items(), key=lambda kv: str(kv[0]))}
    for v in pools.values():
        rng.shuffle(v)
    out: list[T] = []
    limit = max(1, int(max_share * n + 1e-9)) if max_share is not None else n
    taken: Counter[Any] = Counter()
    while len(out) < n and any(pools.values()):
        for k in list(pools):
            if pools[k] and len(out) < n and taken[k] < limit:
                item = _take(pools[k], used)
                if item is not None:
                    out.append(item)
                    taken[k] += 1
            elif taken[k] >= limit:
                pools[k] = []
    rng.shuffle(out)
    return out


def _allocate(
    sizes: dict[str, dict[str, int]], total: int, share: float, overall: float
) -> dict[tuple[str, str], int] | None:
    """How many items of each (class, answer) make `total` items with no answer above `share`
    of its class (or 1/k with k answers) and no answer text above `overall` of all (or 1/K with
    K texts), within the sizes; None when no split of up to three classes is found."""
    classes = sorted(sizes)
    if not classes or len(classes) > 3:
        return None
    texts = {a for c in classes for a in sizes[c]}
    # (As in `balance_groups`, one item of an answer fits any share: small sets stay non-empty.)
    g_cap = max(1, int(max(overall, 1.0 / len(texts)) * total + 1e-9))
    avail = [sum(sizes[c].values()) for c in classes]

    def splits(i: int, left: int) -> Iterator[list[int]]:
        if i == len(classes) - 1:
            if left <= avail[i]:
                yield [left]
            return
        for x in range(min(left, avail[i]), -1, -1):
            for rest in splits(i + 1, left - x):
                yield [x, *rest]

    for xs in splits(0, total):
        used: Counter[str] = Counter()
        counts: dict[tuple[str, str], int] = {}
        ok = True
        # Classes with fewer answers first: they have the least freedom.
        for c, x in sorted(zip(classes, xs, strict=True), key=lambda cx: (len(sizes[cx[0]]), cx[0])):
            if x == 0:
                continue
            cap = max(1, int(max(share, 1.0 / len(sizes[c])) * x + 1e-9))
            take = dict.fromkeys(sizes[c], 0)
            for _ in range(x):
                # One more of the answer used least overall that still fits every cap.
                fits = [a for a in sorted(sizes[c]) if take[a] < min(cap, sizes[c][a]) and used[a] < g_cap]
                if not fits:
                    ok = False
                    break
                a = min(fits, key=lambda a: (used[a], take[a], a))
                take[a] += 1
                used[a] += 1
            if not ok:
                break
            counts.update({(c, a): k for a, k in take.items() if k})
        if ok:
            return counts
    return None


def balance_within_classes(
    by_class: dict[str, dict[str, list[T]]],
    n: int,
    rng: random.Random,
    max_share: float = 0.4,
    max_answer_share: float | None = None,
) -> list[T]:
    """Items balanced over the answers *within every asked class* (no answer above
    `max_share` of its class's items, or 1/k with k answers; a class with one answer only is
    left out: its question would give the answer away), then drawn round-robin over the classes
    up to `n`. With `max_answer_share` an answer text the classes share ("moving") also stays
    within that share of all the items (the most items for which such a split exists)."""
    if max_answer_share is not None:
        return _balance_shared_answers(by_class, n, rng, max_share, max_answer_share)
    used: Counter[str] = Counter()
    per_class = {}
    for cls in sorted(by_class):
        answers = {a: v for a, v in by_class[cls].items() if v}
        if len(answers) < 2:
            continue
        total = sum(len(v) for v in answers.values())
        per_class[cls] = balance_groups(answers, total, rng, used, max_share=max_share)
    out: list[T] = []
    while len(out) < n and any(per_class.values()):
        for cls in list(per_class):
            if per_class[cls] and len(out) < n:
                out.append(per_class[cls].pop())
    rng.shuffle(out)
    return out


def _balance_shared_answers(
    by_class: dict[str, dict[str, list[T]]], n: int, rng: random.Random, share: float, overall: float
) -> list[T]:
    pools: dict[str, dict[str, list[T]]] = {}
    for cls in sorted(by_class):
        answers = {a: _dedup(v) for a, v in sorted(by_class[cls].items()) if v}
        if len(answers) < 2:
            continue
        for v in answers.values():
            rng.shuffle(v)
        pools[cls] = answers
    for total in range(n, 0, -1):
        sizes = {c: {a: len(v) for a, v in ans.items()} for c, ans in pools.items()}
        while True:
            counts = _allocate(sizes, total, share, overall)
            if counts is None:
                break
            # Draw them under the per-image cap; an answer that runs short is drawn again with
            # the size it has left.
            used: Counter[str] = Counter()
            out: list[T] = []
            short = False
            for (c, a), k in sorted(counts.items()):
                pool = list(pools[c][a])
                got = [x for x in (_take(pool, used) for _ in range(k)) if x is not None]
                out += got
                if len(got) < k:
                    sizes[c][a] = min(sizes[c][a] - 1, len(got))
                    short = True
            if not short:
                rng.shuffle(out)
                return out
    return []


def balance_binary(yes: list[T], no: list[T], n: int, rng: random.Random) -> list[T]:
    """Exactly half yes and half no (one more of one when `n` is odd)."""
    return balance_binary_by({"": (yes, no)}, n, rng)


def balance_binary_by(groups: dict[str, tuple[list[T], list[T]]], n: int, rng: random.Random) -> list[T]:
    """Yes/no pairs drawn round-robin over the groups (an asked class): half yes and half no
    within every group, so neither the answer nor the class-and-answer pair can be guessed."""
    used: Counter[str] = Counter()
    pools = {}
    for k, (yes, no) in sorted(groups.items()):
        y, nn = _dedup(yes), _dedup(no)
        rng.shuffle(y)
        rng.shuffle(nn)
        pools[k] = (y, nn)
    out: list[T] = []
    while len(out) + 2 <= n and any(y and nn for y, nn in pools.values()):
        for y, nn in pools.values():
            if len(out) + 2 > n or not (y and nn):
                continue
            a = _take(y, used)
            b = _take(nn, used) if a is not None else None
            if a is not None and b is not None:
                out += [a, b]
            elif a is not None:
                y.clear()  # no partner left: the group is done
    if n % 2 == 1 and len(out) == n - 1:
        # An odd `n`: one more, yes or no (seeded), from the first group with one left.
        for y, nn in pools.values():
            first, second = (y, nn) if rng.random() < 0.5 else (nn, y)
            item = _take(first, used) or _take(second, used)
            if item is not None:
                out.append(item)
                break
    rng.shuffle(out)
    return out


def balance_counts(by_count: dict[Any, list[T]], n: int, rng: random.Random) -> list[T]:
    """Round-robin over the answer values (or (class, value) keys), with 0 capped at
    `MAX_ZERO_SHARE`."""
    used: Counter[str] = Counter()

    def is_zero(k: Any) -> bool:
        return bool((k[-1] if isinstance(k, tuple) else k) == 0)

    nonzero = {k: v for k, v in by_count.items() if not is_zero(k)}
    zero_groups = {k: v for k, v in by_count.items() if is_zero(k)}
    picked = balance_groups(nonzero, n, rng, used)
    n_zero = min(int(MAX_ZERO_SHARE * max(len(picked), 1) / (1 - MAX_ZERO_SHARE)), n - len(picked))
    zeros = balance_groups(zero_groups, max(0, n_zero), rng, used)
    out = picked + zeros
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
class QualityError(DriveHierarchyError, ValueError):
    """A generated record or set breaks a quality rule (names task, record and rule); the CLI
    prints it and exits with status 2."""


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


# -- balance, diversity and the text-only prior ---------------------------------------------------
# An image serves at most this many records of one task.
MAX_RECORDS_PER_IMAGE = 2
# No multiple-choice option (its text) is the answer of more than this share of a task's records.
MAX_OPTION_SHARE = 0.40
# A task fails when its text-only prior beats chance by more than this many points.
MAX_PRIOR_MARGIN = 15.0
# The prior check fails a set only from this many records per task (smaller sets are too noisy
# for a 15-point margin to mean anything; their table still shows it).
PRIOR_STRICT_MIN_RECORDS = 100
_NUMBER = re.compile(r"\d+(?:\.\d+)?")


def template(question: str) -> str:
    """The question with its numbers (pixel coordinates, boxes) blanked: what a text-only rule
    can key on (the asked class, colour and wording stay)."""
    return _NUMBER.sub("#", question)


def answer_content(task: str, rec: dict[str, Any]) -> str:
    """What a record's answer says, independent of option letters (the option's text for
    multiple choice), as JSON text for boxes and orders."""
    from drivehierarchy.benchmark.openloop.records import TASK_KIND

    kind = TASK_KIND[task]
    if kind == "bbox":
        return json.dumps(rec["ground_truth"]["bbox"])
    if kind == "sequence_order":
        return json.dumps(rec["ground_truth_order"])
    ans = str(rec.get("answer", ""))
    if kind == "multi_choice":
        for o in rec.get("options") or []:
            letter, _, text = o.partition(". ")
            if ans in (letter, o):
                return str(text.rstrip("."))
    return str(ans)


def _predict_option(rec: dict[str, Any], content: str, answer_style_letter: bool) -> str | None:
    for o in rec.get("options") or []:
        letter, _, text = o.partition(". ")
        if text.rstrip(".") == content:
            return str(letter if answer_style_letter else o)
    return None


def _image_keys(rec: dict[str, Any]) -> list[str]:
    if "images" in rec:
        return [i["path"] for i in rec["images"]]
    if "image_paths" in rec:
        return list(rec["image_paths"])
    return [rec["image_path"]] if "image_path" in rec else []


def scene_of(rec: dict[str, Any]) -> str:
    """The scenario id of a record."""
    tok = (
        rec.get("scene_token") or rec.get("segment_id") or (rec.get("meta_data") or {}).get("scene_token", "")
    )
    return str(tok).split("__")[0]


def prior_check(task: str, recs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The best answer rule that sees only the question text: for each question template
    (`template`) its most frequent answer content, learned on one half of the scenarios and
    scored on the other (two folds, no scenario in both: the generator makes train and eval sets
    the same way, so this is what a model could learn from a generated train split), against
    chance (yes/no 50, multiple choice 1/options, otherwise the single most frequent answer of
    the train half, whatever the question). Scored with the benchmark's own scorer."""
    from drivehierarchy import _core
    from drivehierarchy.benchmark.openloop.records import TASK_KIND

    kind = TASK_KIND[task]
    scenes = sorted({scene_of(r) for r in recs})
    fold_of = {s: hashlib.sha256(s.encode()).digest()[0] % 2 for s in scenes}
    prior_scores: list[float] = []
    chance_scores: list[float] = []
    for fold in (0, 1):
        train = [r for r in recs if fold_of[scene_of(r)] != fold]
        test = [r for r in recs if fold_of[scene_of(r)] == fold]
        if not train or not test:
            continue
        by_tpl: dict[str, Counter[str]] = {}
        overall: Counter[str] = Counter()
        for r in train:
            c = answer_content(task, r)
            by_tpl.setdefault(template(str(r.get("question", ""))), Counter())[c] += 1
            overall[c] += 1
        top = overall.most_common(1)[0][0]
        preds, cpreds = [], []
        for r in test:
            tpl = by_tpl.get(template(str(r.get("question", ""))))
            guess = tpl.most_common(1)[0][0] if tpl else top
            if kind == "multi_choice":
                letter_style = len(str(r.get("answer", ""))) <= 2
                preds.append(_predict_option(r, guess, letter_style) or "Z")
                n_opt = max(1, len(r.get("options") or []))
                chance_scores.append(100.0 / n_opt)
            else:
                preds.append(guess)
                if kind == "yes_no":
                    chance_scores.append(50.0)
                else:
                    cpreds.append(top)
        if kind == "text":
            # Judged tasks: exact-text agreement stands in for the judge.
            prior_scores += [100.0 * (p == r["answer"]) for p, r in zip(preds, test, strict=True)]
            chance_scores += [100.0 * (top == r["answer"]) for r in test]
            continue
        scores, _ = _core.openloop_score_task(task, test, preds)
        prior_scores += list(scores)
        if cpreds:
            cs, _ = _core.openloop_score_task(task, test, cpreds)
            chance_scores += list(cs)
    n = len(prior_scores)
    prior = sum(prior_scores) / n if n else 0.0
    chance = sum(chance_scores) / len(chance_scores) if chance_scores else 0.0
    return {"prior": round(prior, 1), "chance": round(chance, 1), "scored": n}


def diversity(task: str, recs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Balance and diversity figures of one task's records (the quality table's columns)."""
    from drivehierarchy.benchmark.openloop.records import TASK_KIND

    kind = TASK_KIND[task]
    per_image = Counter(k for r in recs for k in set(_image_keys(r)))
    answers = Counter(answer_content(task, r) for r in recs)
    qa = Counter((str(r.get("question", "")), answer_content(task, r)) for r in recs)
    out: dict[str, Any] = {
        "max_per_image": max(per_image.values(), default=0),
        "top_answer_share": round(max(answers.values(), default=0) / max(1, len(recs)), 3),
        "repeated_question_answer": sum(c - 1 for c in qa.values() if c > 1),
        "scenario_categories": len({_category(r) for r in recs} - {""}),
    }
    if kind == "multi_choice":
        out["max_option_share"] = out["top_answer_share"]
    return out


def _category(rec: dict[str, Any]) -> str:
    meta = rec.get("meta_data") or {}
    if isinstance(meta, dict) and meta.get("scene_classifier"):
        return str(meta["scene_classifier"])
    return str(rec.get("_category", ""))


def quality_rows(
    tasks: Mapping[str, Sequence[dict[str, Any]]],
    categories: dict[str, set[str]],
    asked: int | None = None,
    funnels: Mapping[str, Mapping[str, int]] | None = None,
) -> list[dict[str, Any]]:
    """One row per task: records, prior vs chance, balance and diversity, problems found (a
    task with fewer than `asked` records is one, with the rules that removed its candidates
    from `funnels`)."""
    rows = []
    for task, recs in tasks.items():
        p = prior_check(task, recs) if recs else {"prior": 0.0, "chance": 0.0, "scored": 0}
        d = diversity(task, recs)
        d["scenario_categories"] = len(categories.get(task, set()))
        problems = []
        if asked is not None and len(recs) < asked:
            problems.append(why_short((funnels or {}).get(task, {}), asked, len(recs)))
        if p["prior"] - p["chance"] > MAX_PRIOR_MARGIN:
            problems.append(
                f"text-only prior {p['prior']:.1f} beats chance {p['chance']:.1f} "
                f"by more than {MAX_PRIOR_MARGIN:.0f} points"
            )
        if d["max_per_image"] > MAX_RECORDS_PER_IMAGE:
            problems.append(f"an image serves {d['max_per_image']} records")
        # With k options one of them holds at least 1/k (a yes/no-like pair: a half).
        k_min = min((len(r.get("options") or []) for r in recs), default=0)
        allowed = max(MAX_OPTION_SHARE, 1.0 / k_min if k_min else 0.0) + 1.0 / max(1, len(recs))
        if d.get("max_option_share", 0.0) > allowed:
            problems.append(f"one option is the answer of {100 * d['max_option_share']:.0f} % of the records")
        rows.append({"task": task, "records": len(recs), **p, **d, "problems": problems})
    return rows


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    head = (
        f"{'task':8} {'records':>7} {'prior':>6} {'chance':>6} {'top ans':>7} {'per img':>7} "
        f"{'rep QA':>6} {'cats':>4}  problems"
    )
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['task']:8} {r['records']:7d} {r['prior']:6.1f} {r['chance']:6.1f} "
            f"{100 * r['top_answer_share']:6.0f}% {r['max_per_image']:7d} {r['repeated_question_answer']:6d} "
            f"{r['scenario_categories']:4d}  {'; '.join(r['problems']) or 'ok'}"
        )
    return "\n".join(lines)
