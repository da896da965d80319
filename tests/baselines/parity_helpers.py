"""The check both baseline test files make of a trained model: `r4 run --agent sb3:MODEL` (the
plain env, the agent decoding its own actions) scores exactly what the model scores on the wrapped
env it was trained on."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from drivehierarchy.agents.sb3 import Sb3Agent
from drivehierarchy.baselines.wrappers import make_env
from drivehierarchy.cli import main

# Score-record fields measuring wall-clock time (names before/after protocol v2): the only ones
# that are not simulated.
WALL_CLOCK_KEYS = ("wall_duration", "duration_system")


def wrapped_and_runner_records(
    model: Path, scenario: str | Path, out: Path
) -> tuple[dict[str, Any], dict[str, Any]]:
    """(the wrapped env's score record, `r4 run`'s scene_score.json), seed 0, wall-clock keys dropped."""
    agent = Sb3Agent(model)
    env = make_env([scenario], agent.wrapper, monitor=False)
    obs, _ = env.reset(seed=0)
    while True:
        a, _ = agent.model.predict(obs, deterministic=True)
        obs, _, term, trunc, _ = env.step(a)
        if term or trunc:
            break
    wrapped = env.unwrapped.score()
    argv = ["r4", "run", "--agent", f"sb3:{model}", "--scenario", str(scenario), "--out", str(out)]
    rc = main(argv)
    assert rc == 0, f"drivehierarchy {' '.join(argv)} exited {rc}"
    via_runner = json.loads(next((out / "scenes").glob("*/scene_score.json")).read_text())
    for record in (via_runner, wrapped):
        for key in WALL_CLOCK_KEYS:
            record["meta"].pop(key, None)
    return wrapped, via_runner
