"""Infrastructure faults in a concurrent `r4 evaluate --agent vlm` with SUMO scenarios in worker
processes, and model-server faults. Real loopback server, real libsumo, real processes: a worker
is killed with SIGKILL (SUMO gone mid-episode) or stopped with SIGSTOP (hung)."""

from __future__ import annotations

import json
import os
import signal
import threading
from pathlib import Path

import pytest

from drivehierarchy.agents.vlm import VLMOptions
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.benchmark.r4.workers import WORKER_NAME, running_workers
from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root
from drivehierarchy.testing.openai_server import ChatRequest, Fault, ScriptedOpenAIServer, route_driver

R4 = builtin_root() / "r4"
# Three short scenarios (50–100 decisions with the scripted driver); 06 has SUMO traffic.
OBSTACLES = R4 / "02_obstacles" / "town01_02_cones_right_lane.toml"
SUMO = R4 / "06_traffic_flow" / "bs3d_09_left_turner_queue.toml"
YIELDING = R4 / "09_yielding" / "town01_09_yield_left_turn.toml"
SUMMARY_FILES = ("summary.json", "summary.csv", "summary.md", "table2.md", "table2.csv", "r4_summary.csv")


def _suite(tmp_path: Path) -> Path:
    """A scenario folder (`--suite DIR`) of the three, the maps linked beside it."""
    suite = tmp_path / "suite" / "r4"
    for p in (OBSTACLES, SUMO, YIELDING):
        (suite / p.parent.name).mkdir(parents=True)
        (suite / p.parent.name / p.name).symlink_to(p)
    (suite.parent / "maps").symlink_to(builtin_root() / "maps")
    return suite


def _signal_worker_at(n: int, sig: signal.Signals) -> tuple[object, list[int]]:
    """A policy that sends `sig` to the (one) live worker at the n-th request made while it is
    live — mid-episode of the SUMO scenario, which takes ~100 decisions — then drives on."""
    lock = threading.Lock()
    hit: list[int] = []
    seen = {"n": 0}

    def policy(req: ChatRequest) -> str:
        with lock:
            live = running_workers()
            if live and not hit:
                seen["n"] += 1
                if seen["n"] == n:
                    os.kill(live[0], sig)
                    hit.append(live[0])
        return route_driver(req)

    return policy, hit


def _summaries(out: Path) -> dict[str, bytes]:
    return {name: (out / name).read_bytes() for name in SUMMARY_FILES}


@pytest.mark.timeout(400)
def test_sumo_killed_in_one_scenario_of_jobs_4_fails_it_only_and_a_resume_equals_a_clean_run(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    suite = _suite(tmp_path)
    sumo_key = runner.scenario_key(SUMO)

    def cmd(out: Path) -> list[str]:
        return ["r4", "evaluate", "--agent", "vlm", "--base-url", url, "--model", "test-model",
                "--suite", str(suite), "--out", str(out), "--jobs", "4"]  # fmt: skip

    out = tmp_path / "run"
    policy, killed = _signal_worker_at(20, signal.SIGKILL)
    with ScriptedOpenAIServer(policy) as url:
        assert main(cmd(out)) == 4
        assert len(killed) == 1
        err = capsys.readouterr().err
        assert f"1 scenario(s) failed: {sumo_key}: scenario {sumo_key}: WorkerDied: worker process" in err
        assert f"{WORKER_NAME}-0 (pid {killed[0]})" in err and "died (exit code -9)" in err
        # The others finished; the lost one is recorded as a system error with its cause.
        assert sorted(runner.read_results(out)) == sorted(
            runner.scenario_key(p) for p in (OBSTACLES, YIELDING)
        )
        (failure,) = runner.read_failures(out).values()
        assert failure["key"] == sumo_key and failure["termination_reason"] == "system_error"
        report = json.loads((out / "scenes" / sumo_key / "error.json").read_text())
        assert report["kind"] == "worker_died" and report["type"] == "WorkerDied"
        assert report["pid"] == killed[0] and report["exit_code"] == -signal.SIGKILL
        assert json.loads((out / "summary.json").read_text())["failed"] == [sumo_key]
        assert running_workers() == []

        capsys.readouterr()
        assert main(cmd(out)) == 0  # the resume: only the failed scenario is driven again
        assert capsys.readouterr().out.count("done before, skipped") == 2
        assert runner.read_failures(out) == {}
        assert not (out / "scenes" / sumo_key / "error.json").exists(), "redone from scratch"
        clean = tmp_path / "clean"
        assert main(cmd(clean)) == 0
    keys = [json.loads(x)["key"] for x in (out / "results.jsonl").read_text().splitlines()]
    assert len(keys) == 4 and keys.count(sumo_key) == 2 and keys[-1] == sumo_key
    assert _summaries(out) == _summaries(clean)


@pytest.mark.timeout(300)
def test_a_hung_worker_is_killed_after_the_timeout_and_fails_its_scenario_only(tmp_path: Path) -> None:
    policy, stopped = _signal_worker_at(10, signal.SIGSTOP)
    opts = runner.RunOptions(
        agent="vlm", jobs=2, worker_timeout_s=1.0, vlm=VLMOptions(base_url="", model="test-model")
    )
    out = tmp_path / "run"
    with ScriptedOpenAIServer(policy) as url:
        opts.vlm = VLMOptions(base_url=url, model="test-model")
        with pytest.raises(runner.ScenariosFailed, match="did not answer") as err:
            runner.evaluate([SUMO, OBSTACLES], out, opts, log=print)
    sumo_key = runner.scenario_key(SUMO)
    assert err.value.failed == [sumo_key] and len(stopped) == 1
    assert list(runner.read_results(out)) == [runner.scenario_key(OBSTACLES)]
    report = json.loads((out / "scenes" / sumo_key / "error.json").read_text())
    assert report["kind"] == "worker_timeout" and report["pid"] == stopped[0]
    assert report["exit_code"] == -signal.SIGKILL, "the stopped worker was killed"
    assert running_workers() == []
    with pytest.raises(ProcessLookupError):
        os.kill(stopped[0], 0)


def test_model_server_faults_hold_the_previous_control_and_are_counted(tmp_path: Path) -> None:
    """HTTP 500, 429 + Retry-After, invalid JSON, a truncated body, a reply slower than the
    timeout: each decision without a reply holds the previous control; nothing aborts."""
    decision = {"n": 0}
    faults = {5: Fault.http(500), 15: Fault.malformed_json(), 20: Fault.truncated()}
    slow = 25

    def latency(req: ChatRequest) -> float:  # called first for every request
        if req.attempt == 1:
            decision["n"] += 1
        return 3.0 if decision["n"] == slow else 0.0

    def policy(req: ChatRequest) -> str | Fault:
        n = decision["n"]
        if n == 10 and req.attempt == 1:
            return Fault.http(429, retry_after_s=0.2)
        return faults.get(n) or route_driver(req)

    vlm = VLMOptions(base_url="", model="test-model", timeout_s=0.5, max_retries=1, backoff_s=0.01)
    with ScriptedOpenAIServer(policy, latency_s=latency) as url:
        opts = runner.RunOptions(agent="vlm", vlm=VLMOptions(**{**vlm.__dict__, "base_url": url}))
        (res,) = runner.evaluate([OBSTACLES], tmp_path / "run", opts, log=print)
    log = [json.loads(x) for x in (tmp_path / "run" / "scenes" / res["key"] / "decisions.jsonl").open()]
    by_n = {d["decision"]: d for d in log}
    kinds = {n: by_n[n]["transport_error"] for n in (5, 15, 20, slow)}
    assert kinds == {5: "http_error", 15: "malformed_response", 20: "connection_error", 25: "timeout"}
    for n in kinds:
        assert by_n[n]["raw"] is None and by_n[n]["control"] == by_n[n - 1]["control"], n
    assert by_n[10]["transport_error"] is None and by_n[10]["attempts"] == 2
    assert by_n[10]["latency_s"] >= 0.2, "Retry-After was honoured"
    assert res["vlm"]["transport_errors"] == 4 and res["vlm"]["parse_failures"] == 0
    assert len(log) > slow and res["score"]["decisions"] == len(log), "the episode went on, scored"
