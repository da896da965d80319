from __future__ import annotations

import shutil
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SUITE = REPO / "scenarios" / "r4"
MAPS = REPO / "scenarios" / "maps"
BASE = "http://127.0.0.1:8765"
ORIGIN = {"Origin": BASE}


@pytest.fixture
def workspace(tmp_path: Path) -> Path:
    """A root folder laid out like the repo's scenarios/: r4/<category>/*.toml beside maps/."""
    root = tmp_path / "scenarios"
    shutil.copytree(SUITE / "01_pedestrian", root / "r4" / "01_pedestrian")
    shutil.copytree(SUITE / "07_sudden_brake", root / "r4" / "07_sudden_brake")
    (root / "maps").mkdir()
    (root / "maps" / "town01").symlink_to(MAPS / "town01")
    return root


@pytest.fixture
def client(workspace: Path):
    from starlette.testclient import TestClient

    from drivehierarchy.editor import create_app

    app = create_app(workspace / "r4", "builtin:town01", max_body_bytes=200_000, precompute=False)
    with TestClient(app, base_url=BASE) as c:
        yield c
