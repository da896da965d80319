"""CI-sized end to end on today's suite files: collect expert demonstrations (Minari), train BC,
DAgger (state and BEV) and PPO (SB3 vec envs and the native batch, from scratch and fine-tuned)
through the CLI; every pipeline runs, records its split, resumes after a SIGKILL and is
deterministic; the models score through `r4 evaluate` like any other agent. Whether they learn
is measured by scripts/train_baselines.py (docs/baselines.md), never asserted here."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("minari")

from parity_helpers import wrapped_and_runner_records

from drivehierarchy.agents.sb3 import Sb3Agent
from drivehierarchy.baselines.imitation import DATASET_ID, load_demos
from drivehierarchy.baselines.model_io import load_model, read_meta
from drivehierarchy.baselines.splits import TRAIN_SEED_MIN
from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root

INTERSECTION = builtin_root() / "r4" / "04_intersection" / "town01_04_straight_cross_traffic.toml"
T_JUNCTION = builtin_root() / "r4" / "05_t_intersection" / "town01_05_left_turn_t.toml"

# Three short scenarios of today's suite (no SUMO), linked as they are: a CI-sized suite.
SMALL = [
    "01_pedestrian/town01_01_midblock_crossing",
    "07_sudden_brake/town01_07_lead_brakes",
    "09_yielding/town01_09_yield_left_turn",
]
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "CUBLAS_WORKSPACE_CONFIG": ":4096:8"}


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
    """A `--suite DIR` folder linking today's files (the maps linked beside it)."""
    root = tmp_path_factory.mktemp("suite")
    os.symlink(builtin_root() / "maps", root / "maps")
    for rel in SMALL:
        dest = root / "r4" / f"{rel}.toml"
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.symlink(builtin_root() / "r4" / f"{rel}.toml", dest)
    return root / "r4"


def cli(*args: object) -> None:
    assert main([str(a) for a in args]) == 0


def scores(out: Path) -> dict[str, float]:
    lines = (out / "results.jsonl").read_text().splitlines()
    return {json.loads(x)["key"]: json.loads(x)["score"]["score_composed"] for x in lines}


def same_weights(a: Path, b: Path) -> bool:
    pa, pb = load_model(a)[0].policy.state_dict(), load_model(b)[0].policy.state_dict()
    return list(pa) == list(pb) and all(bool((pa[k] == pb[k]).all()) for k in pa)


@pytest.fixture(scope="module")
def demos(tmp_path_factory: pytest.TempPathFactory, suite: Path) -> Path:
    data = tmp_path_factory.mktemp("demos")
    # Each of the 3 scenarios twice (once clean, once with DART noise).
    cli("baselines", "collect", "--agent", "expert", "--suite", suite, "--episodes", "6", "--out", data)
    return data


def test_collect_writes_a_minari_dataset_on_training_seeds_only(demos: Path) -> None:
    import minari

    assert (demos / DATASET_ID / "data" / "main_data.hdf5").is_file()
    os.environ["MINARI_DATASETS_PATH"] = str(demos)
    ds = minari.load_dataset(DATASET_ID)
    assert ds.total_episodes == 6
    ep = next(iter(ds.iterate_episodes()))
    assert ep.observations["state"].shape[0] == len(ep.actions) + 1
    states, labels = load_demos(demos)
    assert len(states) == len(labels) == ds.total_steps
    assert labels[:, 1].max() > 5.0  # the expert drives
    split = json.loads((demos / "split.json").read_text())
    assert split["kind"] == "seeds" and len(split["train"]) == 3 and split["test_seeds"] == [0, 1, 2, 3, 4]
    meta = json.loads((demos / "collect.json").read_text())
    assert len(meta["episode_seeds"]) == 6 and min(meta["episode_seeds"]) >= TRAIN_SEED_MIN
    assert meta["split"] == split


def test_bc_is_deterministic_records_its_split_and_scores_through_r4_evaluate(
    demos: Path, suite: Path, tmp_path: Path
) -> None:
    for name in ("a", "b"):
        cli(
            "baselines",
            "train",
            "bc",
            "--data",
            demos,
            "--suite",
            suite,
            "--epochs",
            "3",
            "--out",
            tmp_path / name,
        )
    model = tmp_path / "a" / "model.zip"
    assert same_weights(model, tmp_path / "b" / "model.zip")
    meta = read_meta(model)
    assert meta["algo"] == "ppo" and meta["trained_by"] == "bc" and meta["wrapper"]["obs"] == "state"
    assert meta["split"]["kind"] == "seeds" and meta["split"]["train_seeds"][0] == TRAIN_SEED_MIN
    cli("r4", "evaluate", "--agent", f"sb3:{model}", "--suite", suite, "--out", tmp_path / "ev_bc")
    assert len(scores(tmp_path / "ev_bc")) == 3
    manifest = json.loads((tmp_path / "ev_bc" / "manifest.json").read_text())
    assert manifest["agent"] == f"sb3:{model}"


# Runs the CLI in a child process with torch single-threaded and deterministic. CHILD_DAGGER with
# a round number SIGKILLs itself right after DAgger logged that round (its samples and model are
# saved by then); CHILD (PPO) with a step count right after the checkpoint at that step. Kills at
# a count, not at a wall-clock moment, so every machine kills the same run.
CHILD_DAGGER = """
import os, signal, sys
import torch
torch.set_num_threads(1)
torch.use_deterministic_algorithms(True)
from drivehierarchy.baselines import imitation
kill_at = int(sys.argv[1])
write_log = imitation._write_log

def killing_log(out, rec):
    write_log(out, rec)
    if rec.get("iteration") == kill_at:
        os.kill(os.getpid(), signal.SIGKILL)

imitation._write_log = killing_log
from drivehierarchy.cli import main
sys.exit(main(sys.argv[2:]))
"""


def test_dagger_resumes_after_a_kill_to_the_same_model(demos: Path, suite: Path, tmp_path: Path) -> None:
    args = [
        "baselines", "train", "dagger", "--data", str(demos), "--suite", str(suite),
        "--iterations", "2", "--episodes-per-iter", "2", "--epochs", "4",
    ]  # fmt: skip
    run = [sys.executable, "-c", CHILD_DAGGER]
    whole = subprocess.run(
        [*run, "-1", *args, "--out", str(tmp_path / "whole")], env=ENV, capture_output=True, text=True
    )
    assert whole.returncode == 0, whole.stderr
    killed = subprocess.run(
        [*run, "1", *args, "--out", str(tmp_path / "k")], env=ENV, capture_output=True, text=True
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr
    assert not (tmp_path / "k" / "model.zip").exists()
    resumed = subprocess.run(
        [*run, "-1", *args, "--out", str(tmp_path / "k")], env=ENV, capture_output=True, text=True
    )
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming after round 1" in resumed.stderr
    assert same_weights(tmp_path / "whole" / "model.zip", tmp_path / "k" / "model.zip")
    log = [json.loads(x) for x in (tmp_path / "whole" / "train_log.jsonl").read_text().splitlines()]
    rounds = [r for r in log if r["phase"] == "dagger"]
    assert [r["iteration"] for r in rounds] == [0, 1, 2]
    assert [r["beta"] for r in rounds] == [1.0, 0.5, 0.25]
    states, _ = load_demos(demos)
    assert rounds[0]["new_samples"] == len(states) and all(r["new_samples"] > 50 for r in rounds[1:])
    assert log[-1]["samples"] == sum(r["new_samples"] for r in rounds)
    meta = read_meta(tmp_path / "whole" / "model.zip")
    assert meta["trained_by"] == "dagger" and meta["split"]["kind"] == "seeds"
    cli(
        "r4",
        "run",
        "--agent",
        f"sb3:{tmp_path / 'whole' / 'model.zip'}",
        "--scenario",
        INTERSECTION,
        "--out",
        tmp_path / "ev",
    )


def test_dagger_on_the_bev_image_trains_a_cnn_from_its_own_rollouts(suite: Path, tmp_path: Path) -> None:
    out = tmp_path / "bev"
    cli(
        *("baselines", "train", "dagger", "--suite", suite, "--obs", "bev", "--bev-size", "48"),
        *("--iterations", "1", "--episodes-per-iter", "1", "--epochs", "2", "--out", out),
    )
    agent = Sb3Agent(out / "model.zip")
    assert agent.wrapper.uses_images and agent.wrapper.obs == "bev" and agent.wrapper.bev_size == 48
    assert "features_extractor" in str(agent.model.policy)
    with np.load(out / "rounds" / "round_000.npz") as z:
        assert z["x"].dtype == np.uint8 and z["x"].shape[1:] == (48, 48, 3)
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


def test_the_agent_drives_exactly_like_the_training_wrappers(demos: Path, tmp_path: Path) -> None:
    """`sb3:` through the plain env == the model on the wrapped env it was trained on."""
    out = tmp_path / "bc"
    cli("baselines", "train", "bc", "--data", demos, "--epochs", "5", "--out", out)
    assert Sb3Agent(out / "model.zip").uses_images is False
    wrapped, via_runner = wrapped_and_runner_records(out / "model.zip", INTERSECTION, tmp_path / "ev")
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
        "baselines", "train", "ppo", "--suite", str(T_JUNCTION), "--envs", "8",
        "--vec", "dummy", "--checkpoint-every", "2048", "--hp", "n_steps=256", "--seed", "0",
        "--steps", "4096", "--out", str(out),
    ]  # fmt: skip
    env = ENV
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
        *("baselines", "train", "sac", "--suite", INTERSECTION, "--steps", "300"),
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
        *("baselines", "train", "ppo", "--suite", INTERSECTION, "--obs", "state+bev"),
        *("--bev-size", "64", "--steps", "64", "--envs", "1", "--hp", "n_steps=64", "--hp", "batch_size=32"),
        *("--out", out),
    )
    agent = Sb3Agent(out / "model.zip")
    assert agent.wrapper.uses_images and agent.wrapper.bev_size == 64
    # The agent renders its 64 px BEV from the runner's env, as the training env did.
    model = f"sb3:{out / 'model.zip'}"
    cli("r4", "run", "--agent", model, "--scenario", INTERSECTION, "--out", tmp_path / "ev")
    record = json.loads(next((tmp_path / "ev" / "scenes").glob("*/scene_score.json")).read_text())
    assert record["decisions"] > 0


def test_ppo_on_the_native_batch_is_deterministic_and_fine_tunes_a_dagger_model(
    demos: Path, suite: Path, tmp_path: Path
) -> None:
    """`--vec native` (the SB3 adapter over the Rust batch): two runs with one seed learn the
    same weights; `--init` starts PPO from a DAgger model and records it."""
    common = [
        "baselines", "train", "ppo", "--suite", str(suite), "--vec", "native", "--traffic", "idm",
        "--envs", "4", "--steps", "256", "--hp", "n_steps=32", "--hp", "batch_size=64", "--seed", "3",
    ]  # fmt: skip
    for name in ("a", "b"):
        done = subprocess.run(
            [sys.executable, "-c", CHILD, "0", *common, "--out", str(tmp_path / name)],
            env=ENV,
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
    assert same_weights(tmp_path / "a" / "model.zip", tmp_path / "b" / "model.zip")
    assert list((tmp_path / "a" / "monitor").glob("native.monitor.csv"))
    dagger = tmp_path / "dagger"
    cli(
        *("baselines", "train", "dagger", "--data", demos, "--suite", suite, "--iterations", "0"),
        *("--epochs", "2", "--out", dagger),
    )
    tuned = tmp_path / "tuned"
    cli(*common, "--init", dagger / "model.zip", "--out", tuned)
    meta = read_meta(tuned / "model.zip")
    assert meta["init"] == str(dagger / "model.zip") and meta["steps"] == 256
    assert meta["split"]["train_seeds"][0] == TRAIN_SEED_MIN
    # A value warm-up over the whole run: the actor is DAgger's (with the asked exploration
    # noise), only the critic learned.
    warm = tmp_path / "warm"
    cli(*common, "--init", dagger / "model.zip", "--init-log-std", "-3", "--vf-warmup", "256", "--out", warm)
    start, ended = load_model(dagger / "model.zip")[0].policy, load_model(warm / "model.zip")[0].policy
    a, b = start.state_dict(), ended.state_dict()
    actor = [k for k in a if k.startswith(("mlp_extractor.policy_net", "action_net"))]
    critic = [k for k in a if k.startswith(("mlp_extractor.value_net", "value_net"))]
    assert actor and critic
    assert all(bool((a[k] == b[k]).all()) for k in actor)
    assert not all(bool((a[k] == b[k]).all()) for k in critic)
    assert bool((b["log_std"] == -3.0).all())
