"""R1_4 (situation description) judge: the LingoQA text classifier (`wayveai/Lingo-Judge`).

The judge reads `"[CLS]\\nQuestion: {q}\\nAnswer: {gt}\\nStudent: {pred}"` (fields stripped);
the score is 100 × the top label's score, with a diagnostic pass flag at 0.5. A record with
an empty field scores 0 and counts as a parse failure. transformers is imported lazily; when
it is missing the result is a typed `JudgeSkipped` with the reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drivehierarchy import ConfigError

DEFAULT_THRESHOLD = 0.5


@dataclass(frozen=True)
class JudgeSkipped:
    """R1_4 was not scored; `reason` says why (e.g. `transformers_unavailable: ...`)."""

    reason: str


@dataclass(frozen=True)
class JudgeResult:
    """Per-record judge scores in 0–100, pass flags and the number of empty-field records."""

    scores: list[float]
    passed: list[bool]
    parse_fail: int
    model: str
    threshold: float

    @property
    def pass_rate(self) -> float:
        return sum(self.passed) / len(self.passed) if self.passed else 0.0


def judge_input(question: str, answer: str, prediction: str) -> str:
    """The judge's exact input text (each field stripped)."""
    return f"[CLS]\nQuestion: {question.strip()}\nAnswer: {answer.strip()}\nStudent: {prediction.strip()}"


def _clamp01(v: float) -> float:
    return max(0.0, min(1.0, float(v)))


def _device(device: str | int) -> int:
    if device != "auto":
        return int(device)
    try:
        import torch

        return 0 if torch.cuda.is_available() else -1
    except Exception:
        return -1


def load_judge(model: str | Path, *, device: str | int = "auto") -> Any:
    """The transformers text-classification pipeline, or `JudgeSkipped` without transformers.

    Raises ConfigError when transformers is present but the model cannot be loaded.
    """
    try:
        from transformers import pipeline  # type: ignore[import-not-found, unused-ignore]
    except Exception as exc:  # ImportError, or a broken install raising something else
        return JudgeSkipped(f"transformers_unavailable: {type(exc).__name__}: {exc}")
    path = Path(model)
    ref = str(path) if path.exists() else str(model)
    try:
        return pipeline("text-classification", model=ref, device=_device(device))
    except Exception as exc:
        raise ConfigError(f"R1_4 judge: cannot load text-classification model {ref!r}: {exc}") from exc


def run_judge(
    items: Sequence[tuple[str, str, str]],
    model: str | Path | Any,
    *,
    threshold: float = DEFAULT_THRESHOLD,
    device: str | int = "auto",
    batch_size: int = 1,
) -> JudgeResult | JudgeSkipped:
    """Scores `(question, ground_truth, prediction)` triples with the judge.

    `model` is a local model path (or hub id already cached) or a ready pipeline. One
    record per call by default, as the original; larger `batch_size` pads inputs, which
    may move scores in the last float digits.
    """
    judge = load_judge(model, device=device) if isinstance(model, str | Path) else model
    if isinstance(judge, JudgeSkipped):
        return judge
    scores: list[float] = [0.0] * len(items)
    passed: list[bool] = [False] * len(items)
    todo: list[int] = []
    parse_fail = 0
    for i, (q, gt, pred) in enumerate(items):
        if not q.strip() or not gt.strip() or not pred.strip():
            parse_fail += 1
        else:
            todo.append(i)
    texts = [judge_input(*items[i]) for i in todo]
    outputs = judge(texts, batch_size=batch_size, truncation=True) if texts else []
    for i, out in zip(todo, outputs, strict=True):
        top = out[0] if isinstance(out, list) else out
        raw = top.get("score") if isinstance(top, dict) else None
        if raw is None:
            parse_fail += 1
            continue
        p = _clamp01(raw)
        scores[i] = max(0.0, min(100.0, p * 100.0))
        passed[i] = p >= threshold
    name = str(model) if isinstance(model, str | Path) else type(model).__name__
    return JudgeResult(scores=scores, passed=passed, parse_fail=parse_fail, model=name, threshold=threshold)
