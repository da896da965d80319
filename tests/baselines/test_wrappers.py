"""RL-ready wrappers: Gymnasium's and SB3's env checkers, codecs, the shaped reward leaving the
benchmark score alone, the suite sampler and its split, and the `sb3:` agent prefix."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from drivehierarchy import ConfigError
from drivehierarchy.agents.base import run_episode
from drivehierarchy.agents.expert import ExpertAgent
from drivehierarchy.baselines.wrappers import (
    ActionCodec,
    ObsCodec,
    SuiteEnv,
    WrapperConfig,
    make_env,
    split_suite,
)
from drivehierarchy.benchmark.r4 import runner
from drivehierarchy.envs.config import R4Config
from drivehierarchy.envs.r4 import STATE_FIELDS, DriveHierarchyR4Env
from drivehierarchy.scenarios import builtin_root, builtin_scenarios

PED = builtin_root() / "r4" / "01_pedestrian" / "town01_01_midblock_crossing.toml"
BRAKE = builtin_root() / "r4" / "07_sudden_brake" / "town01_07_lead_brakes.toml"
TURN = builtin_root() / "r4" / "03_turning" / "town01_03_right_turn_signalised.toml"
# Score-record fields measuring wall-clock time (names before/after protocol v2).
WALL_CLOCK_KEYS = ("wall_duration", "duration_system")
STATE_ONLY = R4Config(front=None, bev=None, prompt=False)


@pytest.mark.parametrize(
    "cfg",
    [
        WrapperConfig(),
        WrapperConfig(action="raw", reward="score"),
        WrapperConfig(obs="bev", bev_size=64),
        WrapperConfig(obs="state+bev", bev_size=64),
    ],
    ids=["state-decision-shaped", "state-raw-score", "bev", "state+bev"],
)
def test_gymnasium_and_sb3_checkers_pass(cfg: WrapperConfig) -> None:
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = make_env([PED, BRAKE], cfg, monitor=False)
    gym_check(env, skip_render_check=True)
    sb3_check(env, warn=True)
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs)
    env.close()


def test_action_codec_maps_the_box_and_round_trips() -> None:
    dec = ActionCodec(WrapperConfig(max_speed_mps=16.0))
    np.testing.assert_allclose(dec.decode(np.array([-1.0, -1.0])), [-1.0, 0.0])
    np.testing.assert_allclose(dec.decode(np.array([0.5, 0.0])), [0.5, 8.0])  # untrained policy drives
    np.testing.assert_allclose(dec.decode(np.array([1.0, 1.0])), [1.0, 16.0])
    np.testing.assert_allclose(dec.decode(np.array([3.0, 9.0])), [1.0, 16.0])  # clipped
    a = np.array([0.3, -0.4], np.float32)
    np.testing.assert_allclose(dec.encode(dec.decode(a)), a, atol=1e-6)
    raw = ActionCodec(WrapperConfig(action="raw"))
    np.testing.assert_allclose(raw.decode(np.array([0.2, 0.5])), [0.5, 0.0, 0.2])  # throttle, brake, steer
    np.testing.assert_allclose(raw.decode(np.array([-0.2, -0.7])), [0.0, 0.7, -0.2])
    np.testing.assert_allclose(raw.encode(raw.decode(a)), a, atol=1e-6)


def test_obs_codec_scales_state_and_one_hots_the_command() -> None:
    env = DriveHierarchyR4Env(scenario=PED, config=STATE_ONLY)
    obs, _ = env.reset(seed=0)
    codec = ObsCodec(WrapperConfig())
    x = codec.state(obs["state"])
    assert x.shape == (len(STATE_FIELDS) - 1 + 6,) and x.dtype == np.float32
    cmd = int(obs["state"][STATE_FIELDS.index("command")])
    assert x[-6:].sum() == 1.0 and x[-6 + cmd - 1] == 1.0
    assert np.all(np.abs(x) <= 10.0)
    # The protocol's 800×800 BEV is never resized (that image differs from the one the policy
    # trained on): the world renders the policy's size instead, or the codec refuses.
    big = DriveHierarchyR4Env(scenario=PED, config=R4Config(front=None, prompt=False))
    obs_big, _ = big.reset(seed=0)
    bev = ObsCodec(WrapperConfig(obs="bev", bev_size=128))
    img = bev.bev(obs_big, big.sim)
    assert img.shape == (128, 128, 3) and img.dtype == np.uint8 and img.std() > 0
    with pytest.raises(ConfigError, match=r"`bev.size_px` = 800"):
        bev.bev(obs_big)


@pytest.mark.parametrize("protocol_bev", [False, True], ids=["runner-drops-images", "with-800px-bev"])
def test_a_bev_policy_sees_byte_identical_images_in_training_and_at_evaluation(
    tmp_path: Path, protocol_bev: bool
) -> None:
    """Same scenario, seed and actions: the `sb3:` agent's observation on the evaluation env
    (the runner's config: protocol images dropped, or the 800×800 BEV kept, as with `--frames`)
    equals DAgger's (`SuiteEnv` + `ObsCodec`) and PPO's (`make_env`) training observation."""
    from drivehierarchy.agents.sb3 import Sb3Agent
    from drivehierarchy.baselines.imitation import new_policy_model
    from drivehierarchy.baselines.model_io import save_model

    wrapper = WrapperConfig(obs="bev")
    path = save_model(new_policy_model(wrapper, [TURN]), tmp_path / "m.zip", "ppo", wrapper)
    agent = Sb3Agent(path)
    assert agent.uses_images is False  # it renders its own BEV; the runner may drop the protocol's
    config = R4Config() if protocol_bev else R4Config().replace(front=None, bev=None)
    ev = DriveHierarchyR4Env(scenario=TURN, config=config)
    dagger = SuiteEnv([TURN], wrapper.env_config(STATE_ONLY), order="cycle")
    ppo = make_env([TURN], wrapper, monitor=False)
    obs_ev, info = ev.reset(seed=3)
    agent.reset(ev, info)
    obs_dagger, _ = dagger.reset(seed=3)
    obs_ppo, _ = ppo.reset(seed=3)
    codec, actions = ObsCodec(wrapper), ActionCodec(wrapper)
    for _ in range(30):
        seen = agent.observe(obs_ev)
        assert seen.shape == (128, 128, 3) and seen.dtype == np.uint8
        assert seen.tobytes() == codec.encode(obs_dagger).tobytes() == obs_ppo.tobytes()
        a = ev.expert_action()
        obs_ev, _, end, trunc, _ = ev.step(a)
        obs_dagger, *_ = dagger.step(a)
        obs_ppo, *_ = ppo.step(actions.encode(a))
        if end or trunc:
            break
    assert ev.sim.score()["decisions"] >= 30


def test_shaped_reward_never_changes_the_benchmark_score() -> None:
    """Same scenario, seed and actions: the shaped env's score record equals the plain env's."""
    actions = [np.array([0.0, 0.2], np.float32)] * 40 + [np.array([0.05, -0.5], np.float32)] * 200
    records, returns = [], []
    for reward in ("shaped", "score"):
        env = make_env([BRAKE], WrapperConfig(reward=reward), monitor=False)
        env.reset(seed=3)
        total_env = 0.0
        for a in actions:
            _, _, term, trunc, info = env.step(a)
            total_env += info.get("score_reward", 0.0) if reward == "shaped" else 0.0
            if term or trunc:
                break
        record = env.unwrapped.score()
        for key in WALL_CLOCK_KEYS:  # wall-clock time, the one non-simulated field
            record["meta"].pop(key, None)
        records.append(record)
        returns.append(total_env)
    assert records[0] == records[1]
    # The env's own rewards (kept in info) still sum to S_R4 / 100.
    assert returns[0] == pytest.approx(records[0]["score_composed"] / 100.0, abs=1e-6)


def test_split_is_by_file_stable_and_validated() -> None:
    suite = builtin_scenarios()
    train, held = split_suite(suite, 0.3)
    assert len(held) == 30 and len(train) == 70 and not set(train) & set(held)
    assert split_suite(list(reversed(suite)), 0.3)[1] == sorted(held, key=list(reversed(suite)).index)
    train2, held2 = split_suite(suite, ["01_pedestrian/town01_01_midblock_crossing"])
    assert [p.parent.name for p in held2] == ["01_pedestrian"] and len(train2) == 99
    with pytest.raises(ConfigError, match="99_none/x"):
        split_suite(suite, ["99_none/x"])
    with pytest.raises(ConfigError, match="held_out"):
        split_suite(suite, 1.0)


def test_suite_env_samples_with_the_seed_and_is_deterministic() -> None:
    def episode(seed: int) -> tuple[list[str], list[str]]:
        env = SuiteEnv([PED, BRAKE], STATE_ONLY)
        picked, hashes = [], []
        env.reset(seed=seed)
        for _ in range(6):
            _, info = env.reset()
            picked.append(Path(info["scenario"]).parent.name)
            res = run_episode(env, ExpertAgent(), options={"scenario": info["scenario"]}, max_steps=20)
            hashes.append(res.score["ticks"])
        return picked, [str(h) for h in hashes]

    a, b = episode(7), episode(7)
    assert a == b
    assert set(a[0]) == {"01_pedestrian", "07_sudden_brake"}
    # The expert drives through the sampler unchanged (privileged access follows the scenario).
    env = SuiteEnv([PED, BRAKE], STATE_ONLY, order="cycle")
    scores = [run_episode(env, ExpertAgent()).score["score_composed"] for _ in range(2)]
    assert min(scores) >= 90.0


def test_registry_prefix_resolves_and_errors_clearly(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="file not found"):
        runner.AGENTS.create(f"sb3:{tmp_path / 'missing.zip'}")
    bad = tmp_path / "plain.zip"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ConfigError, match="not a zip"):
        runner.AGENTS.create(f"sb3:{bad}")
    with pytest.raises(ConfigError, match="unknown agent"):
        runner.AGENTS.create("nope:thing")
    assert "sb3:..." in runner.AGENTS.names()
    reg = runner.AgentRegistry()
    reg.register_prefix("k", lambda arg: runner.ConstantAgent([0.0, float(arg)], name=f"k:{arg}"))
    assert reg.create("k:3").name == "k:3"
    with pytest.raises(ValueError, match="already"):
        reg.register_prefix("k", lambda arg: runner.ConstantAgent([0.0, 0.0]))


def test_wrapped_env_is_deterministic_for_seed_and_actions() -> None:
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (300, 2)).astype(np.float32)
    runs = []
    for _ in range(2):
        env = make_env([PED, BRAKE], WrapperConfig(), monitor=False)
        obs, info = env.reset(seed=11)
        trace = [("reset", info["scenario"], obs.tobytes())]
        for a in actions:
            obs, r, term, trunc, info = env.step(a)
            trace.append(("step", r, obs.tobytes()))
            if term or trunc:
                obs, info = env.reset()
                trace.append(("reset", info["scenario"], obs.tobytes()))
        runs.append(trace)
    assert runs[0] == runs[1]
    assert sum(t[0] == "reset" for t in runs[0]) >= 2


def test_gymnasium_async_vector_env_runs_the_wrappers() -> None:
    import gymnasium as gym

    def make() -> gym.Env:
        return make_env([PED, BRAKE], WrapperConfig(), monitor=False)

    venv = gym.vector.AsyncVectorEnv([make, make])
    try:
        obs, _ = venv.reset(seed=[1, 2])
        assert obs.shape == (2, ObsCodec(WrapperConfig()).state_dim)
        for _ in range(50):
            obs, rew, _, _, _ = venv.step(np.zeros((2, 2), np.float32))
        assert np.all(np.isfinite(obs)) and rew.shape == (2,)
    finally:
        venv.close()


def test_sb3_vec_envs_in_subprocesses_and_in_process() -> None:
    from drivehierarchy.baselines.rl import make_vec_env

    for vec in ("subproc", "dummy"):
        venv = make_vec_env([PED, BRAKE], WrapperConfig(), 2, seed=5, vec=vec)
        try:
            obs = venv.reset()
            assert obs.shape == (2, ObsCodec(WrapperConfig()).state_dim)
            for _ in range(30):
                obs, rew, _, _ = venv.step(np.zeros((2, 2), np.float32))
            assert np.all(np.isfinite(obs)) and rew.shape == (2,)
        finally:
            venv.close()
    with pytest.raises(ConfigError, match="vec"):
        make_vec_env([PED], WrapperConfig(), 1, vec="threads")


def test_sumo_scenarios_share_the_process_simulation_or_get_a_process_each() -> None:
    from drivehierarchy.baselines.rl import make_vec_env, sumo_scenarios

    flow = next(p for p in builtin_scenarios() if p.parent.name == "06_traffic_flow")
    brake = next(p for p in builtin_scenarios() if p.parent.name == "07_sudden_brake")
    cfg = R4Config(front=None, bev=None, prompt=False)
    # A sampler leaving a SUMO scenario gives the process's libsumo back, so another env of the
    # same process can use it.
    a = SuiteEnv([flow, brake], cfg, order="cycle")
    b = SuiteEnv([flow, brake], cfg, order="cycle")
    a.reset(seed=0)
    a.reset(seed=1)  # a moves on to 07
    obs, _ = b.reset(seed=0)  # b co-simulates 06 now
    assert b.current.traffic_mode == "sumo" and np.isfinite(obs["state"]).all()
    a.close()
    b.close()
    assert sumo_scenarios([str(flow), str(brake)], WrapperConfig()) == [str(flow)]
    # In-process vectorisation (SB3's DummyVecEnv) runs two SUMO simulations at once: the
    # second env's on TraCI.
    venv = make_vec_env([flow], WrapperConfig(), 2, vec="dummy")
    try:
        obs = venv.reset()
        envs = [e.unwrapped for e in venv.envs]
        assert all(e.current.traffic_mode == "sumo" for e in envs)
        transports = sorted(e.current.unwrapped._sumo.transport for e in envs)
        assert len(transports) == 2 and "traci" in transports, transports
        for _ in range(20):
            obs, rew, _, _ = venv.step(np.zeros((2, 2), np.float32))
        assert np.all(np.isfinite(obs)) and rew.shape == (2,)
    finally:
        venv.close()
    venv = make_vec_env([flow, brake], WrapperConfig(traffic="idm"), 2, vec="dummy")
    venv.reset()
    venv.close()


def test_stratified_scenario_split_is_70_30_by_category_and_stable() -> None:
    from drivehierarchy.baselines.splits import make_split, scenario_id, stratified_split

    suite = runner.suite_scenarios("builtin")
    train, test = stratified_split(suite, 0.3)
    assert len(train) == 70 and len(test) == 30
    per_cat: dict[str, int] = {}
    for p in test:
        per_cat[p.parent.name] = per_cat.get(p.parent.name, 0) + 1
    assert set(per_cat.values()) == {3} and len(per_cat) == 10
    # The order of the files does not matter; the split is recorded by id.
    assert {scenario_id(p) for p in stratified_split(list(reversed(suite)), 0.3)[1]} == {
        scenario_id(p) for p in test
    }
    split = make_split(suite, "scenarios")
    record = split.to_dict()
    assert record["kind"] == "scenarios" and record["test_seeds"] == [0, 1, 2, 3, 4]
    assert record["train_seeds"][0] == 100_000 and not set(record["train"]) & set(record["test"])
    seeds = make_split(suite, "seeds").to_dict()
    assert seeds["train"] == seeds["test"] and len(seeds["train"]) == 100
    with pytest.raises(ConfigError, match="test_fraction"):
        stratified_split(suite, 1.0)
    with pytest.raises(ConfigError, match="split"):
        make_split(suite, "bogus")  # type: ignore[arg-type]


def test_training_envs_never_play_a_test_seed() -> None:
    """With train_seeds, an explicit reset seed only seeds the draw: seeds 0-4 never reach a world."""
    env = SuiteEnv([PED, BRAKE], STATE_ONLY, train_seeds=(100_000, 2**31 - 1))
    played = []
    for s in [0, 1, 2, 3, 4, None, None]:
        _, info = env.reset(seed=s)
        played.append(info["episode_seed"])
    assert all(p >= 100_000 for p in played)
    _, again = env.reset(seed=0)
    assert again["episode_seed"] == played[0]  # the draw is seeded: deterministic
    with pytest.raises(ConfigError, match="train_seeds"):
        SuiteEnv([PED], STATE_ONLY, train_seeds=(5, 5))
    env.close()
