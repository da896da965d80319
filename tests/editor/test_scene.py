"""The editor's scene player: times in any order are lookups, never replays, and a new buffer
gets the process's in-process SUMO."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivehierarchy.editor.scene import PlayerCache, ScenePlayer
from drivehierarchy.envs.r4 import DriveHierarchyR4Env

SUITE = Path(__file__).resolve().parents[2] / "scenarios" / "r4"

SUMO_SCENE = "04_intersection/town01_02_emergency_runs_red.toml"


@pytest.fixture
def resets(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Counts world resets (a replay from the start begins with one)."""
    calls: list[int] = []
    reset = DriveHierarchyR4Env.reset

    def counted(self, *args, **kwargs):
        calls.append(1)
        return reset(self, *args, **kwargs)

    monkeypatch.setattr(DriveHierarchyR4Env, "reset", counted)
    return calls


def test_earlier_times_render_from_the_record_without_a_replay(resets: list[int]) -> None:
    path = str(SUITE / SUMO_SCENE)
    player = ScenePlayer(path, None)
    try:
        late = {v: player.png_at(20.0, v) for v in ("front", "bev")}
        early = {v: player.png_at(4.0, v) for v in ("front", "bev")}
        middle = player.state_at(11.0)
        assert len(resets) == 1, "one reset: the world only ever moved forward"
        assert early["front"][1] <= 4.0 < 20.0 - 1 and early["front"] != late["front"]
    finally:
        player.close()
    fresh = ScenePlayer(path, None)
    try:
        for t, got in ((20.0, late), (4.0, early)):
            for view in ("front", "bev"):
                assert fresh.png_at(t, view) == got[view]
        assert fresh.state_at(11.0) == middle
    finally:
        fresh.close()


def test_a_released_world_replays_the_same_episode_beyond_its_record(resets: list[int]) -> None:
    path = str(SUITE / SUMO_SCENE)
    player = ScenePlayer(path, None)
    straight = ScenePlayer(path, None)
    try:
        player.state_at(8.0)
        player.release_world()
        assert player.env is None
        assert player.png_at(3.0, "front")[1] <= 3.0  # recorded: served without a world
        assert player.env is None
        far = player.png_at(25.0, "front")
        assert player.env is not None and len(resets) == 3  # two players, one replay
        assert far == straight.png_at(25.0, "front")
        assert player.states == straight.states[: len(player.states)]
    finally:
        player.close()
        straight.close()


def test_an_ended_episode_closes_its_world_and_keeps_its_score() -> None:
    player = ScenePlayer(str(SUITE / "01_pedestrian/town01_01_midblock_crossing.toml"), None)
    run = player.run_to_end()
    assert player.done and player.env is None
    assert run["score"]["termination_reason"] == run["states"][-1]["termination"]
    assert player.png_at(run["states"][-1]["time_s"] + 50.0, "bev")[1] == run["states"][-1]["time_s"]
    player.close()


def test_a_new_buffer_takes_the_in_process_sumo_from_an_idle_one() -> None:
    from drivehierarchy import _core

    cache = PlayerCache()
    path = str(SUITE / SUMO_SCENE)
    text = Path(path).read_text(encoding="utf-8")
    try:
        first = cache.get(path, text)
        first.state_at(5.0)
        assert first.env is not None and first.env._sumo.transport != "traci"
        second = cache.get(path, text + "# an edit\n")
        assert first.env is None, "the idle buffer gave its world up"
        assert second.env._sumo.transport != "traci" and _core.SumoSession.in_process_busy()
        assert cache.get(path, text) is first and first.state_at(3.0)["time_s"] <= 3.0
    finally:
        cache.close()
    assert not _core.SumoSession.in_process_busy()
