"""`--ray`: scenarios as Ray tasks on a local Ray instance, same results as in-process."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from conftest import short_scenarios
from drivehierarchy.agents.vlm import VLMOptions
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.testing.openai_server import ScriptedOpenAIServer, route_driver

pytestmark = pytest.mark.ray

ray = pytest.importorskip("ray")


def test_ray_tasks_match_the_in_process_run(tmp_path: Path) -> None:
    scenarios = short_scenarios(2)
    server = ScriptedOpenAIServer(route_driver)
    try:
        with server as url:
            vlm = VLMOptions(base_url=url, model="test-model")
            local = runner.evaluate(
                scenarios, tmp_path / "local", runner.RunOptions(agent="vlm", vlm=vlm, jobs=2), log=print
            )
            served_before = server.stats.chat_requests
            ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
            remote = runner.evaluate(
                scenarios,
                tmp_path / "ray",
                runner.RunOptions(agent="vlm", vlm=vlm, jobs=2, ray_address="local"),
                log=print,
            )
            expert = runner.evaluate(
                scenarios[:1], tmp_path / "ray_expert", runner.RunOptions(ray_address="local"), log=print
            )
    finally:
        ray.shutdown()
    assert [r["score"]["score_composed"] for r in remote] == [r["score"]["score_composed"] for r in local]
    assert server.stats.chat_requests - served_before == sum(r["vlm"]["decisions"] for r in remote)
    assert json.loads((tmp_path / "ray" / "summary.json").read_text()) == json.loads(
        (tmp_path / "local" / "summary.json").read_text()
    )
    assert expert[0]["score"]["termination_reason"] == "destination_reached"
    assert (tmp_path / "ray" / "scenes" / remote[0]["key"] / "decisions.jsonl").exists()
