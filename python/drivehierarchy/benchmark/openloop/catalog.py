"""Dataset catalog (the original `open_loop_all.json` format), selection and record loading.

A catalog is `{"name": ..., "root": DIR, "datasets": [{"name", "path", "task"}]}` where `task` is
the answer kind (`yes_no`, `numeric`, ...) and a relative `root` is resolved against the
catalog file's folder. `--data-dir DIR` builds the same catalog in memory for the 14 released
file names. A relative image path in a record (generated sets, `openloop generate`) is resolved
against its task file's folder.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from drivehierarchy import ConfigError

from .records import (
    ANSWER_KINDS,
    TASK_FILE_STEM,
    TASKS,
    ImageRef,
    Record,
    RecordError,
    parse_record,
    task_id_from_name,
)


@dataclass(frozen=True)
class DatasetSpec:
    """One task file of a catalog."""

    name: str  # file stem, e.g. "R1_1_A_Existence"
    path: str  # as written in the catalog (relative to the root, or absolute)
    kind: str  # answer kind
    task: str  # task id ("R1_1_A"), or the name when it starts with no task id


@dataclass(frozen=True)
class Catalog:
    name: str
    root: Path
    datasets: tuple[DatasetSpec, ...]

    def resolve(self, spec: DatasetSpec) -> Path:
        path = Path(spec.path)
        return path if path.is_absolute() else self.root / path


def _spec(name: str, path: str, kind: str) -> DatasetSpec:
    return DatasetSpec(name=name, path=path, kind=kind, task=task_id_from_name(name) or name)


def load_catalog(path: str | Path) -> Catalog:
    """Read a catalog file; errors name the file and the offending field."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read catalog: {exc}") from exc
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{path}: not valid JSON: {exc}") from exc
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: catalog must be a JSON object")
    unknown = set(data) - {"name", "root", "datasets"}
    if unknown:
        raise ConfigError(f"{path}: unknown catalog keys {sorted(unknown)}")
    root = data.get("root", ".")
    if not isinstance(root, str):
        raise ConfigError(f"{path}: field 'root' must be a string, got {root!r}")
    entries = data.get("datasets")
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{path}: field 'datasets' must be a non-empty list")
    specs = []
    seen: set[str] = set()
    for i, entry in enumerate(entries):
        where = f"{path}: datasets[{i}]"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where} must be an object")
        extra = set(entry) - {"name", "path", "task"}
        if extra:
            raise ConfigError(f"{where}: unknown keys {sorted(extra)}")
        for key in ("name", "path", "task"):
            if not isinstance(entry.get(key), str) or not entry[key]:
                raise ConfigError(
                    f"{where}: field {key!r} must be a non-empty string, got {entry.get(key)!r}"
                )
        if entry["task"] not in ANSWER_KINDS:
            raise ConfigError(f"{where}: field 'task' = {entry['task']!r} is not one of {list(ANSWER_KINDS)}")
        if entry["name"] in seen:
            raise ConfigError(f"{where}: duplicate dataset name {entry['name']!r}")
        seen.add(entry["name"])
        specs.append(_spec(entry["name"], entry["path"], entry["task"]))
    root_path = Path(root)
    if not root_path.is_absolute():
        root_path = (path.parent / root_path).resolve()
    return Catalog(name=str(data.get("name", path.stem)), root=root_path, datasets=tuple(specs))


def default_catalog(data_dir: str | Path) -> Catalog:
    """The 14 released task files under `data_dir` (the release's `Open_Loop_Evaluation/`)."""
    return Catalog(
        name="open_loop_all",
        root=Path(data_dir),
        datasets=tuple(_spec(stem, f"{stem}.jsonl", kind) for _, stem, kind, _ in TASKS),
    )


def select_datasets(catalog: Catalog, selection: str | Sequence[str] = "all") -> list[DatasetSpec]:
    """`all`, or task ids / dataset names / file names (comma-separated or a list), in catalog order."""
    tokens = [t.strip() for t in selection.split(",")] if isinstance(selection, str) else list(selection)
    tokens = [t for t in tokens if t]
    if not tokens or [t.lower() for t in tokens] == ["all"]:
        return list(catalog.datasets)
    chosen: set[str] = set()
    for token in tokens:
        hits = [
            d.name
            for d in catalog.datasets
            if token in (d.task, d.name, d.path, Path(d.path).name)
            or (token in TASK_FILE_STEM and d.name == TASK_FILE_STEM[token])
        ]
        if not hits:
            known = ", ".join(d.task for d in catalog.datasets)
            raise ConfigError(
                f"--datasets: {token!r} matches no dataset of catalog {catalog.name!r} ({known})"
            )
        chosen.update(hits)
    return [d for d in catalog.datasets if d.name in chosen]


@dataclass(frozen=True)
class ImageRootMap:
    """`OLD=NEW` prefix rewrites of absolute image paths; the longest matching OLD wins."""

    pairs: tuple[tuple[str, str], ...] = ()

    @classmethod
    def parse(cls, items: Iterable[str] | None) -> ImageRootMap:
        pairs = []
        for item in items or ():
            old, sep, new = item.partition("=")
            if not sep or not old or not new:
                raise ConfigError(f"--image-root: expected OLD=NEW, got {item!r}")
            pairs.append((old.rstrip("/") or "/", new.rstrip("/") or "/"))
        return cls(tuple(sorted(pairs, key=lambda p: len(p[0]), reverse=True)))

    def apply(self, path: str) -> str:
        for old, new in self.pairs:
            if old == "/":
                return new.rstrip("/") + path if path.startswith("/") else path
            if path == old or path.startswith(old + "/"):
                return new + path[len(old) :]
        return path

    def as_strings(self) -> list[str]:
        return [f"{old}={new}" for old, new in self.pairs]


@dataclass(frozen=True)
class LoadIssue:
    """A line of a task file that could not be used (logged as a failure, not predicted)."""

    dataset: str
    task: str
    line: int
    id: str | None
    detail: str


@dataclass
class LoadedDataset:
    spec: DatasetSpec
    path: Path
    records: list[Record] = field(default_factory=list)
    issues: list[LoadIssue] = field(default_factory=list)
    sha256: str = ""


def load_dataset(
    catalog: Catalog, spec: DatasetSpec, image_roots: ImageRootMap | None = None, limit: int | None = None
) -> LoadedDataset:
    """Read one task file unchanged. Undecodable or unusable lines become `LoadIssue`s; a
    duplicate id keeps its first record. `limit` keeps the first N usable records."""
    path = catalog.resolve(spec)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"dataset {spec.name}: cannot read {path}: {exc}") from exc
    out = LoadedDataset(spec=spec, path=path, sha256=hashlib.sha256(data).hexdigest())
    roots = image_roots or ImageRootMap()
    seen: set[str] = set()
    for lineno, line in enumerate(data.decode("utf-8", errors="replace").splitlines(), start=1):
        if limit is not None and len(out.records) >= limit:
            break
        if not line.strip():
            continue
        try:
            raw = json.loads(line)
        except json.JSONDecodeError as exc:
            out.issues.append(LoadIssue(spec.name, spec.task, lineno, None, f"invalid JSON: {exc}"))
            continue
        try:
            rec = parse_record(raw, task=spec.task, kind=spec.kind, dataset=spec.name, line=lineno)
        except RecordError as exc:
            rid = raw.get("Question_id") or raw.get("task_id") if isinstance(raw, dict) else None
            out.issues.append(LoadIssue(spec.name, spec.task, lineno, rid and str(rid), str(exc)))
            continue
        if rec.id in seen:
            out.issues.append(LoadIssue(spec.name, spec.task, lineno, rec.id, "duplicate id; first kept"))
            continue
        seen.add(rec.id)
        if roots.pairs:
            imgs = tuple(ImageRef(roots.apply(i.path), i.label) for i in rec.images)
            rec = Record(**{**rec.__dict__, "images": imgs})
        if any(not os.path.isabs(i.path) for i in rec.images):
            # Relative image paths (generated sets) are relative to the task file's folder.
            imgs = tuple(
                ImageRef(i.path if os.path.isabs(i.path) else str(path.parent / i.path), i.label)
                for i in rec.images
            )
            rec = Record(**{**rec.__dict__, "images": imgs})
        out.records.append(rec)
    return out
