"""An R4 run's files: the append-only results log (flushed and synced per line, torn lines
skipped), the manifest, atomic JSON/text writes and the per-scenario folders."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from drivehierarchy import __version__
from drivehierarchy._core import ConfigError
from drivehierarchy._manifest import git_commit
from drivehierarchy.benchmark.r4.jobs import Job, RunOptions


def read_results(out: Path) -> dict[str, dict[str, Any]]:
    """Finished scenarios of a run by key; a torn last line (killed mid-write) is ignored."""
    return read_jsonl_by_key(out / "results.jsonl")


def read_jsonl_by_key(path: Path) -> dict[str, dict[str, Any]]:
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
            done.setdefault(rec["key"], rec)
    return done


def append_line(path: Path, record: dict[str, Any]) -> None:
    data = json.dumps(record, sort_keys=True) + "\n"
    # A line torn by a kill is closed first (and then skipped as invalid JSON), never extended.
    if path.exists() and path.stat().st_size > 0:
        with path.open("rb") as fh:
            fh.seek(-1, os.SEEK_END)
            if fh.read(1) != b"\n":
                data = "\n" + data
    with path.open("a", encoding="utf-8") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())


def write_json_atomic(path: Path, obj: Any) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def write_manifest(out: Path, jobs: list[Job], opts: RunOptions) -> None:
    manifest = {
        "drivehierarchy_version": __version__,
        "git_commit": git_commit(),
        "agent": opts.agent,
        "seed": opts.seed,
        "seeds": opts.seed_list(),
        "identity": opts.identity(),
        "vlm": opts.vlm.manifest() if opts.vlm is not None else None,
        "jobs": opts.jobs,
        "ray_address": opts.ray_address,
        "config": json.loads(opts.config.to_json()),
        "scenarios": {
            j.key: {"path": str(j.scenario), "sha256": _sha256(j.scenario), "seed": j.seed} for j in jobs
        },
        "python": sys.version.split()[0],
        "started_unix": time.time(),
    }
    path = out / "manifest.json"
    old = check_manifest(out, opts)
    if old is not None:
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
