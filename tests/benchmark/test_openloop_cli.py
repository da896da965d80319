"""The `drivehierarchy openloop` command group: wiring of predict, report, deficit, export-sft."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drivehierarchy.benchmark.openloop.catalog import ImageRootMap, default_catalog, load_dataset
from drivehierarchy.benchmark.openloop.finetune import sft_sample, target_text
from drivehierarchy.benchmark.openloop.prompts import system_prompt
from drivehierarchy.benchmark.openloop.synthetic import OraclePolicy, write_images
from drivehierarchy.cli import main
from drivehierarchy.testing.openai_server import ScriptedOpenAIServer


def test_predict_command(openloop_data_dir: Path, tmp_path: Path, capsys) -> None:
    root_arg = f"/data/sets={tmp_path}/sets"
    cat = default_catalog(openloop_data_dir)
    recs = load_dataset(cat, cat.datasets[0], ImageRootMap.parse([root_arg]), limit=5).records
    write_images(recs)
    server = ScriptedOpenAIServer(OraclePolicy(recs), api_key="k-123")
    with server as url:
        argv = ["openloop", "predict", "--base-url", url, "--model", "m"]
        argv += ["--data-dir", str(openloop_data_dir), "--out", str(tmp_path / "run")]
        argv += ["--image-root", root_arg, "--datasets", "R1_1_A", "--limit", "5"]
        assert main([*argv, "--no-progress", "--api-key-env", "OLRUN_TEST_KEY"]) == 2  # env var unset
        assert "OLRUN_TEST_KEY" in capsys.readouterr().err
        import os

        os.environ["OLRUN_TEST_KEY"] = "k-123"
        try:
            assert main([*argv, "--no-progress", "--api-key-env", "OLRUN_TEST_KEY"]) == 0
        finally:
            del os.environ["OLRUN_TEST_KEY"]
    out = capsys.readouterr().out
    assert "5 records, 0 already done, 5 predicted, 0 failed" in out
    lines = (tmp_path / "run" / "predictions" / "R1_1_A_Existence.jsonl").read_text().splitlines()
    assert [json.loads(line)["prediction"] for line in lines] != [] and len(lines) == 5


def test_export_sft_command(openloop_data_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "sft.jsonl"
    argv = ["openloop", "export-sft", "--tasks", "R1_2_A,R1_3,R3_2,R2_2_B,R1_1_A", "--out", str(out)]
    assert main([*argv, "--data-dir", str(openloop_data_dir), "--image-root", "/data/sets=/mnt/ds"]) == 0
    samples = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(samples) == 18 + 23 + 10 + 7 + 23
    by_first_user = {s["messages"][1]["content"][:40]: s for s in samples}
    assert len(by_first_user) > 1
    first = samples[0]  # R1_1_A_0 (catalog order)
    assert first == {
        "messages": [
            {"role": "system", "content": system_prompt("yes_no")},
            {"role": "user", "content": "<image>Is there any Pedestrian visible in CAM_FRONT?"},
            {"role": "assistant", "content": "no"},
        ],
        "images": [
            "/mnt/ds/nuscenes/samples/CAM_FRONT/n015-2018-07-18-11-07-57+0800__CAM_FRONT__1531883530412470.jpg"
        ],
    }
    answers = {}
    for s in samples:
        answers.setdefault(s["messages"][0]["content"], []).append(s["messages"][2]["content"])
    assert answers[system_prompt("numeric")][0] == "52.54"  # "52.54 m" → bare number
    assert answers[system_prompt("bbox")][0] == "[1452, 738, 1560, 960]"
    assert answers[system_prompt("sequence_order")][0] == '["A", "B", "C"]'
    assert answers[system_prompt("multi_choice")][0] == "C"  # full option text → its letter
    r32 = next(s for s in samples if s["messages"][0]["content"] == system_prompt("sequence_order"))
    assert r32["messages"][1]["content"].startswith("Image A<image>Image B<image>Image C<image>Please")
    assert all(s["messages"][1]["content"].count("<image>") == len(s["images"]) for s in samples)
    # --require-images drops records whose images are not on disk.
    assert main([*argv, "--data-dir", str(openloop_data_dir), "--require-images"]) == 0
    assert out.read_text() == ""


def test_sft_targets_follow_the_output_format(openloop_data_dir: Path) -> None:
    cat = default_catalog(openloop_data_dir)
    for spec in cat.datasets:
        for rec in load_dataset(cat, spec).records:
            answer = target_text(rec)
            assert answer, rec.id
            if rec.kind == "multi_choice":
                assert len(answer) == 1 and any(o.startswith(answer) for o in rec.options), rec.id
            if rec.kind == "numeric":
                float(answer)
            assert sft_sample(rec) is not None


def test_deficit_and_report_commands(tmp_path: Path, capsys) -> None:
    from drivehierarchy.benchmark.openloop.records import TASK_IDS

    scores = tmp_path / "s.csv"
    rows = ["model," + ",".join(TASK_IDS)]
    rows += [f"{m}," + ",".join(str(b + i) for i in range(14)) for m, b in (("a", 10), ("b", 40), ("c", 20))]
    scores.write_text("\n".join(rows) + "\n")
    assert main(["openloop", "deficit", "--scores", str(scores), "--model", "a", "--threshold", "0.5"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].split("\t")[:2] == ["Avg.Score", "R1_1_A"]
    assert out[1].split("\t")[1] == "-0.75"  # 10 vs 40
    assert out[2].startswith("R1: R1_1_A, R1_1_B")
    rep = str(tmp_path / "rep")
    assert main(["openloop", "report", "--scores", str(scores), "--out", rep, "--no-plots"]) == 0
    assert (tmp_path / "rep" / "table1.md").exists()
    assert main(["openloop", "report", "--out", str(tmp_path / "rep2")]) == 2  # nothing to report


def test_openloop_group_is_registered(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["openloop", "--help"])
    helptext = capsys.readouterr().out
    for cmd in ("predict", "score", "calibrate", "report", "deficit", "export-sft"):
        assert cmd in helptext
