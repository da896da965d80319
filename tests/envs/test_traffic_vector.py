"""SUMO envs vectorised: over processes (each on libsumo), and in one process (the first env on
libsumo, the others on TraCI: libsumo holds one simulation per process)."""

from __future__ import annotations

import functools
import os
import signal
import threading
import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("libsumo")

import drivehierarchy  # noqa: F401  (registers DriveHierarchy-R4)
from drivehierarchy._core import SimulationError
from drivehierarchy.envs.traffic.vector import sumo_vector_env
from drivehierarchy.scenarios import builtin_root

BENCH = str(builtin_root() / "bench" / "town01_sumo_traffic.toml")
N = 4


def make_env(backend: str = "auto") -> gym.Env[Any, Any]:
    return gym.make(
        "DriveHierarchy-R4", scenario=BENCH, front=None, bev=None, prompt=False, sumo_backend=backend
    )


def run(venv: gym.vector.VectorEnv[Any, Any], steps: int) -> list[np.ndarray]:
    obs, _ = venv.reset(seed=[10, 11, 12, 10])
    states = [obs["state"].copy()]
    action = np.tile(np.array([0.0, 6.0], np.float32), (N, 1))
    for _ in range(steps):
        obs, _, _, _, _ = venv.step(action)
        states.append(obs["state"].copy())
    return states


@pytest.mark.parametrize("backend", ["libsumo", "libsumo-python"])
def test_async_vector_env_runs_four_sumo_envs(backend: str) -> None:
    venv = gym.vector.AsyncVectorEnv([functools.partial(make_env, backend)] * N)
    try:
        a = run(venv, 12)
        b = run(venv, 12)
    finally:
        venv.close()
    # Four SUMO simulations ran side by side: traffic differs by seed, repeats with it.
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[-1][0], a[-1][1])
    np.testing.assert_array_equal(a[-1][0], a[-1][3])  # same seed in another process


def test_a_dead_worker_is_an_error_not_a_hang() -> None:
    venv = sumo_vector_env(2, scenario=BENCH, front=None, bev=None, prompt=False)
    outcome: dict[str, BaseException | None] = {}
    try:
        venv.reset(seed=0)
        os.kill(venv.processes[1].pid, signal.SIGKILL)
        venv.processes[1].join(10)

        def step() -> None:
            try:
                venv.step(np.tile(np.array([0.0, 6.0], np.float32), (2, 1)))
                outcome["error"] = None
            except BaseException as exc:  # the failure we expect
                outcome["error"] = exc

        t = threading.Thread(target=step, daemon=True)
        t0 = time.monotonic()
        t.start()
        t.join(60)
        assert not t.is_alive(), "step() hung on a dead worker"
        err = outcome.get("error")
        assert isinstance(err, SimulationError), repr(err)
        assert "worker 1" in str(err) and "died" in str(err), str(err)
        assert time.monotonic() - t0 < 60
    finally:
        venv.close(terminate=True)


def test_sync_vector_env_runs_sumo_envs_in_one_process() -> None:
    kw = {"scenario": BENCH, "front": None, "bev": None, "prompt": False}
    venv = gym.make_vec("DriveHierarchy-R4", num_envs=3, vectorization_mode="sync", **kw)
    try:
        obs, _ = venv.reset(seed=[10, 11, 10])
        transports = [e.unwrapped._sumo.transport for e in venv.envs]  # type: ignore[attr-defined]
        assert transports == ["libsumo", "traci", "traci"]
        action = np.tile(np.array([0.0, 6.0], np.float32), (3, 1))
        for _ in range(12):
            obs, _, _, _, _ = venv.step(action)
    finally:
        venv.close()
    assert not np.array_equal(obs["state"][0], obs["state"][1])
    np.testing.assert_array_equal(obs["state"][0], obs["state"][2])  # same seed: libsumo = TraCI


def test_sb3_make_vec_env_runs_sumo_envs_in_one_process() -> None:
    env_util = pytest.importorskip("stable_baselines3.common.env_util")
    venv = env_util.make_vec_env(make_env, n_envs=2, seed=0)  # a DummyVecEnv
    try:
        venv.reset()
        assert [e.unwrapped._sumo.transport for e in venv.envs] == ["libsumo", "traci"]
        action = np.tile(np.array([0.0, 6.0], np.float32), (2, 1))
        for _ in range(12):
            obs, _, _, _ = venv.step(action)
        assert obs["state"].shape[0] == 2 and np.isfinite(obs["state"]).all()
    finally:
        venv.close()
