"""`--ray`: demonstration collection and DAgger's rollouts as Ray tasks on a local Ray instance
give the same demonstrations and samples as the in-process run with the same seeds.

Kept as cheap as the proof allows (the gate's budget): one Ray CPU (one worker process, which
imports torch only for DAgger's learner round), the fewest episodes that still make several
chunks with clean and noisy episodes, one epoch."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("minari")

from drivehierarchy.baselines.imitation import load_demos
from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root

pytestmark = pytest.mark.ray

ray = pytest.importorskip("ray")

SMALL = [
    "01_pedestrian/town01_01_midblock_crossing",
    "07_sudden_brake/town01_07_lead_brakes",
    "09_yielding/town01_09_yield_left_turn",
]


def cli(*args: object) -> None:
    assert main([str(a) for a in args]) == 0


@pytest.fixture(scope="module")
def suite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("suite")
    (root / "maps").symlink_to(builtin_root() / "maps")
    for name in SMALL:
        link = root / "r4" / f"{name}.toml"
        link.parent.mkdir(parents=True, exist_ok=True)
        link.symlink_to(builtin_root() / "r4" / f"{name}.toml")
    return root / "r4"


def test_collect_and_dagger_rollouts_on_ray_match_the_in_process_run(suite: Path, tmp_path: Path) -> None:
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the Ray tasks' learner runs on one thread too
    try:
        for where in ("local", "ray"):
            ray_args = ["--ray", "local"] if where == "ray" else []
            # 3 episodes over 3 files: every file, DART noise on the odd one; a chunk per
            # episode, more than workers, so the results' order is checked. At the meta level:
            # the level reaches the tasks, and its integer labels and noise survive them.
            cli(
                *("baselines", "collect", "--suite", suite, "--episodes", 3, "--seed", 4),
                *("--action-level", "meta", "--out", tmp_path / where / "demos", *ray_args),
            )
            # Round 0: a clean and a noisy expert episode; round 1: the learner of round 0 in the
            # mixture, rebuilt in the task from the sent weights.
            cli(
                *("baselines", "train", "dagger", "--suite", suite, "--iterations", 1),
                *("--episodes-per-iter", 2, "--epochs", 1, "--seed", 4),
                *("--out", tmp_path / where / "dagger", *ray_args),
            )
            if where == "local":
                ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    finally:
        ray.shutdown()
        torch.set_num_threads(threads)
    local, remote = tmp_path / "local", tmp_path / "ray"
    for a, b in zip(load_demos(local / "demos"), load_demos(remote / "demos"), strict=True):
        assert a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
    states, labels = load_demos(remote / "demos")
    assert labels.dtype == np.int64 and labels.shape == (len(states), 2)
    meta = [json.loads((d / "demos" / "collect.json").read_text()) for d in (local, remote)]
    assert meta[0]["action_level"] == meta[1]["action_level"] == "meta"
    assert meta[0]["episode_seeds"] == meta[1]["episode_seeds"] and len(set(meta[0]["episode_seeds"])) == 3
    assert meta[0]["mean_score"] == meta[1]["mean_score"] and meta[1]["ray"] is True
    # Round 0 (expert rollouts) and round 1 (the learner of round 0 in the mixture) on Ray.
    for r in ("round_000.npz", "round_001.npz"):
        with np.load(local / "dagger" / "rounds" / r) as za, np.load(remote / "dagger" / "rounds" / r) as zb:
            assert za["x"].tobytes() == zb["x"].tobytes() and za["y"].tobytes() == zb["y"].tobytes()
    logs = [
        [json.loads(x) for x in (d / "dagger" / "train_log.jsonl").read_text().splitlines()]
        for d in (local, remote)
    ]
    assert [r.get("rollout_mean_score") for r in logs[0]] == [r.get("rollout_mean_score") for r in logs[1]]
