"""R1_4 judge: exact input text, scores from a real (tiny, random, local) text classifier."""

from __future__ import annotations

import builtins
import json
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy import ConfigError
from drivehierarchy.benchmark.openloop import judge as judge_mod
from drivehierarchy.benchmark.openloop.judge import JudgeResult, JudgeSkipped, judge_input, run_judge
from drivehierarchy.benchmark.openloop.scoring import score_run


def test_judge_input_is_exact() -> None:
    assert judge_input(" What now? ", "Turn left.\n", "  left ") == (
        "[CLS]\nQuestion: What now?\nAnswer: Turn left.\nStudent: left"
    )


def test_missing_transformers_gives_typed_skip(monkeypatch: pytest.MonkeyPatch) -> None:
    real_import = builtins.__import__

    def fake_import(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "transformers" or name.startswith("transformers."):
            raise ImportError("No module named 'transformers'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    res = run_judge([("q", "a", "p")], "some/model")
    assert isinstance(res, JudgeSkipped)
    assert res.reason.startswith("transformers_unavailable")


class _FakePipeline:
    """Stands in for a pipeline: returns a fixed top-label score per call."""

    def __init__(self, score: float) -> None:
        self.score = score
        self.seen: list[str] = []

    def __call__(self, texts: list[str], **_: Any) -> list[list[dict[str, Any]]]:
        self.seen.extend(texts)
        return [[{"label": "true", "score": self.score}] for _ in texts]


def test_scores_pass_flags_and_empty_fields() -> None:
    fake = _FakePipeline(0.75)
    res = run_judge([("q", "a", "p"), ("q", "", "p"), (" ", "a", "p")], fake)
    assert isinstance(res, JudgeResult)
    assert res.scores == [75.0, 0.0, 0.0]
    assert res.passed == [True, False, False]
    assert res.parse_fail == 2
    assert fake.seen == ["[CLS]\nQuestion: q\nAnswer: a\nStudent: p"]


def _tiny_bert(path: Path) -> Path:
    torch = pytest.importorskip("torch")
    transformers = pytest.importorskip("transformers")
    words = [
        "[PAD]",
        "[UNK]",
        "[CLS]",
        "[SEP]",
        "[MASK]",
        "question",
        "answer",
        "student",
        ":",
        "turn",
        "left",
        "right",
        "the",
        "car",
        "is",
        "stopped",
        "what",
        "?",
        ".",
    ]
    path.mkdir(parents=True, exist_ok=True)
    vocab = path / "vocab.txt"
    vocab.write_text("\n".join(words) + "\n", encoding="utf-8")
    tok = transformers.BertTokenizer(vocab_file=str(vocab))
    torch.manual_seed(0)
    cfg = transformers.BertConfig(
        vocab_size=len(words),
        hidden_size=16,
        num_hidden_layers=1,
        num_attention_heads=2,
        intermediate_size=32,
        max_position_embeddings=64,
        num_labels=2,
        id2label={0: "false", 1: "true"},
        label2id={"false": 0, "true": 1},
    )
    model = transformers.BertForSequenceClassification(cfg).eval()
    model.save_pretrained(path)
    tok.save_pretrained(path)
    return path


def test_real_tiny_bert_judge_scores_run(tmp_path: Path) -> None:
    model_dir = _tiny_bert(tmp_path / "judge")
    import torch
    import transformers

    items = [
        ("What is the car doing?", "The car is stopped.", "stopped"),
        ("what?", "turn left.", "turn right"),
    ]
    res = run_judge(items, model_dir, device=-1)
    assert isinstance(res, JudgeResult)
    # Same numbers straight from the model: softmax top probability × 100.
    tok = transformers.AutoTokenizer.from_pretrained(model_dir)
    model = transformers.AutoModelForSequenceClassification.from_pretrained(model_dir).eval()
    for (q, a, p), s in zip(items, res.scores, strict=True):
        enc = tok(judge_input(q, a, p), return_tensors="pt")
        with torch.no_grad():
            probs = model(**enc).logits.softmax(-1)[0]
        assert s == pytest.approx(100 * float(probs.max()), abs=1e-4)
        assert 50.0 <= s <= 100.0  # the top label of two classes
    # Through score_run: R1_4 enabled, pass_rate reported, S_open complete only if all tasks.
    rec = {"Question_id": "R1_4_0", "question": items[0][0], "answer": items[0][1], "image_paths": ["a"]}
    pred = tmp_path / "run" / "predictions"
    pred.mkdir(parents=True)
    (pred / "R1_4_Situation_Description.jsonl").write_text(
        json.dumps({"id": "R1_4_0", "task": "R1_4", "prediction": "stopped", "record": rec, "model": "m"})
        + "\n",
        encoding="utf-8",
    )
    out = score_run(tmp_path / "run", judge_model=model_dir, judge_device=-1)
    assert out["config"]["l1_4"]["enabled"] is True
    assert out["tasks"]["R1_4"]["mean"] == pytest.approx(res.scores[0], abs=1e-6)
    assert out["per_file"][0]["pass_rate"] in (0.0, 1.0)
    # The original runner's line for the same record: the judge reads question, ground_truth
    # and model_prediction from it, with the same score; --skip-l1-4 leaves nothing to score.
    orig = tmp_path / "original"
    orig.mkdir()
    line = {"Question_id": "R1_4_0", "question": items[0][0], "ground_truth": items[0][1]}
    line["model_prediction"] = "stopped"
    (orig / "R1_4_Situation_Description_pred.jsonl").write_text(json.dumps(line) + "\n", encoding="utf-8")
    res_orig = score_run(orig, judge_model=model_dir, judge_device=-1)
    assert res_orig["layout"] == "original"
    assert res_orig["tasks"]["R1_4"]["mean"] == out["tasks"]["R1_4"]["mean"]
    with pytest.raises(ConfigError, match="skip_l1_4_flag"):
        score_run(orig, judge_model=model_dir, skip_l1_4=True)


def test_judge_module_imports_without_transformers() -> None:
    # Lazy import: the module itself never needs transformers.
    assert "transformers" not in judge_mod.__dict__
