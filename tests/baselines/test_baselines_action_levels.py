"""RL and imitation at every action level (docs/baselines.md#action-levels): the wrapped env passes
SB3's checker with the level's policy action space, `collect` labels with the expert's plan at
the level, BC learns it (regression on the Box levels, classification on meta), the model carries
its level so `r4 evaluate --agent sb3:` drives it there and refuses another, and the native batch
equals SB3's `DummyVecEnv` at the waypoint and meta levels. CI-sized: a few hundred steps each."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("minari")

from gymnasium import spaces
from parity_helpers import wrapped_and_runner_records
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.vec_env import DummyVecEnv

from drivehierarchy._core import ConfigError
from drivehierarchy.agents.sb3 import Sb3Agent
from drivehierarchy.baselines.imitation import DATASET_ID, load_demos
from drivehierarchy.baselines.model_io import read_meta
from drivehierarchy.baselines.vec_sb3 import NativeSuiteVecEnv
from drivehierarchy.baselines.wrappers import ActionCodec, WrapperConfig, make_env
from drivehierarchy.cli import main
from drivehierarchy.envs.vector_native import drop_none
from drivehierarchy.scenarios import builtin_root

LEVELS = ("control", "waypoints", "meta")
R4 = builtin_root() / "r4"
SCENARIO = R4 / "07_sudden_brake" / "town01_07_lead_brakes.toml"
SUITE = [SCENARIO, R4 / "03_turning" / "town01_03_right_turn_signalised.toml"]


@pytest.fixture(scope="module", autouse=True)
def deterministic_torch() -> Iterator[None]:
    import torch

    threads, strict = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)
    yield
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(strict)


def cli(*args: object) -> None:
    assert main([str(a) for a in args]) == 0


@pytest.mark.parametrize("level", LEVELS)
def test_the_wrapped_env_passes_sb3s_checker_with_the_levels_action_space(level: str) -> None:
    wrapper = WrapperConfig(action_level=level)  # type: ignore[arg-type]
    env = make_env([SCENARIO], wrapper, monitor=False)
    check_env(env, warn=True)
    expected = {
        "control": spaces.Box(-1.0, 1.0, (2,), np.float32),
        "waypoints": spaces.Box(-1.0, 1.0, (8, 2), np.float32),
        "meta": spaces.MultiDiscrete([6, 4]),
    }[level]
    assert env.action_space == expected
    assert env.unwrapped.current.config.action_mode == wrapper.env_action_mode
    # Every policy action decodes to an action the env accepts.
    codec = ActionCodec(wrapper)
    env.action_space.seed(0)
    for _ in range(50):
        assert env.unwrapped.action_space.contains(codec.decode(env.action_space.sample()))


def test_waypoint_codec_maps_the_policys_box_to_reachable_plans_and_back() -> None:
    codec = ActionCodec(WrapperConfig(action_level="waypoints", max_speed_mps=10.0))
    reach = 10.0 * 0.5 * np.arange(1, 9)
    # a = 0: straight on at half max speed; a = (1, ±1): max speed's reach forward and sideways.
    np.testing.assert_allclose(codec.decode(np.zeros((8, 2))), np.c_[reach / 2, np.zeros(8)], rtol=1e-6)
    np.testing.assert_allclose(codec.decode(np.ones((8, 2))), np.c_[reach, reach], rtol=1e-6)
    np.testing.assert_allclose(codec.decode(-np.ones((8, 2))), np.c_[np.zeros(8), -reach], rtol=1e-6)
    plan = np.c_[np.linspace(2.0, 16.0, 8), np.linspace(0.0, -3.0, 8)].astype(np.float32)
    np.testing.assert_allclose(codec.decode(codec.encode(plan)), plan, atol=1e-5)
    # Beyond the reach, points are clipped into it (the policy cannot express them).
    assert codec.decode(codec.encode(plan * 10.0))[-1, 0] == pytest.approx(reach[-1])
    meta = ActionCodec(WrapperConfig(action_level="meta"))
    np.testing.assert_array_equal(meta.decode(np.array([9, -2])), [5, 0])


def test_raw_control_is_the_control_level_only() -> None:
    with pytest.raises(ConfigError, match=r"`action` = 'raw'.*`action_level` is 'meta'"):
        WrapperConfig(action="raw", action_level="meta")
    with pytest.raises(ConfigError, match="`action_level` = 'pixels'"):
        WrapperConfig(action_level="pixels")  # type: ignore[arg-type]
    # A model saved before the levels existed reads as the control level.
    old = WrapperConfig().to_dict()
    for key in ("action_level", "waypoints", "waypoint_dt_s"):
        old.pop(key)
    assert WrapperConfig.from_dict(old).action_level == "control"


@pytest.fixture(scope="module")
def demos(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = {}
    for level in LEVELS:
        data = tmp_path_factory.mktemp(f"demos_{level}")
        # Twice the scenario: once clean, once with the level's DART noise.
        cli(
            *("baselines", "collect", "--suite", SCENARIO, "--episodes", "2", "--out", data),
            *("--action-level", level),
        )
        out[level] = data
    return out


@pytest.mark.parametrize("level", LEVELS)
def test_collect_labels_every_step_with_the_experts_plan_at_the_level(
    demos: dict[str, Path], level: str
) -> None:
    import minari

    data = demos[level]
    meta = json.loads((data / "collect.json").read_text())
    assert meta["action_level"] == level and meta["mean_score"] > 80.0
    os.environ["MINARI_DATASETS_PATH"] = str(data)
    ds = minari.load_dataset(DATASET_ID)
    shape = {"control": (2,), "waypoints": (8, 2), "meta": (2,)}[level]
    assert ds.action_space.shape == shape
    assert isinstance(ds.action_space, spaces.MultiDiscrete) == (level == "meta")
    clean, noisy = list(ds.iterate_episodes())
    for ep, executed_is_label in ((clean, True), (noisy, False)):
        n = len(ep.actions)
        labels = np.asarray(ep.infos["expert_action"][:n])
        assert labels.shape == (n, *shape) and n > 100
        # The clean episode drives the labels; the noisy one drives perturbed plans, labelled clean.
        assert bool(np.array_equal(np.asarray(ep.actions), labels)) == executed_is_label
    states, labels = load_demos(data)
    assert len(states) == len(labels) == ds.total_steps
    if level == "meta":
        assert labels.dtype == np.int64 and set(labels[:, 0]) <= set(range(6))
        assert len(set(labels[:, 1].tolist())) >= 2  # the expert changes speed actions
    elif level == "waypoints":
        assert labels[:, -1, 0].max() > 20.0  # 4 s ahead at speed


@pytest.mark.parametrize("level", LEVELS)
def test_bc_learns_the_levels_labels_records_the_level_and_evaluates_there(
    demos: dict[str, Path], level: str, tmp_path: Path
) -> None:
    out = tmp_path / "bc"
    # No --action-level: BC trains at the dataset's level.
    cli(
        "baselines",
        "train",
        "bc",
        "--data",
        demos[level],
        "--suite",
        SCENARIO,
        "--epochs",
        "40",
        "--out",
        out,
    )
    model = out / "model.zip"
    wrapper = read_meta(model)["wrapper"]
    assert wrapper["action_level"] == level and wrapper["waypoints"] == 8
    # Fits the expert on its own demonstrations (a broken loss or label encoding would not).
    agent = Sb3Agent(model)
    states, labels = load_demos(demos[level])
    x = np.stack([agent.obs_codec.state(s) for s in states])
    pred, _ = agent.model.predict(x, deterministic=True)
    decoded = np.stack([agent.action_codec.decode(a) for a in pred])
    if level == "meta":
        # Better than always answering the most common pair (about 2/3 of the labels here).
        _, counts = np.unique(labels, axis=0, return_counts=True)
        assert np.mean(np.all(decoded == labels, axis=1)) > counts.max() / len(labels) + 0.08
    elif level == "waypoints":
        assert np.median(np.abs(decoded - labels)[:, -1, :]) < 2.0  # metres, 4 s ahead
    else:
        assert np.median(np.abs(decoded[:, 1] - labels[:, 1])) < 1.0  # m/s
    # `r4 evaluate` drives the model at its level without being told.
    ev = tmp_path / "ev"
    cli("r4", "evaluate", "--agent", f"sb3:{model}", "--suite", SCENARIO, "--out", ev)
    [line] = [json.loads(x) for x in (ev / "results.jsonl").read_text().splitlines()]
    assert line["action_level"] == level and line["score"]["decisions"] > 0
    decisions = (ev / "scenes" / line["key"] / "decisions.jsonl").read_text().splitlines()
    assert decisions
    # The same level, asked for explicitly, is accepted.
    cli(
        "r4", "evaluate", "--agent", f"sb3:{model}", "--action-level", level, "--suite", SCENARIO, "--out", ev
    )


def test_another_level_than_the_models_or_the_datasets_is_refused(
    demos: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "bc"
    cli("baselines", "train", "bc", "--data", demos["waypoints"], "--epochs", "1", "--out", out)
    model = f"sb3:{out / 'model.zip'}"
    args = ["r4", "evaluate", "--agent", model, "--suite", str(SCENARIO), "--out", str(tmp_path / "ev")]
    assert main([*args, "--action-level", "meta"]) == 2
    err = capsys.readouterr().err
    assert "`action_level` = 'meta'" in err and "decides at the 'waypoints' level" in err
    assert not (tmp_path / "ev").exists()
    # The Python API is checked as well, before anything is written.
    from drivehierarchy.benchmark.r4 import runner

    with pytest.raises(ConfigError, match="decides at the 'waypoints' level"):
        runner.evaluate([SCENARIO], tmp_path / "ev", runner.RunOptions(agent=model, action_level="control"))
    assert not (tmp_path / "ev").exists()
    # The agent itself refuses an env of another mode.
    from drivehierarchy.envs.r4 import DriveHierarchyR4Env

    env = DriveHierarchyR4Env(scenario=SCENARIO, front=None, bev=None, action_mode="meta")
    with pytest.raises(ConfigError, match="trained with action mode 'waypoints'"):
        Sb3Agent(out / "model.zip").reset(env, {})
    # Demonstrations of one level do not train another.
    argv = ["baselines", "train", "bc", "--data", str(demos["meta"]), "--out", str(tmp_path / "x")]
    assert main([*argv, "--action-level", "waypoints"]) == 2
    err = capsys.readouterr().err
    assert "collect.json: field `action_level` = 'meta'" in err
    # SAC has no MultiDiscrete policy.
    assert main(["baselines", "train", "sac", "--action-level", "meta", "--out", str(tmp_path / "s")]) == 2
    assert "SAC needs a continuous (Box) action space" in capsys.readouterr().err


def test_the_agent_drives_exactly_like_the_training_wrappers_at_the_waypoint_level(
    demos: dict[str, Path], tmp_path: Path
) -> None:
    out = tmp_path / "bc"
    cli("baselines", "train", "bc", "--data", demos["waypoints"], "--epochs", "5", "--out", out)
    wrapped, via_runner = wrapped_and_runner_records(out / "model.zip", SCENARIO, tmp_path / "ev")
    assert via_runner == wrapped


def test_dagger_and_ppo_train_at_the_meta_level(tmp_path: Path) -> None:
    """DAgger's online expert labels meta actions and fits them by cross-entropy; PPO trains a
    MultiDiscrete policy on the native batch."""
    out = tmp_path / "dagger"
    cli(
        *("baselines", "train", "dagger", "--suite", SCENARIO, "--action-level", "meta"),
        *("--iterations", "1", "--episodes-per-iter", "1", "--epochs", "4", "--out", out),
    )
    with np.load(out / "rounds" / "round_001.npz") as z:
        assert z["y"].dtype == np.int64 and z["y"].shape[1:] == (2,)
    assert read_meta(out / "model.zip")["wrapper"]["action_level"] == "meta"
    ppo = tmp_path / "ppo"
    cli(
        *("baselines", "train", "ppo", "--suite", SCENARIO, "--action-level", "meta", "--vec", "native"),
        *("--traffic", "idm", "--envs", "2", "--steps", "128", "--hp", "n_steps=64", "--out", ppo),
    )
    agent = Sb3Agent(ppo / "model.zip")
    assert agent.wrapper.action_level == "meta"
    assert isinstance(agent.model.action_space, spaces.MultiDiscrete)


def same(a: object, b: object, where: str) -> None:
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), f"{where}: {sorted(a)} != {sorted(b)}"
        for k in a:
            same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (np.ndarray, np.generic)) or isinstance(b, (np.ndarray, np.generic)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b), err_msg=where)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


@pytest.mark.parametrize("level", ["waypoints", "meta"])
def test_the_native_batch_equals_dummy_vec_env_at_the_level(level: str) -> None:
    wrapper = WrapperConfig(traffic="idm", action_level=level)  # type: ignore[arg-type]
    n = 2
    ref = DummyVecEnv([lambda: make_env(SUITE, wrapper, monitor=False) for _ in range(n)])
    nat = NativeSuiteVecEnv(SUITE, wrapper, n, threads=2)
    assert nat.action_space == ref.action_space
    for v in (ref, nat):
        v.seed(3)
    same(nat.reset(), ref.reset(), "reset obs")
    space = ref.action_space
    space.seed(0)
    ends = 0
    for t in range(120):
        # Random plans now and then (episodes end at different steps), else straight on.
        a = np.stack([space.sample() if t % 30 < 4 else np.zeros(space.shape, space.dtype) for _ in range(n)])
        o_ref, r_ref, d_ref, i_ref = ref.step(a)
        o_nat, r_nat, d_nat, i_nat = nat.step(a)
        same(o_nat, o_ref, f"obs {t}")
        np.testing.assert_allclose(r_nat, r_ref, rtol=1e-6, err_msg=f"rewards {t}")
        same(d_nat, d_ref, f"dones {t}")
        for i in range(n):
            keys = ("best_progress_m", "termination_reason", "score_reward")
            same(
                {k: drop_none(i_nat[i]).get(k) for k in keys},
                {k: drop_none(i_ref[i]).get(k) for k in keys},
                f"info {t}.{i}",
            )
        ends += int(d_ref.sum())
    assert ends >= 1
    nat.close()
    ref.close()
