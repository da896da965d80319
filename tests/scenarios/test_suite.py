"""The shipped R4 suite (issue 9): shape, validity, solvability and discrimination.

The discrimination test runs the four reference policies of `drivehierarchy scenario probe` over
all 100 scenarios (state-only, in worker processes) and checks the must-holds, then checks that
`docs/suite.md` publishes exactly the measured table (so the published numbers cannot go stale).
"""

from __future__ import annotations

import re
import tomllib
from collections import Counter
from pathlib import Path

import pytest

from drivehierarchy import _core, suite_probe
from drivehierarchy.scenarios import builtin_root, sumo_home

SUITE = builtin_root() / "r4"
DOC = Path(__file__).resolve().parents[2] / "docs" / "suite.md"
CATEGORIES = [
    "01_pedestrian",
    "02_obstacles",
    "03_turning",
    "04_intersection",
    "05_t_intersection",
    "06_traffic_flow",
    "07_sudden_brake",
    "08_merging",
    "09_yielding",
    "10_roundabout",
]
HAZARD = ["01_pedestrian", "02_obstacles", "04_intersection", "07_sudden_brake", "09_yielding"]
# Real-world city networks shipped inside eclipse-sumo (OpenStreetMap / survey based). The
# synthetic ones there (grid6, square, ...) do not count.
REAL_WORLD_SUMO = {
    "tools/game/fkk_in/ingolstadt.net.xml.gz",
    "tools/game/bs3d/bs.net.xml",
    "tools/game/A10KW/osm.net.xml",
    "tools/game/DRT/osm.net.xml",
}

# Project maps cut from a real-world network (scenarios/maps/README.md says from which).
REAL_WORLD_PROJECT = {"bs3d_arterial"}

FILES = sorted(SUITE.glob("*/*.toml"))


def _doc(path: Path) -> dict:
    return tomllib.loads(path.read_text(encoding="utf-8"))


def _is_real_world(path: Path, map_ref: str) -> bool:
    if map_ref.startswith("sumo:"):
        return map_ref.removeprefix("sumo:") in REAL_WORLD_SUMO
    folder = (path.parent / map_ref).resolve().parent.name
    # A project map imported from OpenStreetMap keeps "osm" in its folder name.
    return "osm" in folder or folder in REAL_WORLD_PROJECT


def test_suite_shape() -> None:
    per = Counter(f.parent.name for f in FILES)
    assert sorted(per) == CATEGORIES, per
    assert all(n == 10 for n in per.values()), per
    ids, maps, real_world_categories = [], set(), set()
    for f in FILES:
        doc = _doc(f)
        assert doc["id"] == f.stem, f"{f}: id {doc['id']!r} must equal the file stem"
        assert doc["category"] == f.parent.name, f
        assert doc.get("description", "").strip(), f"{f}: a one-line description"
        assert "\n" not in doc["description"], f
        ids.append(doc["id"])
        map_ref = doc["map"]
        maps.add(map_ref if map_ref.startswith("sumo:") else (f.parent / map_ref).resolve().name)
        if _is_real_world(f, map_ref):
            real_world_categories.add(doc["category"])
    assert len(set(ids)) == len(ids) == 100
    assert len(maps) >= 3, maps
    assert len(real_world_categories) >= 2, real_world_categories


@pytest.mark.parametrize("path", FILES, ids=[f.stem for f in FILES])
def test_validates(path: Path) -> None:
    _core.validate_scenario(str(path), sumo_home())


@pytest.fixture(scope="module")
def probe_rows() -> list[dict]:
    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    return suite_probe.probe(FILES, seed=0, jobs=2, progress=False)


def test_solvable_and_discriminating(probe_rows: list[dict]) -> None:
    assert len(probe_rows) == 4 * len(FILES)
    assert all(r["termination"] for r in probe_rows), "every episode runs to a termination"
    s = suite_probe.summarize(probe_rows)
    cats = s["categories"]
    low = {c: round(v["expert"], 1) for c, v in cats.items() if v["expert"] < 90.0}
    assert not low, f"expert below 90 in {low}"
    assert s["completed"].get("expert", 0) >= 95
    assert s["overall"]["zero"] <= 20.0
    assert s["overall"]["constant"] <= 20.0
    assert s["overall"]["follower"] <= 50.0
    high = {c: round(cats[c]["follower"], 1) for c in HAZARD if cats[c]["follower"] >= 60.0}
    assert not high, f"the hazard-blind follower scores ≥ 60 in {high}"


def test_docs_publish_the_measured_table(probe_rows: list[dict]) -> None:
    s = suite_probe.summarize(probe_rows)
    text = DOC.read_text(encoding="utf-8")
    for c in CATEGORIES:
        m = re.search(rf"^\| {c} \| 10 \| (.+) \|$", text, re.M)
        assert m, f"docs/suite.md: no table row for {c}"
        published = [float(x) for x in m.group(1).split(" | ")]
        measured = [round(s["categories"][c][p], 1) for p in suite_probe.POLICIES]
        assert published == pytest.approx(measured, abs=0.051), c


def test_episodes_are_deterministic() -> None:
    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    one_per_category = [sorted(SUITE.glob(f"{c}/*.toml"))[-1] for c in CATEGORIES]
    for path in one_per_category:
        a = suite_probe.run_one(str(path), "expert", 3, None)
        b = suite_probe.run_one(str(path), "expert", 3, None)
        assert {k: v for k, v in a.items() if k != "wall_s"} == {k: v for k, v in b.items() if k != "wall_s"}
