"""Rendering through the Python bindings: determinism, shapes, ownership of frames, the actor
projection helper, traffic-light colours, the GIF writer, config errors, the gallery and the R4
runner's `--video`."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drivehierarchy
from drivehierarchy import _core
from drivehierarchy.envs.config import BevConfig, CameraConfig, R4Config
from drivehierarchy.envs.r4 import STATE_FIELDS, DriveHierarchyR4Env
from drivehierarchy.scenarios import builtin_root, resolve_scenario

SIGNALISED = "03_turning/town01_03_right_turn_signalised"
LEAD_BRAKES = "07_sudden_brake/town01_07_lead_brakes"
TOWN01 = builtin_root() / "maps" / "town01" / "town01.net.xml"


def cam_json(**kw: Any) -> CameraConfig:
    return CameraConfig(**kw)


def bev_json(**kw: Any) -> BevConfig:
    return BevConfig(**kw)


def state(obs: dict[str, Any]) -> dict[str, float]:
    return dict(zip(STATE_FIELDS, (float(v) for v in obs["state"]), strict=True))


def no_image_env(scenario: str | Path) -> DriveHierarchyR4Env:
    return DriveHierarchyR4Env(scenario=scenario, front=None, bev=None, prompt=False)


# -- determinism and frame hand-off ------------------------------------------------------------


def test_same_seed_and_actions_give_identical_frames_across_instances() -> None:
    actions = [np.array([s, 8.0], np.float32) for s in (0.0, 0.1, 0.1, -0.05, 0.0, 0.0)]

    def rollout() -> list[tuple[bytes, bytes, bytes]]:
        env = gym.make(drivehierarchy.R4_ENV_ID, scenario=SIGNALISED)
        obs, _ = env.reset(seed=7)
        frames = [(obs["front"].tobytes(), obs["bev"].tobytes(), env.unwrapped.sim.render("chase").tobytes())]
        for a in actions:
            obs, *_ = env.step(a)
            frames.append(
                (obs["front"].tobytes(), obs["bev"].tobytes(), env.unwrapped.sim.render("chase").tobytes())
            )
        env.close()
        return frames

    a, b = rollout(), rollout()
    assert len(a) == len(b) == len(actions) + 1
    for i, (fa, fb) in enumerate(zip(a, b, strict=True)):
        for view, x, y in zip(("front", "bev", "chase"), fa, fb, strict=True):
            assert x == y, f"step {i}: {view} frames differ between two instances"
    # The ego moved, so the pictures changed: the comparison above is not between constants.
    assert a[0][0] != a[-1][0] and a[0][1] != a[-1][1]


def test_frame_shapes_and_dtypes_follow_the_config() -> None:
    env = gym.make(
        drivehierarchy.R4_ENV_ID,
        scenario=LEAD_BRAKES,
        front={"width": 320, "height": 180},
        bev={"size_px": 128, "px_per_m": 2.0},
    )
    obs, _ = env.reset(seed=0)
    assert obs["front"].shape == (180, 320, 3) and obs["front"].dtype == np.uint8
    assert obs["bev"].shape == (128, 128, 3) and obs["bev"].dtype == np.uint8
    assert env.observation_space["front"].contains(obs["front"])
    assert env.observation_space["bev"].contains(obs["bev"])
    obs, *_ = env.step(np.array([0.0, 5.0], np.float32))
    assert obs["front"].shape == (180, 320, 3) and obs["bev"].shape == (128, 128, 3)
    # The BEV's centre is the yellow ego disc at any size.
    assert tuple(obs["bev"][64, 64]) == (255, 230, 80)  # the ego disc

    sim = env.unwrapped.sim
    for w, h in ((400, 225), (64, 48), (801, 451)):
        img = sim.render_camera(cam_json(width=w, height=h))
        assert img.shape == (h, w, 3) and img.dtype == np.uint8 and img.flags.c_contiguous
    assert sim.render_bev(bev_json(size_px=96, px_per_m=3.0)).shape == (96, 96, 3)
    assert sim.render("front").shape == (180, 320, 3)  # the env's own front camera
    assert sim.render("bev").shape == (128, 128, 3)
    assert sim.render("chase").shape == (450, 800, 3)
    rig = sim.render_surround()
    assert sorted(rig) == sorted(
        ["CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_BACK_RIGHT"]
    )
    for name, img in rig.items():
        assert img.shape == (450, 800, 3) and img.dtype == np.uint8, name
    assert not np.array_equal(rig["CAM_FRONT"], rig["CAM_BACK"])
    env.close()


def test_frames_are_owned_and_not_mutated_by_later_steps() -> None:
    env = gym.make(drivehierarchy.R4_ENV_ID, scenario=LEAD_BRAKES)
    obs, _ = env.reset(seed=0)
    sim = env.unwrapped.sim
    kept = {
        "front": obs["front"],
        "bev": obs["bev"],
        "render": sim.render_camera(cam_json(width=400, height=225)),
    }
    copies = {k: v.copy() for k, v in kept.items()}
    for _ in range(4):
        obs, *_ = env.step(np.array([0.0, 9.0], np.float32))
    later = sim.render_camera(cam_json(width=400, height=225))
    for k, v in kept.items():
        assert np.array_equal(v, copies[k]), f"{k} frame changed after later steps"
        assert v.flags.writeable and v.flags.c_contiguous
    assert not np.shares_memory(kept["front"], obs["front"])
    assert not np.shares_memory(kept["render"], later)
    assert not np.array_equal(kept["front"], obs["front"])  # the scene did move
    # Writing into a kept frame does not reach the simulator's next frame.
    kept["render"][:] = 0
    assert np.array_equal(sim.render_camera(cam_json(width=400, height=225)), later)
    env.close()


# -- the projection helper --------------------------------------------------------------------


def test_project_actors_finds_the_lead_vehicle_ahead() -> None:
    env = no_image_env(LEAD_BRAKES)
    env.reset(seed=0)
    w, h = 800, 450
    found = {a["id"]: a for a in env.unwrapped.sim.project_actors(cam_json())}
    # Ids: ego 0, then actors in file order: 1 = the lead (22 m ahead in the ego's lane at
    # the start: it paces itself there), 2 = the car in the left lane (20 m ahead).
    assert 1 in found, found
    lead = found[1]
    assert 20.0 < lead["distance_m"] < 25.0
    x0, y0, x1, y1 = lead["bbox_px"]
    assert 0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h
    cx, cy = lead["center_px"]
    assert x0 <= cx <= x1 and y0 <= cy <= y1
    assert abs(cx - w / 2) < 0.05 * w, "the lead is in the ego's lane: straight ahead"
    assert lead["visible_fraction"] > 0.9 and lead["pixel_count"] > 50
    left = found[2]
    assert 15.0 < left["distance_m"] < 25.0
    assert left["center_px"][0] < cx, "the left-lane car projects left of the lead"
    assert left["pixel_count"] > lead["pixel_count"], "nearer ⇒ bigger"
    # Looking backwards, neither is in view.
    assert not [a for a in env.unwrapped.sim.project_actors(cam_json(yaw_deg=180.0)) if a["id"] in (1, 2)]


def test_project_actors_names_each_actor_colour_from_its_pixels() -> None:
    env = no_image_env(LEAD_BRAKES)
    env.reset(seed=0)
    names = {p["name"] for p in _core.colour_palette()}
    found = env.unwrapped.sim.project_actors(cam_json())
    assert found and all(a["colour_name"] in names for a in found), found
    # The two scenario cars get the default actor colours in file order: red, then blue.
    by_id = {a["id"]: a for a in found}
    assert by_id[1]["colour_name"] == "red" and by_id[2]["colour_name"] == "blue", by_id


def test_palette_entries_are_named_by_their_own_names() -> None:
    pal = _core.colour_palette()
    assert [p["name"] for p in pal][:4] == ["black", "white", "silver", "gray"]
    for p in pal:
        assert _core.colour_name(p["rgb"]) == p["name"]
        lo, hi = p["value"]
        assert 0.0 <= lo < hi
    white, glass = (240, 240, 238), (50, 64, 82)
    assert _core.colour_name_of_pixels([white, white, glass]) == "white"
    assert _core.colour_name_of_pixels([]) is None


# -- traffic lights ---------------------------------------------------------------------------


def lamp_pixels(img: np.ndarray) -> tuple[int, int]:
    """(lit red, lit green) lamp pixels, with the thresholds of the Rust semantic test."""
    r, g, b = (img[..., i].astype(np.int32) for i in range(3))
    red = (r > 230) & (g < 60) & (b < 60)
    green = (g > 230) & (r < 60) & (b < 120)
    return int(red.sum()), int(green.sum())


def approach_scenario(tmp: Path, name: str, start: str, dest: str) -> Path:
    """The signalised crossing C of town01 approached from one arm, 30 m before the stop line."""
    p = tmp / f"{name}.toml"
    p.write_text(
        "\n".join(
            [
                "version = 1",
                f'id = "{name}"',
                'category = "03_turning"',
                f"map = {json.dumps(str(TOWN01.resolve()))}",
                "[ego]",
                f"start = {start}",
                f"destination = {dest}",
            ]
        )
        + "\n",
        encoding="utf-8",
    )
    return p


@pytest.mark.parametrize(
    ("name", "start", "dest", "stop"),
    [
        # Light C: east-west green for 0–42 s, north-south red until 45 s (docs/scenario-format.md).
        ("eastbound_green", '{ lane = "W2C_1", s = 210.0 }', '{ lane = "C2T_1", s = 100.0 }', 0.0),
        ("northbound_red", '{ lane = "S2C_1", s = 160.0 }', '{ lane = "C2N_1", s = 100.0 }', 1.0),
    ],
)
def test_light_ahead_renders_in_its_colour(
    tmp_path: Path, name: str, start: str, dest: str, stop: float
) -> None:
    env = DriveHierarchyR4Env(scenario=approach_scenario(tmp_path, name, start, dest), bev=None, prompt=False)
    obs, _ = env.reset(seed=0)
    s = state(obs)
    assert 20.0 < s["light_ahead_distance_m"] < 40.0, s["light_ahead_distance_m"]
    assert s["light_ahead_stop"] == stop
    img = obs["front"]
    h, w, _ = img.shape
    # The heads of the ego's approach hang over its road, straight ahead, above the horizon;
    # heads of the crossing road (other colour, seen obliquely) stand farther out to the sides.
    red, green = lamp_pixels(img[: h // 2, int(0.40 * w) : int(0.55 * w)])
    if stop:
        assert red >= 6 and green == 0, (red, green)
    else:
        assert green >= 6 and red == 0, (red, green)
    env.close()


def test_signalised_scenario_shows_a_green_light_ahead_on_approach() -> None:
    env = no_image_env(SIGNALISED)
    obs, _ = env.reset(seed=0)
    sim = env.unwrapped.sim
    for _ in range(200):
        s = state(obs)
        if s["light_ahead_distance_m"] < 35.0:
            break
        obs, _, terminated, truncated, _ = env.step(env.expert_action())
        assert not (terminated or truncated)
    else:
        pytest.fail("the ego never came within 35 m of the light")
    assert s["light_ahead_stop"] == 0.0  # green for east-west at this time
    img = sim.render_camera(cam_json())
    red, green = lamp_pixels(img[:225, 320:440])
    assert green >= 6 and red == 0, (red, green)
    env.close()


# -- GIF writer -------------------------------------------------------------------------------


def test_gif_writer_writes_a_valid_animation(tmp_path: Path) -> None:
    from PIL import Image

    env = no_image_env(LEAD_BRAKES)
    env.reset(seed=0)
    sim = env.unwrapped.sim
    path = tmp_path / "clip.gif"
    gif = _core.GifWriter(str(path), fps=4)
    frames = []
    for _ in range(5):
        frames.append(sim.render_camera(cam_json(width=160, height=90)))
        gif.push(frames[-1])
        env.step(np.array([0.0, 10.0], np.float32))
    assert gif.frames == 5
    with pytest.raises(drivehierarchy.ConfigError, match="frame"):
        gif.push(np.zeros((90, 160, 4), np.uint8))
    gif.close()
    with pytest.raises(drivehierarchy.RenderError, match="closed"):
        gif.push(frames[0])
    with Image.open(path) as im:
        assert im.format == "GIF" and im.size == (160, 90)
        assert im.n_frames == 5
        assert im.info.get("duration") == 250  # 4 fps
        im.seek(0)
        first = np.asarray(im.convert("RGB"), dtype=np.int32)
        im.seek(4)
        last = np.asarray(im.convert("RGB"), dtype=np.int32)
    # A palette GIF: close to the source frame, and the animation moves.
    assert np.abs(first - frames[0]).mean() < 12.0
    assert not np.array_equal(first, last)
    env.close()


# -- config errors ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"fov_deg": None}, "fov_deg"),  # missing field
        ({"fov_deg": 200.0}, "camera.fov_deg"),
        ({"width": 0}, "camera.width"),
        ({"supersample": 9}, "camera.supersample"),
        ({"lens": "fisheye"}, "lens"),  # unknown field
    ],
)
def test_bad_camera_config_raises_config_error_naming_the_field(change: dict[str, Any], named: str) -> None:
    env = no_image_env(LEAD_BRAKES)
    env.reset(seed=0)
    cfg = dataclasses.asdict(CameraConfig())
    for k, v in change.items():
        if v is None:
            del cfg[k]
        else:
            cfg[k] = v
    for call in (env.unwrapped.sim.render_camera, env.unwrapped.sim.project_actors):
        with pytest.raises(drivehierarchy.ConfigError) as info:
            call(cfg)
        assert named in str(info.value)
        assert isinstance(info.value, ValueError)
    env.close()


def test_bad_bev_config_and_json_raise_config_error() -> None:
    env = no_image_env(LEAD_BRAKES)
    env.reset(seed=0)
    sim = env.unwrapped.sim
    with pytest.raises(drivehierarchy.ConfigError, match=r"bev\.size_px"):
        sim.render_bev(bev_json(size_px=0))
    with pytest.raises(drivehierarchy.ConfigError, match=r"bev\.px_per_m"):
        sim.render_bev(bev_json(px_per_m=-1.0))
    with pytest.raises(drivehierarchy.ConfigError, match="camera"):
        sim.render_camera("front")  # type: ignore[arg-type]
    with pytest.raises(drivehierarchy.ConfigError, match=r"render\.kind"):
        sim.render("side")
    env.close()


def test_rendering_before_reset_is_an_error_not_a_crash() -> None:
    config = R4Config(front=None, bev=None).to_core()
    sim = _core.Sim(resolve_scenario(LEAD_BRAKES), config)
    with pytest.raises(drivehierarchy.DriveHierarchyError):
        sim.render_camera(cam_json())


# -- gallery and runner video ------------------------------------------------------------------


def test_gallery_writes_front_bev_and_index(tmp_path: Path) -> None:
    from PIL import Image

    from drivehierarchy.benchmark.r4 import gallery

    scenarios = [Path(resolve_scenario(LEAD_BRAKES)), Path(resolve_scenario(SIGNALISED))]
    entries = gallery.write_gallery(tmp_path, scenarios, featured=gallery.scenario_key(scenarios[1]), log=str)
    assert [e.key for e in entries] == [gallery.scenario_key(p) for p in scenarios]
    sizes = {"front": (800, 450), "bev": (800, 800), "chase": (800, 450), "surround": (1200, 450)}
    index = (tmp_path / "README.md").read_text(encoding="utf-8")
    for e in entries:
        for view, fname in e.files.items():
            with Image.open(tmp_path / fname) as im:
                assert im.size == sizes[view], fname
            assert fname in index
    assert set(entries[0].files) == {"front", "bev"}
    assert set(entries[1].files) == {"front", "bev", "chase", "surround"}
    # The BEV file is exactly what the binding renders at reset (no resampling on the way).
    env = no_image_env(scenarios[0])
    env.reset(seed=0)
    with Image.open(tmp_path / entries[0].files["bev"]) as im:
        assert np.array_equal(np.asarray(im.convert("RGB")), env.unwrapped.sim.render_bev(bev_json()))
    env.close()


def test_runner_video_writes_one_gif_frame_per_decision(tmp_path: Path) -> None:
    from PIL import Image

    from drivehierarchy.benchmark.r4 import runner

    path = Path(resolve_scenario(LEAD_BRAKES))
    results = runner.evaluate([path], tmp_path, runner.RunOptions(video=True), log=str)
    gif = tmp_path / "scenes" / runner.scenario_key(path) / "episode.gif"
    with Image.open(gif) as im:
        assert im.size == (400, 225)
        assert im.n_frames == results[0]["steps"]


def test_settings_go_in_as_dataclasses_or_dicts_and_errors_name_field_and_value() -> None:
    env = no_image_env(LEAD_BRAKES)
    env.reset(seed=0)
    sim = env.unwrapped.sim
    cam = CameraConfig(width=160, height=90)
    assert np.array_equal(sim.render_camera(cam), sim.render_camera(dataclasses.asdict(cam)))
    with pytest.raises(drivehierarchy.ConfigError, match=r"`camera\.width` = -3: "):
        sim.render_camera({**dataclasses.asdict(cam), "width": -3})
    core = R4Config(front=None, bev=None).to_core()
    front = {**dataclasses.asdict(CameraConfig()), "fov_deg": "wide"}
    with pytest.raises(drivehierarchy.ConfigError, match=r"`config\.front\.fov_deg` = 'wide': "):
        _core.Sim(resolve_scenario(LEAD_BRAKES), {**core, "front": front})
    env.close()
