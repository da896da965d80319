"""The shipped R4 suite (issue 9): shape, validity, solvability and discrimination.

The discrimination test runs the four reference policies of `drivehierarchy scenario probe` over
all 100 scenarios (state-only, in worker processes) and checks the must-holds, then checks that
`docs/suite.md` publishes exactly the measured table (so the published numbers cannot go stale).
"""

from __future__ import annotations

import tomllib
from collections import Counter
from pathlib import Path

import pytest

from drivehierarchy import _core, suite_probe
from drivehierarchy.scenarios import builtin_root, sumo_home

SUITE = builtin_root() / "r4"
DOC = Path(__file__).resolve().parents[2] / "docs" / "suite.md"
# The protocol's ten categories, as the Rust scenario reader defines them (its schema's enum).
CATEGORIES = sorted(_core.scenario_json_schema()["properties"]["category"]["enum"])
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


RESULTS = DOC.parent / "suite_probe.csv"


@pytest.fixture(scope="module")
def committed() -> list[dict]:
    return suite_probe.read_results(RESULTS)


def test_committed_results_cover_the_suite(committed: list[dict]) -> None:
    """The committed sweep is complete and was measured on the current scenario files."""
    want = {(f.stem, c, s) for f in FILES for c in suite_probe.SWEEP for s in suite_probe.SEEDS}
    have = [(r["id"], r["cell"], r["seed"]) for r in committed]
    assert len(have) == len(set(have)), "duplicate rows in docs/suite_probe.csv"
    assert not (want - set(have)), f"missing from docs/suite_probe.csv: {sorted(want - set(have))[:5]} …"
    assert not (set(have) - want), f"rows not in the sweep: {sorted(set(have) - want)[:5]} …"
    digest = {f.stem: suite_probe.scenario_digest(f) for f in FILES}
    stale = sorted({r["id"] for r in committed if r["scenario_sha256"] != digest[r["id"]]})
    assert not stale, f"re-probe (`drivehierarchy scenario probe`): scenarios changed since measured: {stale}"


def test_discrimination_must_holds(committed: list[dict]) -> None:
    s = suite_probe.summarize(committed)
    failed = [f"{name}: {detail}" for name, ok, detail in suite_probe.must_holds(s) if not ok]
    assert not failed, "\n".join(failed)


def test_docs_publish_the_committed_table(committed: list[dict]) -> None:
    table = suite_probe.markdown(suite_probe.summarize(committed))
    assert suite_probe.doc_block(DOC) == table, (
        "regenerate: drivehierarchy scenario probe … --update-doc docs/suite.md"
    )


def test_a_stratified_subset_reproduces_the_committed_results(committed: list[dict]) -> None:
    """Re-runs 2 (cell, seed) pairs per scenario, chosen by a hash of its id, on fresh envs: the
    score, termination and trajectory hash must equal the committed ones bit for bit."""
    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    subset = suite_probe.ci_subset([f.stem for f in FILES])
    path_of = {f.stem: str(f) for f in FILES}
    tasks = [(path_of[sid], cell, (seed,)) for sid, pairs in subset.items() for cell, seed in pairs]
    rows = suite_probe.probe([], jobs=2, progress=False, tasks=tasks)
    assert len(rows) == len(tasks)
    old = {(r["id"], r["cell"], r["seed"]): r for r in committed}
    diff = []
    for r in rows:
        c = old[(r["id"], r["cell"], r["seed"])]
        got = (r["score"], r["termination"], r["trajectory_hash"][: suite_probe.TRAJECTORY_HASH_HEX])
        want = (c["score"], c["termination"], c["trajectory_hash"])
        if got != want:
            diff.append(f"{r['id']} {r['cell']} seed {r['seed']}: measured {got}, committed {want}")
    assert not diff, "\n".join(diff)


def test_episodes_are_deterministic() -> None:
    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    one_per_category = [sorted(SUITE.glob(f"{c}/*.toml"))[-1] for c in CATEGORIES]
    for path in one_per_category:
        a = suite_probe.run_one(str(path), "expert", 3, None)
        b = suite_probe.run_one(str(path), "expert", 3, None)
        assert {k: v for k, v in a.items() if k != "wall_s"} == {k: v for k, v in b.items() if k != "wall_s"}
