"""Differential test: every rule-scored record of a synthetic run scores the same through the Rust
scorers (`score_run`) as through the independent pure-Python reference (`openloop_reference`).

The synthetic predictions mix plausible answers with odd replies (Unicode digits, nested boxes,
NaN, prefixes), so the parsers are compared on more than clean input.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest
from openloop_reference import TASKS, build_run, ref_score, ref_score_run

from drivehierarchy.benchmark.openloop.scoring import score_run

EXACT_SCORERS = {t["scorer"] for t in TASKS.values()} - {"text_lingo_judge"}


def _ours(run: Path) -> dict[tuple[str, str], tuple[float, bool]]:
    out = {}
    for line in (run / "evaluation" / "per_record.jsonl").read_text(encoding="utf-8").splitlines():
        o = json.loads(line)
        out[(o["task"], o["id"])] = (o["score"], o["parsed"])
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_rust_scorers_equal_the_reference(tmp_path: Path, seed: int) -> None:
    run = tmp_path / "run"
    build_run(run, 3000, seed=seed)
    score_run(run)
    ours, ref = _ours(run), ref_score_run(run)
    # Every exact scorer is exercised, with parsed and unparsed replies and partial credit.
    assert len(ref) > 2500
    seen = Counter(TASKS[task]["scorer"] for task, _ in ref)
    assert set(seen) == EXACT_SCORERS, seen
    assert any(not parsed for _, parsed in ref.values())
    assert any(0.0 < score < 100.0 for score, _ in ref.values())
    mismatches = [(k, ours.get(k), v) for k, v in ref.items() if ours.get(k) != v]
    assert not mismatches, mismatches[:10]


def test_reference_is_not_vacuous() -> None:
    # The oracle disagrees with a wrong answer, so equality above is a real check.
    assert ref_score("yes_no", "Yes", "no") == (0.0, True)
    assert ref_score("multi_choice", "B", "(b) parked") == (100.0, True)
    assert ref_score("numeric_count", "4", "5")[0] < 100.0
    assert ref_score("bbox", {"bbox": [0, 0, 10, 10]}, "[0, 0, 10, 5]") == (50.0, True)
    assert ref_score("sequence_order", ["A", "B", "C"], '["C", "B", "A"]') == (0.0, True)
