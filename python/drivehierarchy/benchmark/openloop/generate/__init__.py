"""`drivehierarchy openloop generate`: R1–R3 question files from the R4 scenes, with exact
ground truth from the world and the renderer (docs/openloop_generate.md).

`rollout` drives the suite and samples `Moment`s; the task modules (`r1`, `r2`, `r3`) register
one record builder per task id; `quality` checks and balances; `writer` writes the 14 files
and the images."""

from __future__ import annotations

import importlib

# Task modules, imported on demand so that a missing one (built on another branch) only
# leaves its tasks out.
TASK_MODULES = ("r1", "r2", "r3")


def load_builders() -> list[str]:
    """Imports the task modules present; returns the names of those loaded."""
    loaded = []
    for name in TASK_MODULES:
        try:
            importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
            continue
        loaded.append(name)
    return loaded
