"""`r4 evaluate --history 4` end to end through the CLI parser against the loopback scripted
server: the exact layout on the wire, past frames byte-identical to what was sent when they were
current, and a run stopped mid-suite (server outage, batch abort) and resumed sends what an
uninterrupted run sends and ends with the same summary."""

from __future__ import annotations

import itertools
import json
from pathlib import Path

from conftest import short_scenarios
from drivehierarchy.agents.vlm import VLMOptions
from drivehierarchy.agents.vlm.history import HistoryOptions
from drivehierarchy.benchmark.r4 import report, runner
from drivehierarchy.cli import main
from drivehierarchy.testing.openai_server import ChatRequest, Fault, ScriptedOpenAIServer, route_driver

FLAGS = ["--history", "4", "--history-bev", "--ego-history", "2", "--memory", "2"]


def _argv(url: str, suite: Path, out: Path) -> list[str]:
    return ["r4", "evaluate", "--agent", "vlm", "--base-url", url, "--model", "test-model",
            "--suite", str(suite), "--out", str(out), "--max-retries", "0", *FLAGS]  # fmt: skip


def _wire(req: ChatRequest) -> tuple:
    return tuple((k, v if k == "text" else v.sha256) for k, v in req.parts)


def _decisions(path: Path) -> list[dict]:
    drop = ("latency_s", "attempts")
    return [{k: v for k, v in json.loads(x).items() if k not in drop} for x in path.read_text().splitlines()]


def test_history_through_the_cli_with_an_outage_and_a_resume(tmp_path: Path, suite_dir: Path) -> None:
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    server = ScriptedOpenAIServer(route_driver)
    server.keep_log = True
    with server as url:
        assert main(_argv(url, suite_dir, whole)) == 0
    sent = [_wire(r) for r in server.requests_log]

    # The layout of a decision with a full history: 4 past (front, BEV) pairs oldest first, the
    # current pair, ego history, memory, question.
    first = sent[:10]
    assert [k for k, _ in first[0]] == ["text", "image"] * 2 + ["text"] * 3
    assert [k for k, _ in first[9]] == ["text", "image"] * 10 + ["text"] * 3
    texts = [v for k, v in first[9] if k == "text"]
    assert [t.split(" (", 1)[0] for t in texts[:10]] == [
        f"{what} at {when}"
        for when in ("t-1.00 s", "t-0.75 s", "t-0.50 s", "t-0.25 s", "t-0.00 s, the current frame")
        for what in ("Front camera image", "Bird's-eye view image")
    ]
    assert texts[10].startswith("Ego history, oldest first")
    assert texts[11].startswith("Your previous decisions")
    assert texts[12].startswith("Q(frame 10): ")
    # The frame sent at t-0.25 s is, byte for byte, the one sent as current a decision earlier.
    images = [[v for k, v in req if k == "image"] for req in first]
    assert images[9][6:8] == images[8][8:10] and images[9][0:2] == images[5][8:10]

    calls = {"n": 0}

    def flaky(req: ChatRequest) -> str | Fault:
        calls["n"] += 1
        return route_driver(req) if calls["n"] <= 70 else Fault.http(503)

    with ScriptedOpenAIServer(flaky) as url:
        assert main(_argv(url, suite_dir, cut)) == 3  # the second scenario meets the outage
    done = [json.loads(x)["key"] for x in (cut / "results.jsonl").read_text().splitlines()]
    assert len(done) == 1
    resumed = ScriptedOpenAIServer(route_driver)
    resumed.keep_log = True
    with resumed as url:
        assert main(_argv(url, suite_dir, cut)) == 0
    n_first = len(_decisions(whole / "scenes" / done[0] / "decisions.jsonl"))
    # The redone scenarios' requests are exactly the uninterrupted run's: history rebuilt from
    # each episode's start.
    assert [_wire(r) for r in resumed.requests_log] == sent[n_first:]
    for scene in sorted((whole / "scenes").iterdir()):
        assert _decisions(cut / "scenes" / scene.name / "decisions.jsonl") == _decisions(
            scene / "decisions.jsonl"
        )
    assert json.loads((cut / "summary.json").read_text()) == json.loads((whole / "summary.json").read_text())
    summary = json.loads((whole / "summary.json").read_text())
    assert summary["inputs"] == {
        "history": 4, "stride": 1, "history_bev": True, "ego_history": 2, "memory": 2, "controls": [],
    }  # fmt: skip
    manifest = json.loads((cut / "manifest.json").read_text())
    assert manifest["vlm"]["history"]["frames"] == 4 and manifest["action_level"] == "control"
    line = json.loads((cut / "results.jsonl").read_text().splitlines()[-1])
    assert line["inputs"] == summary["inputs"] and line["action_level"] == "control"
    assert report.row_label("test-model", summary) == "test-model [history 4 (+BEV), ego-history 2, memory 2]"


def test_history_offsets_are_true_under_latency_aware(tmp_path: Path) -> None:
    """With `--latency-aware` decisions are not evenly spaced: each past frame's label is how long
    ago it really was (its tick), and the memory says when each decision was asked."""
    # Replies alternate between instant and 0.5 s late, so the spacing of decisions is uneven
    # however fast or loaded the machine is (0.5 s is 10 ticks; an instant reply costs ~0-2).
    calls = itertools.count()
    server = ScriptedOpenAIServer(route_driver, latency_s=lambda _req: 0.5 if next(calls) % 2 else 0.0)
    server.keep_log = True
    with server as url:
        vlm = VLMOptions(
            base_url=url, model="test-model", latency_aware=True, history=HistoryOptions(frames=2, memory=1)
        )
        (res,) = runner.evaluate(short_scenarios(1), tmp_path / "r", runner.RunOptions(agent="vlm", vlm=vlm))
    log = [
        json.loads(x)
        for x in (tmp_path / "r" / "scenes" / res["key"] / "decisions.jsonl").read_text().splitlines()
    ]
    ticks = [d["tick"] for d in log]
    assert len({b - a for a, b in itertools.pairwise(ticks)}) > 1, "uneven spacing expected"
    for i, d in enumerate(log):
        want = [round((ticks[i] - ticks[j]) * 0.05, 4) for j in range(max(0, i - 2), i)]
        assert d["history_offsets_s"] == want
    req = server.requests_log[5]
    assert req.user_texts[0] == (
        f"Front camera image at t-{(ticks[5] - ticks[3]) * 0.05:.2f} s (800x450, looking forward from the "
        "ego vehicle's roof, 100 degree field of view):"
    )
    assert req.user_texts[-2].startswith(
        f"Your previous decisions, oldest first: t-{(ticks[5] - ticks[4]) * 0.05:.2f} s (frame 5): "
    )
