"""The rollout's sim hooks and the Moment API: one raster pass gives exactly the separate image
and projection, actor views carry class/colour/motion, moments know frames and futures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from drivehierarchy.benchmark.openloop.generate import rollout as R
from drivehierarchy.envs.r4 import DriveHierarchyR4Env

REPO = Path(__file__).resolve().parents[3]
BUS = REPO / "scenarios" / "r4" / "01_pedestrian" / "town01_02_bus_occlusion.toml"


@pytest.fixture(scope="module")
def env():
    e = DriveHierarchyR4Env(scenario=str(BUS), front=None, bev=None, prompt=False)
    e.reset(seed=0)
    for _ in range(60):
        e.step(e.unwrapped.sim.expert_action())
    yield e
    e.close()


def test_render_and_project_equals_the_separate_calls(env) -> None:
    sim = env.unwrapped.sim
    for name in ("CAM_FRONT", "CAM_BACK"):
        cfg = R.camera_config(name)
        img, found = sim.render_and_project(cfg)
        assert np.array_equal(np.asarray(img), np.asarray(sim.render_camera(cfg)))
        assert json.dumps(found) == json.dumps(sim.project_actors(cfg))  # NaN-safe
        assert np.asarray(img).shape == (900, 1600, 3)


def test_actor_views_carry_class_colour_and_motion(env) -> None:
    sim = env.unwrapped.sim
    views = {v["id"]: v for v in sim.actor_views()}
    assert [int(r[0]) for r in sim.actors_array()] == sorted(views)
    bus = next(v for v in views.values() if v["kind"] == "bus")
    assert bus["motion"] == "static" and bus["color"] == [230, 190, 40] and bus["speed_mps"] == 0.0
    state = R.actor_state(bus)
    assert (state.category, state.subtype, state.colour, state.status) == (
        "Vehicle",
        "bus",
        "yellow",
        "parked",
    )
    assert {v["kind"] for v in views.values()} >= {"bus", "pedestrian"}
    assert not any(v["beacon"] for v in views.values())  # no emergency vehicle in this scene
    assert sim.time_s == pytest.approx(0.05 * (4 + 60 * 5))


def test_moments_know_frames_clips_and_futures() -> None:
    needs = [R.Needs(), R.Needs(cameras=R.SURROUND, clip=4), R.Needs(history=3)]
    ro = R.rollout(BUS, "expert", 0, needs)
    ms = ro.moments()
    assert ms and [m.step for m in ms] == ro.anchors
    m = ms[0]
    for cam in R.SURROUND:
        f = m.frame(cam)
        assert f is not None and f.size == R.IMAGE_SIZE and f.image[:2] == b"\xff\xd8"
        for v in f.visible:
            assert v.visible_pixels >= R.MIN_VISIBLE_PIXELS and v.visible_fraction >= R.MIN_VISIBLE_FRACTION
            assert 0 <= v.bbox[0] < v.bbox[2] < 1600 and 0 <= v.bbox[1] < v.bbox[3] < 900
    clip = m.clip(4)
    assert clip is not None and [f.step for f in clip] == [m.step + 2 * k for k in range(4)]
    hist = m.history(3)
    assert hist is not None and [f.step for f in hist] == [m.step - 4, m.step - 2, m.step]
    fut = m.ego_future(2.0)
    assert len(fut) == 8 and fut[0] == ro.states[m.step + 1][1]
    ped = next(a for a in m.actors.values() if a.category == "Pedestrian")
    assert all(s.id == ped.id for s in m.future(ped.id, 1.0))
    # Same inputs, same rollout (frames included).
    again = R.rollout(BUS, "expert", 0, needs)
    assert again.anchors == ro.anchors and again.states == ro.states
    assert {k: f.image for k, f in again.frames.items()} == {k: f.image for k, f in ro.frames.items()}


def test_unknown_driver_and_camera_are_named() -> None:
    from drivehierarchy import ConfigError

    with pytest.raises(ConfigError, match="driver 'bogus'"):
        R.make_driver("bogus", 0)
    with pytest.raises(ConfigError, match="camera 'CAM_TOP'"):
        R.camera_config("CAM_TOP")
