"""Bad drivers at the waypoint and meta levels (`drivehierarchy.testing.bad_agents.PLAN_KINDS`:
random, huge, all-zero and non-finite plans; garbage, empty, 1 MB, missing and mixed replies).

Every episode must end with a protocol termination (no exception from `step`; a non-finite plan is
rejected with `ConfigError` and changes nothing), and re-scoring its episode log must give the
record the run produced. CI drives every kind on one scenario per category (state only, seed 0);
`DH_PLAN_FUZZ_FULL=1` drives every kind on every scenario of the suite (≥ 1,000 episodes).
"""

from __future__ import annotations

import os
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy.scenarios import builtin_scenarios, scenario_id, sumo_home
from drivehierarchy.testing.bad_agents import PLAN_KINDS, fuzz_episode

TERMINATIONS = {
    "collision_pedestrian",
    "collision_vehicle",
    "collision_static",
    "offroad_timeout",
    "destination_reached",
    "blocked_timeout",
    "scenario_timeout",
}
FULL = os.environ.get("DH_PLAN_FUZZ_FULL") == "1"


def plan_tasks(full: bool) -> list[tuple[str, str]]:
    files = builtin_scenarios()
    if not full:
        files = [p for p in files if p == min(q for q in files if q.parent == p.parent)]
    return [(str(p), kind) for p in files for kind in PLAN_KINDS]


def _run(pool: ProcessPoolExecutor, full: bool) -> list[dict[str, Any]]:
    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    tasks = plan_tasks(full)
    return list(pool.map(fuzz_episode, *zip(*tasks, strict=True), chunksize=4))


def _check(rows: list[dict[str, Any]]) -> None:
    where = lambda r: f"{scenario_id(Path(r['scenario']))} {r['kind']}"  # noqa: E731
    failed = [f"{where(r)}: {r['error']}" for r in rows if r["error"] or r.get("close_error")]
    assert not failed, f"{len(failed)} episodes raised:\n" + "\n".join(failed[:50])
    ended = Counter(r["termination"] for r in rows)
    assert set(ended) <= TERMINATIONS, ended
    assert all(0.0 <= r["score"] <= 100.0 for r in rows)
    differ = [where(r) for r in rows if not r["rescore_equal"]]
    assert not differ, differ[:50]
    by_kind: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        by_kind.setdefault(r["kind"], []).append(r)
    for mode in ("waypoints", "meta"):
        # No reply ever holds a plan: every decision is a counted failure.
        for style in ("garbage", "empty", "none"):
            rs = by_kind[f"{mode}_{style}_reply"]
            assert all(r["parse_failures"] == r["steps"] for r in rs), (mode, style)
        assert all(r["rejected"] > 0 for r in by_kind[f"{mode}_non_finite"]), mode
        mixed = by_kind[f"{mode}_mixed_reply"]
        assert all(0 < r["parse_failures"] < r["steps"] for r in mixed if r["steps"] > 6), mode


def test_bad_plan_drivers_never_break_an_episode(worker_pool: ProcessPoolExecutor) -> None:
    rows = _run(worker_pool, full=False)
    assert len(rows) == 10 * len(PLAN_KINDS)
    _check(rows)


@pytest.mark.skipif(not FULL, reason="the full plan fuzz (≥ 1,000 episodes) runs with DH_PLAN_FUZZ_FULL=1")
def test_bad_plan_drivers_on_the_whole_suite(worker_pool: ProcessPoolExecutor) -> None:
    rows = _run(worker_pool, full=True)
    assert len(rows) >= 1000
    _check(rows)
