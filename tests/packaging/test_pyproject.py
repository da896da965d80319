"""The package's declared facts agree with each other (issue 17): one SUMO pin for building and
running, a core without heavy machine-learning stacks, extras by job, the Python CI tests."""

from __future__ import annotations

import re
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
HEAVY = re.compile(
    r"^(torch|torchvision|jax|jaxlib|ray|tensorflow|transformers|stable-baselines3|nvidia-)", re.I
)


def _name(req: str) -> str:
    return re.split(r"[<>=!~\[; ]", req, maxsplit=1)[0].lower()


def test_the_build_compiles_against_the_sumo_it_runs_with() -> None:
    pins = [
        r for r in PROJECT["project"]["dependencies"] if _name(r) in ("eclipse-sumo", "libsumo", "sumolib")
    ]
    build = [r for r in PROJECT["build-system"]["requires"] if _name(r) == "eclipse-sumo"]
    assert build, "eclipse-sumo must be a build requirement (the SUMO shims' headers)"
    assert build[0] in pins
    assert len({p.split("==")[1] for p in pins}) == 1, pins


def test_the_core_installs_no_heavy_stack() -> None:
    heavy = [r for r in PROJECT["project"]["dependencies"] if HEAVY.match(_name(r))]
    assert not heavy, heavy


def test_extras_by_job_and_all_holds_them() -> None:
    extras = PROJECT["project"]["optional-dependencies"]
    for job in ("rl", "ray", "judge", "dev", "all"):
        assert job in extras, job
    (all_of,) = extras["all"]
    listed = set(re.search(r"\[(.*)\]", all_of).group(1).split(","))
    assert listed >= {name for name, reqs in extras.items() if reqs and name != "all"}


def test_declared_python_is_the_one_ci_runs() -> None:
    assert PROJECT["project"]["requires-python"] == ">=3.11"
    tested = [
        c
        for c in PROJECT["project"]["classifiers"]
        if re.fullmatch(r"Programming Language :: Python :: 3\.\d+", c)
    ]
    assert tested == [f"Programming Language :: Python :: {sys.version_info.major}.{sys.version_info.minor}"]
