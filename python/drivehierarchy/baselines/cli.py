"""`drivehierarchy baselines ...`: collect expert demonstrations, train PPO / SAC / BC / DAgger.

Every `train` writes OUT/model.zip (Stable-Baselines3 format, with the wrapper config inside), which
`drivehierarchy r4 evaluate --agent sb3:OUT/model.zip` scores like any other agent.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from drivehierarchy._core import ConfigError
from drivehierarchy.baselines.splits import Split
from drivehierarchy.envs.config import ACTION_LEVELS
from drivehierarchy.envs.traffic.modes import TRAFFIC_MODES, traffic_mode_arg


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    bl = sub.add_parser("baselines", help="RL and imitation baselines (needs the `rl` extra)")
    cmds = bl.add_subparsers(dest="baselines_command", required=True)

    def suite_args(p: argparse.ArgumentParser) -> None:
        p.add_argument("--suite", default="builtin", help="'builtin', a folder of scenarios, or one file")
        p.add_argument(
            "--split",
            default="seeds",
            choices=["seeds", "scenarios"],
            help="seeds: train on every file at seeds >= 100000, test on seeds 0-4 (the benchmark's); "
            "scenarios: also hold out --test-fraction of each category's files (transfer)",
        )
        p.add_argument(
            "--test-fraction",
            type=float,
            default=0.3,
            help="share of each category held out (--split scenarios)",
        )
        p.add_argument("--seed", type=int, default=0)
        p.add_argument(
            "--ray",
            metavar="ADDRESS",
            help="collect / dagger: drive the episodes as Ray tasks on this cluster ('local' starts one)",
        )

    def level_arg(p: argparse.ArgumentParser, default: str | None, extra: str = "") -> None:
        p.add_argument(
            "--action-level",
            choices=list(ACTION_LEVELS),
            default=default,
            help="what the policy decides: control = [steer, target speed] (the paper's), waypoints = "
            "8 ego-frame points 0.5 s apart for the waypoint tracker, meta = a path action x a speed "
            "action (docs/r4.md#action-levels)" + extra,
        )

    col = cmds.add_parser("collect", help="record expert demonstrations as a Minari dataset")
    col.add_argument("--agent", default="expert", help="demonstrator (only 'expert')")
    col.add_argument("--episodes", type=int, required=True, help="episodes, scenarios taken in turn")
    col.add_argument("--out", type=Path, required=True, help="dataset directory (Minari root)")
    col.add_argument(
        "--noise",
        type=float,
        default=1.0,
        help="σ of DART-style action noise on every other episode (0 = none)",
    )
    level_arg(col, "control", "; the label is the expert's plan at this level")
    suite_args(col)
    col.set_defaults(func=_collect)

    tr = cmds.add_parser("train", help="train a policy; writes OUT/model.zip")
    tr.add_argument("algo", choices=["ppo", "sac", "bc", "dagger"])
    tr.add_argument("--out", type=Path, required=True, help="output directory (resumable for ppo/sac)")
    tr.add_argument(
        "--data",
        type=Path,
        help="demonstrations from `collect` (bc; dagger: its first round, else expert rollouts)",
    )
    tr.add_argument("--steps", type=int, default=1_000_000, help="environment steps (ppo, sac)")
    tr.add_argument("--envs", type=int, default=8, help="parallel envs (ppo, sac)")
    tr.add_argument(
        "--vec",
        default="auto",
        choices=["auto", "subproc", "dummy", "native"],
        help="vectorisation (native: the Rust batch via the SB3 adapter; SUMO scenarios need --traffic idm)",
    )
    tr.add_argument("--max-minutes", type=float, help="stop this run's learning after N minutes (ppo, sac)")
    tr.add_argument("--checkpoint-every", type=int, default=50_000, help="steps between checkpoints")
    tr.add_argument("--epochs", type=int, default=60, help="passes over the data (bc; dagger per round)")
    tr.add_argument("--iterations", type=int, default=6, help="DAgger rounds")
    tr.add_argument(
        "--episodes-per-iter", type=int, help="DAgger episodes per round (default: one per training file)"
    )
    tr.add_argument(
        "--init",
        type=Path,
        help="ppo: start from this model.zip's policy (e.g. a DAgger model) instead of scratch",
    )
    tr.add_argument(
        "--init-log-std",
        type=float,
        help="ppo: log σ of the exploration noise (normalised actions) at the start, e.g. -3 to fine-tune",
    )
    tr.add_argument(
        "--vf-warmup",
        type=int,
        default=0,
        metavar="STEPS",
        help="ppo: train only the value function (policy frozen) for the first STEPS steps",
    )
    tr.add_argument("--obs", default="state", choices=["state", "bev", "state+bev"])
    tr.add_argument("--bev-size", type=int, default=128, help="side of the BEV image (obs bev, state+bev)")
    tr.add_argument(
        "--action",
        default="decision",
        choices=["decision", "raw"],
        help="control level: the protocol's decision, or raw pedals and steering",
    )
    level_arg(
        tr,
        None,
        "; recorded in model.zip, so `r4 evaluate --agent sb3:` drives at it. Default: the "
        "--data's level (bc, dagger), else control",
    )
    tr.add_argument("--reward", default="shaped", choices=["shaped", "score"], help="training reward")
    tr.add_argument("--max-speed", type=float, default=16.0, help="target speed at a[1] = +1 (m/s)")
    tr.add_argument(
        "--traffic",
        type=traffic_mode_arg,
        metavar="{" + ",".join(TRAFFIC_MODES) + "}",
        help="background traffic while training (default: each scenario's own mode)",
    )
    tr.add_argument(
        "--threads", type=int, default=1, help="torch threads (small MLPs: 1 is fastest on a shared box)"
    )
    tr.add_argument(
        "--hp", action="append", default=[], metavar="KEY=JSON", help="SB3 hyperparameter override"
    )
    suite_args(tr)
    tr.set_defaults(func=_train)

    cv = cmds.add_parser("curve", help="redraw OUT/learning_curve.png from the monitor logs")
    cv.add_argument("out", type=Path)
    cv.set_defaults(func=_curve)


def split_from_args(args: argparse.Namespace) -> Split:
    from drivehierarchy.baselines.splits import make_split
    from drivehierarchy.benchmark.r4.runner import suite_scenarios

    return make_split(suite_scenarios(args.suite), args.split, args.test_fraction)


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _collect(args: argparse.Namespace) -> int:
    from drivehierarchy.baselines import imitation

    split = split_from_args(args)
    imitation.collect(
        split,
        args.episodes,
        args.out,
        agent=args.agent,
        noise=args.noise,
        seed=args.seed,
        action_level=args.action_level,
        ray_address=args.ray,
        log=_log,
    )
    (args.out / "split.json").write_text(json.dumps(split.to_dict(), indent=2) + "\n", encoding="utf-8")
    return 0


def _hyperparams(items: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError(f"config `hp` = {item!r}: expected KEY=VALUE")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            raise ConfigError(f"config `hp.{key}` = {value!r}: not a JSON value") from None
    return out


def _train(args: argparse.Namespace) -> int:
    import torch

    from drivehierarchy.baselines.wrappers import WrapperConfig

    torch.set_num_threads(max(1, args.threads))
    split = split_from_args(args)
    level: dict[str, Any] = {"action_level": args.action_level or "control"}
    if args.data is not None and args.algo in ("bc", "dagger"):
        from drivehierarchy.baselines.imitation import demos_level

        have = demos_level(args.data)
        # The demonstrations' level (and plan shape) unless one is asked for; a different one
        # is refused by the trainer with the dataset's file named.
        level = have if args.action_level in (None, have["action_level"]) else level
    wrapper = WrapperConfig(
        action=args.action,
        max_speed_mps=args.max_speed,
        obs=args.obs,
        bev_size=args.bev_size,
        reward=args.reward,
        traffic=args.traffic,
        **level,
    )
    if args.ray is not None and args.algo != "dagger":
        raise ConfigError(f"config `ray` = {args.ray!r}: only `train dagger` runs its rollouts on Ray")
    if args.algo in ("ppo", "sac"):
        from drivehierarchy.baselines.rl import train_rl

        train_rl(
            args.algo,
            split,
            args.out,
            steps=args.steps,
            n_envs=args.envs,
            wrapper=wrapper,
            seed=args.seed,
            vec=args.vec,
            checkpoint_every=args.checkpoint_every,
            hyperparams=_hyperparams(args.hp),
            max_minutes=args.max_minutes,
            init=args.init,
            init_log_std=args.init_log_std,
            vf_warmup=args.vf_warmup,
            log=_log,
        )
        return 0
    from drivehierarchy.baselines import imitation
    from drivehierarchy.baselines.rl import write_split

    if args.data is None and args.algo == "bc":
        raise ConfigError(f"config `data` = None: `train {args.algo}` needs --data DIR from `collect`")
    args.out.mkdir(parents=True, exist_ok=True)
    write_split(args.out, split, wrapper, args.algo)
    if args.algo == "bc":
        imitation.train_bc(
            args.data, split, args.out, epochs=args.epochs, wrapper=wrapper, seed=args.seed, log=_log
        )
    else:
        imitation.train_dagger(
            args.data,
            split,
            args.out,
            iterations=args.iterations,
            episodes_per_iter=args.episodes_per_iter,
            epochs=max(1, args.epochs // 2),
            wrapper=wrapper,
            seed=args.seed,
            max_minutes=args.max_minutes,
            ray_address=args.ray,
            log=_log,
        )
    return 0


def _curve(args: argparse.Namespace) -> int:
    from drivehierarchy.baselines.rl import learning_curve

    png = learning_curve(args.out / "monitor", args.out / "learning_curve.png", title=args.out.name)
    print(png)
    return 0
