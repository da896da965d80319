"""Expert demonstrations (Minari datasets), behaviour cloning and DAgger.

The `imitation` library pins Gymnasium 0.29 (we need ≥ 1.0), so BC and DAgger are a small torch
loop over a Stable-Baselines3 policy: the result is a normal SB3 `model.zip` (a PPO actor-critic,
so it can also be fine-tuned with PPO) that plugs in as `sb3:OUT/model.zip`.

Demonstrations: `collect` drives the privileged expert over a suite and records through
`minari.DataCollector`. The stored observation is the env's raw `{"state": ...}` and the stored
action the executed env action; each step's `infos["expert_action"]` is the expert's label for the
observation it comes with (so with `--noise`, DART-style perturbed driving is recorded together
with clean labels, which shows the learner how to recover from its own small errors).

At the waypoint and meta levels (`action_level`, docs/r4.md#action-levels) the env takes the
level's plans and the label is the expert's plan at that level (`env.expert_action()`, the
level's oracle); the dataset's level is recorded in `collect.json`, and BC / DAgger on it must
train at the same level. Meta actions are classes, so BC and DAgger fit them by cross-entropy
(the policy's log-likelihood of the expert's pair) instead of the squared error of the Box levels.
"""

from __future__ import annotations

import json
import os
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from drivehierarchy._core import ConfigError
from drivehierarchy.baselines.model_io import save_model
from drivehierarchy.baselines.splits import Split
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
        # Meta labels are class indices; the Box levels' labels float32, as before the levels.
        self._dtype: type[np.generic] = (
            np.int64 if isinstance(env.action_space, gym.spaces.MultiDiscrete) else np.float32
        )

    def _info(self, info: dict[str, Any], terminated: bool) -> dict[str, Any]:
        label = (
            np.zeros(self.env.action_space.shape or (), self._dtype)
            if terminated
            else np.asarray(self.env.unwrapped.expert_action(), self._dtype)  # type: ignore[attr-defined]
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


def level_config(action_level: str) -> R4Config:
    """The state-only env of the demonstrations at `action_level`."""
    return WrapperConfig(action_level=action_level).env_config(STATE_ONLY)  # type: ignore[arg-type]


def collect(
    split: Split,
    episodes: int,
    out: Path,
    *,
    agent: str = "expert",
    noise: float = 0.0,
    seed: int = 0,
    action_level: str = "control",
    ray_address: str | None = None,
    log: Any = print,
) -> Any:
    """Drives `episodes` episodes (the split's training scenarios in turn, at seeds drawn from its
    training seeds) and writes a Minari dataset under `out`, the expert deciding at
    `action_level` (its plan at that level is both what is driven and the label).

    `noise` > 0: the executed action is the expert's plus DART noise (`ActionCodec.perturb`:
    σ·[0.1 steer, 2 m/s speed] at the control level) on every other episode; labels stay the
    expert's. Episode k depends only on (seed, k), so `ray_address` (a Ray cluster, 'local'
    starts one) drives chunks of episodes as Ray tasks and writes the same dataset as the
    in-process run."""
    import minari

    config = level_config(action_level)
    if agent != "expert":
        raise ConfigError(f"config `agent` = {agent!r}: demonstrations come from the privileged 'expert'")
    if episodes < 1:
        raise ConfigError(f"config `episodes` = {episodes!r}: expected ≥ 1")
    out = Path(out)
    _minari_root(out)
    if (out / DATASET_ID).exists():
        raise ConfigError(f"config `out` = {str(out)!r}: a dataset {DATASET_ID} already exists there")
    scenarios = [str(p) for p in split.train_paths]
    job = _DemoJob(scenarios, split.train_seeds, noise, seed, action_level)
    t0 = time.perf_counter()
    results = _run_chunks(_demo_chunk, job, list(range(episodes)), ray_address, None)
    buffers = [r[0] for r in results]
    played = [r[1] for r in results]
    scores = [r[2] for r in results]
    probe = ExpertLabels(SuiteEnv(scenarios[:1], config))
    with warnings.catch_warnings():
        # Minari nags about optional metadata (author e-mail, code permalink, env spec).
        warnings.simplefilter("ignore", UserWarning)
        dataset = minari.create_dataset_from_buffers(
            dataset_id=DATASET_ID,
            buffer=buffers,
            observation_space=probe.observation_space,
            action_space=probe.action_space,
            algorithm_name="drivehierarchy expert (privileged autopilot)"
            + (f", noise {noise}" if noise else ""),
            author="drivehierarchy",
            description=(
                "DriveHierarchy-R4 expert demonstrations: observations {'state'}, actions "
                f"{LEVEL_ACTIONS[action_level]} (action level {action_level!r}), "
                "infos['expert_action'] = the expert's label for each observation. "
                f"Scenarios: {', '.join(scenarios)}"
            ),
        )
    probe.close()
    (out / "collect.json").write_text(
        json.dumps(
            {
                "dataset_id": DATASET_ID,
                "action_level": action_level,
                "waypoints": config.waypoints,
                "waypoint_dt_s": config.waypoint_dt_s,
                "episodes": episodes,
                "noise": noise,
                "split": split.to_dict(),
                "episode_seeds": played,
                "mean_score": float(np.mean(scores)),
                "wall_s": time.perf_counter() - t0,
                "ray": ray_address is not None,
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


LEVEL_ACTIONS = {
    "control": "[steer, target_speed_mps]",
    "waypoints": "(K, 2) ego-frame waypoints (x forward, y left, metres)",
    "meta": "[path action, speed action] indices",
}


def demos_level(data: Path) -> dict[str, Any]:
    """The action level (and waypoint shape) a dataset was collected at (`collect.json`;
    datasets from before the levels are the control level)."""
    path = Path(data) / "collect.json"
    meta = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    default = R4Config()
    return {
        "action_level": meta.get("action_level", "control"),
        "waypoints": meta.get("waypoints", default.waypoints),
        "waypoint_dt_s": meta.get("waypoint_dt_s", default.waypoint_dt_s),
    }


def check_demos_level(data: Path, wrapper: WrapperConfig) -> None:
    """Refuses demonstrations of another level (or another waypoint plan) than the learner's."""
    have = demos_level(data)
    want = {k: getattr(wrapper, k) for k in have}
    if wrapper.action_level != "waypoints":
        for k in ("waypoints", "waypoint_dt_s"):
            have.pop(k), want.pop(k)
    if have != want:
        key = next(k for k in have if have[k] != want[k])
        raise ConfigError(
            f"{Path(data) / 'collect.json'}: field `{key}` = {have[key]!r}: the demonstrations are "
            f"at {have[key]!r} but this run trains at {want[key]!r} (pass --action-level "
            f"{have['action_level']} or collect at {want['action_level']})"
        )


@dataclass(frozen=True)
class _DemoJob:
    scenarios: list[str]
    train_seeds: tuple[int, int]
    noise: float
    seed: int
    action_level: str = "control"


def _demo_chunk(job: _DemoJob, episodes: list[int], _model: Any) -> list[tuple[Any, int, float]]:
    """Expert episodes `episodes` at the job's action level (indices k: scenario k mod n, reset
    seed `seed + k`, DART noise (`ActionCodec.perturb`) from its own generator on odd k):
    (Minari episode buffer, played seed, S_R4) of each."""
    from minari import StepDataCallback
    from minari.data_collector import EpisodeBuffer

    base = SuiteEnv(job.scenarios, level_config(job.action_level), order="cycle", train_seeds=job.train_seeds)
    env = ExpertLabels(base)
    codec = ActionCodec(WrapperConfig(action_level=job.action_level))  # type: ignore[arg-type]
    record = StepDataCallback()
    out: list[tuple[Any, int, float]] = []
    try:
        for k in episodes:
            rng = np.random.default_rng([job.seed, k])
            path = job.scenarios[k % len(job.scenarios)]
            obs, info = env.reset(seed=job.seed + k, options={"scenario": path})
            step = record(env=env, obs=obs, info=info)
            buf = EpisodeBuffer(id=k, seed=job.seed + k, observations=step["observation"], infos=step["info"])
            noisy = job.noise > 0 and k % 2 == 1
            while True:
                a = np.asarray(info["expert_action"])  # int64 classes at meta, else float32
                if noisy:
                    a = codec.perturb(a, rng, job.noise)
                obs, rew, terminated, truncated, info = env.step(a)
                buf = buf.add_step_data(
                    record(
                        env=env,
                        obs=obs,
                        info=info,
                        action=a,
                        rew=rew,
                        terminated=terminated,
                        truncated=truncated,
                    )
                )
                if terminated or truncated:
                    break
            assert env.last_score is not None
            out.append((buf, int(base.episode_seed or 0), float(env.last_score["score_composed"])))
    finally:
        env.close()
    return out


def _run_chunks(fn: Any, job: Any, episodes: list[int], ray_address: str | None, model: Any) -> list[Any]:
    """`fn(job, episodes, model)` in this process, or over contiguous chunks of `episodes` as Ray
    tasks (a chunk per worker CPU, several each, so a slow scenario does not hold the rest); the
    results in episode order either way. A task gets the model's weights and rebuilds it."""
    if ray_address is None:
        return list(fn(job, episodes, model))
    from drivehierarchy.benchmark.r4.dispatch import _ray_init

    ray = _ray_init(ray_address)
    cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
    n = max(1, min(len(episodes), 4 * cpus))
    chunks = [list(c) for c in np.array_split(np.array(episodes, dtype=np.int64), n) if len(c)]
    params = None if model is None else ray.put(model.get_parameters())
    task = ray.remote(_remote_chunk)
    refs = [task.remote(fn, job, [int(k) for k in c], params) for c in chunks]
    return [r for part in ray.get(refs) for r in part]


def _remote_chunk(fn: Any, job: Any, episodes: list[int], params: Any) -> list[Any]:
    """A Ray task: the learner rebuilt from its weights (one torch thread), then `fn`."""
    model = None
    if params is not None:
        import torch

        torch.set_num_threads(1)
        model = new_policy_model(job.wrapper, [Path(job.scenarios[0])])
        model.set_parameters(params)
    return list(fn(job, episodes, model))


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
        label = np.asarray(ep.infos["expert_action"][:n])
        labels.append(label if label.dtype.kind in "iu" else label.astype(np.float32))
    if not states:
        raise ConfigError(f"config `data` = {str(data)!r}: the dataset has no episode")
    return np.concatenate(states), np.concatenate(labels)


def new_policy_model(wrapper: WrapperConfig, scenarios: Sequence[Path], seed: int = 0) -> Any:
    """An SB3 PPO actor-critic over the wrapped env's spaces (its actor is what BC trains): an
    MLP for the state, SB3's NatureCNN for the BEV image."""
    from stable_baselines3 import PPO

    env = make_env(scenarios[:1], wrapper, monitor=False)
    policy = {"state": "MlpPolicy", "bev": "CnnPolicy", "state+bev": "MultiInputPolicy"}[wrapper.obs]
    return PPO(
        policy,
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
    """Fits the policy to the labels; returns the last loss. Box actions (control, waypoints):
    the policy's mean action regressed on the normalised labels (MSE); meta actions (integer
    labels): the negative log-likelihood of the expert's (path, speed) pair under the policy's
    categoricals (cross-entropy). `x` is a batch of policy observations (states, or H×W×3
    uint8 BEV images)."""
    import torch as th

    policy = model.policy
    policy.set_training_mode(True)
    opt = th.optim.Adam(policy.parameters(), lr=lr)
    classes = np.asarray(y).dtype.kind in "iu"
    yt = th.as_tensor(y) if classes else th.as_tensor(y).reshape(len(y), -1)
    gen = th.Generator().manual_seed(seed)
    last = float("nan")
    for _ in range(epochs):
        perm = th.randperm(len(yt), generator=gen).numpy()
        total, n = 0.0, 0
        for i in range(0, len(yt), batch):
            idx = perm[i : i + batch]
            # obs_to_tensor transposes images to the policy's channel-first layout.
            obs, _ = policy.obs_to_tensor(x[idx])
            dist = policy.get_distribution(obs)
            if classes:
                loss = -th.mean(dist.log_prob(yt[idx]))
            else:
                loss = th.mean((dist.distribution.mean - yt[idx]) ** 2)
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
    y = np.stack([ac.encode(a) for a in labels])
    return x, y


def _imitation_wrapper(wrapper: WrapperConfig | None, *, images: bool = False) -> WrapperConfig:
    wrapper = wrapper or WrapperConfig()
    allowed = ("state", "bev") if images else ("state",)
    if wrapper.obs not in allowed or wrapper.action != "decision":
        raise ConfigError(
            f"config `obs`/`action` = {wrapper.obs!r}/{wrapper.action!r}: "
            + (
                "DAgger learns the expert's decisions (action 'decision') from 'state' or 'bev'"
                if images
                else "BC learns from the recorded state and the expert's decisions (obs 'state', "
                "action 'decision'); "
                "for the BEV image use DAgger, which renders it online"
            )
        )
    return wrapper


def train_bc(
    data: Path,
    split: Split,
    out: Path,
    *,
    epochs: int = 60,
    wrapper: WrapperConfig | None = None,
    seed: int = 0,
    log: Any = print,
) -> Path:
    wrapper = _imitation_wrapper(wrapper)
    check_demos_level(data, wrapper)
    t0 = time.perf_counter()
    states, labels = load_demos(data)
    x, y = _encode(wrapper, states, labels)
    model = new_policy_model(wrapper, split.train_paths, seed)
    loss = fit(model, x, y, epochs=epochs, seed=seed)
    out.mkdir(parents=True, exist_ok=True)
    path = save_model(
        model, out / "model.zip", "ppo", wrapper, trained_by="bc", samples=len(x), split=split.to_dict()
    )
    wall = time.perf_counter() - t0
    _write_log(out, {"phase": "bc", "samples": len(x), "epochs": epochs, "loss": loss, "wall_s": wall})
    log(f"BC on {len(x)} samples, {epochs} epochs, loss {loss:.4f}, {wall:.0f} s -> {path}")
    return path


def _round_file(out: Path, it: int) -> Path:
    return out / "rounds" / f"round_{it:03d}.npz"


@dataclass(frozen=True)
class _RolloutJob:
    scenarios: list[str]
    train_seeds: tuple[int, int]
    wrapper: WrapperConfig
    beta: float
    noise: float
    seed: int
    start: int  # the round's first episode plays scenarios[start mod n]


def _rollout_chunk(
    job: _RolloutJob, episodes: list[int], model: Any, env: SuiteEnv | None = None
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """Episodes `episodes` of a round with the mixture policy (expert with probability `beta` per
    step, else the learner; with `noise` > 0 odd episodes add DART noise to what is executed).
    Episode k plays scenario start + k at reset seed `seed + k` with its own generator, so it is
    the same wherever it runs. Returns (policy observations, normalised expert labels, S_R4)."""
    wrapper = job.wrapper
    oc, ac = ObsCodec(wrapper), ActionCodec(wrapper)
    own = env is None
    if env is None:
        env = SuiteEnv(
            job.scenarios, wrapper.env_config(STATE_ONLY), order="cycle", train_seeds=job.train_seeds
        )
    out: list[tuple[np.ndarray, np.ndarray, float]] = []
    try:
        for k in episodes:
            rng = np.random.default_rng([job.seed, k])
            path = job.scenarios[(job.start + k) % len(job.scenarios)]
            obs, _ = env.reset(seed=job.seed + k, options={"scenario": path})  # seeds the seed draw
            noisy = job.noise > 0 and k % 2 == 1
            xs: list[Any] = []
            ys: list[np.ndarray] = []
            while True:
                expert = np.asarray(env.expert_action())
                o = oc.encode(obs)
                xs.append(o)
                ys.append(ac.encode(expert))
                if model is None or rng.random() < job.beta:
                    act = expert
                else:
                    a, _ = model.predict(o, deterministic=True)
                    act = ac.decode(a)
                if noisy:
                    act = ac.perturb(act, rng, job.noise)
                obs, _, terminated, truncated, _ = env.step(act)
                if terminated or truncated:
                    break
            # Labels keep the codec's dtype: int64 classes at meta, float32 otherwise.
            out.append((np.stack(xs), np.stack(ys), float(env.score()["score_composed"])))
    finally:
        if own:
            env.close()
    return out


def _rollouts(
    job: _RolloutJob, episodes: int, model: Any, env: SuiteEnv, ray_address: str | None
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """A round's `episodes` episodes, here (on `env`) or as Ray tasks: (observations, labels,
    S_R4 of each episode)."""
    ks = list(range(episodes))
    if ray_address is None:
        results = _rollout_chunk(job, ks, model, env)
    else:
        results = _run_chunks(_rollout_chunk, job, ks, ray_address, model)
    return (
        np.concatenate([r[0] for r in results]),
        np.concatenate([r[1] for r in results]),
        [r[2] for r in results],
    )


def train_dagger(
    data: Path | None,
    split: Split,
    out: Path,
    *,
    iterations: int = 6,
    episodes_per_iter: int | None = None,
    epochs: int = 30,
    beta_decay: float = 0.5,
    noise: float = 1.0,
    wrapper: WrapperConfig | None = None,
    seed: int = 0,
    max_minutes: float | None = None,
    ray_address: str | None = None,
    log: Any = print,
) -> Path:
    """DAgger over the split's training scenarios and seeds. Round 0 is the demonstrations of
    `data` (state only) or, without data, expert rollouts (DART noise on every other episode);
    round i ≥ 1 drives with the mixture policy (expert with probability β = beta_decay^i, else
    the learner), labels every visited state with the expert (the online teacher), aggregates
    and refits. `obs` 'bev' learns a CNN on the BEV image rendered during the rollouts.

    Resumable: every round's samples (`rounds/round_NNN.npz`) and the model after it
    (`rounds/model_NNN.zip`) are kept, so a killed run continues after its last whole round.
    `max_minutes` stops starting new rounds after that much wall time (the model is saved).
    `ray_address` drives each round's rollouts as Ray tasks (same samples as in-process)."""
    wrapper = _imitation_wrapper(wrapper, images=True)
    if data is not None:
        check_demos_level(data, wrapper)
    if data is not None and wrapper.obs != "state":
        raise ConfigError(
            f"config `data` = {str(data)!r}: demonstrations record the state only; DAgger on "
            f"obs {wrapper.obs!r} starts from its own expert rollouts (leave out --data)"
        )
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    (out / "rounds").mkdir(exist_ok=True)
    n_eps = episodes_per_iter or len(split.train)
    model = new_policy_model(wrapper, split.train_paths, seed)
    env = SuiteEnv(
        split.train_paths, wrapper.env_config(STATE_ONLY), order="cycle", train_seeds=split.train_seeds
    )
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    done = 0
    while _round_file(out, done).exists():
        with np.load(_round_file(out, done)) as z:
            xs.append(z["x"])
            ys.append(z["y"])
        done += 1
    if done:
        from stable_baselines3 import PPO

        model.set_parameters(
            PPO.load(str(out / "rounds" / f"model_{done - 1:03d}.zip"), device="cpu").get_parameters()
        )
        log(f"DAgger: resuming after round {done - 1} ({sum(len(y) for y in ys)} samples)")
    for it in range(done, iterations + 1):
        if max_minutes is not None and it > 0 and time.perf_counter() - t0 > max_minutes * 60.0:
            log(f"DAgger: wall-time budget of {max_minutes} min reached before round {it}")
            break
        r0 = time.perf_counter()
        if it == 0 and data is not None:
            states, labels = load_demos(data)
            x, y = _encode(wrapper, states, labels)
            scores: list[float] = []
            beta = 1.0
        else:
            beta = 1.0 if it == 0 else beta_decay**it
            job = _RolloutJob(
                scenarios=[str(p) for p in split.train_paths],
                train_seeds=split.train_seeds,
                wrapper=wrapper,
                beta=beta,
                noise=noise if it == 0 else 0.0,
                seed=seed + 1000 * it,
                # Rounds take the training files in turn, continuing where the last round ended.
                start=((it - 1) if data is not None else it) * n_eps,
            )
            x, y, scores = _rollouts(job, n_eps, model if it > 0 else None, env, ray_address)
        roll_s = time.perf_counter() - r0
        save = np.savez_compressed if x.dtype == np.uint8 else np.savez  # BEV images compress well
        save(_round_file(out, it).with_suffix(".tmp.npz"), x=x, y=y)
        _round_file(out, it).with_suffix(".tmp.npz").replace(_round_file(out, it))
        xs.append(x)
        ys.append(y)
        loss = fit(
            model,
            np.concatenate(xs),
            np.concatenate(ys),
            epochs=epochs * (2 if it == 0 else 1),
            seed=seed + it,
        )
        model.save(out / "rounds" / f"model_{it:03d}.zip")
        rec = {
            "phase": "dagger",
            "iteration": it,
            "beta": beta,
            "new_samples": len(y),
            "samples": int(sum(len(a) for a in ys)),
            "rollout_mean_score": float(np.mean(scores)) if scores else None,
            "loss": loss,
            "rollout_s": roll_s,
            "fit_s": time.perf_counter() - r0 - roll_s,
        }
        _write_log(out, rec)
        log(
            f"DAgger {it}/{iterations}: beta {beta:.3f}, +{len(y)} samples, rollouts S_R4 "
            f"{rec['rollout_mean_score']}, loss {loss:.4f}, {time.perf_counter() - r0:.0f} s"
        )
    env.close()
    total = int(sum(len(a) for a in ys))
    path = save_model(
        model, out / "model.zip", "ppo", wrapper, trained_by="dagger", samples=total, split=split.to_dict()
    )
    _write_log(out, {"phase": "done", "samples": total, "wall_s": time.perf_counter() - t0})
    return path


def _write_log(out: Path, rec: dict[str, Any]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with (out / "train_log.jsonl").open("a", encoding="utf-8") as fh:
        fh.write(json.dumps(rec) + "\n")
