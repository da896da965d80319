"""PPO and SAC (Stable-Baselines3) on the RL-ready wrappers, resumable.

Output directory:

    model.zip                 the final policy (SB3 archive + drivehierarchy.json wrapper config)
    split.json                training / test scenarios and seeds (`splits`)
    checkpoints/rl_model_<N>_steps.zip  (+ SAC's replay buffer) every --checkpoint-every steps
    monitor/<k>.monitor.csv   one line per training episode: shaped return, length, S_R4, reason
    tb/                       TensorBoard logs
    learning_curve.png        S_R4 of training episodes (and return) against environment steps

A run killed at any point resumes from its newest checkpoint when started again with the same
`--out` (the step budget counts the steps already done).
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from drivehierarchy._core import ConfigError
from drivehierarchy.baselines.model_io import algo_class, save_model
from drivehierarchy.baselines.splits import Split
from drivehierarchy.baselines.wrappers import WrapperConfig, make_env

MONITOR_KEYS = ("termination_reason", "score_composed")


def make_vec_env(
    scenarios: Sequence[Path],
    wrapper: WrapperConfig,
    n_envs: int,
    *,
    seed: int = 0,
    vec: str = "auto",
    monitor_dir: Path | None = None,
    train_seeds: tuple[int, int] | None = None,
) -> Any:
    """`n_envs` learner envs: `SubprocVecEnv` (one process each) or `DummyVecEnv` (all in this
    process: the Rust world needs no SUMO process, so many envs share one process cheaply).
    `auto` = one process per env when there are at least 2 envs and 2 cores, else in-process.
    `train_seeds`: every episode's seed is drawn from this range (`SuiteEnv`)."""
    import os

    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    if n_envs < 1:
        raise ConfigError(f"config `envs` = {n_envs!r}: expected ≥ 1")
    if vec not in ("auto", "subproc", "dummy", "native"):
        raise ConfigError(f"config `vec` = {vec!r}: expected 'auto', 'subproc', 'dummy' or 'native'")
    paths = [str(p) for p in scenarios]
    if vec == "native":
        from stable_baselines3.common.vec_env import VecMonitor

        from drivehierarchy.baselines.vec_sb3 import NativeSuiteVecEnv

        native = NativeSuiteVecEnv(paths, wrapper, n_envs, train_seeds=train_seeds)
        filename = None
        if monitor_dir is not None:
            filename = str(monitor_dir / "native")
            if Path(filename + ".monitor.csv").exists():
                # Resuming: VecMonitor always starts its file anew, so keep the old lines aside.
                Path(filename + ".monitor.csv").rename(_free_name(monitor_dir, "native"))
        venv: Any = VecMonitor(native, filename=filename, info_keywords=MONITOR_KEYS)
        venv.seed(seed)
        return venv
    # SUMO envs in one process work (the first on libsumo, the others on TraCI, a TCP round
    # trip per call), but a process each is faster: `auto` picks subprocesses for them.
    sumo = n_envs >= 2 and sumo_scenarios(paths, wrapper)
    if vec == "auto":
        vec = "subproc" if n_envs >= 2 and (sumo or (os.cpu_count() or 1) >= 2) else "dummy"

    def factory(rank: int) -> Any:
        def make() -> Any:
            env = make_env(paths, wrapper, monitor=False, train_seeds=train_seeds)
            filename = None if monitor_dir is None else str(monitor_dir / f"{rank}")
            # Resuming appends to the existing log (SB3 writes the header only for a new file).
            fresh = filename is None or not Path(filename + ".monitor.csv").exists()
            env = Monitor(env, filename=filename, info_keywords=MONITOR_KEYS, override_existing=fresh)
            env.reset(seed=seed + rank)
            return env

        return make

    fns = [factory(i) for i in range(n_envs)]
    venv = SubprocVecEnv(fns, start_method="fork") if vec == "subproc" else DummyVecEnv(fns)
    venv.seed(seed)
    return venv


def _free_name(folder: Path, stem: str) -> Path:
    k = 1
    while (folder / f"{stem}-{k}.monitor.csv").exists():
        k += 1
    return folder / f"{stem}-{k}.monitor.csv"


def sumo_scenarios(paths: Sequence[str], wrapper: WrapperConfig) -> list[str]:
    """The scenario files that co-simulate with SUMO under the wrapper's env settings."""
    from drivehierarchy import _core
    from drivehierarchy.envs.traffic import resolve_traffic_mode
    from drivehierarchy.scenarios import sumo_home

    config = wrapper.env_config()
    out = []
    for path in paths:
        sim = _core.Sim(path, config.to_core(), sumo_home())
        if resolve_traffic_mode(config.traffic, sim.scenario_traffic_mode) == "sumo":
            out.append(path)
    return out


def default_hyperparams(algo: str, n_envs: int, steps: int | None = None) -> dict[str, Any]:
    """Settings that learn on this env in minutes on 2 cores (short decision horizon, dense
    shaped reward); any of them can be overridden from the CLI with --hp key=value. A PPO budget
    of `steps` below one default rollout gets one rollout of that size (SB3 would otherwise play a
    whole 2,048-step rollout for `--steps 64`)."""
    if algo == "ppo":
        n_steps = max(64, 2048 // n_envs)
        if steps is not None and steps < n_steps * n_envs:
            n_steps = max(8, -(-steps // n_envs))
        return {
            "n_steps": n_steps,
            "batch_size": min(256, n_steps * n_envs),
            "n_epochs": 10,
            "learning_rate": 3e-4,
            "gamma": 0.99,
            "gae_lambda": 0.95,
            "clip_range": 0.2,
            "ent_coef": 0.0,
            "policy_kwargs": {"net_arch": [128, 128], "log_std_init": -1.0},
        }
    return {
        "learning_rate": 3e-4,
        "buffer_size": 300_000,
        "learning_starts": 2_000,
        "batch_size": 256,
        "gamma": 0.99,
        "train_freq": 1,
        "gradient_steps": 1,
        "policy_kwargs": {"net_arch": [256, 256]},
    }


def latest_checkpoint(out: Path) -> Path | None:
    best: tuple[int, Path] | None = None
    for p in (out / "checkpoints").glob("rl_model_*_steps.zip"):
        m = re.fullmatch(r"rl_model_(\d+)_steps\.zip", p.name)
        if m and (best is None or int(m.group(1)) > best[0]):
            best = (int(m.group(1)), p)
    return None if best is None else best[1]


def train_rl(
    algo: str,
    split: Split,
    out: Path,
    *,
    steps: int,
    n_envs: int = 8,
    wrapper: WrapperConfig | None = None,
    seed: int = 0,
    vec: str = "auto",
    checkpoint_every: int = 50_000,
    hyperparams: dict[str, Any] | None = None,
    max_minutes: float | None = None,
    init: Path | None = None,
    init_log_std: float | None = None,
    vf_warmup: int = 0,
    log: Any = print,
) -> Path:
    """Trains (or resumes) and writes OUT/model.zip on the split's training scenarios and seeds.
    `max_minutes` stops this run's learning after that much wall time (the model is saved as
    usual; a later run resumes from it). `init`: a model.zip (e.g. DAgger's, a PPO actor-critic
    of the same wrapper) whose policy weights PPO starts from (fine-tuning).

    Fine-tuning keeps near its start with `init_log_std` (the exploration noise, log σ of the
    normalised action, replacing the init's) and `vf_warmup` (the first N steps train only the
    value function, the policy frozen: an imitation model's critic is untrained, and PPO steps
    on its advantages would first move the policy away from the expert's)."""
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    if steps < 1:
        raise ConfigError(f"config `steps` = {steps!r}: expected ≥ 1")
    wrapper = wrapper or WrapperConfig()
    if algo == "sac" and wrapper.action_level == "meta":
        raise ConfigError(
            "config `action_level` = 'meta': SAC needs a continuous (Box) action space and meta "
            "actions are MultiDiscrete; use ppo (or bc / dagger)"
        )
    out.mkdir(parents=True, exist_ok=True)
    write_split(out, split, wrapper, algo)
    (out / "monitor").mkdir(exist_ok=True)
    venv = make_vec_env(
        split.train_paths,
        wrapper,
        n_envs,
        seed=seed,
        vec=vec,
        monitor_dir=out / "monitor",
        train_seeds=split.train_seeds,
    )
    cls = algo_class(algo)
    policy = {"state": "MlpPolicy", "bev": "CnnPolicy", "state+bev": "MultiInputPolicy"}[wrapper.obs]
    ckpt = latest_checkpoint(out)
    t0 = time.perf_counter()
    if ckpt is not None:
        log(f"resuming from {ckpt}")
        model = cls.load(str(ckpt), env=venv, device="cpu", tensorboard_log=str(out / "tb"))
        buf = ckpt.with_name(
            ckpt.name.replace("rl_model_", "rl_model_replay_buffer_").replace(".zip", ".pkl")
        )
        if algo == "sac" and buf.exists():
            model.load_replay_buffer(str(buf))
        reset = False
    else:
        hp = default_hyperparams(algo, n_envs, steps)
        hp.update(hyperparams or {})
        if init is not None:
            hp.setdefault("policy_kwargs", {})
            hp["policy_kwargs"] = {**hp["policy_kwargs"], **_init_policy_kwargs(init, algo, wrapper)}
        model = cls(policy, venv, seed=seed, device="cpu", tensorboard_log=str(out / "tb"), verbose=0, **hp)
        if init is not None:
            from drivehierarchy.baselines.model_io import load_model

            start, _, _ = load_model(init)
            model.policy.load_state_dict(start.policy.state_dict())
            log(f"initialised the policy from {init}")
        if init_log_std is not None:
            import torch as th

            if not hasattr(model.policy, "log_std"):
                raise ConfigError(
                    f"config `init_log_std` = {init_log_std!r}: {algo} has no state-independent log σ"
                )
            with th.no_grad():
                model.policy.log_std.fill_(float(init_log_std))
        reset = True
    if vf_warmup > 0 and algo != "ppo":
        raise ConfigError(f"config `vf_warmup` = {vf_warmup!r}: only PPO has a separate value function")
    cb = CheckpointCallback(
        save_freq=max(1, checkpoint_every // n_envs),
        save_path=str(out / "checkpoints"),
        save_replay_buffer=(algo == "sac"),
    )
    callbacks: list[Any] = [cb]
    limit = wall_clock_limit(max_minutes * 60.0) if max_minutes is not None else None
    if limit is not None:
        callbacks.append(limit)
    # Phases: the value warm-up (policy frozen) up to `vf_warmup` steps, then everything. The
    # step counter is in every checkpoint, so a resumed run continues in the right phase.
    for end, frozen in ((min(vf_warmup, steps), True), (steps, False)):
        remaining = end - model.num_timesteps
        if remaining <= 0 or (limit is not None and limit.expired):
            continue
        if frozen:
            log(f"value warm-up: policy frozen until step {end}")
        _freeze_policy(model, frozen)
        model.learn(
            total_timesteps=remaining,
            callback=CallbackList(callbacks),
            reset_num_timesteps=reset,
            tb_log_name=algo,
        )
        reset = False
    _freeze_policy(model, False)
    wall = time.perf_counter() - t0
    extra: dict[str, Any] = {"steps": int(model.num_timesteps), "split": split.to_dict()}
    if init is not None:
        extra["init"] = str(init)
    path = save_model(model, out / "model.zip", algo, wrapper, **extra)
    venv.close()
    _append_timing(
        out,
        {"phase": "train", "algo": algo, "total_steps": int(model.num_timesteps), "wall_s": wall},
    )
    try:
        learning_curve(out / "monitor", out / "learning_curve.png", title=f"{algo.upper()} ({out.name})")
    except ImportError:
        log("matplotlib missing: no learning_curve.png (install the `report` extra)")
    except ConfigError as exc:  # e.g. a budget too short to finish one episode: the model stands
        log(f"no learning_curve.png: {exc}")
    log(f"saved {path} after {model.num_timesteps} steps ({wall:.0f} s this run)")
    return path


def wall_clock_limit(seconds: float) -> Any:
    """A callback ending `learn` after `seconds` of wall time (built on use: SB3 is optional);
    its clock runs from its creation, across `learn` calls."""
    from stable_baselines3.common.callbacks import BaseCallback

    class WallClockLimit(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.t0 = time.perf_counter()

        @property
        def expired(self) -> bool:
            return time.perf_counter() - self.t0 >= seconds

        def _on_step(self) -> bool:
            return not self.expired

    return WallClockLimit()


def _freeze_policy(model: Any, frozen: bool) -> None:
    """Stops (or restarts) gradient updates of a PPO actor: its own layers, mean head and log σ
    (the critic's layers and the parameter-free feature extractor of an MLP keep learning)."""
    policy = model.policy
    if not hasattr(policy, "action_net"):
        return
    actor = [policy.action_net.parameters(), policy.mlp_extractor.policy_net.parameters()]
    if getattr(policy, "log_std", None) is not None:
        actor.append(iter([policy.log_std]))
    if not getattr(policy, "share_features_extractor", True):
        actor.append(policy.pi_features_extractor.parameters())
    for params in actor:
        for p in params:
            p.requires_grad_(not frozen)


def _init_policy_kwargs(init: Path, algo: str, wrapper: WrapperConfig) -> dict[str, Any]:
    """The architecture of the model to start from (so its weights fit), checked against the run."""
    from drivehierarchy.baselines.model_io import read_meta

    meta = read_meta(init)
    # What the policy sees and answers must match; traffic and reward are training-only settings.
    keys = ("obs", "action", "max_speed_mps", "bev_size", "action_level", "waypoints", "waypoint_dt_s")
    theirs = WrapperConfig.from_dict(meta["wrapper"]).to_dict()  # older models: their defaults
    theirs = {k: theirs[k] for k in keys}
    ours = {k: wrapper.to_dict()[k] for k in keys}
    if meta["algo"] != algo or theirs != ours:
        raise ConfigError(
            f"{init}: field `algo`/`wrapper` = {meta['algo']!r}/{theirs!r}: does not match this "
            f"run's {algo!r}/{ours!r}, so its weights cannot start it"
        )
    import zipfile

    with zipfile.ZipFile(init) as zf:
        data = json.loads(zf.read("data"))
    kwargs = data.get("policy_kwargs", {})
    # SB3 stores policy_kwargs pickled in the JSON; the plain fields are what it needs here.
    return {k: kwargs[k] for k in ("net_arch", "log_std_init") if k in kwargs}


def write_split(out: Path, split: Split, wrapper: WrapperConfig, algo: str) -> None:
    data = {"algo": algo, "split": split.to_dict(), "wrapper": wrapper.to_dict()}
    path = out / "split.json"
    if path.exists():
        old = json.loads(path.read_text(encoding="utf-8"))
        if old.get("split") != data["split"] or old.get("algo") != algo:
            raise ConfigError(
                f"{path}: field `train`/`algo` differs from this run's: the output directory belongs to "
                "another training run; use a new --out"
            )
    path.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")


def _append_timing(out: Path, rec: dict[str, Any]) -> None:
    with (out / "timing.jsonl").open("a", encoding="utf-8") as fh:
        fh.write(json.dumps(rec) + "\n")


def read_monitor(monitor_dir: Path) -> list[dict[str, Any]]:
    """Training episodes of all envs, ordered by wall time, with cumulative env steps."""
    import csv

    rows: list[dict[str, Any]] = []
    for path in sorted(monitor_dir.glob("*.monitor.csv")):
        with path.open(encoding="utf-8") as fh:
            fh.readline()  # the JSON header line
            for r in csv.DictReader(fh):
                try:
                    rows.append(
                        {
                            "r": float(r["r"]),
                            "l": int(r["l"]),
                            "t": float(r["t"]),
                            "score": float(r["score_composed"]) if r.get("score_composed") else float("nan"),
                            "reason": r.get("termination_reason", ""),
                        }
                    )
                except (KeyError, ValueError):
                    continue  # a line torn by a kill
    rows.sort(key=lambda r: r["t"])
    total = 0
    for r in rows:
        total += r["l"]
        r["steps"] = total
    return rows


def learning_curve(monitor_dir: Path, png: Path, title: str = "") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = read_monitor(monitor_dir)
    if not rows:
        raise ConfigError(f"{monitor_dir}: no finished training episode to plot")
    steps = np.array([r["steps"] for r in rows])
    score = np.array([r["score"] for r in rows])
    ret = np.array([r["r"] for r in rows])
    k = max(1, len(rows) // 50)
    smooth = np.convolve(np.nan_to_num(score), np.ones(k) / k, mode="valid")
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(steps, score, ".", alpha=0.25, label="S_R4 per training episode")
    ax.plot(steps[k - 1 :], smooth, "-", label=f"S_R4, mean of {k}")
    ax.set_xlabel("environment steps (decisions)")
    ax.set_ylabel("S_R4")
    ax.set_ylim(0, 100)
    ax2 = ax.twinx()
    ax2.plot(steps[k - 1 :], np.convolve(ret, np.ones(k) / k, mode="valid"), "g-", alpha=0.4, label="return")
    ax2.set_ylabel("training return", color="g")
    ax.legend(loc="upper left")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(png, dpi=90)
    plt.close(fig)
    return png
