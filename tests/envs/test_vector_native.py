"""The native vector env (`vector_entry_point` of `DriveHierarchy-R4`): Gymnasium conformance,
equality with N single envs in a `SyncVectorEnv` step for step (autoresets included), determinism."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drivehierarchy  # noqa: F401  (registers the id)
from drivehierarchy import ConfigError
from drivehierarchy.envs.vector_native import DriveHierarchyR4VectorEnv, DropNoneInfo

SCENARIO = "03_turning/town01_03_right_turn_signalised"
OTHER = "07_sudden_brake/town01_07_lead_brakes"
NO_IMAGES: dict[str, Any] = {"front": None, "bev": None, "traffic": "idm"}
SMALL_IMAGES: dict[str, Any] = {
    "front": {"width": 64, "height": 36},
    "bev": {"size_px": 48},
    "traffic": "idm",
}


def native(n: int, **kw: Any) -> DriveHierarchyR4VectorEnv:
    env = gym.make_vec("DriveHierarchy-R4", num_envs=n, vectorization_mode="vector_entry_point", **kw)
    assert isinstance(env, DriveHierarchyR4VectorEnv)
    return env


def sync(n: int, scenarios: list[str] | None = None, **kw: Any) -> gym.vector.SyncVectorEnv:
    scenarios = scenarios or [SCENARIO] * n
    fns = [lambda s=s: DropNoneInfo(gym.make("DriveHierarchy-R4", scenario=s, **kw)) for s in scenarios]
    return gym.vector.SyncVectorEnv(fns)


def off_road_actions(steps: int, n: int) -> np.ndarray:
    """Env 0 steers off the road (terminates early, then autoresets); the others drive on."""
    acts = np.zeros((steps, n, 2), np.float32)
    acts[:, :, 1] = 6.0
    acts[:5, 0] = [0.24, 8.0]
    for i in range(1, n):
        acts[:, i, 0] = np.linspace(-0.05, 0.05, steps) * i
    return acts


def assert_same(a: Any, b: Any, where: str) -> None:
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for k in a:
            assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), f"{where}: {type(b)}"
        assert a.dtype == b.dtype and a.shape == b.shape, f"{where}: {a.dtype}{a.shape} vs {b.dtype}{b.shape}"
        if a.dtype == object:
            for i, (x, y) in enumerate(zip(a, b, strict=True)):
                assert_same(x, y, f"{where}[{i}]")
        else:
            np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, (list, tuple)):
        assert type(a) is type(b) and len(a) == len(b), f"{where}: {a!r} vs {b!r}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def rollout(env: gym.vector.VectorEnv, actions: np.ndarray, seed: int) -> list[tuple[Any, ...]]:
    out: list[tuple[Any, ...]] = [env.reset(seed=seed)]
    for a in actions:
        out.append(env.step(a))
    return out


# The trajectory hash of `info` differs if a single tick differs; `info["time_s"]` would too.
def test_equals_sync_vector_env_of_single_envs_across_autoreset() -> None:
    n, steps = 3, 60
    acts = off_road_actions(steps, n)
    kw = {**NO_IMAGES, "prompt": True}
    ours = rollout(native(n, scenario=SCENARIO, **kw), acts, seed=7)
    ref = rollout(sync(n, **kw), acts, seed=7)
    resets = 0
    for t, (x, y) in enumerate(zip(ours, ref, strict=True)):
        assert len(x) == len(y)
        for j, (p, q) in enumerate(zip(x, y, strict=True)):
            assert_same(p, q, f"step {t} item {j}")
        if t > 0:
            resets += int(x[2].sum())
    assert resets >= 1, "the actions were meant to end env 0's episode and autoreset it"
    # NEXT_STEP: the step after a termination is a reset (tick back at the warm-up, reward 0).
    t_end = next(t for t in range(1, len(ours)) if ours[t][2][0])
    assert ours[t_end + 1][1][0] == 0.0 and ours[t_end + 1][4]["tick"][0] == 4


def test_images_and_per_env_scenarios_equal_single_envs() -> None:
    n, steps = 2, 6
    scenarios = [SCENARIO, OTHER]
    acts = off_road_actions(steps, n)
    ours_env = native(n, scenario=scenarios, **SMALL_IMAGES)
    ours = rollout(ours_env, acts, seed=3)
    ref = rollout(sync(n, scenarios, **SMALL_IMAGES), acts, seed=3)
    obs = ours[-1][0]
    assert obs["front"].shape == (n, 36, 64, 3) and obs["front"].dtype == np.uint8
    assert obs["bev"].shape == (n, 48, 48, 3)
    assert ours_env.observation_space.contains(obs)
    for t, (x, y) in enumerate(zip(ours, ref, strict=True)):
        for j, (p, q) in enumerate(zip(x, y, strict=True)):
            assert_same(p, q, f"step {t} item {j}")


def test_spaces_equal_the_single_env() -> None:
    env = native(2, **SMALL_IMAGES, prompt=True, action_mode="raw")
    single = gym.make("DriveHierarchy-R4", **SMALL_IMAGES, prompt=True, action_mode="raw")
    assert env.single_observation_space == single.observation_space
    assert env.single_action_space == single.action_space
    assert env.action_space.shape == (2, 3)
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert isinstance(obs["prompt"], tuple) and len(obs["prompt"]) == 2 and obs["prompt"][0]
    assert info["_tick"].all()


def test_deterministic_across_runs() -> None:
    acts = off_road_actions(30, 2)
    a = rollout(native(2, **NO_IMAGES), acts, seed=11)
    b = rollout(native(2, **NO_IMAGES, threads=1), acts, seed=11)
    for t, (x, y) in enumerate(zip(a, b, strict=True)):
        for j, (p, q) in enumerate(zip(x, y, strict=True)):
            assert_same(p, q, f"step {t} item {j}")


def test_reset_option_switches_scenarios_per_env() -> None:
    env = native(2, **NO_IMAGES)
    ids = [
        gym.make("DriveHierarchy-R4", scenario=s, **NO_IMAGES).unwrapped.sim.scenario_id
        for s in (SCENARIO, OTHER)
    ]
    assert env.scenario_ids == [ids[0], ids[0]]
    env.reset(seed=0, options={"scenario": [None, OTHER]})
    assert env.scenario_ids == ids
    env.reset(seed=0, options={"scenario": OTHER})
    assert env.scenario_ids == [ids[1], ids[1]]
    with pytest.raises(ConfigError, match=r"options\.scenario"):
        env.reset(options={"scenario": [OTHER]})
    with pytest.raises(ConfigError, match="reset_mask"):  # supported, but must be a (num_envs,) bool mask
        env.reset(options={"reset_mask": np.ones(3, bool)})
    with pytest.raises(ConfigError, match=r"options\.bogus"):
        env.reset(options={"bogus": 1})


def test_sumo_traffic_is_refused_with_the_scenario_named() -> None:
    with pytest.raises(
        ConfigError, match=r"traffic.*'sumo'.*town01_03_right_turn_signalised.*traffic=\"idm\""
    ):
        native(2, scenario=SCENARIO, front=None, bev=None, traffic="sumo")
    # A scenario whose own `[traffic]` mode is SUMO: refused by default, runs with native IDM.
    sumo_scenario = "06_traffic_flow/bs3d_09_left_turner_queue"
    with pytest.raises(ConfigError, match="bs3d_09_left_turner_queue"):
        native(2, scenario=sumo_scenario, front=None, bev=None)
    env = native(2, scenario=sumo_scenario, **NO_IMAGES)
    assert env.reset(seed=0)[0]["state"].shape[0] == 2


def test_bad_actions_and_lifecycle_errors() -> None:
    env = native(2, **NO_IMAGES)
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros((2, 2)))
    env.reset(seed=0)
    with pytest.raises(ConfigError, match="expected shape"):
        env.step(np.zeros((3, 2)))
    with pytest.raises(ConfigError, match=r"actions\[1\]"):
        env.step(np.array([[0.0, 1.0], [np.nan, 1.0]]))
    env.close()
    with pytest.raises(gym.error.ClosedEnvironmentError):
        env.reset()


def test_gymnasium_vector_env_checks() -> None:
    # Gymnasium 1.x has no vector-env checker (`check_env` and `check_environments_match` take
    # single envs); these are what its own vector tests assert: batched spaces, the autoreset
    # mode in metadata, seeded resets reproducible, dtypes of rewards and flags.
    env = native(3, **NO_IMAGES)
    assert env.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    assert env.observation_space == gym.vector.utils.batch_space(env.single_observation_space, 3)
    assert env.action_space == gym.vector.utils.batch_space(env.single_action_space, 3)
    o1, _ = env.reset(seed=5)
    o2, _ = env.reset(seed=5)
    assert_same(o1, o2, "reset")
    obs, rew, term, trunc, _ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
    assert rew.shape == (3,) and rew.dtype == np.float64
    assert term.dtype == np.bool_ and trunc.dtype == np.bool_
    env.close()
