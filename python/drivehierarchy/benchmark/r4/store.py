"""An R4 run's files: the append-only results log (synced per line, torn lines skipped), the
manifest, atomic JSON/text writes and the per-scenario folders.

results.jsonl holds a scenario's results line once it finished, or a failure line (`"termination_reason":
"system_error"`) when infrastructure failed it; the last line of a key wins, and only finished
scenarios count as done, so a resume redoes the failed ones. A write that fails (disk full, I/O
error) raises `ResultWriteError` and leaves no partial line or file behind."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from drivehierarchy import __version__
from drivehierarchy._core import ConfigError, DriveHierarchyError
from drivehierarchy._manifest import git_commit
from drivehierarchy.benchmark.r4.jobs import Job, RunOptions


class ResultWriteError(DriveHierarchyError):
    """A run's file could not be written (disk full, I/O error); nothing partial was left behind.
    The batch stops: nothing more could be recorded."""


def read_results(out: Path) -> dict[str, dict[str, Any]]:
    """Finished scenarios of a run by key (a later line for a key wins; failure lines and a torn
    last line, killed mid-write, do not count)."""
    return {k: r for k, r in read_jsonl_by_key(out / "results.jsonl").items() if not is_failure(r)}


def read_failures(out: Path) -> dict[str, dict[str, Any]]:
    """Scenarios whose last results line is a failure (redone on resume)."""
    return {k: r for k, r in read_jsonl_by_key(out / "results.jsonl").items() if is_failure(r)}


def is_failure(line: dict[str, Any]) -> bool:
    return "system_error" in line


def read_jsonl_by_key(path: Path) -> dict[str, dict[str, Any]]:
    """The last complete line of every key."""
    done: dict[str, dict[str, Any]] = {}
    if not path.exists():
        return done
    with path.open("r", encoding="utf-8") as fh:
        for line in fh:
            if not line.endswith("\n"):
                break  # torn write: the scenario is redone
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                continue
            done[rec["key"]] = rec
    return done


def append_line(path: Path, record: dict[str, Any]) -> None:
    """Appends one JSON line and syncs it to disk; on failure the file is cut back to what it was."""
    data = (json.dumps(record, sort_keys=True) + "\n").encode("utf-8")
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_APPEND, 0o644)
    except OSError as exc:
        raise _write_error(path, record, exc) from exc
    try:
        size = os.fstat(fd).st_size
        if size > 0 and os.pread(fd, 1, size - 1) != b"\n":
            # A line torn by a kill is closed first (and then skipped as invalid JSON), never extended.
            data = b"\n" + data
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            os.fsync(fd)
        except OSError as exc:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, size)  # no partial line stays behind
                os.fsync(fd)
            raise _write_error(path, record, exc) from exc
    finally:
        os.close(fd)


def _write_error(path: Path, record: dict[str, Any], exc: OSError) -> ResultWriteError:
    return ResultWriteError(
        f"{path}: could not record scenario {record.get('key')!r} ({type(exc).__name__}: {exc}); "
        "the file is left as it was. Free space or fix the disk, then run the same command again "
        "to resume."
    )


def write_json_atomic(path: Path, obj: Any) -> None:
    write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True) + "\n")


def write_text_atomic(path: Path, text: str) -> None:
    """Writes a whole file or nothing: a temporary file renamed over `path`."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise ResultWriteError(
            f"{path}: could not write ({type(exc).__name__}: {exc}); the file is left as it was"
        ) from exc


def sha256_of(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_manifest(out: Path, jobs: list[Job], opts: RunOptions) -> None:
    manifest: dict[str, Any] = {
        "drivehierarchy_version": __version__,
        "git_commit": git_commit(),
        "agent": opts.agent,
        "seed": opts.seed,
        "seeds": opts.seed_list(),
        "identity": opts.identity(),
        "vlm": opts.vlm.manifest() if opts.vlm is not None else None,
        # action_level: "control" is the paper's protocol; "waypoints" and "meta" are this
        # project's extension. inputs: history and memory beyond the paper's one turn.
        **opts.run_facts(),
        "controls": opts.controls(),
        "jobs": opts.jobs,
        "ray_address": opts.ray_address,
        "config": opts.config.to_core(),
        "scenarios": {
            j.key: {"path": str(j.scenario), "sha256": sha256_of(j.scenario), "seed": j.seed} for j in jobs
        },
        "python": sys.version.split()[0],
        "started_unix": time.time(),
    }
    path = out / "manifest.json"
    old = check_manifest(out, opts)
    if old is not None:
        # Scenarios of earlier invocations into this directory keep their entries.
        manifest["scenarios"] = {**old.get("scenarios", {}), **manifest["scenarios"]}
        manifest["started_unix"] = old.get("started_unix", manifest["started_unix"])
        manifest["resumed_unix"] = time.time()
    write_json_atomic(path, manifest)


def check_manifest(out: Path, opts: RunOptions) -> dict[str, Any] | None:
    """The existing manifest of `out`, if any; refuses a directory of another run."""
    path = out / "manifest.json"
    if not path.exists():
        return None
    old: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    old_ident = old.get("identity", {"agent": old.get("agent"), "seeds": [old.get("seed")]})
    ident = opts.identity()
    if old_ident != ident:
        a, b = _flatten(old_ident), _flatten(ident)
        diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
        raise ConfigError(
            f"{path}: field `{'/'.join(diff)}` = {[a.get(k) for k in diff]!r}: this output "
            f"directory belongs to another run (asked: {[b.get(k) for k in diff]!r}); use a new --out"
        )
    return old


def changed_scenarios(old: dict[str, Any] | None, jobs: list[Job], done: dict[str, Any]) -> list[str]:
    """Keys of finished jobs whose scenario file no longer has the hash the manifest recorded."""
    if old is None:
        return []
    recorded = old.get("scenarios", {})
    return [
        j.key
        for j in jobs
        if j.key in done and j.key in recorded and recorded[j.key].get("sha256") != sha256_of(j.scenario)
    ]


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def fresh_scene_dir(out: Path, job: Job, frames: bool) -> Path:
    """The scenario's directory, emptied: an interrupted scenario is redone from scratch."""
    scene_dir = out / "scenes" / job.key
    if scene_dir.exists():
        shutil.rmtree(scene_dir)
    scene_dir.mkdir(parents=True)
    if frames:
        (scene_dir / "frames").mkdir()
    return scene_dir
