"""Resumable open-loop prediction runner (`drivehierarchy openloop predict`).

Output layout (the contract the scorer reads):

    OUT/manifest.json                   run manifest (version, git commit, config, data hashes, times)
    OUT/predictions/<file_stem>.jsonl   one JSON object per line, appended and flushed per record
    OUT/errors.jsonl                    typed failure records (not predictions, so resume retries them)

A prediction line is `{"id", "task", "prediction", "record", "model", "latency_s", "usage"}` plus
the original runner's fields (`Question_id`/`task_id`, `question`, `ground_truth`,
`model_prediction`, `ground_truth_order` for R3_2), so the original scorer reads it too.
Kill the process at any moment: a restart drops a torn last line, skips ids already present and
sends only the rest, so predict → kill → predict gives the same predictions as one run.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import IO, Any

from drivehierarchy import ConfigError
from drivehierarchy._manifest import git_commit

from .catalog import (
    Catalog,
    ImageRootMap,
    LoadedDataset,
    default_catalog,
    load_catalog,
    load_dataset,
    select_datasets,
)
from .client import ChatClient, DecodingConfig, ImageError, RequestFailure, image_data_url
from .prompts import build_messages, question_text
from .records import SEQUENCE_ORDER, Record

MANIFEST_VERSION = 1


def utc_now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


@dataclass(frozen=True)
class RunConfig:
    """Everything `predict` needs. Exactly one of `data_dir` / `catalog` is set."""

    base_url: str
    model: str
    out: Path
    datasets: str = "all"
    data_dir: Path | None = None
    catalog: Path | None = None
    image_roots: tuple[str, ...] = ()
    concurrency: int = 64
    limit: int | None = None
    api_key_env: str | None = None
    decoding: DecodingConfig = field(default_factory=DecodingConfig)
    timeout_s: float = 300.0
    max_retries: int = 6
    backoff_s: float = 0.5  # first retry delay; doubles per attempt (capped at 30 s)
    progress: bool = True

    def __post_init__(self) -> None:
        if (self.data_dir is None) == (self.catalog is None):
            raise ConfigError("give exactly one of --data-dir DIR or --catalog FILE")
        if self.concurrency < 1:
            raise ConfigError(f"--concurrency must be >= 1, got {self.concurrency}")
        if self.limit is not None and self.limit < 0:
            raise ConfigError(f"--limit must be >= 0, got {self.limit}")
        if not self.model:
            raise ConfigError("--model must not be empty")

    def load_catalog(self) -> Catalog:
        if self.catalog is not None:
            return load_catalog(self.catalog)
        assert self.data_dir is not None
        return default_catalog(self.data_dir)

    def manifest_config(self) -> dict[str, Any]:
        d = asdict(self)
        for key in ("out", "data_dir", "catalog"):
            d[key] = None if d[key] is None else str(d[key])
        d["image_roots"] = list(self.image_roots)
        d.pop("progress")
        return d


@dataclass
class RunSummary:
    out: Path
    total: int = 0  # records selected
    already_done: int = 0  # found in predictions at start
    written: int = 0  # new predictions this session
    failed: int = 0  # failure records this session
    elapsed_s: float = 0.0
    interrupted: bool = False

    @property
    def complete(self) -> bool:
        return self.already_done + self.written == self.total


# --- prediction files ----------------------------------------------------------------------------


def read_done_ids(path: Path, repair: bool = True) -> set[str]:
    """Ids already predicted in `path`. A torn last line (no trailing newline, or not JSON)
    left by a kill is cut off when `repair` so the next append starts on a clean line."""
    if not path.exists():
        return set()
    data = path.read_bytes()
    done: set[str] = set()
    end_ok = data.rfind(b"\n") + 1  # bytes up to the last complete line
    if repair:
        _cut_torn_tail(path, data)
    for line in data[:end_ok].splitlines():
        if not line.strip():
            continue
        try:
            obj = json.loads(line)
        except json.JSONDecodeError:
            continue  # a damaged line does not count as done; the record is asked again
        if (
            isinstance(obj, dict)
            and isinstance(obj.get("id"), str)
            and isinstance(obj.get("prediction"), str)
        ):
            done.add(obj["id"])
    return done


def _cut_torn_tail(path: Path, data: bytes | None = None) -> None:
    """Truncate `path` after its last newline (a line torn by a kill has none)."""
    if data is None:
        if not path.exists():
            return
        data = path.read_bytes()
    end_ok = data.rfind(b"\n") + 1
    if end_ok < len(data):
        with open(path, "r+b") as fh:
            fh.truncate(end_ok)


def original_fields(rec: Record, text: str) -> dict[str, Any]:
    """The original runner's fields of a prediction line, as it writes them: `Question_id`
    (plus `task_id` or `id` when that is the record's id field), `question` (the record's own,
    else the text sent), `ground_truth` (the task's target field as is), `model_prediction`,
    and `ground_truth_order` for ordering tasks. With them the original scorer reads our files."""
    id_key = next((k for k in ("Question_id", "task_id", "id") if k in rec.raw), "id")
    out: dict[str, Any] = {"Question_id": rec.id}
    if id_key != "Question_id":
        out[id_key] = rec.id
    out["question"] = rec.question or question_text(rec)
    out["ground_truth"] = rec.ground_truth
    out["model_prediction"] = text
    if rec.kind == SEQUENCE_ORDER and rec.raw.get("ground_truth_order") is not None:
        out["ground_truth_order"] = rec.raw["ground_truth_order"]
    return out


def prediction_line(rec: Record, text: str, model: str, latency_s: float, usage: dict[str, Any]) -> str:
    obj = {
        "id": rec.id,
        "task": rec.task,
        "prediction": text,
        "record": rec.raw,
        "model": model,
        "latency_s": round(latency_s, 4),
        "usage": usage,
        **original_fields(rec, text),
    }
    return json.dumps(obj, ensure_ascii=False) + "\n"


def failure_record(rec_id: str | None, task: str, kind: str, detail: str, **extra: Any) -> dict[str, Any]:
    return {"id": rec_id, "task": task, "kind": kind, "detail": detail, "time": utc_now(), **extra}


class _Appender:
    """Append-only line writer shared by worker threads; every line is flushed."""

    def __init__(self, path: Path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._fh: IO[str] = open(path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()
        self._lock = threading.Lock()

    def write(self, line: str) -> None:
        with self._lock:
            self._fh.write(line)
            self._fh.flush()

    def close(self) -> None:
        with self._lock:
            self._fh.close()


# --- manifest ------------------------------------------------------------------------------------


def _write_json_atomic(path: Path, obj: Any) -> None:
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=2, ensure_ascii=False) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def _check_resume(manifest_path: Path, config: RunConfig) -> dict[str, Any] | None:
    if not manifest_path.exists():
        return None
    try:
        old = json.loads(manifest_path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{manifest_path}: unreadable manifest ({exc}); use a new --out") from exc
    if old.get("model") != config.model or old.get("decoding") != asdict(config.decoding):
        raise ConfigError(
            f"{manifest_path}: --out already holds a run of model {old.get('model')!r} with decoding "
            f"{old.get('decoding')}; resuming it with model {config.model!r} and decoding "
            f"{asdict(config.decoding)} would mix runs. Use a new --out."
        )
    manifest: dict[str, Any] = old
    return manifest


# --- the run -------------------------------------------------------------------------------------


class _Progress:
    def __init__(self, total: int, enabled: bool):
        self.total = total
        self.enabled = enabled
        self.done = 0
        self.failed = 0
        self.start = time.monotonic()
        self._last = 0.0
        self._tty = sys.stderr.isatty()
        self._lock = threading.Lock()

    def update(self, ok: bool, force: bool = False) -> None:
        with self._lock:
            if ok:
                self.done += 1
            else:
                self.failed += 1
            self._render(force)

    def _render(self, force: bool) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last < (0.25 if self._tty else 10.0):
            return
        self._last = now
        n = self.done + self.failed
        rate = n / max(now - self.start, 1e-9)
        left = (self.total - n) / rate if rate > 0 else float("inf")
        eta = time.strftime("%H:%M:%S", time.gmtime(left)) if left != float("inf") else "--:--:--"
        pct = 100.0 * n / self.total if self.total else 100.0
        line = (
            f"predict {n}/{self.total} ({pct:5.1f}%) ok={self.done} failed={self.failed} "
            f"{rate:6.1f} req/s eta {eta}"
        )
        sys.stderr.write(("\r" + line) if self._tty else (line + "\n"))
        sys.stderr.flush()

    def finish(self) -> None:
        if self.enabled:
            with self._lock:
                self._render(force=True)
            if self._tty:
                sys.stderr.write("\n")


def _predict_one(client: ChatClient, rec: Record) -> tuple[str, float, dict[str, Any]]:
    if not rec.images:
        raise ImageError("no_images", "", "record lists no images")
    urls: dict[str, str] = {}
    for img in rec.images:
        if img.path not in urls:
            urls[img.path] = image_data_url(img.path)
    messages = build_messages(rec, lambda img: urls[img.path])
    completion = client.complete(messages)
    return completion.text, completion.latency_s, {**completion.usage, "attempts": completion.attempts}


def predict(config: RunConfig) -> RunSummary:
    """Run (or resume) predictions for the selected datasets; returns counts for this session."""
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / "manifest.json"
    old_manifest = _check_resume(manifest_path, config)

    api_key = None
    if config.api_key_env:
        api_key = os.environ.get(config.api_key_env)
        if not api_key:
            raise ConfigError(f"--api-key-env: environment variable {config.api_key_env!r} is not set")

    catalog = config.load_catalog()
    specs = select_datasets(catalog, config.datasets)
    roots = ImageRootMap.parse(config.image_roots)
    loaded: list[LoadedDataset] = [load_dataset(catalog, s, roots, config.limit) for s in specs]
    client = ChatClient(
        config.base_url,
        config.model,
        api_key=api_key,
        decoding=config.decoding,
        timeout_s=config.timeout_s,
        max_retries=config.max_retries,
        backoff_s=config.backoff_s,
    )

    summary = RunSummary(out=out)
    session: dict[str, Any] = {"started_at": utc_now(), "finished_at": None, "status": "running"}
    manifest: dict[str, Any] = {
        "version": MANIFEST_VERSION,
        "drivehierarchy_version": _package_version(),
        "git_commit": git_commit(),
        "model": config.model,
        "base_url": config.base_url,
        "decoding": asdict(config.decoding),
        "config": config.manifest_config(),
        "catalog": {"name": catalog.name, "root": str(catalog.root)},
        "data_files": {
            ld.spec.name: {
                "path": str(ld.path),
                "sha256": ld.sha256,
                "task": ld.spec.task,
                "kind": ld.spec.kind,
            }
            for ld in loaded
        },
        "started_at": (old_manifest or {}).get("started_at", session["started_at"]),
        "finished_at": None,
        "sessions": [*(old_manifest or {}).get("sessions", []), session],
    }
    _write_json_atomic(manifest_path, manifest)

    _cut_torn_tail(out / "errors.jsonl")
    errors = _Appender(out / "errors.jsonl")
    writers: dict[str, _Appender] = {}
    pending: list[tuple[Record, _Appender]] = []
    try:
        for ld in loaded:
            for issue in ld.issues:
                errors.write(
                    json.dumps(
                        failure_record(
                            issue.id, issue.task, "malformed_record", issue.detail, line=issue.line
                        )
                    )
                    + "\n"
                )
            pred_path = out / "predictions" / f"{ld.spec.name}.jsonl"
            done = read_done_ids(pred_path)
            summary.total += len(ld.records)
            todo = [r for r in ld.records if r.id not in done]
            summary.already_done += len(ld.records) - len(todo)
            if todo:
                writers[ld.spec.name] = _Appender(pred_path)
                pending.extend((r, writers[ld.spec.name]) for r in todo)

        progress = _Progress(len(pending), config.progress)
        start = time.monotonic()
        counts_lock = threading.Lock()

        def job(rec: Record, writer: _Appender) -> None:
            try:
                text, latency, usage = _predict_one(client, rec)
            except ImageError as exc:
                errors.write(
                    json.dumps(failure_record(rec.id, rec.task, exc.kind, exc.detail, path=exc.path)) + "\n"
                )
                ok = False
            except RequestFailure as exc:
                errors.write(
                    json.dumps(
                        failure_record(
                            rec.id, rec.task, exc.kind, exc.detail, status=exc.status, attempts=exc.attempts
                        )
                    )
                    + "\n"
                )
                ok = False
            else:
                writer.write(prediction_line(rec, text, config.model, latency, usage))
                ok = True
            with counts_lock:
                if ok:
                    summary.written += 1
                else:
                    summary.failed += 1
            progress.update(ok)

        # Bounded submission: at most 2×concurrency jobs queued, so memory stays flat on 76k items.
        with ThreadPoolExecutor(max_workers=config.concurrency, thread_name_prefix="olrun") as pool:
            inflight: set[Future[None]] = set()
            try:
                for rec, writer in pending:
                    if len(inflight) >= 2 * config.concurrency:
                        finished, inflight = wait(inflight, return_when=FIRST_COMPLETED)
                        for f in finished:
                            f.result()
                    inflight.add(pool.submit(job, rec, writer))
                for f in inflight:
                    f.result()
            except KeyboardInterrupt:
                summary.interrupted = True
                for f in inflight:
                    f.cancel()
                raise
        progress.finish()
        summary.elapsed_s = time.monotonic() - start
    finally:
        for w in writers.values():
            w.close()
        errors.close()
        session["finished_at"] = utc_now()
        session["status"] = "interrupted" if summary.interrupted else "finished"
        session.update(
            total=summary.total,
            already_done=summary.already_done,
            written=summary.written,
            failed=summary.failed,
        )
        manifest["finished_at"] = session["finished_at"]
        manifest["complete"] = summary.complete
        with contextlib.suppress(OSError):
            _write_json_atomic(manifest_path, manifest)
    return summary


def _package_version() -> str | None:
    try:
        from drivehierarchy import __version__

        return str(__version__)
    except ImportError:  # pragma: no cover - the extension always provides it
        return None
