"""Trains and scores every baseline of docs/baselines.md in one resumable run.

    python scripts/train_baselines.py --out runs/baselines [--ppo-minutes 20] [--episodes 70]

Steps (each skipped when its output exists, so a killed run resumes): collect expert demos →
BC → DAgger → PPO (state, stopped after --ppo-minutes of wall time) → `r4 evaluate` of the expert,
the naive policies and every trained model on the built-in suite → OUT/results.md (per category,
training vs held-out scenarios, wall times) and OUT/results.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from drivehierarchy.cli import main as dh


def run(*args: object) -> None:
    code = dh([str(a) for a in args])
    if code != 0:
        raise SystemExit(f"failed ({code}): drivehierarchy {' '.join(map(str, args))}")


def quick_suite(folder: Path) -> Path:
    """Three short built-in scenarios without SUMO, linked into `folder` as a suite (with the maps
    beside it: the files name theirs as ../../maps/...)."""
    from drivehierarchy.scenarios import builtin_root

    r4 = builtin_root() / "r4"
    maps = folder.parent / "maps"
    if not maps.exists():
        maps.parent.mkdir(parents=True, exist_ok=True)
        maps.symlink_to(builtin_root() / "maps")
    for name in (
        "01_pedestrian/town01_01_midblock_crossing.toml",
        "02_obstacles/town01_02_cones_right_lane.toml",
        "09_yielding/town01_09_yield_left_turn.toml",
    ):
        link = folder / name
        if not link.exists():
            link.parent.mkdir(parents=True, exist_ok=True)
            link.symlink_to(r4 / name)
    return folder


def timed(marker: Path, fn: object, *args: object) -> float:
    """Runs a step once; its wall time is kept in `marker` (a resumed run reports the first)."""
    if marker.exists():
        return float(json.loads(marker.read_text())["wall_s"])
    t0 = time.perf_counter()
    fn(*args)  # type: ignore[operator]
    wall = time.perf_counter() - t0
    marker.write_text(json.dumps({"wall_s": wall}) + "\n")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("runs/baselines"))
    ap.add_argument("--episodes", type=int, default=70, help="expert demonstration episodes")
    ap.add_argument("--ppo-minutes", type=float, default=20.0)
    ap.add_argument("--ppo-envs", type=int, default=8)
    ap.add_argument("--dagger-iterations", type=int, default=6)
    ap.add_argument("--sac-minutes", type=float, default=0.0, help="also train SAC for this long (0 = no)")
    ap.add_argument("--until", choices=["collect", "bc", "dagger", "ppo", "eval"], default="eval")
    ap.add_argument("--suite", default="builtin", help="'builtin', a folder of scenarios, or one file")
    ap.add_argument(
        "--quick",
        action="store_true",
        help="smoke run (CI): 3 scenarios, 2 demos, one pass each, 64 PPO steps",
    )
    a = ap.parse_args()
    steps: list[object] = ["--steps", 5_000_000]
    epochs: list[object] = []
    if a.quick:
        a.suite = quick_suite(a.out / "suite" / "r4")
        a.episodes, a.ppo_envs, a.dagger_iterations, a.ppo_minutes = 2, 1, 1, 1.0
        steps, epochs = ["--steps", 64], ["--epochs", 1]
    order = ["collect", "bc", "dagger", "ppo", "eval"]
    last = order.index(a.until)
    out: Path = a.out
    out.mkdir(parents=True, exist_ok=True)
    walls: dict[str, float] = {}
    data = out / "data"
    walls["collect"] = timed(
        out / "collect.done",
        run,
        *("baselines", "collect", "--agent", "expert", "--suite", a.suite),
        *("--episodes", a.episodes, "--out", data),
    )
    if last < 1:
        return
    walls["bc"] = timed(
        out / "bc.done", run, "baselines", "train", "bc", "--data", data, "--out", out / "bc", *epochs
    )
    if last < 2:
        return
    walls["dagger"] = timed(
        out / "dagger.done",
        run,
        *("baselines", "train", "dagger", "--data", data, "--out", out / "dagger"),
        *("--iterations", a.dagger_iterations, *epochs),
    )
    if last < 3:
        return
    walls["ppo"] = timed(
        out / "ppo.done",
        run,
        *("baselines", "train", "ppo", "--suite", a.suite, *steps),
        *("--envs", a.ppo_envs, "--vec", "dummy", "--max-minutes", a.ppo_minutes, "--out", out / "ppo"),
    )
    if a.sac_minutes > 0:
        walls["sac"] = timed(
            out / "sac.done",
            run,
            *("baselines", "train", "sac", "--suite", a.suite, *steps),
            *("--envs", 4, "--vec", "dummy", "--max-minutes", a.sac_minutes, "--out", out / "sac"),
        )
    if last < 4:
        return
    agents = {
        "expert": "expert",
        "zero speed": "zero",
        "constant 8 m/s": "constant8",
        "BC": f"sb3:{out / 'bc' / 'model.zip'}",
        "DAgger": f"sb3:{out / 'dagger' / 'model.zip'}",
        "PPO (state)": f"sb3:{out / 'ppo' / 'model.zip'}",
    }
    if (out / "sac" / "model.zip").exists():
        agents["SAC (state)"] = f"sb3:{out / 'sac' / 'model.zip'}"
    split = json.loads((out / "bc" / "split.json").read_text())
    train = {f"{Path(p).parent.name}__{Path(p).stem}" for p in split["train"]}
    results: dict[str, dict[str, float]] = {}
    for label, agent in agents.items():
        ev = out / "eval" / label.split()[0].lower()
        run("r4", "evaluate", "--agent", agent, "--suite", a.suite, "--out", ev)
        lines = (ev / "results.jsonl").read_text().splitlines()
        results[label] = {json.loads(x)["key"]: json.loads(x)["score"]["score_composed"] for x in lines}
    keys = sorted(next(iter(results.values())))
    head = ["agent", *[k.split("__")[0] + (" (train)" if k in train else " (held-out)") for k in keys]]
    rows = [
        "| " + " | ".join([*head, "train mean", "held-out mean"]) + " |",
        "|" + "---|" + "---:|" * (len(keys) + 2),
    ]
    summary: dict[str, dict[str, float]] = {}
    for label, res in results.items():
        tr = float(np.mean([res[k] for k in keys if k in train]))
        ho = float(np.mean([res[k] for k in keys if k not in train]))
        summary[label] = {"train_mean": tr, "held_out_mean": ho, **res}
        cells = [f"{res[k]:.1f}" for k in keys]
        rows.append(f"| {label} | " + " | ".join(cells) + f" | **{tr:.1f}** | **{ho:.1f}** |")
    ppo_meta = json.loads((out / "ppo" / "timing.jsonl").read_text().splitlines()[-1])
    text = (
        "\n".join(rows)
        + "\n\nWall time (this machine): "
        + ", ".join(f"{k} {v / 60:.1f} min" for k, v in walls.items())
    )
    text += f"; PPO steps in its budget: {ppo_meta['total_steps']}\n"
    (out / "results.md").write_text(text)
    record = {"results": summary, "wall_s": walls, "ppo": ppo_meta}
    (out / "results.json").write_text(json.dumps(record, indent=2))
    print(text)


if __name__ == "__main__":
    main()
