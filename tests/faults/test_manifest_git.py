"""The manifest's git commit: one helper for both runners, never failing the manifest write."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from drivehierarchy import _manifest
from drivehierarchy.benchmark.openloop import runner as openloop_runner
from drivehierarchy.benchmark.r4 import store
from drivehierarchy.benchmark.r4.jobs import RunOptions, jobs_for
from drivehierarchy.scenarios import builtin_scenarios


def test_both_runners_use_the_one_helper() -> None:
    assert store.git_commit is _manifest.git_commit
    assert openloop_runner.git_commit is _manifest.git_commit


@pytest.mark.parametrize(
    "failure",
    [subprocess.TimeoutExpired(["git"], 5), FileNotFoundError("git"), PermissionError("git")],
    ids=["timeout", "no-git", "not-executable"],
)
def test_a_git_that_hangs_or_is_absent_gives_none_and_the_manifest_is_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, failure: Exception
) -> None:
    def run(*args: object, **kwargs: object) -> object:
        raise failure

    monkeypatch.setattr(_manifest.subprocess, "run", run)
    assert _manifest.git_commit() is None
    opts = RunOptions()
    store.write_manifest(tmp_path, jobs_for(builtin_scenarios()[:1]), opts)
    assert json.loads((tmp_path / "manifest.json").read_text())["git_commit"] is None


def test_outside_a_checkout_it_is_none(monkeypatch: pytest.MonkeyPatch) -> None:
    def run(*args: object, **kwargs: object) -> subprocess.CompletedProcess[str]:
        return subprocess.CompletedProcess(args, 128, stdout="", stderr="fatal: not a git repository")

    monkeypatch.setattr(_manifest.subprocess, "run", run)
    assert _manifest.git_commit() is None
