"""Shared fixtures: where the original release's reference files live (read-only)."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
# The original release's reference files sit beside the checkout, never inside it.
OFFICIAL_DIR = REPO_ROOT.parent / "shared" / "official"


@pytest.fixture(scope="session")
def official_dir() -> Path:
    """`../shared/official` relative to the repository root; skips the test when absent."""
    if not OFFICIAL_DIR.is_dir():
        pytest.skip(f"original release files not found at {OFFICIAL_DIR}")
    return OFFICIAL_DIR


@pytest.fixture(scope="session")
def openloop_data_dir(official_dir: Path) -> Path:
    """The released open-loop sample records (`Open_Loop_Evaluation/*.jsonl`)."""
    path = official_dir / "Open_Loop_Evaluation"
    if not path.is_dir():
        pytest.skip(f"open-loop sample records not found at {path}")
    return path
