"""Faults in one scenario of an R4 run (in-process): an agent or the env raising mid-episode fails
that scenario only (recorded as `system_error` with an error.json), the batch goes on, the run
exits non-zero naming it, and a resume redoes only it; the summary then equals a clean run's."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drivehierarchy import ConfigError, SimulationError
from drivehierarchy.agents.expert import ExpertAgent
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.cli import main
from drivehierarchy.envs.r4 import DriveHierarchyR4Env
from drivehierarchy.scenarios import builtin_root

R4 = builtin_root() / "r4"
PEDESTRIAN = sorted((R4 / "01_pedestrian").glob("*.toml"))[0]
SUDDEN_BRAKE = sorted((R4 / "07_sudden_brake").glob("*.toml"))[0]
SUMO = R4 / "06_traffic_flow" / "bs3d_09_left_turner_queue.toml"
SUMMARY_FILES = ("summary.json", "summary.csv", "summary.md", "table2.md", "table2.csv", "r4_summary.csv")

FAULTY = {"category": None}  # which category the test agent breaks in (None: it drives cleanly)


class BreaksInOneCategory(ExpertAgent):
    """The expert, except that it raises on its 30th decision in `FAULTY["category"]`."""

    name = "test-breaks-in-one-category"

    def reset(self, env: Any, info: dict[str, Any]) -> None:
        super().reset(env, info)
        self.decisions = 0
        self.category = env.unwrapped.sim.category

    def act(self, observation: dict[str, Any], info: dict[str, Any]) -> np.ndarray:
        self.decisions += 1
        if self.category == FAULTY["category"] and self.decisions == 30:
            raise RuntimeError("agent bug: index out of range")
        return super().act(observation, info)


runner.AGENTS.register(BreaksInOneCategory.name, BreaksInOneCategory)


class MisconfiguredAgent(ExpertAgent):
    name = "test-misconfigured"

    def reset(self, env: Any, info: dict[str, Any]) -> None:
        raise ConfigError("config `action_mode` = 'raw': this policy was trained on 'decision'")


runner.AGENTS.register(MisconfiguredAgent.name, MisconfiguredAgent)


def _summaries(out: Path) -> dict[str, bytes]:
    return {name: (out / name).read_bytes() for name in SUMMARY_FILES}


def test_an_agent_raising_in_one_scenario_fails_it_only_and_a_resume_redoes_only_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    scenarios = [PEDESTRIAN, SUDDEN_BRAKE]
    bad = runner.scenario_key(SUDDEN_BRAKE)
    out = tmp_path / "run"
    suite = tmp_path / "suite"
    args = ["r4", "evaluate", "--agent", BreaksInOneCategory.name, "--suite", str(suite), "--out", str(out)]
    suite.mkdir()
    for p in scenarios:  # a suite folder of the two scenarios (maps resolve from the built-ins)
        (suite / p.parent.name).mkdir()
        (suite / p.parent.name / p.name).symlink_to(p)

    monkeypatch.setitem(FAULTY, "category", "07_sudden_brake")
    assert main(args) == 4
    err = capsys.readouterr().err
    assert f"1 scenario(s) failed: {bad}" in err and "RuntimeError: agent bug" in err
    lines = [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]
    assert sorted(x["key"] for x in lines) == sorted(runner.scenario_key(p) for p in scenarios)
    failure = next(x for x in lines if x["key"] == bad)
    assert failure["termination_reason"] == "system_error" and failure["status"] == "Failed"
    assert failure["system_error"]["kind"] == "exception" and "score" not in failure
    report = json.loads((out / "scenes" / bad / "error.json").read_text())
    assert report["type"] == "RuntimeError" and report["message"] == "agent bug: index out of range"
    assert "in act" in report["traceback"]
    assert list(runner.read_results(out)) == [runner.scenario_key(PEDESTRIAN)]
    assert list(runner.read_failures(out)) == [bad]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failed"] == [bad] and summary["scenarios"] == 1
    assert bad in (out / "summary.md").read_text()

    # The agent is fixed: the resume redoes only the failed scenario, appending to the log.
    monkeypatch.setitem(FAULTY, "category", None)
    assert main(args) == 0
    assert capsys.readouterr().out.count("done before, skipped") == 1
    keys = [json.loads(x)["key"] for x in (out / "results.jsonl").read_text().splitlines()]
    assert len(keys) == 3 and keys[2] == bad
    assert not (out / "scenes" / bad / "error.json").exists(), "redone from scratch"
    assert runner.read_failures(out) == {}

    clean = tmp_path / "clean"
    assert main([*args[:-1], str(clean)]) == 0
    assert _summaries(out) == _summaries(clean)


def test_the_env_failing_mid_episode_is_a_recorded_failure_and_the_next_sumo_scenario_runs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """libsumo failing inside a step (in the harness's process): the env and its SUMO are closed,
    so the next scenario with SUMO traffic still gets libsumo."""
    real_step = DriveHierarchyR4Env.step
    calls = {"n": 0}

    def failing_step(self: DriveHierarchyR4Env, action: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 40:
            raise SimulationError("libsumo: connection to the simulation lost (injected)")
        return real_step(self, action)

    monkeypatch.setattr(DriveHierarchyR4Env, "step", failing_step)
    out = tmp_path / "run"
    opts = runner.RunOptions(seeds=2)  # the same SUMO scenario twice, one after the other
    with pytest.raises(runner.ScenariosFailed, match="injected") as err:
        runner.evaluate([SUMO], out, opts, log=print)
    first = f"{runner.scenario_key(SUMO)}__s0"
    assert err.value.failed == [first]
    assert list(runner.read_results(out)) == [f"{runner.scenario_key(SUMO)}__s1"]
    assert json.loads((out / "scenes" / first / "error.json").read_text())["type"] == "SimulationError"


def test_configuration_errors_stop_the_run_instead_of_failing_every_scenario(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="unknown agent"):
        runner.evaluate([PEDESTRIAN], tmp_path / "a", runner.RunOptions(agent="nobody"), log=print)
    out = tmp_path / "b"
    with pytest.raises(ConfigError, match="trained on 'decision'"):
        opts = runner.RunOptions(agent=MisconfiguredAgent.name)
        runner.evaluate([PEDESTRIAN, SUDDEN_BRAKE], out, opts, log=print)
    assert runner.read_results(out) == {} and runner.read_failures(out) == {}
