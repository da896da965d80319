"""Scoring a run folder: exact scorers through Rust, resume artefacts, final_score.json."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy import ConfigError, _core
from drivehierarchy.benchmark.openloop.scoring import PredictionFileWarning, score_run

TASKS = {t["id"]: t for t in _core.openloop_tasks()}


def _line(task: str, rid: str, prediction: str, record: dict[str, Any], model: str = "m") -> str:
    return json.dumps(
        {
            "id": rid,
            "task": task,
            "prediction": prediction,
            "record": record,
            "model": model,
            "latency_s": 0.1,
        }
    )


def _write(run: Path, task: str, lines: list[str], tail: str = "") -> Path:
    pred = run / "predictions"
    pred.mkdir(parents=True, exist_ok=True)
    path = pred / f"{TASKS[task]['stem']}.jsonl"
    path.write_text("".join(line + "\n" for line in lines) + tail, encoding="utf-8")
    return path


def _perfect(task: str, record: dict[str, Any]) -> str:
    kind = TASKS[task]["scorer"]
    if kind == "bbox":
        return json.dumps(record["ground_truth"]["bbox"])
    if kind == "sequence_order":
        return json.dumps(record["ground_truth_order"])
    return str(record["answer"])


def _official_records(data: Path) -> dict[str, list[dict[str, Any]]]:
    out = {}
    for tid, t in TASKS.items():
        lines = (data / f"{t['stem']}.jsonl").read_text(encoding="utf-8").splitlines()
        out[tid] = [json.loads(x) for x in lines if x.strip()]
    return out


def _rid(rec: dict[str, Any]) -> str:
    return str(rec.get("Question_id", rec.get("task_id")))


def test_official_samples_perfect_answers_score_100(tmp_path: Path, openloop_data_dir: Path) -> None:
    recs = _official_records(openloop_data_dir)
    for tid, rs in recs.items():
        assert _core.openloop_task_from_record(rs[0]) == tid
        _write(tmp_path, tid, [_line(tid, _rid(r), _perfect(tid, r), r) for r in rs])
    result = score_run(tmp_path)
    saved = json.loads((tmp_path / "evaluation" / "final_score.json").read_text(encoding="utf-8"))
    assert saved["tasks"] == result["tasks"]
    assert set(result["tasks"]) == set(TASKS) - {"R1_4"}
    for tid, t in result["tasks"].items():
        assert t["mean"] == 100.0 and t["parse_fail"] == 0 and t["n"] == len(recs[tid]), tid
    assert result["S_open"] is None  # R1_4 has no judge here
    assert result["S_open_partial"]["missing"] == ["R1_4"]
    assert result["S_open_partial"]["value"] == pytest.approx(100.0)
    assert result["config"]["l1_4"]["enabled"] is False
    assert result["config"]["l1_4"]["skip_reason"].startswith("no_judge_model")
    assert result["ranks"]["R2"] == {
        "mean": 100.0,
        "tasks": ["R2_1", "R2_2_A", "R2_2_B", "R2_3"],
        "missing": [],
        "complete": True,
    }
    types = {t["task_type"]: t for t in result["per_task"]}
    assert set(types) == {
        "yes_no",
        "multi_choice",
        "numeric_count",
        "numeric_distance",
        "bbox",
        "sequence_order",
    }
    assert types["numeric_count"]["n"] == sum(len(recs[t]) for t in ("R1_1_B", "R1_2_C", "R2_1", "R2_2_A"))
    assert result["overall"]["n"] == sum(len(v) for k, v in recs.items() if k != "R1_4")
    per_record = (tmp_path / "evaluation" / "per_record.jsonl").read_text(encoding="utf-8").splitlines()
    assert len(per_record) == result["overall"]["n"]
    assert json.loads(per_record[0]).keys() == {"task", "id", "score", "parsed"}


def test_official_samples_full_option_text_and_wrong_answers(tmp_path: Path, openloop_data_dir: Path) -> None:
    recs = _official_records(openloop_data_dir)
    # R2_2_B and R3_1 give the answer as full option text; reply with the bare letter,
    # with the option text without its letter, and with a wrong letter.
    for tid in ("R2_2_B", "R3_1"):
        for r in recs[tid]:
            letter = r["answer"][0]
            text = r["answer"][2:].strip()
            wrong = next(o[0] for o in r["options"] if o[0] != letter)
            assert _core.openloop_score_answer(tid, r["answer"], letter) == (100.0, True)
            assert _core.openloop_score_answer(tid, r["answer"], text) == (100.0, True)
            assert _core.openloop_score_answer(tid, r["answer"], wrong) == (0.0, True)
    # R1_2_A: distances with units; half the distance → exp(-|ln((g/2+0.1)/(g+0.1))|).
    r = recs["R1_2_A"][0]
    g = float(r["answer"].split()[0])
    s, ok = _core.openloop_score_answer("R1_2_A", r["answer"], f"{g / 2} meters")
    assert ok and s == pytest.approx(100 * math.exp(-abs(math.log((g / 2 + 0.1) / (g + 0.1)))))


def test_resume_duplicates_and_truncated_tail_match_clean_run(tmp_path: Path) -> None:
    def rec(i: int) -> dict[str, Any]:
        return {
            "Question_id": f"R1_1_B_{i}",
            "question": "How many?",
            "answer": str(i % 4),
            "image_path": "x.jpg",
        }

    preds = ["0", "1 car", "3", "two"]
    clean = [_line("R1_1_B", f"R1_1_B_{i}", preds[i], rec(i)) for i in range(4)]
    a = tmp_path / "a"
    _write(a, "R1_1_B", clean)
    # Crash-resume: a record written twice (first wins) and a line cut by a kill.
    resumed = [*clean[:2], _line("R1_1_B", "R1_1_B_1", "999", rec(1)), *clean[2:]]
    b = tmp_path / "b"
    _write(b, "R1_1_B", resumed, tail=clean[0][:40])
    ra = score_run(a)
    with pytest.warns(PredictionFileWarning, match="truncated"):
        rb = score_run(b)
    assert ra["tasks"] == rb["tasks"]
    t = ra["tasks"]["R1_1_B"]
    assert t["n"] == 4 and t["parse_fail"] == 1
    # 0→0, 1→1: 100 each; g=2, p=3: E=0.5 → 100·exp(−0.45/σ); "two": unparseable.
    sigma = 0.15 / math.log(2)
    assert t["mean"] == pytest.approx((200 + 100 * math.exp(-0.45 / sigma)) / 4)
    read = rb["read"][f"{TASKS['R1_1_B']['stem']}.jsonl"]
    assert read["duplicates_skipped"] == 1 and read["truncated_tail"] is True


def test_r3_2_quirk_default_and_strict(tmp_path: Path) -> None:
    rec = {
        "Question_id": "R3_2_0",
        "task_id": "R3_2_0",
        "ground_truth_order": ["A", "B", "C"],
        "images": [{"label": "A", "path": "a"}, {"label": "B", "path": "b"}, {"label": "C", "path": "c"}],
    }
    _write(tmp_path, "R3_2", [_line("R3_2", "R3_2_0", "I don't know", rec)])
    assert score_run(tmp_path)["tasks"]["R3_2"]["mean"] == 100.0
    strict = score_run(tmp_path, strict_order=True)["tasks"]["R3_2"]
    assert strict["mean"] == 0.0 and strict["parse_fail"] == 1


def test_batch_scoring_contract_and_errors(tmp_path: Path) -> None:
    recs = [{"task_id": "R1_3_0", "ground_truth": {"bbox": [0, 0, 10, 10], "format": "xyxy"}}] * 3
    scores, parsed = _core.openloop_score_task("R1_3", recs, ["[0,0,10,10]", '"[[5, 0, 15, 10]]"', "none"])
    assert scores == [100.0, pytest.approx(100 / 3), 0.0] and parsed == [True, True, False]
    with pytest.raises(ConfigError, match="judge"):
        _core.openloop_score_task("R1_4", [{"answer": "x"}], ["y"])
    with pytest.raises(ConfigError, match="ground_truth"):
        _core.openloop_score_task("R1_3", [{"task_id": "x"}], ["[1,2,3,4]"])
    with pytest.raises(ConfigError, match="unknown open-loop task"):
        _core.openloop_score_task("R9", [], [])
    with pytest.raises(ConfigError, match="nowhere: no such folder"):
        score_run(tmp_path / "nowhere")
    (tmp_path / "a_file").write_text("x", encoding="utf-8")
    with pytest.raises(ConfigError, match="not a results folder"):
        score_run(tmp_path / "a_file")
    with pytest.raises(ConfigError, match="no prediction files"):
        score_run(tmp_path)
    # A record lacking its ground truth is skipped; a file with nothing else fails the run,
    # naming file, line and field.
    _write(tmp_path, "R1_1_A", [_line("R1_1_A", "q", "yes", {"Question_id": "q"})])
    with pytest.raises(ConfigError, match=r"R1_1_A_Existence\.jsonl: nothing to score.*line 1: .*`answer`"):
        score_run(tmp_path)


def test_unknown_files_fail_and_weights_overridable(tmp_path: Path) -> None:
    rec = {"Question_id": "R1_1_A_0", "answer": "Yes", "image_path": "x"}
    _write(tmp_path, "R1_1_A", [_line("R1_1_A", "R1_1_A_0", "yes", rec)])
    notes = tmp_path / "predictions" / "notes.jsonl"
    notes.write_text("{}\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"notes\.jsonl: unknown task file"):
        score_run(tmp_path)
    notes.unlink()
    res = score_run(tmp_path, weights={"R1_1_A": 1.0})
    assert res["skipped_files"] == []
    assert res["weights"] == {"R1_1_A": 1.0}
    assert res["S_open"] == 100.0
    assert res["config"]["l1_4"]["skip_reason"] == "l1_4_result_file_missing"
