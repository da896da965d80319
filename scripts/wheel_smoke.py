"""Smoke test of an installed wheel, run from a venv with no Rust toolchain (scripts/wheel_check.sh).

1. `gym.make` + reset + step with images;
2. a SUMO scenario on the native backend, with no fallback warning;
3. `drivehierarchy r4 evaluate --agent expert` on one category;
4. `drivehierarchy openloop score` on the released open-loop samples (answered with their own
   ground truth: every scored task must get the full score).

Usage: python scripts/wheel_smoke.py WORKDIR [OFFICIAL_OPEN_LOOP_DIR]
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import warnings
from pathlib import Path


def check(cond: bool, what: str) -> None:
    if not cond:
        sys.exit(f"wheel smoke: FAILED: {what}")
    print(f"wheel smoke: ok: {what}")


def main() -> None:
    work = Path(sys.argv[1])
    official = Path(sys.argv[2]) if len(sys.argv) > 2 else None
    import gymnasium as gym
    import numpy as np

    import drivehierarchy

    check(
        "site-packages" in drivehierarchy.__file__, f"drivehierarchy imported from {drivehierarchy.__file__}"
    )
    check(shutil.which("cargo") is None and shutil.which("rustc") is None, "no cargo or rustc on PATH")

    env = gym.make("DriveHierarchy-R4")
    obs, _ = env.reset(seed=0)
    obs, _, _, _, _ = env.step([0.0, 5.0])
    check(obs["front"].shape == (450, 800, 3) and obs["front"].any(), "front camera rendered")
    check(obs["bev"].shape == (800, 800, 3) and obs["bev"].any(), "BEV rendered")
    env.close()

    from drivehierarchy._core import NativeSumo

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = gym.make(
            "DriveHierarchy-R4",
            scenario="06_traffic_flow/bs3d_09_left_turner_queue",
            front=None,
            bev=None,
            sumo_backend="native",
        )
        env.reset(seed=0)
        for _ in range(20):
            env.step(env.unwrapped.expert_action())
        check(isinstance(env.unwrapped._sumo, NativeSumo), "SUMO scenario runs on the native backend")
        check(np.isfinite(env.unwrapped.score()["score_route"]), "SUMO scenario stepped")
        env.close()
    check(not [w for w in caught if "SUMO" in str(w.message)], "no SUMO fallback warning")

    runs = work / "runs"
    rc = subprocess.call(
        ["drivehierarchy", "r4", "evaluate", "--agent", "expert", "--suite",
         str(Path(drivehierarchy.__file__).parent / "_data" / "scenarios" / "r4" / "07_sudden_brake"),
         "--out", str(runs), "--no-progress"]
    )  # fmt: skip
    check(rc == 0, "r4 evaluate --agent expert on one category exits 0")
    summary = json.loads((runs / "summary.json").read_text())
    check(summary["n"] == 10, "10 scenarios evaluated")

    if official is None or not official.is_dir():
        print("wheel smoke: open-loop samples not given; skipping openloop score")
        return
    from drivehierarchy import _core

    tasks = {t["stem"]: t for t in _core.openloop_tasks()}
    pred = work / "oracle"
    pred.mkdir()
    for stem, task in tasks.items():
        lines = []
        for raw in map(json.loads, filter(str.strip, (official / f"{stem}.jsonl").read_text().splitlines())):
            scorer = task["scorer"]
            gt = (
                raw.get("ground_truth_order")
                if scorer == "sequence_order"
                else raw.get("ground_truth" if scorer == "bbox" else "answer")
            )
            answer = (
                json.dumps(gt["bbox"] if scorer == "bbox" else gt)
                if scorer in ("bbox", "sequence_order")
                else str(gt)
            )
            line = {"Question_id": str(raw.get("Question_id", raw.get("task_id"))), "question": "q",
                    "ground_truth": gt, "model_prediction": answer}  # fmt: skip
            if scorer == "sequence_order":
                line["ground_truth_order"] = gt
            lines.append(json.dumps(line))
        (pred / f"{stem}_pred.jsonl").write_text("\n".join(lines) + "\n")
    rc = subprocess.call(["drivehierarchy", "openloop", "score", str(pred), "--skip-l1-4"])
    check(rc == 0, "openloop score on the released samples exits 0")
    final = json.loads((pred / "evaluation" / "final_score.json").read_text())
    means = {k: v["mean"] if isinstance(v, dict) else v for k, v in final["tasks"].items()}
    check(len(means) == 13 and all(m >= 0.999 for m in means.values()), f"oracle answers score 1.0: {means}")


if __name__ == "__main__":
    main()
