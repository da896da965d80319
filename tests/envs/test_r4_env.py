"""The `DriveHierarchy-R4` Gymnasium env: conformance, protocol behaviour, determinism, errors."""

from __future__ import annotations

import pickle
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import drivehierarchy
from drivehierarchy import ConfigError, ScenarioError, SimulationError, _core
from drivehierarchy.agents.base import ConstantAgent, run_episode
from drivehierarchy.agents.expert import ExpertAgent
from drivehierarchy.envs.r4 import STATE_FIELDS, DriveHierarchyR4Env
from drivehierarchy.scenarios import builtin_root, builtin_scenarios, scenario_id

SCENARIO = "03_turning/town01_03_right_turn_signalised"
TOWN01 = builtin_root() / "maps" / "town01" / "town01.net.xml"
NO_IMAGES = {"front": None, "bev": None}


def make(scenario: str = SCENARIO, **kw: object) -> DriveHierarchyR4Env:
    env = gym.make("DriveHierarchy-R4", scenario=scenario, **kw)
    return env.unwrapped  # type: ignore[return-value]


def ticks_of(env: DriveHierarchyR4Env) -> list[dict]:
    return [x for x in env.sim.episode_log() if x["kind"] == "tick"]


def test_registration_is_idempotent() -> None:
    drivehierarchy.register_envs()
    drivehierarchy.register_envs()
    assert drivehierarchy.R4_ENV_ID in gym.registry
    env = gym.make("drivehierarchy:DriveHierarchy-R4", **NO_IMAGES)
    assert isinstance(env.unwrapped, DriveHierarchyR4Env)


def test_gymnasium_env_checker_passes_on_the_default_observation() -> None:
    from gymnasium.utils.env_checker import check_env

    env = make()
    assert set(env.observation_space.spaces) == {"front", "bev", "prompt", "state"}
    check_env(env, skip_render_check=True)
    check_env(make(render_mode="rgb_array"), skip_render_check=False)


@pytest.mark.parametrize("action_mode", ["decision", "raw"])
def test_sb3_env_checker_passes_on_numeric_observations(action_mode: str) -> None:
    # SB3 has no text spaces: its checker runs on the prompt-free configuration RL uses.
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    env = make(
        prompt=False,
        action_mode=action_mode,
        front={"width": 160, "height": 90},
        bev={"size_px": 128, "px_per_m": 2.0},
    )
    sb3.check_env(env)


def test_observation_contents_follow_the_protocol() -> None:
    env = make()
    obs, info = env.reset(seed=3)
    assert obs["front"].shape == (450, 800, 3) and obs["front"].dtype == np.uint8
    assert obs["bev"].shape == (800, 800, 3) and obs["bev"].dtype == np.uint8
    assert obs["prompt"].startswith("The ego vehicle is driving at the speed of 0.0 m/s, and it wants to ")
    assert obs["prompt"].endswith("steer: <float in [-1.0, 1.0]>\ntarget_speed_mps: <float in [0.0, 30.0]>")
    assert obs["state"].shape == (len(STATE_FIELDS),) and obs["state"].dtype == np.float32
    state = dict(zip(STATE_FIELDS, obs["state"].tolist(), strict=True))
    assert state["route_length_m"] == pytest.approx(info["route_length_m"], rel=1e-6)
    assert state["route_p1_forward_m"] == pytest.approx(5.0, abs=0.3)
    # The original's warm-up: zero control on ticks 1–4; the first decision sees tick 4.
    assert info["tick"] == 4 and info["decision"] == 0 and info["termination_reason"] is None
    assert info["reply"] is None
    _, early = make(warmup_ticks=0, **NO_IMAGES).reset(seed=3)
    assert early["tick"] == 0


@pytest.mark.parametrize("path", builtin_scenarios(), ids=scenario_id)
def test_expert_scores_at_least_90_on_every_builtin_scenario(path: Path, reference_rows: list[dict]) -> None:
    # The expert's episodes of the session's reference run (tests/conftest.py), not a second drive.
    (row,) = [r for r in reference_rows if r["scenario"] == str(path) and r["policy"] == "expert"]
    assert row["termination"] == "destination_reached", row
    assert row["score"] >= 90.0, row


@pytest.mark.parametrize("scenario", [SCENARIO, "06_traffic_flow/bs3d_09_left_turner_queue"])
def test_an_episodes_return_is_its_score(scenario: str) -> None:
    env = make(scenario, **NO_IMAGES)
    result = run_episode(env, ExpertAgent(), seed=0)
    score = result.score
    assert score["termination_reason"] == "destination_reached", score
    # Rewards are shaped so that an episode's return is its S_R4 / 100.
    assert result.total_reward == pytest.approx(score["score_composed"] / 100.0, abs=1e-9)


def test_zero_speed_policy_ends_with_blocked_timeout_and_the_protocol_score() -> None:
    env = make(**NO_IMAGES)
    result = run_episode(env, ConstantAgent([0.0, 0.0]), seed=0)
    s = result.score
    assert s["termination_reason"] == "blocked_timeout"
    # Speed < 1 km/h for more than 100 consecutive ticks, counted from t = 0: ends at tick 101.
    assert s["ticks"] == 101
    assert s["meta"]["duration_game"] == 5.05
    # Hand-computed: no progress → S_route 0; safety = 0.7 (blocked) × (1 − 0 off-road);
    # no travel → distance efficiency 1; 1.5·T_ref ≥ 5.05 s → time efficiency 1.
    assert s["score_route"] == 0.0
    assert s["score_safety"] == pytest.approx(0.7)
    assert s["score_efficiency"] == pytest.approx(1.0)
    assert s["score_composed"] == 0.0
    assert [e["type"] for e in s["events"]] == ["blocked_timeout"]
    assert s["events"][0]["penalty_multiplier"] == 0.7
    assert s["events"][0]["blocked_steps"] == 101
    assert s["status"] == "Failed"


def test_steering_off_the_road_ends_on_the_31st_off_road_tick() -> None:
    env = make(**NO_IMAGES)
    env.reset(seed=0)
    actions = [[0.12, 8.0]] + [[0.24, 8.0]] * 4 + [[0.0, 8.0]] * 400
    info: dict = {}
    for a in actions:
        _, _, terminated, _, info = env.step(a)
        if terminated:
            break
    assert info["termination_reason"] == "offroad_timeout"
    ticks = ticks_of(env)
    first_off = next(i for i, t in enumerate(ticks) if not t["on_road"])
    assert all(not t["on_road"] for t in ticks[first_off:])
    # The original measures 1.5 s from the first off-road sample: the 31st off-road tick ends it.
    assert ticks[-1]["time_s"] - ticks[first_off]["time_s"] == pytest.approx(1.5, abs=1e-9)
    assert len(ticks) - first_off == 31
    s = env.score()
    assert s["score_safety"] == 0.0 and s["score_composed"] == 0.0
    assert [e["type"] for e in s["events"]] == ["route_deviation"]
    assert s["events"][0]["offroad_duration"] == 1.5
    assert s["termination_reason"] == "offroad_timeout"


def test_raw_replies_are_parsed_in_rust_and_a_failure_holds_the_control() -> None:
    env = make("07_sudden_brake/town01_07_lead_brakes", **NO_IMAGES)
    env.reset(seed=0)
    _, _, _, _, first = env.step("steer: 0.3\ntarget_speed_mps: 6.0")
    held = first["control"]
    assert held["steer"] == pytest.approx(0.12)  # rate-limited from 0
    assert first["reply"]["parsed"] == {"steer": 0.3, "target_speed_mps": 6.0}
    before = len(ticks_of(env))
    _, _, _, _, info = env.step("I would keep going carefully.")
    assert info["control"] == held
    assert info["parse_failures"] == 1
    assert info["reply"]["failure"] == "missing_both"
    assert info["reply"]["raw"] == "I would keep going carefully."
    assert info["reply"]["parsed"] is None
    # The control was unchanged for the 5 ticks of that decision.
    assert len(ticks_of(env)) - before == 5
    # `None` is "no reply" (a transport error): held and counted too.
    _, _, _, _, info = env.unwrapped.step_reply(None)
    assert info["control"] == held and info["reply"]["failure"] == "no_reply"
    log = env.unwrapped.decision_log()
    assert [d["tick"] for d in log] == [4, 9, 14]
    assert [d["failure"] for d in log] == [None, "missing_both", "no_reply"]
    assert env.score()["parse_failures"] == 2
    raw = make(action_mode="raw", **NO_IMAGES)
    raw.reset(seed=0)
    with pytest.raises(ConfigError, match="action_mode"):
        raw.step("steer: 0.1\ntarget_speed_mps: 3")


def run_fixed(seed: int, images: bool) -> tuple[str, list[bytes], list[float]]:
    cfg = {} if images else NO_IMAGES
    env = make("01_pedestrian/town01_01_midblock_crossing", **cfg)
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(7)
    frames, rewards = [], []
    for _ in range(25):
        obs, r, term, _, info = env.step(np.array([rng.uniform(-0.2, 0.2), rng.uniform(3, 9)], np.float32))
        rewards.append(r)
        if images:
            frames += [obs["front"].tobytes(), obs["bev"].tobytes()]
        if term:
            break
    return info["trajectory_hash"], frames, rewards


def test_same_seed_and_actions_give_identical_trajectories_and_frames() -> None:
    a = run_fixed(5, images=True)
    b = run_fixed(5, images=True)
    assert a[0] == b[0]
    assert a[1] == b[1]
    assert a[2] == b[2]
    # Images do not influence the dynamics.
    assert run_fixed(5, images=False)[0] == a[0]


def test_rescore_from_the_log_reproduces_the_live_score() -> None:
    env = make("07_sudden_brake/town01_07_lead_brakes", **NO_IMAGES)
    live = run_episode(env, ExpertAgent(), seed=1).score
    again = _core.rescore(env.sim.episode_log())
    for key in ("score_route", "score_safety", "score_efficiency", "score_composed", "termination_reason"):
        assert again[key] == live[key]
    assert again["events"] == live["events"]


def test_env_pickles_by_config() -> None:
    env = make(**NO_IMAGES)
    env.reset(seed=0)
    clone = pickle.loads(pickle.dumps(env))
    obs_a, _ = env.reset(seed=11)
    obs_b, _ = clone.reset(seed=11)
    assert np.array_equal(obs_a["state"], obs_b["state"])


# --- bad input ---------------------------------------------------------------------------


def test_step_before_reset_is_a_simulation_error() -> None:
    env = make(**NO_IMAGES)
    with pytest.raises(SimulationError, match="reset"):
        env.step([0.0, 1.0])


@pytest.mark.parametrize(
    ("action", "needle"),
    [([float("nan"), 1.0], "NaN"), ([0.0, float("inf")], "NaN or infinity"), ([0.0, 1.0, 2.0], "shape")],
)
def test_bad_actions_are_config_errors(action: list[float], needle: str) -> None:
    env = make(**NO_IMAGES)
    env.reset(seed=0)
    with pytest.raises(ConfigError, match=needle) as exc:
        env.step(action)
    assert "action" in str(exc.value)
    assert isinstance(exc.value, ValueError)


def test_step_after_termination_asks_for_reset() -> None:
    env = make(**NO_IMAGES)
    run_episode(env, ConstantAgent([0.0, 0.0]), seed=0)
    with pytest.raises(SimulationError, match="reset"):
        env.step([0.0, 0.0])


def write_scenario(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "bad.toml"
    p.write_text(text, encoding="utf-8")
    return p


def base_scenario() -> str:
    text = (builtin_root() / "r4" / f"{SCENARIO}.toml").read_text(encoding="utf-8")
    return text.replace('map = "builtin:town01"', f'map = "{TOWN01.as_posix()}"')


def test_malformed_toml_names_the_file_and_position(tmp_path: Path) -> None:
    p = write_scenario(tmp_path, base_scenario() + "\n[ego\n")
    with pytest.raises(ScenarioError) as exc:
        make(str(p), **NO_IMAGES)
    line = p.read_text(encoding="utf-8").splitlines().index("[ego") + 1
    assert str(exc.value).startswith(f"{p}:{line}:"), exc.value  # file:line:column


def test_missing_map_names_the_field_and_value(tmp_path: Path) -> None:
    p = write_scenario(tmp_path, base_scenario().replace(TOWN01.as_posix(), "nowhere/missing.net.xml"))
    with pytest.raises(ScenarioError) as exc:
        make(str(p), **NO_IMAGES)
    msg = str(exc.value)
    assert str(p) in msg and "map" in msg and "missing.net.xml" in msg


def test_unknown_lane_in_the_ego_route_names_it(tmp_path: Path) -> None:
    p = write_scenario(tmp_path, base_scenario().replace('lane = "C2S_1"', 'lane = "NOPE_1"'))
    with pytest.raises(ScenarioError) as exc:
        make(str(p), **NO_IMAGES)
    msg = str(exc.value)
    assert str(p) in msg and "ego.destination" in msg and "NOPE_1" in msg


def test_unknown_edge_in_route_edges_names_it(tmp_path: Path) -> None:
    text = base_scenario().replace(
        'destination = { lane = "C2S_1", s = 100.0 }',
        'destination = { lane = "C2S_1", s = 100.0 }\nroute_edges = ["W2C", "XX9"]',
    )
    p = write_scenario(tmp_path, text)
    with pytest.raises(ScenarioError) as exc:
        make(str(p), **NO_IMAGES)
    assert "XX9" in str(exc.value) and str(p) in str(exc.value)


def test_unknown_settings_and_options_are_rejected() -> None:
    with pytest.raises(ConfigError, match="colour"):
        make(colour="red")
    env = make(**NO_IMAGES)
    with pytest.raises(ConfigError, match=r"options\.level"):
        env.reset(options={"level": 3})
    with pytest.raises(ScenarioError, match=r"not a file and not a built-in"):
        env.reset(options={"scenario": "99_nowhere/none"})


def test_reset_can_switch_scenarios() -> None:
    env = make(**NO_IMAGES)
    _, a = env.reset(seed=0)
    _, b = env.reset(seed=0, options={"scenario": "07_sudden_brake/town01_07_lead_brakes"})
    assert a["route_length_m"] != b["route_length_m"]
    assert env.sim.category == "07_sudden_brake"


def test_a_wrongly_typed_setting_names_its_field() -> None:
    with pytest.raises(ConfigError, match=r"config\.front\.width") as exc:
        make(front={"width": "wide"})
    assert "wide" in str(exc.value)
