"""Runner end to end against the real loopback server, on the released sample records with
synthetic images: oracle answers, resume after SIGKILL, error injection, missing images."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from drivehierarchy import ConfigError
from drivehierarchy.benchmark.openloop.catalog import ImageRootMap, default_catalog, load_dataset
from drivehierarchy.benchmark.openloop.client import DecodingConfig
from drivehierarchy.benchmark.openloop.runner import RunConfig, predict, read_done_ids
from drivehierarchy.benchmark.openloop.synthetic import OraclePolicy, oracle_answer, write_images
from drivehierarchy.testing.openai_server import Fault, ScriptedOpenAIServer

N_SAMPLES = 220


@pytest.fixture()
def sample_setup(openloop_data_dir: Path, tmp_path: Path):
    """Sample records with their image roots remapped under tmp_path, and images written there."""
    root_arg = f"/data/sets={tmp_path}/sets"
    cat = default_catalog(openloop_data_dir)
    roots = ImageRootMap.parse([root_arg])
    records = [r for spec in cat.datasets for r in load_dataset(cat, spec, roots).records]
    assert len(records) == N_SAMPLES
    write_images(records)
    return records, root_arg


def _config(url: str, data_dir: Path, out: Path, root_arg: str, **kw) -> RunConfig:
    return RunConfig(
        base_url=url,
        model="oracle",
        out=out,
        data_dir=data_dir,
        image_roots=(root_arg,),
        progress=False,
        **kw,
    )


def _predictions(out: Path) -> dict[str, dict]:
    preds: dict[str, dict] = {}
    for path in sorted((out / "predictions").glob("*.jsonl")):
        for line in path.read_text(encoding="utf-8").splitlines():
            obj = json.loads(line)
            assert obj["id"] not in preds, f"duplicate prediction for {obj['id']}"
            preds[obj["id"]] = obj
    return preds


def _errors(out: Path) -> list[dict]:
    path = out / "errors.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def _task_scores(out: Path) -> dict[str, float]:
    from drivehierarchy.benchmark.openloop.report import extract_task_scores
    from drivehierarchy.benchmark.openloop.scoring import score_run

    result = score_run(out)
    assert (out / "evaluation" / "final_score.json").exists()
    return extract_task_scores(result)


def test_oracle_run_scores_perfectly(sample_setup, openloop_data_dir: Path, tmp_path: Path) -> None:
    records, root_arg = sample_setup
    policy = OraclePolicy(records)
    server = ScriptedOpenAIServer(policy, latency_s=0.01)
    out = tmp_path / "run"
    with server as url:
        summary = predict(_config(url, openloop_data_dir, out, root_arg, concurrency=32))
    assert summary.complete and summary.written == N_SAMPLES and summary.failed == 0
    assert policy.unmatched == 0 and server.stats.chat_requests == N_SAMPLES
    assert _errors(out) == []
    preds = _predictions(out)
    by_id = {r.id: r for r in records}
    assert set(preds) == set(by_id)
    for rid, obj in preds.items():
        rec = by_id[rid]
        assert obj["task"] == rec.task and obj["model"] == "oracle"
        assert obj["record"] == rec.raw  # original record, original (unmapped) paths
        assert obj["prediction"] == oracle_answer(rec).strip()
        assert obj["latency_s"] > 0 and obj["usage"]["attempts"] == 1
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["model"] == "oracle" and manifest["complete"] is True
    assert manifest["decoding"] == {
        "temperature": 0.0, "top_p": 1.0, "max_tokens": 256,
        "repetition_penalty": 1.0, "presence_penalty": 0.0, "seed": 0,
    }  # fmt: skip
    assert len(manifest["data_files"]) == 14
    assert all(len(f["sha256"]) == 64 for f in manifest["data_files"].values())
    assert manifest["started_at"] and manifest["finished_at"]
    scores = _task_scores(out)
    for task, score in scores.items():
        if task != "R1_4":  # the learned judge is not installed in tests
            assert score == pytest.approx(100.0), task
    assert len([t for t in scores if t != "R1_4"]) == 13


def test_wrong_answers_score_zero_on_exact_tasks(
    sample_setup, openloop_data_dir: Path, tmp_path: Path
) -> None:
    from drivehierarchy.benchmark.openloop.synthetic import wrong_answer

    records, root_arg = sample_setup
    out = tmp_path / "run"
    with ScriptedOpenAIServer(OraclePolicy(records, answer=wrong_answer)) as url:
        predict(_config(url, openloop_data_dir, out, root_arg, concurrency=16))
    scores = _task_scores(out)
    for task in ("R1_1_A", "R1_1_C", "R2_2_B", "R2_3", "R3_1"):
        assert scores[task] == 0.0, task


def test_resume_after_sigkill_equals_uninterrupted(
    sample_setup, openloop_data_dir: Path, tmp_path: Path
) -> None:
    records, root_arg = sample_setup
    policy = OraclePolicy(records)
    full, resumed = tmp_path / "full", tmp_path / "resumed"
    with ScriptedOpenAIServer(policy, latency_s=0.02) as url:
        predict(_config(url, openloop_data_dir, full, root_arg, concurrency=8))
        cmd = [
            sys.executable, "-m", "drivehierarchy.cli", "openloop", "predict",
            "--base-url", url, "--model", "oracle", "--data-dir", str(openloop_data_dir),
            "--out", str(resumed), "--image-root", root_arg, "--concurrency", "4", "--no-progress",
        ]  # fmt: skip
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + 60
        try:
            while True:  # kill once some, but not all, predictions are on disk
                n = sum(len(p.read_bytes().splitlines()) for p in (resumed / "predictions").glob("*.jsonl"))
                if n >= 40:
                    break
                assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
                assert time.monotonic() < deadline
                time.sleep(0.01)
            os.kill(proc.pid, signal.SIGKILL)
        finally:
            proc.wait()
        assert proc.returncode == -signal.SIGKILL
        partial = _predictions(resumed)
        assert 40 <= len(partial) < N_SAMPLES
        # A kill can tear the line being written; simulate that on one file.
        torn = resumed / "predictions" / "R1_1_A_Existence.jsonl"
        with open(torn, "a", encoding="utf-8") as fh:
            fh.write('{"id": "R1_1_A_22", "task": "R1_1_A", "predic')
        before = policy.unmatched
        summary = predict(_config(url, openloop_data_dir, resumed, root_arg, concurrency=8))
    assert policy.unmatched == before
    assert summary.already_done == len(partial) and summary.written == N_SAMPLES - len(partial)
    a, b = _predictions(full), _predictions(resumed)
    strip = ("latency_s", "usage")
    assert {k: {f: v for f, v in o.items() if f not in strip} for k, o in a.items()} == {
        k: {f: v for f, v in o.items() if f not in strip} for k, o in b.items()
    }
    manifest = json.loads((resumed / "manifest.json").read_text())
    assert [s["status"] for s in manifest["sessions"]] == [
        "running",
        "finished",
    ]  # the killed one never closed
    assert _task_scores(full) == _task_scores(resumed)


def test_read_done_ids_repairs_a_torn_tail(tmp_path: Path) -> None:
    path = tmp_path / "p.jsonl"
    good = json.dumps({"id": "a", "prediction": "yes"}) + "\n"
    path.write_text(
        good + "not json\n" + json.dumps({"id": "b", "prediction": "no"}) + "\n" + '{"id": "c", "pre'
    )
    assert read_done_ids(path) == {"a", "b"}
    assert path.read_text().endswith('"no"}\n')  # torn tail cut, complete lines kept
    assert read_done_ids(tmp_path / "absent.jsonl") == set()


def test_http_faults_are_retried_and_malformed_replies_recorded(
    sample_setup, openloop_data_dir: Path, tmp_path: Path
) -> None:
    records, root_arg = sample_setup
    oracle = OraclePolicy(records)
    malformed_ids = {"R1_1_A_3", "R3_1_2", "R2_1_A_1"}
    empty_ids = {"R1_3_5"}

    def answer(rec):
        if rec.id in malformed_ids:
            return Fault.malformed_json()
        if rec.id in empty_ids:
            return Fault.empty_choices()
        return oracle_answer(rec)

    policy = OraclePolicy(records, answer=answer)
    # Every request fails twice with HTTP 500 before the policy is consulted.
    server = ScriptedOpenAIServer(policy, fail_first_attempts=2)
    out = tmp_path / "run"
    with server as url:
        cfg = _config(url, openloop_data_dir, out, root_arg, concurrency=16, backoff_s=0.005)
        summary = predict(cfg)
        assert summary.failed == 4 and summary.written == N_SAMPLES - 4 and not summary.complete
        assert server.stats.faults["http_500"] == 2 * N_SAMPLES
        errors = _errors(out)
        assert {e["id"] for e in errors} == malformed_ids | empty_ids
        assert {e["kind"] for e in errors} == {"malformed_response"}
        assert all(e["task"] and e["detail"] and e["time"] for e in errors)
        assert not (malformed_ids | empty_ids) & set(_predictions(out))
        # The server is fixed; a resume asks only the failed records again.
        policy.answer = oracle_answer
        n_before = server.stats.chat_requests
        summary = predict(cfg)
    assert summary.complete and summary.written == 4 and summary.already_done == N_SAMPLES - 4
    # Only the 4 failed records are sent again (the injected 500s were spent on their first try).
    assert server.stats.chat_requests - n_before == 4
    assert set(_predictions(out)) == {r.id for r in records}
    assert oracle is not policy


def test_missing_and_unreadable_images_are_logged_and_retried(
    openloop_data_dir: Path, tmp_path: Path
) -> None:
    root_arg = f"/data/sets={tmp_path}/sets"
    cat = default_catalog(openloop_data_dir)
    records = [
        r for spec in cat.datasets for r in load_dataset(cat, spec, ImageRootMap.parse([root_arg])).records
    ]
    lingo = {i.path for r in records if r.task == "R1_4" for i in r.images}
    write_images(records, skip=lambda p: p in lingo)  # R1_4's LingoQA images are "not downloaded"
    r32 = next(r for r in records if r.id == "R3_2_0")
    Path(r32.images[1].path).write_bytes(b"\xff\xd8\xff not really a jpeg")
    policy = OraclePolicy([r for r in records if r.task != "R1_4" and r.id != "R3_2_0"])
    out = tmp_path / "run"
    server = ScriptedOpenAIServer(policy)
    with server as url:
        cfg = _config(url, openloop_data_dir, out, root_arg, concurrency=8)
        s1 = predict(cfg)
        n_r14 = sum(r.task == "R1_4" for r in records)
        assert s1.failed == n_r14 + 1 and server.stats.chat_requests == N_SAMPLES - n_r14 - 1
        errors = _errors(out)
        kinds = {e["id"]: e["kind"] for e in errors}
        assert kinds["R3_2_0"] == "unreadable_image"
        assert {k for i, k in kinds.items() if i != "R3_2_0"} == {"missing_image"}
        assert all(e["path"] for e in errors)
        assert not {"R3_2_0"} & set(_predictions(out))
        # The user fetches the images; the resume sends exactly the skipped records.
        for p in lingo:
            Path(p).unlink(missing_ok=True)
        Path(r32.images[1].path).unlink()
        write_images(records)
        policy2 = OraclePolicy(records)
        server.policy = policy2
        s2 = predict(cfg)
    assert s2.written == n_r14 + 1 and s2.complete and policy2.unmatched == 0
    assert set(_predictions(out)) == {r.id for r in records}


def test_limit_and_dataset_selection(sample_setup, openloop_data_dir: Path, tmp_path: Path) -> None:
    records, root_arg = sample_setup
    out = tmp_path / "run"
    with ScriptedOpenAIServer(OraclePolicy(records)) as url:
        s = predict(_config(url, openloop_data_dir, out, root_arg, datasets="R1_3,R3_2", limit=3))
    assert s.total == 6 and s.written == 6
    assert sorted(p.name for p in (out / "predictions").iterdir()) == [
        "R1_3_Location_Questions.jsonl",
        "R3_2_Sequential_Planning.jsonl",
    ]
    assert set(_predictions(out)) == {"R1_3_0", "R1_3_1", "R1_3_2", "R3_2_0", "R3_2_1", "R3_2_2"}


def test_resume_refuses_another_model_or_decoding(
    sample_setup, openloop_data_dir: Path, tmp_path: Path
) -> None:
    records, root_arg = sample_setup
    out = tmp_path / "run"
    with ScriptedOpenAIServer(OraclePolicy(records)) as url:
        predict(_config(url, openloop_data_dir, out, root_arg, datasets="R1_3", limit=1))
        other = RunConfig(base_url=url, model="other", out=out, data_dir=openloop_data_dir, progress=False)
        with pytest.raises(ConfigError, match="would mix runs"):
            predict(other)
        with pytest.raises(ConfigError, match="would mix runs"):
            predict(_config(url, openloop_data_dir, out, root_arg, decoding=DecodingConfig(max_tokens=128)))


def test_config_validation(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="exactly one"):
        RunConfig(base_url="http://x/v1", model="m", out=tmp_path)
    with pytest.raises(ConfigError, match="concurrency"):
        RunConfig(base_url="http://x/v1", model="m", out=tmp_path, data_dir=tmp_path, concurrency=0)
    with pytest.raises(ConfigError, match="NO_SUCH_KEY_VAR"):
        predict(
            RunConfig(
                base_url="http://127.0.0.1:9/v1",
                model="m",
                out=tmp_path / "o",
                data_dir=tmp_path,
                api_key_env="NO_SUCH_KEY_VAR_OLRUN",
                datasets="R1_3",
                progress=False,
            )
        )


def test_many_requests_in_flight(tmp_path: Path) -> None:
    from drivehierarchy.benchmark.openloop.synthetic import make_synthetic_records

    data = make_synthetic_records(tmp_path / "data", 25, tmp_path / "images")
    cat = default_catalog(data)
    records = [r for spec in cat.datasets for r in load_dataset(cat, spec).records]
    write_images(records)
    policy = OraclePolicy(records)
    server = ScriptedOpenAIServer(policy, latency_s=0.05)
    with server as url:
        s = predict(RunConfig(base_url=url, model="m", out=tmp_path / "run", data_dir=data, progress=False))
    assert s.complete and s.written == 14 * 25 and policy.unmatched == 0
    assert server.stats.max_in_flight >= 32
