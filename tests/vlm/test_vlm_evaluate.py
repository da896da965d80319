"""`r4 evaluate --agent vlm` end to end against the real loopback server: records, protocol text,
held and counted failures, the batch-abort rule, resume, seeds, controls, CLI and report."""

from __future__ import annotations

import dataclasses
import itertools
import json
import re
from collections import Counter
from pathlib import Path

import pytest

from conftest import ACTION_QUESTION, short_scenarios
from drivehierarchy import ConfigError
from drivehierarchy.agents.vlm import PayloadOptions, VLMOptions
from drivehierarchy.agents.vlm.payload import bev_descriptor, front_descriptor
from drivehierarchy.agents.vlm.transport import ServerUnavailable
from drivehierarchy.benchmark.openloop.report import read_r4_csv
from drivehierarchy.benchmark.r4 import report, runner
from drivehierarchy.cli import main
from drivehierarchy.testing.openai_server import Fault, ScriptedOpenAIServer, route_driver

PREFIX = re.compile(
    r"^Q\(frame (\d+)\): The ego vehicle is driving at the speed of \d+\.\d m/s, and it wants to "
    r"(turn left at the intersection|turns right at the intersection|drive straight at the "
    r"intersection|follow the road|do a lane change to the left|do a lane change to the right)\. "
    r"(Remaining route distance to destination is approximately \d+\.\d meters\. )?"
    r"The local future route in ego coordinates is given as \(forward_m, right_m\): \[.*\]\. $"
)


def _opts(url: str, **kw) -> runner.RunOptions:
    vlm_kw = {k: kw.pop(k) for k in list(kw) if k in ("payload", "max_retries", "backoff_s", "timeout_s")}
    vlm_kw.setdefault("backoff_s", 0.001)
    return runner.RunOptions(agent="vlm", vlm=VLMOptions(base_url=url, model="test-model", **vlm_kw), **kw)


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def _hash(req) -> str:
    import hashlib

    h = hashlib.sha256()
    for t in req.user_texts:
        h.update(t.encode())
        h.update(b"\x00")
    return h.hexdigest()[:16]


def test_suite_writes_every_record_with_the_exact_protocol_message(tmp_path: Path) -> None:
    server = ScriptedOpenAIServer(route_driver)
    server.keep_log = True
    out = tmp_path / "run"
    with server as url:
        results = runner.evaluate(short_scenarios(), out, _opts(url, jobs=3), log=lambda _: None)
    assert [r["category"] for r in results] == ["02_obstacles", "06_traffic_flow", "09_yielding"]
    decisions = 0
    logged_hashes: Counter[str] = Counter()
    for r in results:
        scene = out / "scenes" / r["key"]
        record = json.loads((scene / "scene_score.json").read_text())
        assert record == r["score"] and json.loads((scene / "events.json").read_text()) == record["events"]
        assert (scene / "episode_log.jsonl").stat().st_size > 0
        log = _lines(scene / "decisions.jsonl")
        assert (
            [d["decision"] for d in log]
            == list(range(1, len(log) + 1))
            == list(range(1, r["vlm"]["decisions"] + 1))
        )
        assert record["decisions"] == len(log) and record["parse_failures"] == 0
        assert all(d["failure"] is None and d["parsed"] is not None and d["images"] == 2 for d in log)
        assert all(d["tick"] == 4 + 5 * (d["decision"] - 1) for d in log)  # warm-up, then every 5 ticks
        assert all(re.fullmatch(r"steer: -?\d\.\d{3}\ntarget_speed_mps: \d+\.\d", d["raw"]) for d in log)
        assert all(d["latency_s"] >= 0 and d["attempts"] == 1 for d in log)
        logged_hashes.update(d["prompt_hash"] for d in log)
        decisions += len(log)
    # Every request: one user turn, front descriptor, front JPEG, BEV descriptor, BEV JPEG, question.
    assert len(server.requests_log) == decisions
    for req in server.requests_log:
        assert [k for k, _ in req.parts] == ["text", "image", "text", "image", "text"]
        assert len(req.images) == 2 and all(i.mime == "image/jpeg" and i.data for i in req.images)
        assert req.user_texts[0] == front_descriptor(800, 450)
        assert req.user_texts[1] == bev_descriptor(800)
        q = req.user_texts[2]
        assert q.endswith(ACTION_QUESTION)
        assert PREFIX.match(q[: -len(ACTION_QUESTION)]), q[:300]
        assert req.system == "" and len(req.body["messages"]) == 1
    # What the decision logs say was sent is what the server received.
    assert Counter(_hash(r) for r in server.requests_log) == logged_hashes

    summary = json.loads((out / "summary.json").read_text())
    assert summary["scenarios"] == 3 and summary["model"] == "test-model"
    assert summary["decisions"] == decisions and summary["parse_failures"] == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["vlm"]["model"] == "test-model" and manifest["vlm"]["decoding"]["temperature"] == 0.0
    assert manifest["vlm"]["payload"]["blind"] is False and manifest["jobs"] == 3
    assert read_r4_csv(out / "r4_summary.csv") == {"test-model": pytest.approx(summary["r4_score"], abs=1e-6)}
    assert "| Models | Sce 2 | Sce 6 | Sce 9 | Avg.Score | Rank |" in (out / "table2.md").read_text()


def test_malformed_replies_are_held_and_counted(tmp_path: Path) -> None:
    server = ScriptedOpenAIServer(route_driver, malformed_reply_rate=0.3, seed=1)
    out = tmp_path / "run"
    with server as url:
        (res,) = runner.evaluate(short_scenarios(1), out, _opts(url), log=lambda _: None)
    bad = server.stats.faults["malformed_reply"]
    assert bad > 3
    assert res["vlm"]["parse_failures"] == bad == res["score"]["parse_failures"]
    log = _lines(out / "scenes" / res["key"] / "decisions.jsonl")
    failed = [d for d in log if d["failure"] is not None]
    assert len(failed) == bad and all(d["failure"] == "missing_both" and d["parsed"] is None for d in failed)
    for prev, d in itertools.pairwise(log):
        if d["failure"] is not None:
            assert d["control"] == prev["control"], "an unparseable reply holds the previous control"


def test_outage_mid_run_aborts_cleanly_and_a_rerun_resumes(tmp_path: Path) -> None:
    calls = {"n": 0}

    def flaky(req):
        calls["n"] += 1
        return route_driver(req) if calls["n"] <= 60 else Fault.http(503)

    out = tmp_path / "run"
    scenarios = short_scenarios()
    with ScriptedOpenAIServer(flaky) as url, pytest.raises(runner.BatchAborted, match="server_unavailable"):
        runner.evaluate(scenarios, out, _opts(url, max_retries=1), log=lambda _: None)
    finished = runner.read_results(out)
    assert list(finished) == ["02_obstacles__town01_02_cones_right_lane"]  # 50 decisions, then the outage
    (aborted,) = _lines(out / "aborted.jsonl")
    assert aborted["key"] == "06_traffic_flow__bs3d_09_left_turner_queue"
    assert aborted["vlm"]["transport_errors"] == 3 and "HTTP 503" in aborted["last_error"]
    aborted_after = out / "scenes" / "09_yielding__town01_09_yield_left_turn"
    assert not aborted_after.exists(), "nothing new after an abort"
    assert not (out / "summary.json").exists()

    with ScriptedOpenAIServer(route_driver) as url:
        logged: list[str] = []
        results = runner.evaluate(scenarios, out, _opts(url), log=logged.append)
    assert sum("done before, skipped" in m for m in logged) == 1
    assert [r["key"] for r in results] == [runner.scenario_key(p) for p in scenarios]
    keys = [r["key"] for r in _lines(out / "results.jsonl")]
    assert sorted(keys) == sorted(set(keys)) and len(keys) == 3
    assert not (out / "scenes" / aborted["key"] / "aborted.json").exists()  # redone from scratch


def test_a_scenario_without_any_valid_decision_aborts_the_batch(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with (
        ScriptedOpenAIServer(lambda r: "I would rather not drive.") as url,
        pytest.raises(runner.BatchAborted, match="no_valid_decision"),
    ):
        runner.evaluate(short_scenarios(2), out, _opts(url), log=lambda _: None)
    assert runner.read_results(out) == {}
    (line,) = _lines(out / "aborted.jsonl")
    assert line["aborted"] == "no_valid_decision" and line["vlm"]["valid"] == 0
    assert line["vlm"]["parse_failures"] == line["vlm"]["decisions"] > 0


def test_server_down_or_model_not_served_fails_before_writing(tmp_path: Path) -> None:
    with ScriptedOpenAIServer(models=("other",)) as url, pytest.raises(ServerUnavailable, match="not served"):
        runner.evaluate(short_scenarios(1), tmp_path / "a", _opts(url), log=lambda _: None)
    assert not (tmp_path / "a").exists()
    with pytest.raises(ConfigError, match="needs a server"):
        runner.evaluate(short_scenarios(1), tmp_path / "b", runner.RunOptions(agent="vlm"), log=print)


def test_seeds_give_keys_intervals_and_reproducible_episodes(tmp_path: Path) -> None:
    with ScriptedOpenAIServer(route_driver) as url:
        a = runner.evaluate(short_scenarios(2), tmp_path / "a", _opts(url, seeds=2, jobs=4), log=print)
        b = runner.evaluate(short_scenarios(2), tmp_path / "b", _opts(url, seeds=2, jobs=1), log=print)
    assert [r["key"] for r in a] == [
        "02_obstacles__town01_02_cones_right_lane__s0",
        "02_obstacles__town01_02_cones_right_lane__s1",
        "06_traffic_flow__bs3d_09_left_turner_queue__s0",
        "06_traffic_flow__bs3d_09_left_turner_queue__s1",
    ]
    # Same seeds and replies => identical episodes, whatever the concurrency.
    for x, y in zip(a, b, strict=True):
        assert x["score"]["score_composed"] == y["score"]["score_composed"]
        # Every tick identical (the end line also carries the wall time).
        ticks = [
            (tmp_path / d / "scenes" / r["key"] / "episode_log.jsonl").read_text().splitlines()[:-1]
            for d, r in (("a", x), ("b", y))
        ]
        assert ticks[0] == ticks[1] and len(ticks[0]) > 100
    sa = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert sa == json.loads((tmp_path / "b" / "summary.json").read_text())
    assert sa["seeds"] == [0, 1] and sa["counts"] == {"02_obstacles": 2, "06_traffic_flow": 2}
    for c, (lo, hi) in sa["categories_ci95"].items():
        assert lo <= sa["categories"][c] <= hi
    with pytest.raises(ConfigError, match="another run"):
        runner.evaluate(short_scenarios(2), tmp_path / "a", _opts("http://127.0.0.1:9/v1", seeds=3))


@pytest.mark.parametrize(
    ("payload", "parts"),
    [
        (PayloadOptions(blind=True), ["text"]),
        (PayloadOptions(no_bev=True), ["text", "image", "text"]),
        (PayloadOptions(corrupt="dark"), ["text", "image", "text", "image", "text"]),
    ],
)
def test_controls_change_what_is_sent(tmp_path: Path, payload: PayloadOptions, parts: list[str]) -> None:
    server = ScriptedOpenAIServer(route_driver)
    server.keep_log = True
    with server as url:
        (res,) = runner.evaluate(short_scenarios(1), tmp_path / "r", _opts(url, payload=payload), log=print)
    assert {tuple(k for k, _ in r.parts) for r in server.requests_log} == {tuple(parts)}
    assert res["vlm"]["valid"] == res["vlm"]["decisions"]
    manifest = json.loads((tmp_path / "r" / "manifest.json").read_text())
    assert manifest["identity"]["vlm"]["payload"]["blind"] == payload.blind


def test_cli_evaluate_and_report(tmp_path: Path, suite_dir: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "run"
    with ScriptedOpenAIServer(route_driver, models=("Qwen/Qwen3-VL-8B-Instruct",)) as url:
        argv = ["r4", "evaluate", "--agent", "vlm", "--base-url", url, "--model", "qwen3-vl-8b",
                "--suite", str(suite_dir), "--out", str(out), "--jobs", "3"]  # fmt: skip
        assert main([*argv, "--progress"]) == 0
        first = capsys.readouterr()
        assert "| **R4 (mean of categories)** | 3 |" in first.out
        assert "3/3" in first.err and "mean_S_R4=" in first.err and "parse_fail=0" in first.err  # tqdm bar
        assert main(argv) == 0  # resumed: nothing to redo
        assert capsys.readouterr().out.count("done before, skipped") == 3
        assert main([*argv[:7], "not-served", *argv[8:]]) == 2
        assert "belongs to another run" in capsys.readouterr().err
        assert main([*argv[:7], "not-served", *argv[8:-3], str(tmp_path / "new"), "--jobs", "3"]) == 2
        assert "not served" in capsys.readouterr().err
    expert = tmp_path / "expert"
    assert main(["r4", "evaluate", "--suite", str(suite_dir), "--out", str(expert)]) == 0
    rep = tmp_path / "report"
    assert main(["r4", "report", str(out), str(expert), "--out", str(rep), "--paper"]) == 0
    table = (rep / "table2.md").read_text()
    assert "| Qwen/Qwen3-VL-8B-Instruct |" in table and "| expert |" in table
    assert "| Qwen3-VL(8B) (paper) | 1.278 | 1.726 |" in table  # the paper row: Sce 1, Sce 2
    r4 = read_r4_csv(rep / "r4_summary.csv")
    assert set(r4) == {"Qwen/Qwen3-VL-8B-Instruct", "expert"}
    assert (rep / "r4_categories.png").stat().st_size > 1000
    assert report.table_rows([("a", {"categories": {"01_x": 1.0}, "r4_score": 1.0})])[1][0]["rank"] == 1


def test_latency_aware_holds_the_previous_control_while_the_model_thinks(tmp_path: Path) -> None:
    with ScriptedOpenAIServer(route_driver, latency_s=0.1) as url:
        opts = _opts(url)
        opts.vlm = dataclasses.replace(opts.vlm, latency_aware=True)
        (res,) = runner.evaluate(short_scenarios(1), tmp_path / "late", opts, log=print)
        (frozen,) = runner.evaluate(short_scenarios(1), tmp_path / "frozen", _opts(url), log=print)
    log = _lines(tmp_path / "late" / "scenes" / res["key"] / "decisions.jsonl")
    assert all(d["held_ticks"] == round(d["latency_s"] / 0.05) >= 2 for d in log)
    # The next question comes k + 5 ticks later: the world moved on while the model thought.
    for a, b in itertools.pairwise(log):
        assert b["tick"] - a["tick"] == a["held_ticks"] + 5
    record = res["score"]
    assert record["decisions"] == len(log) == res["vlm"]["decisions"] and record["parse_failures"] == 0
    assert record["latency_aware"]["held_ticks"] == sum(d["held_ticks"] for d in log)
    assert json.loads((tmp_path / "late" / "scenes" / res["key"] / "scene_score.json").read_text()) == record
    assert record["ticks"] != frozen["score"]["ticks"]
    manifest = json.loads((tmp_path / "late" / "manifest.json").read_text())
    assert manifest["identity"]["vlm"]["latency_aware"] is True
