"""Shared fixtures: where the original release's reference files live (read-only), one pool of
worker processes, and the reference policies' episodes over the suite (driven once per session)."""

from __future__ import annotations

import multiprocessing as mp
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
# The original release's reference files sit beside the checkout, never inside it.
OFFICIAL_DIR = REPO_ROOT.parent / "shared" / "official"
# Worker processes for the suite-wide tests: the CI machine has 2 cores.
WORKERS = 2


def _require_official(path: Path = OFFICIAL_DIR, what: str = "original release files") -> Path:
    """`path` (under `../shared/official`) if it exists. Absent: the test skips with one line —
    except in CI (`CI=true`), where the files are provisioned and their absence is a failure."""
    if path.exists():
        return path
    message = f"{what} not found at {path}"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{message} (CI=true: they must be present)", pytrace=False)
    pytest.skip(message)


@pytest.fixture(scope="session")
def require_official() -> Any:
    """The check every test needing `../shared/official` uses: `require_official(path, what)`."""
    return _require_official


@pytest.fixture(scope="session")
def official_dir() -> Path:
    """`../shared/official` relative to the repository root (see `_require_official`)."""
    return _require_official()


@pytest.fixture(scope="session")
def openloop_data_dir(official_dir: Path) -> Path:
    """The released open-loop sample records (`Open_Loop_Evaluation/*.jsonl`)."""
    return _require_official(official_dir / "Open_Loop_Evaluation", "open-loop sample records")


@pytest.fixture(scope="session")
def worker_pool() -> Iterator[ProcessPoolExecutor]:
    """Spawned worker processes (one episode at a time each, so SUMO's one-simulation-per-process
    libsumo is fine), shared by every test that drives the whole suite."""
    with ProcessPoolExecutor(max_workers=WORKERS, mp_context=mp.get_context("spawn")) as pool:
        yield pool


@pytest.fixture(scope="session")
def reference_rows() -> list[dict[str, Any]]:
    """The expert of `drivehierarchy scenario probe` over every built-in scenario, seed 0,
    state-only: driven once per test session and shared by every test that needs them. (The bad
    reference drivers' rows are the committed probe's, which tests/scenarios/test_suite.py checks
    and re-drives in part; no test here reads them live, so they are not driven again.)"""
    from drivehierarchy import suite_probe
    from drivehierarchy.scenarios import builtin_scenarios, sumo_home

    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    rows = suite_probe.probe(builtin_scenarios(), cells=("expert",), seeds=(0,), jobs=WORKERS, progress=False)
    # `policy` names the reference driver as tests read it (the probe's cell).
    return [{**r, "policy": r["cell"]} for r in rows]


# The files that take the most CPU in the gate, longest first, run before all others. With
# `--dist loadfile` a file is one unit of work on one worker; a long file started last keeps one
# worker busy while the others are done, and longest-first keeps the workers' end times close.
# (CPU-seconds per file, its processes included, read from /proc; order only, never skips.)
HEAVY_FIRST = (
    "tests/docs/test_docs_commands_run.py",  # ~165 CPU-s: every documented command as a process
    "tests/fuzz/test_agent_fuzz.py",  # ~110: 1,340 bad-driver episodes
    "tests/editor/test_e2e.py",  # ~90: Chromium and the editor server
    "tests/scripts/test_scripts_quick.py",  # ~65
    "tests/baselines/test_end_to_end.py",  # ~50: training runs
    "tests/openloop/generate/test_generate.py",  # ~45: whole generated sets
    "tests/vlm/test_transformers_serve.py",  # ~30
    "tests/baselines/test_baselines_action_levels.py",
    "tests/vlm/test_vlm_sumo_workers.py",
    "tests/vlm/test_vlm_kill_resume.py",
    "tests/vlm/test_vlm_evaluate.py",
    "tests/benchmark/test_hierarchy.py",
    "tests/envs/test_r4_env.py",  # the expert over the suite
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    rank = {name: i for i, name in enumerate(HEAVY_FIRST)}
    last = len(rank)
    # A stable sort: each file's tests keep their order and stay together.
    items.sort(key=lambda item: rank.get(item.path.relative_to(REPO_ROOT).as_posix(), last))
