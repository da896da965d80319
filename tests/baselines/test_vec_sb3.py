"""The SB3 `VecEnv` over the native vector env (`baselines.vec_sb3.NativeSuiteVecEnv`): equal to
SB3's `DummyVecEnv` of the single learner envs step for step (autoresets, terminal observations,
shaped rewards, scenario and seed draws included), SB3's own checks, and PPO training on it."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

from drivehierarchy._core import ConfigError
from drivehierarchy.baselines.splits import TRAIN_SEED_MAX, TRAIN_SEED_MIN
from drivehierarchy.baselines.vec_sb3 import NativeSuiteVecEnv
from drivehierarchy.baselines.wrappers import WrapperConfig, make_env
from drivehierarchy.envs.vector_native import drop_none
from drivehierarchy.scenarios import builtin_root

R4 = builtin_root() / "r4"
SUITE = [
    R4 / "03_turning" / "town01_03_right_turn_signalised.toml",
    R4 / "07_sudden_brake" / "town01_07_lead_brakes.toml",
    R4 / "02_obstacles" / "town01_02_cones_right_lane.toml",
]
SEEDS = (TRAIN_SEED_MIN, TRAIN_SEED_MAX)


def dummy(n: int, wrapper: WrapperConfig, **kw: Any) -> DummyVecEnv:
    return DummyVecEnv([lambda: make_env(SUITE, wrapper, monitor=False, **kw) for _ in range(n)])


def same(a: Any, b: Any, where: str) -> None:
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), f"{where}: {sorted(a)} != {sorted(b)}"
        for k in a:
            same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (np.ndarray, np.generic)) or isinstance(b, (np.ndarray, np.generic)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=where)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def actions(rng: np.random.Generator, n: int, t: int) -> np.ndarray:
    """Mostly ahead at a moderate speed; env 0 swerves now and then, so episodes end (off road,
    collisions) at different steps in different envs and autoresets interleave."""
    a = np.zeros((n, 2), np.float32)
    a[:, 0] = rng.normal(0.0, 0.05, n)
    a[:, 1] = rng.uniform(-0.2, 0.6, n)
    if t % 40 < 6:
        a[0, 0] = 0.9
    return a


@pytest.mark.parametrize(
    "wrapper,kw",
    [
        (WrapperConfig(traffic="idm"), {"train_seeds": SEEDS}),
        (WrapperConfig(traffic="idm", obs="state+bev", bev_size=32, reward="score"), {"order": "cycle"}),
    ],
    ids=["state-shaped-train-seeds", "state+bev-cycle"],
)
def test_equals_dummy_vec_env_of_single_learner_envs(wrapper: WrapperConfig, kw: dict[str, Any]) -> None:
    n, steps = 3, 150
    ref, nat = dummy(n, wrapper, **kw), NativeSuiteVecEnv(SUITE, wrapper, n, threads=2, **kw)
    for v in (ref, nat):
        v.seed(7)
    o_ref, o_nat = ref.reset(), nat.reset()
    same(o_nat, o_ref, "reset obs")
    for i in range(n):
        same(drop_none(nat.reset_infos[i]), drop_none(ref.reset_infos[i]), f"reset_infos[{i}]")
    rng = np.random.default_rng(0)
    ends = 0
    for t in range(steps):
        a = actions(rng, n, t)
        o_ref, r_ref, d_ref, i_ref = ref.step(a)
        o_nat, r_nat, d_nat, i_nat = nat.step(a)
        same(o_nat, o_ref, f"step {t} obs")
        same(r_nat, r_ref, f"step {t} reward")
        same(d_nat, d_ref, f"step {t} done")
        for i in range(n):
            same(drop_none(i_nat[i]), drop_none(i_ref[i]), f"step {t} info[{i}]")
            if d_ref[i]:
                same(
                    drop_none(nat.reset_infos[i]), drop_none(ref.reset_infos[i]), f"step {t} reset_infos[{i}]"
                )
        ends += int(d_ref.sum())
    assert ends >= 3, "the actions should end several episodes"
    if "train_seeds" in kw:
        assert all(s is not None and s >= TRAIN_SEED_MIN for s in nat.episode_seeds)
    ref.close()
    nat.close()


def test_sb3_checks_and_a_short_ppo_run() -> None:
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecCheckNan

    wrapper = WrapperConfig(traffic="idm")
    # SB3's check_env is for single envs: the learner env this batch equals passes it.
    check_env(make_env(SUITE, wrapper, monitor=False))
    venv = VecCheckNan(
        VecMonitor(NativeSuiteVecEnv(SUITE, wrapper, 4, threads=2), info_keywords=("termination_reason",))
    )
    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    assert model.num_timesteps == 256
    assert venv.get_attr("render_mode") == [None] * 4
    [score] = venv.env_method("score", indices=[1])
    assert "score_composed" in score
    with pytest.raises(ConfigError, match="env_method"):
        venv.env_method("expert_action")
    venv.close()


def test_partial_reset_mask_keeps_the_other_envs() -> None:
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    env = gym.make_vec(
        "DriveHierarchy-R4",
        num_envs=3,
        vectorization_mode="vector_entry_point",
        scenario=[str(p) for p in SUITE],
        traffic="idm",
        front=None,
        bev=None,
        autoreset_mode=AutoresetMode.DISABLED,
    )
    obs, _ = env.reset(seed=1)
    act = np.tile(np.array([[0.0, 6.0]]), (3, 1))
    for _ in range(5):
        obs, *_ = env.step(act)
    mask = np.array([False, True, False])
    obs2, info = env.reset(seed=[None, 2, None], options={"reset_mask": mask})
    np.testing.assert_array_equal(obs2["state"][[0, 2]], obs["state"][[0, 2]])
    assert info["_speed_mps"].tolist() == [False, True, False]  # infos of the reset env only
    fresh, _ = gym.make(
        "DriveHierarchy-R4", scenario=str(SUITE[1]), traffic="idm", front=None, bev=None
    ).reset(seed=2)
    np.testing.assert_array_equal(obs2["state"][1], fresh["state"])
    with pytest.raises(ConfigError, match="reset_mask"):
        env.reset(options={"reset_mask": np.zeros(3, np.bool_)})
    # DISABLED: an ended episode is not restarted behind the caller's back.
    swerve = np.tile(np.array([[0.6, 10.0]]), (3, 1))
    for _ in range(300):
        _, _, term, _, _ = env.step(swerve)
        if term.any():
            break
    assert term.any()
    with pytest.raises(gym.error.ResetNeeded, match="DISABLED"):
        env.step(swerve)
    env.close()
