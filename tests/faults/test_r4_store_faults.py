"""A results write that fails (disk full, I/O error): a clear error naming the file and the
scenario, and nothing half-written left behind (the write and the sync are made to fail)."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest

from drivehierarchy.benchmark.r4 import runner, store
from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root

PEDESTRIAN = sorted((builtin_root() / "r4" / "01_pedestrian").glob("*.toml"))[0]
ENOSPC = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.mark.parametrize("where", ["write", "fsync"])
def test_a_failed_append_leaves_the_file_as_it_was(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, where: str
) -> None:
    path = tmp_path / "results.jsonl"
    store.append_line(path, {"key": "a", "score": 1})
    before = path.read_bytes()
    real_write = os.write
    if where == "write":
        state = {"calls": 0}

        def write(fd: int, data: bytes) -> int:
            state["calls"] += 1
            if state["calls"] == 1:
                return real_write(fd, bytes(data[: len(data) // 2]))
            raise ENOSPC

        monkeypatch.setattr(store.os, "write", write)
    else:

        def fsync(fd: int) -> None:
            raise OSError(errno.EIO, "Input/output error")

        monkeypatch.setattr(store.os, "fsync", fsync)
    with pytest.raises(store.ResultWriteError, match=r"results.jsonl: could not record scenario 'b'"):
        store.append_line(path, {"key": "b", "score": 2})
    assert path.read_bytes() == before
    monkeypatch.undo()
    store.append_line(path, {"key": "b", "score": 2})
    assert [json.loads(x)["key"] for x in path.read_text().splitlines()] == ["a", "b"]


def test_a_failed_atomic_write_keeps_the_old_file_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "summary.json"
    store.write_json_atomic(path, {"old": True})

    def replace(src: object, dst: object) -> None:
        raise ENOSPC

    monkeypatch.setattr(store.os, "replace", replace)
    with pytest.raises(store.ResultWriteError, match=r"summary\.json: could not write"):
        store.write_json_atomic(path, {"new": True})
    assert json.loads(path.read_text()) == {"old": True}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.json"]


def test_a_full_disk_stops_the_run_with_a_clear_message_and_a_resume_completes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "run"
    args = ["r4", "evaluate", "--agent", "expert", "--suite", str(PEDESTRIAN), "--out", str(out)]
    real_fsync = os.fsync

    def fsync(fd: int) -> None:
        results = out / "results.jsonl"
        if results.exists() and os.fstat(fd).st_ino == results.stat().st_ino:
            raise ENOSPC
        real_fsync(fd)

    monkeypatch.setattr(store.os, "fsync", fsync)
    assert main(args) == 2
    err = capsys.readouterr().err
    key = runner.scenario_key(PEDESTRIAN)
    assert f"results.jsonl: could not record scenario '{key}' (OSError: [Errno {errno.ENOSPC}]" in err
    assert (out / "results.jsonl").read_bytes() == b""
    assert not (out / "summary.json").exists()
    monkeypatch.undo()
    assert main(args) == 0
    assert list(runner.read_results(out)) == [key]
