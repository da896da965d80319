"""Expert demonstrations (Minari datasets), behaviour cloning and DAgger.

The `imitation` library pins Gymnasium 0.29 (we need ≥ 1.0), so BC and DAgger are a small torch
loop over a Stable-Baselines3 policy: the result is a normal SB3 `model.zip` (a PPO actor-critic,
so it can also be fine-tuned with PPO) that plugs in as `sb3:OUT/model.zip`.

Demonstrations: `collect` drives the privileged expert over a suite and records through
`minari.DataCollector`. The stored observation is the env's raw `{"state": ...}` and the stored
action the executed env action; each step's `infos["expert_action"]` is the expert's label for the
observation it comes with (so with `--noise`, DART-style perturbed driving is recorded together
with clean labels, which shows the learner how to recover from its own small errors).
"""

from __future__ import annotations

import json
import os
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from drivehierarchy._core import ConfigError
from drivehierarchy.baselines.model_io import save_model
from drivehierarchy.baselines.wrappers import ActionCodec, ObsCodec, SuiteEnv, WrapperConfig, make_env
from drivehierarchy.envs.config import R4Config

DATASET_ID = "drivehierarchy/r4-expert-v0"
STATE_ONLY = R4Config(front=None, bev=None, prompt=False)


class ExpertLabels(gym.Wrapper[Any, Any, Any, Any]):
    """Keeps a fixed, storable `info` per step: the expert's action for the returned observation
    (zeros once terminated), the env's reward and the route progress."""

    def __init__(self, env: gym.Env[Any, Any]) -> None:
        super().__init__(env)
        self.last_score: dict[str, Any] | None = None

    def _info(self, info: dict[str, Any], terminated: bool) -> dict[str, Any]:
        label = (
            np.zeros(self.env.action_space.shape, np.float32)  # type: ignore[type-var]
            if terminated
            else np.asarray(self.env.unwrapped.expert_action(), np.float32)  # type: ignore[attr-defined]
        )
        return {
            "expert_action": label,
            "best_progress_m": np.float64(info.get("best_progress_m", 0.0)),
        }

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        return obs, self._info(info, False)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            self.last_score = self.env.unwrapped.score()  # type: ignore[attr-defined]
        return obs, float(reward), terminated, truncated, self._info(info, terminated or truncated)


def _minari_root(out: Path) -> None:
    # Minari keeps datasets under MINARI_DATASETS_PATH/<namespace>/<name>; point it at --out.
    os.environ["MINARI_DATASETS_PATH"] = str(Path(out).resolve())


def collect(
    scenarios: Sequence[Path],
    episodes: int,
    out: Path,
    *,
    agent: str = "expert",
    noise: float = 0.0,
    seed: int = 0,
    log: Any = print,
) -> Any:
    """Drives `episodes` episodes (scenarios in turn) and writes a Minari dataset under `out`.

    `noise` > 0: the executed action is the expert's plus Gaussian noise (σ·[0.1 steer,
    2 m/s speed]) on every other episode; labels stay the expert's."""
    import minari

    if agent != "expert":
        raise ConfigError(f"config `agent` = {agent!r}: demonstrations come from the privileged 'expert'")
    if episodes < 1:
        raise ConfigError(f"config `episodes` = {episodes!r}: expected ≥ 1")
    out = Path(out)
    _minari_root(out)
    if (out / DATASET_ID).exists():
        raise ConfigError(f"config `out` = {str(out)!r}: a dataset {DATASET_ID} already exists there")
    base = SuiteEnv(scenarios, STATE_ONLY, order="cycle")
    labelled = ExpertLabels(base)
    env = minari.DataCollector(labelled, record_infos=True)
    rng = np.random.default_rng(seed)
    scale = np.array([0.1, 2.0], np.float32)
    scores: list[float] = []
    t0 = time.perf_counter()
    for ep in range(episodes):
        _, info = env.reset(seed=seed + ep)
        noisy = noise > 0 and ep % 2 == 1
        while True:
            a = np.asarray(info["expert_action"], np.float32)
            if noisy:
                a = a + rng.normal(0.0, noise, 2).astype(np.float32) * scale
                a = np.clip(a, base.action_space.low, base.action_space.high)  # type: ignore[attr-defined]
            _obs, _, terminated, truncated, info = env.step(a)
            if terminated or truncated:
                break
        assert labelled.last_score is not None
        scores.append(float(labelled.last_score["score_composed"]))
    with warnings.catch_warnings():
        # Minari nags about optional metadata (author e-mail, code permalink, env spec).
        warnings.simplefilter("ignore", UserWarning)
        dataset = env.create_dataset(
            dataset_id=DATASET_ID,
            algorithm_name="drivehierarchy expert (privileged autopilot)"
            + (f", noise {noise}" if noise else ""),
            author="drivehierarchy",
            description=(
                "DriveHierarchy-R4 expert demonstrations: observations {'state'}, actions [steer, "
                "target_speed_mps], infos['expert_action'] = the expert's label for each observation. "
                f"Scenarios: {', '.join(str(p) for p in scenarios)}"
            ),
        )
    env.close()
    (out / "collect.json").write_text(
        json.dumps(
            {
                "dataset_id": DATASET_ID,
                "episodes": episodes,
                "noise": noise,
                "scenarios": [str(p) for p in scenarios],
                "mean_score": float(np.mean(scores)),
                "wall_s": time.perf_counter() - t0,
            },
            indent=2,
        )
        + "\n",
        encoding="utf-8",
    )
    log(
        f"{episodes} episodes, {dataset.total_steps} steps, mean S_R4 {np.mean(scores):.1f} "
        f"-> {out / DATASET_ID}"
    )
    return dataset


def load_demos(data: Path) -> tuple[np.ndarray, np.ndarray]:
    """(raw states, expert env actions) of every step of a collected dataset."""
    import minari

    data = Path(data)
    if not (data / DATASET_ID).is_dir():
        raise ConfigError(
            f"config `data` = {str(data)!r}: no Minari dataset {DATASET_ID} there (run `collect`)"
        )
    _minari_root(data)
    ds = minari.load_dataset(DATASET_ID)
    states, labels = [], []
    for ep in ds.iterate_episodes():
        n = len(ep.actions)
        states.append(np.asarray(ep.observations["state"][:n], np.float32))
        labels.append(np.asarray(ep.infos["expert_action"][:n], np.float32))
    if not states:
        raise ConfigError(f"config `data` = {str(data)!r}: the dataset has no episode")
    return np.concatenate(states), np.concatenate(labels)


def new_policy_model(wrapper: WrapperConfig, scenarios: Sequence[Path], seed: int = 0) -> Any:
    """An SB3 PPO actor-critic over the wrapped env's spaces (its actor is what BC trains)."""
    from stable_baselines3 import PPO

    env = make_env(scenarios, wrapper, monitor=False)
    return PPO(
        "MlpPolicy",
        env,
        seed=seed,
        device="cpu",
        policy_kwargs={"net_arch": [256, 256], "log_std_init": -2.0},
    )


def fit(
    model: Any,
    x: np.ndarray,
    y: np.ndarray,
    *,
    epochs: int,
    batch: int = 256,
    lr: float = 1e-3,
    seed: int = 0,
) -> float:
    """Regresses the policy's mean action on the normalised labels (MSE); returns the last loss."""
    import torch as th

    policy = model.policy
    policy.set_training_mode(True)
    opt = th.optim.Adam(policy.parameters(), lr=lr)
    xt, yt = th.as_tensor(x), th.as_tensor(y)
    gen = th.Generator().manual_seed(seed)
    last = float("nan")
    for _ in range(epochs):
        perm = th.randperm(len(xt), generator=gen)
        total, n = 0.0, 0
        for i in range(0, len(xt), batch):
            idx = perm[i : i + batch]
            mean = policy.get_distribution(xt[idx]).distribution.mean
            loss = th.mean((mean - yt[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
            n += len(idx)
        last = total / max(n, 1)
    policy.set_training_mode(False)
    return last


def _encode(wrapper: WrapperConfig, states: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    oc, ac = ObsCodec(wrapper), ActionCodec(wrapper)
    x = np.stack([oc.state(s) for s in states]).astype(np.float32)
    y = np.stack([ac.encode(a) for a in labels]).astype(np.float32)
    return x, y


def _imitation_wrapper(wrapper: WrapperConfig | None) -> WrapperConfig:
    wrapper = wrapper or WrapperConfig()
    if wrapper.obs != "state" or wrapper.action != "decision":
        raise ConfigError(
            f"config `obs`/`action` = {wrapper.obs!r}/{wrapper.action!r}: imitation learns from the "
            "recorded state and the expert's decisions (obs 'state', action 'decision')"
        )
    return wrapper


def train_bc(
    data: Path,
    scenarios: Sequence[Path],
    out: Path,
    *,
    epochs: int = 60,
    wrapper: WrapperConfig | None = None,
    seed: int = 0,
    log: Any = print,
) -> Path:
    wrapper = _imitation_wrapper(wrapper)
    t0 = time.perf_counter()
    states, labels = load_demos(data)
    x, y = _encode(wrapper, states, labels)
    model = new_policy_model(wrapper, scenarios, seed)
    loss = fit(model, x, y, epochs=epochs, seed=seed)
    out.mkdir(parents=True, exist_ok=True)
    path = save_model(model, out / "model.zip", "ppo", wrapper, trained_by="bc", samples=len(x))
    wall = time.perf_counter() - t0
    _write_log(out, {"phase": "bc", "samples": len(x), "epochs": epochs, "loss": loss, "wall_s": wall})
    log(f"BC on {len(x)} samples, {epochs} epochs, loss {loss:.4f}, {wall:.0f} s -> {path}")
    return path


def train_dagger(
    data: Path,
    scenarios: Sequence[Path],
    out: Path,
    *,
    iterations: int = 6,
    episodes_per_iter: int | None = None,
    epochs: int = 30,
    beta_decay: float = 0.5,
    wrapper: WrapperConfig | None = None,
    seed: int = 0,
    log: Any = print,
) -> Path:
    """DAgger: BC on the demos, then `iterations` rounds of driving with the mixture policy
    (expert with probability β = beta_decay^i, else the learner), labelling every visited state
    with the expert's action (the online teacher), aggregating and refitting."""
    wrapper = _imitation_wrapper(wrapper)
    t0 = time.perf_counter()
    states, labels = load_demos(data)
    x, y = _encode(wrapper, states, labels)
    model = new_policy_model(wrapper, scenarios, seed)
    fit(model, x, y, epochs=epochs * 2, seed=seed)
    oc, ac = ObsCodec(wrapper), ActionCodec(wrapper)
    env = SuiteEnv(scenarios, wrapper.env_config(STATE_ONLY), order="cycle")
    rng = np.random.default_rng(seed)
    n_eps = episodes_per_iter or len(scenarios)
    xs, ys = [x], [y]
    for it in range(1, iterations + 1):
        beta = beta_decay**it
        new_x, new_y, scores = [], [], []
        for ep in range(n_eps):
            obs, _ = env.reset(seed=seed + 1000 * it + ep)
            while True:
                expert = env.expert_action()
                s = oc.state(obs["state"])
                new_x.append(s)
                new_y.append(ac.encode(expert))
                if rng.random() < beta:
                    act = expert
                else:
                    a, _ = model.predict(s, deterministic=True)
                    act = ac.decode(a)
                obs, _, terminated, truncated, _ = env.step(act)
                if terminated or truncated:
                    break
            scores.append(float(env.score()["score_composed"]))
        xs.append(np.stack(new_x))
        ys.append(np.stack(new_y))
        loss = fit(model, np.concatenate(xs), np.concatenate(ys), epochs=epochs, seed=seed + it)
        _write_log(
            out,
            {
                "phase": "dagger",
                "iteration": it,
                "beta": beta,
                "new_samples": len(new_x),
                "rollout_mean_score": float(np.mean(scores)),
                "loss": loss,
            },
        )
        log(
            f"DAgger {it}/{iterations}: beta {beta:.3f}, +{len(new_x)} samples, rollouts S_R4 "
            f"{np.mean(scores):.1f}, loss {loss:.4f}"
        )
    env.close()
    total = int(sum(len(a) for a in xs))
    path = save_model(model, out / "model.zip", "ppo", wrapper, trained_by="dagger", samples=total)
    _write_log(out, {"phase": "done", "samples": total, "wall_s": time.perf_counter() - t0})
    return path


def _write_log(out: Path, rec: dict[str, Any]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with (out / "train_log.jsonl").open("a", encoding="utf-8") as fh:
        fh.write(json.dumps(rec) + "\n")
