"""CI-sized end to end (≈ 1–2 min on 2 cores): collect expert demonstrations (Minari), train BC and
PPO through the CLI, save, resume after a kill at a step count, and score the models through
`r4 evaluate` exactly like any other agent. Seeded, single-threaded, deterministic torch. Whether
PPO learns is measured by scripts/train_baselines.py (docs/baselines.md), not asserted here."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("minari")

from drivehierarchy.agents.sb3 import Sb3Agent
from drivehierarchy.baselines.imitation import DATASET_ID, load_demos
from drivehierarchy.baselines.model_io import read_meta
from drivehierarchy.baselines.wrappers import make_env
from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root

# Score-record fields measuring wall-clock time (names before/after protocol v2).
WALL_CLOCK_KEYS = ("wall_duration", "duration_system")
INTERSECTION = builtin_root() / "r4" / "04_intersection" / "town01_04_straight_cross_traffic.toml"
T_JUNCTION = builtin_root() / "r4" / "05_t_intersection" / "town01_05_left_turn_t.toml"


# The ten scenarios the suite started with (one per category): small enough for a CI-sized BC /
# DAgger run, and what these tests' thresholds were set on.
CLASSIC = [
    "01_pedestrian/town01_01_midblock_crossing",
    "02_obstacles/town01_02_cones_right_lane",
    "03_turning/town01_03_right_turn_signalised",
    "04_intersection/town01_04_straight_cross_traffic",
    "05_t_intersection/town01_05_left_turn_t",
    "06_traffic_flow/ingolstadt_06_westbound_flow",
    "07_sudden_brake/town01_07_lead_brakes",
    "08_merging/town01_08_join_main_road",
    "09_yielding/town01_09_yield_left_turn",
    "10_roundabout/town01_10_roundabout_exit_south",
]


# 07 as it was before the suite's retune (the lead brakes on a distance trigger; now it paces
# itself ahead of the ego and stops in front of it). These tests are about the imitation
# pipeline, so they keep the scenario their thresholds were set on; BC on the retuned 07's
# stop-and-go demonstrations drives worse everywhere (measured 10.1 vs zero's 0.4 on the seven
# training scenarios), a learning result for scripts/train_baselines.py, not a CI gate.
KEPT = {
    "07_sudden_brake/town01_07_lead_brakes": Path(__file__).parent
    / "data"
    / "town01_07_lead_brakes_time_triggered.toml"
}


@pytest.fixture(scope="module", autouse=True)
def deterministic_torch() -> Iterator[None]:
    """BC / DAgger train in this process: one thread and deterministic kernels, so what a test
    learns does not depend on the machine's core count (restored afterwards)."""
    import torch

    threads, strict = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(1)
    torch.use_deterministic_algorithms(True)
    yield
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(strict)


@pytest.fixture(scope="module")
def suite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A `--suite DIR` folder with the classic ten scenarios, the maps linked beside it."""
    root = tmp_path_factory.mktemp("suite")
    os.symlink(builtin_root() / "maps", root / "maps")
    for rel in CLASSIC:
        src = KEPT.get(rel, builtin_root() / "r4" / f"{rel}.toml")
        dest = root / "r4" / f"{rel}.toml"
        dest.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(src, dest)
    return root / "r4"


def cli(*args: str) -> None:
    assert main([str(a) for a in args]) == 0


def scores(out: Path) -> dict[str, float]:
    lines = (out / "results.jsonl").read_text().splitlines()
    return {json.loads(x)["key"]: json.loads(x)["score"]["score_composed"] for x in lines}


@pytest.fixture(scope="module")
def demos(tmp_path_factory: pytest.TempPathFactory, suite: Path) -> Path:
    data = tmp_path_factory.mktemp("demos")
    # 14 episodes = each of the 7 training scenarios twice (once clean, once with DART noise).
    cli("baselines", "collect", "--agent", "expert", "--suite", suite, "--episodes", "14", "--out", data)
    return data


def test_collect_writes_a_minari_dataset_with_expert_labels(demos: Path) -> None:
    import minari

    assert (demos / DATASET_ID / "data" / "main_data.hdf5").is_file()
    os.environ["MINARI_DATASETS_PATH"] = str(demos)
    ds = minari.load_dataset(DATASET_ID)
    assert ds.total_episodes == 14
    ep = next(iter(ds.iterate_episodes()))
    assert ep.observations["state"].shape[0] == len(ep.actions) + 1
    states, labels = load_demos(demos)
    assert len(states) == len(labels) == ds.total_steps
    assert labels[:, 1].max() > 5.0  # the expert drives
    split = json.loads((demos / "split.json").read_text())
    assert len(split["train"]) == 7 and len(split["held_out"]) == 3
    meta = json.loads((demos / "collect.json").read_text())
    assert meta["mean_score"] > 50.0


def test_bc_beats_zero_speed_through_r4_evaluate(demos: Path, suite: Path, tmp_path: Path) -> None:
    out = tmp_path / "bc"
    cli("baselines", "train", "bc", "--data", demos, "--suite", suite, "--epochs", "40", "--out", out)
    model = out / "model.zip"
    meta = read_meta(model)
    assert meta["algo"] == "ppo" and meta["trained_by"] == "bc" and meta["wrapper"]["obs"] == "state"
    train = {
        f"{Path(p).parent.name}__{Path(p).stem}"
        for p in json.loads((out / "split.json").read_text())["train"]
    }
    cli("r4", "evaluate", "--agent", f"sb3:{model}", "--suite", suite, "--out", tmp_path / "ev_bc")
    cli("r4", "evaluate", "--agent", "zero", "--suite", suite, "--out", tmp_path / "ev_zero")
    bc, zero = scores(tmp_path / "ev_bc"), scores(tmp_path / "ev_zero")
    bc_train = float(np.mean([bc[k] for k in train]))
    zero_train = float(np.mean([zero[k] for k in train]))
    assert bc_train > zero_train + 20.0, (bc, zero)
    manifest = json.loads((tmp_path / "ev_bc" / "manifest.json").read_text())
    assert manifest["agent"] == f"sb3:{model}"


def test_dagger_aggregates_expert_labels_of_its_own_rollouts(
    demos: Path, suite: Path, tmp_path: Path
) -> None:
    out = tmp_path / "dagger"
    cli(
        *("baselines", "train", "dagger", "--data", demos, "--suite", suite),
        *("--iterations", "2", "--epochs", "8", "--out", out),
    )
    log = [json.loads(x) for x in (out / "train_log.jsonl").read_text().splitlines()]
    rounds = [r for r in log if r["phase"] == "dagger"]
    assert [r["iteration"] for r in rounds] == [1, 2]
    assert [r["beta"] for r in rounds] == [0.5, 0.25]
    assert all(r["new_samples"] > 100 for r in rounds)
    states, _ = load_demos(demos)
    assert log[-1]["samples"] == len(states) + sum(r["new_samples"] for r in rounds)
    assert read_meta(out / "model.zip")["trained_by"] == "dagger"
    model = f"sb3:{out / 'model.zip'}"
    cli("r4", "run", "--agent", model, "--scenario", INTERSECTION, "--out", tmp_path / "ev")


def test_the_agent_drives_exactly_like_the_training_wrappers(demos: Path, tmp_path: Path) -> None:
    """`sb3:` through the plain env == the model on the wrapped env it was trained on."""
    out = tmp_path / "bc"
    cli("baselines", "train", "bc", "--data", demos, "--epochs", "5", "--out", out)
    agent = Sb3Agent(out / "model.zip")
    assert agent.uses_images is False
    env = make_env([INTERSECTION], agent.wrapper, monitor=False)
    obs, _ = env.reset(seed=0)
    while True:
        a, _ = agent.model.predict(obs, deterministic=True)
        obs, _, term, trunc, _ = env.step(a)
        if term or trunc:
            break
    wrapped = env.unwrapped.score()
    cli(
        "r4",
        "run",
        "--agent",
        f"sb3:{out / 'model.zip'}",
        "--scenario",
        INTERSECTION,
        "--out",
        tmp_path / "ev",
    )
    via_runner = json.loads(next((tmp_path / "ev" / "scenes").glob("*/scene_score.json")).read_text())
    for record in (via_runner, wrapped):
        for key in WALL_CLOCK_KEYS:  # wall-clock time, the one non-simulated field
            record["meta"].pop(key, None)
    assert via_runner == wrapped


# Runs the CLI in a child process with torch single-threaded and deterministic; with a step count
# as its first argument, the child SIGKILLs itself right after saving the checkpoint at that step
# (a kill at a step count, not at a wall-clock moment, so every machine kills the same run).
CHILD = """
import os, signal, sys
import torch
torch.set_num_threads(1)
torch.use_deterministic_algorithms(True)
from stable_baselines3.common import callbacks
kill_at = int(sys.argv[1])

class KillAfterCheckpoint(callbacks.CheckpointCallback):
    def _on_step(self):
        ok = super()._on_step()
        if kill_at and self.num_timesteps >= kill_at:
            os.kill(os.getpid(), signal.SIGKILL)
        return ok

callbacks.CheckpointCallback = KillAfterCheckpoint
from drivehierarchy.cli import main
sys.exit(main(sys.argv[2:]))
"""


def test_ppo_trains_saves_resumes_after_a_kill_and_evaluates(tmp_path: Path) -> None:
    """Mechanics only (whether PPO learns is measured by scripts/train_baselines.py): train, get
    SIGKILLed at step 2048 right after its checkpoint, resume from it to 4096, save, evaluate."""
    out = tmp_path / "ppo"
    args = [
        "baselines", "train", "ppo", "--suite", str(T_JUNCTION), "--held-out", "0", "--envs", "8",
        "--vec", "dummy", "--checkpoint-every", "2048", "--hp", "n_steps=256", "--seed", "0",
        "--steps", "4096", "--out", str(out),
    ]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1", "CUBLAS_WORKSPACE_CONFIG": ":4096:8"}
    killed = subprocess.run(
        [sys.executable, "-c", CHILD, "2048", *args], capture_output=True, text=True, env=env, timeout=300
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert [p.name for p in (out / "checkpoints").glob("*.zip")] == ["rl_model_2048_steps.zip"]
    assert not (out / "model.zip").exists()
    done = subprocess.run(
        [sys.executable, "-c", CHILD, "0", *args], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, done.stderr
    assert "resuming from" in done.stderr and "rl_model_2048_steps.zip" in done.stderr
    meta = read_meta(out / "model.zip")
    assert meta["algo"] == "ppo" and meta["steps"] == 4096
    assert (out / "learning_curve.png").stat().st_size > 0
    assert list((out / "tb").rglob("events.out.tfevents.*"))
    assert list((out / "monitor").glob("*.monitor.csv"))
    model = f"sb3:{out / 'model.zip'}"
    cli("r4", "evaluate", "--agent", model, "--suite", T_JUNCTION, "--out", tmp_path / "ev")
    [record] = [json.loads(x)["score"] for x in (tmp_path / "ev" / "results.jsonl").read_text().splitlines()]
    assert record["termination_reason"] and record["decisions"] > 0
    # The same model through the same harness scores the same (the evaluation is deterministic).
    cli("r4", "evaluate", "--agent", model, "--suite", T_JUNCTION, "--out", tmp_path / "ev2")
    assert scores(tmp_path / "ev2") == scores(tmp_path / "ev")


def test_bad_inputs_fail_with_clear_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(["baselines", "train", "bc", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "o")])
        == 2
    )
    assert "no Minari dataset" in capsys.readouterr().err
    assert main(["baselines", "train", "bc", "--out", str(tmp_path / "o")]) == 2
    assert "--data" in capsys.readouterr().err
    assert main(["r4", "evaluate", "--agent", f"sb3:{tmp_path / 'x.zip'}", "--out", str(tmp_path / "e")]) == 2
    assert "file not found" in capsys.readouterr().err


def test_sac_trains_and_plugs_in_as_an_agent(tmp_path: Path) -> None:
    out = tmp_path / "sac"
    cli(
        *("baselines", "train", "sac", "--suite", INTERSECTION, "--held-out", "0", "--steps", "300"),
        *("--envs", "1", "--hp", "learning_starts=100", "--hp", "buffer_size=1000", "--hp", "batch_size=32"),
        *("--hp", 'policy_kwargs={"net_arch": [32, 32]}'),
        *("--checkpoint-every", "200", "--out", out),
    )
    assert read_meta(out / "model.zip")["algo"] == "sac"
    # SAC checkpoints carry the replay buffer, so a resumed run continues off-policy learning.
    assert (out / "checkpoints" / "rl_model_replay_buffer_200_steps.pkl").is_file()
    model = f"sb3:{out / 'model.zip'}"
    cli("r4", "run", "--agent", model, "--scenario", INTERSECTION, "--out", tmp_path / "ev")


def test_a_bev_cnn_policy_trains_and_sees_the_protocols_bev_when_evaluated(tmp_path: Path) -> None:
    out = tmp_path / "bev"
    cli(
        *("baselines", "train", "ppo", "--suite", INTERSECTION, "--held-out", "0", "--obs", "state+bev"),
        *("--bev-size", "64", "--steps", "64", "--envs", "1", "--hp", "n_steps=64", "--hp", "batch_size=32"),
        *("--out", out),
    )
    agent = Sb3Agent(out / "model.zip")
    assert agent.uses_images is True and agent.wrapper.bev_size == 64
    # The runner renders the protocol's 800×800 BEV for an image agent; the agent downsamples it.
    model = f"sb3:{out / 'model.zip'}"
    cli("r4", "run", "--agent", model, "--scenario", INTERSECTION, "--out", tmp_path / "ev")
    record = json.loads(next((tmp_path / "ev" / "scenes").glob("*/scene_score.json")).read_text())
    assert record["decisions"] > 0
