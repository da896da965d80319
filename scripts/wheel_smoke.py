"""Smoke test of an installed wheel, run from a venv with no Rust toolchain (scripts/wheel_check.sh).

1. `gym.make` + reset + step with images;
2. a SUMO scenario on the libsumo transport, with no fallback warning;
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


def oracle_line(scorer: str, raw: dict) -> dict:
    """A line of the original runner's layout answering a released record with its own truth."""
    if scorer == "sequence_order":
        truth = raw["ground_truth_order"]
    else:
        truth = raw["ground_truth"] if scorer == "bbox" else raw["answer"]
    if scorer == "bbox":
        answer = json.dumps(truth["bbox"])
    else:
        answer = json.dumps(truth) if scorer == "sequence_order" else str(truth)
    line = {
        "Question_id": str(raw.get("Question_id", raw.get("task_id"))),
        "question": "q",
        "ground_truth": truth,
        "model_prediction": answer,
    }
    if scorer == "sequence_order":
        line["ground_truth_order"] = truth
    return line


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

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = gym.make(
            "DriveHierarchy-R4",
            scenario="06_traffic_flow/bs3d_09_left_turner_queue",
            front=None,
            bev=None,
            sumo_backend="libsumo",
        )
        env.reset(seed=0)
        for _ in range(20):
            env.step(env.unwrapped.expert_action())
        transport = env.unwrapped._sumo.transport
        check(transport == "libsumo", f"SUMO scenario runs on the libsumo shim (transport {transport})")
        check(np.isfinite(env.unwrapped.score()["score_route"]), "SUMO scenario stepped")
        env.close()
    check(not [w for w in caught if "SUMO" in str(w.message)], "no SUMO fallback warning")

    runs = work / "runs"
    rc = subprocess.call(
        ["drivehierarchy", "r4", "evaluate", "--agent", "expert", "--suite",
         str(Path(drivehierarchy.__file__).parent / "_data" / "scenarios" / "r4" / "07_sudden_brake"),
         "--out", str(runs)]
    )  # fmt: skip
    check(rc == 0, "r4 evaluate --agent expert on one category exits 0")
    summary = json.loads((runs / "summary.json").read_text())
    check(summary["completed"] == 10 and not summary["failed"], "10 scenarios evaluated, none failed")

    # The editor's page ships in the wheel (no CDN): served from the installed package.
    from starlette.testclient import TestClient

    from drivehierarchy.editor import create_app

    with TestClient(create_app(work, precompute=False), base_url="http://127.0.0.1:8765") as client:
        assets = (("/", "<canvas"), ("/static/editor.js", "window.editor"), ("/static/editor.css", "{"))
        for url, marker in assets:
            r = client.get(url)
            check(r.status_code == 200 and marker in r.text, f"the editor serves {url} from the wheel")

    if official is None or not official.is_dir():
        print("wheel smoke: open-loop samples not given; skipping openloop score")
        return
    from drivehierarchy import _core

    pred = work / "oracle"
    pred.mkdir()
    for task in _core.openloop_tasks():
        records = (official / f"{task['stem']}.jsonl").read_text(encoding="utf-8").splitlines()
        lines = [json.dumps(oracle_line(task["scorer"], json.loads(r))) for r in records if r.strip()]
        (pred / f"{task['stem']}_pred.jsonl").write_text("\n".join(lines) + "\n", encoding="utf-8")
    rc = subprocess.call(["drivehierarchy", "openloop", "score", str(pred), "--skip-l1-4"])
    check(rc == 0, "openloop score on the released samples exits 0")
    final = json.loads((pred / "evaluation" / "final_score.json").read_text())
    means = {k: v["mean"] if isinstance(v, dict) else v for k, v in final["tasks"].items()}
    check(len(means) == 13 and all(m == 100.0 for m in means.values()), f"oracle answers score 100: {means}")


if __name__ == "__main__":
    main()
