"""`kill -9` during `r4 evaluate --agent vlm`, then the same command again: finished scenarios are
not redone, nothing is lost or duplicated, and the summary equals an uninterrupted run's.
Real processes: the loopback server and the CLI run as subprocesses."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def server_url() -> Iterator[str]:
    port = _free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "drivehierarchy.testing.openai_server", "--port", str(port), "--driver",
         "--latency-ms", "5"],
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert proc.stderr is not None
        assert "serving" in proc.stderr.readline()
        yield f"http://127.0.0.1:{port}/v1"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def _cmd(url: str, suite: Path, out: Path, extra: tuple[str, ...] = ()) -> list[str]:
    return [sys.executable, "-m", "drivehierarchy.cli", "r4", "evaluate", "--agent", "vlm",
            "--base-url", url, "--model", "test-model", "--suite", str(suite), "--out", str(out),
            "--jobs", "2", *extra]  # fmt: skip


def _keys(out: Path) -> list[str]:
    path = out / "results.jsonl"
    if not path.exists():
        return []
    keys = []
    for line in path.read_text().splitlines():
        with contextlib.suppress(json.JSONDecodeError):  # a line torn by the kill
            keys.append(json.loads(line)["key"])
    return keys


def _descendants(pid: int) -> list[int]:
    """Child processes (recursively) from /proc; [] where /proc does not list children."""
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*/children"):
        with contextlib.suppress(OSError):
            for child in map(int, task.read_text().split()):
                out += [child, *_descendants(child)]
    return out


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


def _cmdline(pid: int) -> str:
    with contextlib.suppress(OSError):
        return Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " ")
    return ""


def _decisions(path: Path) -> list[tuple]:
    lines = [json.loads(x) for x in path.read_text().splitlines()]
    return [(d["prompt_hash"], d["images"], d.get("history_offsets_s"), d["raw"]) for d in lines]


@pytest.mark.parametrize(
    "extra",
    [(), ("--history", "2", "--history-bev", "--ego-history", "2", "--memory", "2")],
    ids=["paper", "history"],
)
def test_kill_9_then_rerun_equals_an_uninterrupted_run(
    tmp_path: Path, suite_dir: Path, server_url: str, extra: tuple[str, ...]
) -> None:
    """With history on too: the redone scenarios rebuild it from their start."""
    whole = tmp_path / "whole"
    done = subprocess.run(
        _cmd(server_url, suite_dir, whole, extra), capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr
    assert len(_keys(whole)) == 3

    out = tmp_path / "killed"
    proc = subprocess.Popen(
        _cmd(server_url, suite_dir, out, extra), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
    )
    # Killed once a scenario is finished and the SUMO scenario (06) is in flight in its worker
    # process (with 2 jobs it runs in one); where /proc lists no children, after the first result.
    watch = Path(f"/proc/{proc.pid}/task").is_dir()
    deadline = time.monotonic() + 300
    children: list[int] = []
    while time.monotonic() < deadline and proc.poll() is None:
        children = _descendants(proc.pid)
        worker = any("drivehierarchy.benchmark.r4.workers" in _cmdline(c) for c in children)
        if len(_keys(out)) >= 1 and (worker or not watch):
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be killed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 30
    while any(map(_running, children)) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(map(_running, children)), "the killed harness's worker processes exit with it"
    before = _keys(out)
    assert 1 <= len(before) < 3
    mtimes = {k: (out / "scenes" / k / "scene_score.json").stat().st_mtime_ns for k in before}

    again = subprocess.run(
        _cmd(server_url, suite_dir, out, extra), capture_output=True, text=True, timeout=600
    )
    assert again.returncode == 0, again.stderr
    assert again.stdout.count("done before, skipped") == len(before)
    after = _keys(out)
    assert after[: len(before)] == before and sorted(after) == sorted(set(after)) and len(after) == 3
    for k, t in mtimes.items():  # finished scenarios were not redone
        assert (out / "scenes" / k / "scene_score.json").stat().st_mtime_ns == t
    assert json.loads((out / "summary.json").read_text()) == json.loads((whole / "summary.json").read_text())
    for k in after:
        assert (out / "scenes" / k / "decisions.jsonl").read_text().count("\n") == json.loads(
            (out / "scenes" / k / "scene_score.json").read_text()
        )["decisions"]
        # Every request as the uninterrupted run's (texts, image counts, history offsets, replies).
        assert _decisions(out / "scenes" / k / "decisions.jsonl") == _decisions(
            whole / "scenes" / k / "decisions.jsonl"
        )
