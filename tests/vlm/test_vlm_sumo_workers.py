"""Scenarios with SUMO traffic in a concurrent `r4 evaluate --agent vlm`: each runs in a worker
process of its own (libsumo runs one simulation per process) while its requests go out from the
harness's one connection pool. Real loopback server, real libsumo, real processes; a worker is
killed for real with SIGKILL."""

from __future__ import annotations

import dataclasses
import itertools
import json
import os
import signal
import threading
from pathlib import Path

import pytest

from conftest import short_scenarios
from drivehierarchy.agents.vlm import PayloadOptions, VLMOptions
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.benchmark.r4.workers import WORKER_NAME, running_workers
from drivehierarchy.envs.config import BevConfig, CameraConfig, R4Config
from drivehierarchy.testing.openai_server import ScriptedOpenAIServer, route_driver

OBSTACLES, SUMO, YIELDING = short_scenarios(3)
# Small camera and BEV images: the workers must send, save and encode the same frames as the
# harness process, which any size shows; the protocol's 800 px frames cost most of these tests'
# time in rendering and PNG/GIF encoding.
SMALL_IMAGES = R4Config(front=CameraConfig(width=200, height=112), bev=BevConfig(size_px=200, px_per_m=4.0))


def _opts(url: str, **kw) -> runner.RunOptions:
    return runner.RunOptions(agent="vlm", vlm=VLMOptions(base_url=url, model="test-model"), **kw)


def _scene(out: Path, key: str) -> dict:
    """Everything a scenario wrote that must not depend on where or how fast it ran."""
    d = out / "scenes" / key
    record = json.loads((d / "scene_score.json").read_text())
    del record["meta"]["duration_system"]  # wall time
    decisions = [json.loads(line) for line in (d / "decisions.jsonl").read_text().splitlines()]
    for x in decisions:
        del x["latency_s"]
    ticks = (d / "episode_log.jsonl").read_text().splitlines()[:-1]  # the end line has the wall time
    return {"record": record, "decisions": decisions, "ticks": ticks}


def test_the_suite_has_a_sumo_scenario() -> None:
    assert runner.uses_sumo(SUMO, R4Config()) and not runner.uses_sumo(OBSTACLES, R4Config())


def test_sumo_scenarios_run_at_once_in_workers_and_match_a_sequential_run(tmp_path: Path) -> None:
    seen: list[set[int]] = []
    sent: list[tuple] = []  # what each request carried: its texts and images

    def policy(req):
        seen.append(set(running_workers()))
        sent.append((req.user_texts, tuple(i.sha256 for i in req.images)))
        return route_driver(req)

    scenarios = [SUMO, OBSTACLES]
    with ScriptedOpenAIServer(policy, latency_s=0.01) as url:
        small = {"seeds": 3, "config": SMALL_IMAGES}
        serial = runner.evaluate(scenarios, tmp_path / "serial", _opts(url, jobs=1, **small), log=print)
        assert not any(seen), "with one job everything runs in the harness's process"
        serial_sent, seen[:], sent[:] = list(sent), [], []
        parallel = runner.evaluate(scenarios, tmp_path / "par", _opts(url, jobs=6, **small), log=print)
    # Three SUMO scenarios at once, each in a worker of its own (a worker is started only when none
    # is free), gone once the run is over.
    assert max(len(s) for s in seen) == 3 and len(set().union(*seen)) == 3
    assert running_workers() == []
    assert [r["key"] for r in parallel] == [r["key"] for r in serial]
    for a, b in zip(serial, parallel, strict=True):
        assert a["vlm"]["decisions"] == b["vlm"]["decisions"] > 0
        assert _scene(tmp_path / "serial", a["key"]) == _scene(tmp_path / "par", b["key"])
    # Every request, images included (they show the SUMO traffic), was sent alike.
    assert sorted(sent) == sorted(serial_sent)
    # The serial run went scenario after scenario: the seeds' SUMO traffic differs on camera.
    n0 = serial[0]["vlm"]["decisions"]
    assert serial_sent[0][1] != serial_sent[n0][1], "different seeds give different SUMO traffic"
    assert json.loads((tmp_path / "serial" / "summary.json").read_text()) == json.loads(
        (tmp_path / "par" / "summary.json").read_text()
    )


@pytest.mark.timeout(300)
def test_a_worker_killed_mid_episode_fails_its_scenario_clearly_and_a_rerun_resumes(tmp_path: Path) -> None:
    lock = threading.Lock()
    killed: list[int] = []
    sumo_requests = {"n": 0}

    def killer(req):
        with lock:
            live = running_workers()
            if live and not killed:
                sumo_requests["n"] += 1
                if sumo_requests["n"] == 20:  # mid-episode: the SUMO scenario takes 100 decisions
                    os.kill(live[0], signal.SIGKILL)
                    killed.append(live[0])
        return route_driver(req)

    scenarios = [OBSTACLES, SUMO, YIELDING]
    sumo_key = runner.scenario_key(SUMO)
    out = tmp_path / "run"
    with ScriptedOpenAIServer(killer) as url:
        with pytest.raises(runner.ScenariosFailed) as err:
            runner.evaluate(scenarios, out, _opts(url, jobs=3), log=print)
        assert len(killed) == 1 and err.value.failed == [sumo_key]
        msg = str(err.value)
        assert msg.startswith(
            f"scenario {sumo_key}: WorkerDied: worker process {WORKER_NAME}-0 (pid {killed[0]})"
        )
        assert "died (exit code -9)" in msg and "2/3 scenarios finished" in msg and "run the same" in msg
        # The others finished and were kept; the lost one is recorded and says why; the summary
        # covers the finished ones and lists the failed one.
        assert sorted(runner.read_results(out)) == sorted(
            runner.scenario_key(p) for p in (OBSTACLES, YIELDING)
        )
        assert "died" in json.loads((out / "scenes" / sumo_key / "error.json").read_text())["message"]
        assert json.loads((out / "summary.json").read_text())["failed"] == [sumo_key]
        assert running_workers() == []

        logged: list[str] = []
        results = runner.evaluate(scenarios, out, _opts(url, jobs=3), log=logged.append)
        whole = runner.evaluate(scenarios, tmp_path / "whole", _opts(url, jobs=1), log=print)
    assert sum("done before, skipped" in m for m in logged) == 2
    assert not (out / "scenes" / sumo_key / "error.json").exists(), "redone from scratch"
    keys = [json.loads(line)["key"] for line in (out / "results.jsonl").read_text().splitlines()]
    assert len(keys) == 4 and keys.count(sumo_key) == 2, "the failure line, then the redone one"
    assert [r["key"] for r in results] == [r["key"] for r in whole]
    for r in whole:
        assert _scene(out, r["key"]) == _scene(tmp_path / "whole", r["key"])
    assert json.loads((out / "summary.json").read_text()) == json.loads(
        (tmp_path / "whole" / "summary.json").read_text()
    )


def test_expert_runs_sumo_scenarios_in_workers_too(tmp_path: Path) -> None:
    serial = runner.evaluate([SUMO], tmp_path / "a", runner.RunOptions(seeds=2, jobs=1), log=print)
    parallel = runner.evaluate([SUMO], tmp_path / "b", runner.RunOptions(seeds=2, jobs=2), log=print)
    for a, b in zip(serial, parallel, strict=True):
        assert a["score"]["termination_reason"] == "destination_reached"
        for x in (a, b):
            del x["score"]["meta"]["duration_system"]
        assert a["score"] == b["score"]


def test_controls_frames_and_video_in_a_worker_match_the_harness_process(tmp_path: Path) -> None:
    sent: dict[int, list[tuple]] = {1: [], 2: []}
    current = {"jobs": 1}

    def policy(req):
        sent[current["jobs"]].append((req.user_texts, tuple(i.sha256 for i in req.images)))
        return route_driver(req)

    payload = PayloadOptions(corrupt="noise")  # seeded by the episode seed and the decision
    with ScriptedOpenAIServer(policy) as url:
        for jobs in (1, 2):
            current["jobs"] = jobs
            opts = _opts(url, jobs=jobs, frames=True, video=True, config=SMALL_IMAGES)
            opts.vlm = dataclasses.replace(opts.vlm, payload=payload)
            (res,) = runner.evaluate([SUMO], tmp_path / str(jobs), opts, log=print)
            scene = tmp_path / str(jobs) / "scenes" / res["key"]
            n = res["vlm"]["decisions"]
            assert len(list((scene / "frames").glob("*_front.png"))) == n
            assert len(list((scene / "frames").glob("*_bev.png"))) == n
            assert (scene / "episode.gif").stat().st_size > 10_000
    assert sent[1] == sent[2] and len(sent[1]) == n
    assert _scene(tmp_path / "1", res["key"]) == _scene(tmp_path / "2", res["key"])


def test_latency_aware_in_a_worker(tmp_path: Path) -> None:
    with ScriptedOpenAIServer(route_driver, latency_s=0.1) as url:
        opts = _opts(url, jobs=2, config=SMALL_IMAGES)
        opts.vlm = dataclasses.replace(opts.vlm, latency_aware=True)
        (res,) = runner.evaluate([SUMO], tmp_path / "late", opts, log=print)
    log = [json.loads(x) for x in (tmp_path / "late" / "scenes" / res["key"] / "decisions.jsonl").open()]
    assert all(d["held_ticks"] == round(d["latency_s"] / 0.05) >= 2 for d in log)
    for a, b in itertools.pairwise(log):
        assert b["tick"] - a["tick"] == a["held_ticks"] + 5
    assert res["score"]["decisions"] == len(log) and res["score"]["parse_failures"] == 0
