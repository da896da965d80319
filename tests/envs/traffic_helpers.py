"""Shared by the SUMO and IDM traffic tests: scenario files, envs, traffic rows, an expert run."""

from __future__ import annotations

import hashlib
import textwrap
from pathlib import Path

import numpy as np

from drivehierarchy.envs.r4 import DriveHierarchyR4Env
from drivehierarchy.scenarios import builtin_root

TOWN01 = builtin_root() / "maps" / "town01" / "town01.net.xml"
BENCH = builtin_root() / "bench" / "town01_sumo_traffic.toml"
IS_TRAFFIC = 7  # column of actors_array


def write_scenario(tmp_path: Path, body: str, name: str = "s.toml") -> Path:
    head = f'version = 1\nid = "t"\ncategory = "06_traffic_flow"\nmap = "{TOWN01.as_posix()}"\n'
    p = tmp_path / name
    p.write_text(head + textwrap.dedent(body), encoding="utf-8")
    return p


def make_env(scenario: str | Path, **kw: object) -> DriveHierarchyR4Env:
    return DriveHierarchyR4Env(scenario=scenario, front=None, bev=None, prompt=False, **kw)


def traffic_rows(env: DriveHierarchyR4Env) -> np.ndarray:
    a = env.sim.actors_array()
    return a[a[:, IS_TRAFFIC] == 1.0]


def frame(env: DriveHierarchyR4Env) -> tuple[np.ndarray, np.ndarray]:
    """Ego pose and traffic rows (ego frame: forward, left) of the current tick."""
    ego = env.sim.ego_array()
    rows = traffic_rows(env)
    d = rows[:, 1:3] - ego[:2]
    fwd = np.array([np.cos(ego[2]), np.sin(ego[2])])
    left = np.array([-fwd[1], fwd[0]])
    rel = np.stack([d @ fwd, d @ left], axis=1)
    return ego, np.concatenate([rows, rel], axis=1)


def run_expert(
    scenario: str | Path, seed: int, steps: int | None = None, traffic: str | None = None, **kw: object
) -> dict[str, object]:
    """The expert over `scenario`: digests of the traffic and the trajectory, vehicle counts."""
    env = make_env(scenario, **kw) if traffic is None else make_env(scenario, traffic=traffic, **kw)
    try:
        env.reset(seed=seed)
        digest = hashlib.sha256()
        counts = [len(traffic_rows(env))]
        info: dict[str, object] = {}
        n = 0
        while steps is None or n < steps:
            _, _, term, _, info = env.step(env.expert_action())
            digest.update(np.ascontiguousarray(env.sim.actors_array()).tobytes())
            counts.append(len(traffic_rows(env)))
            n += 1
            if term:
                break
        return {
            "traffic": digest.hexdigest(),
            "trajectory": env.sim.trajectory_hash,
            "counts": counts,
            "info": info,
            "score": env.score(),
        }
    finally:
        env.close()
