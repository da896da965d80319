"""Every script under `scripts/` runs end to end in its `--quick` mode (a tiny workload, seconds),
so a benchmark, the soak or the training pipeline cannot rot between the times someone runs it
for real. The figures they print mean nothing here; only the exit status and the files count.

Also: the quick lane's skip list in `scripts/test.sh` names only tests that exist."""

from __future__ import annotations

import ast
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"
# script -> its quick command line (after `python scripts/NAME`); {tmp} is the test's folder.
QUICK: dict[str, str] = {
    "bench_action_levels.py": "--quick",
    "bench_editor.py": "--quick",
    "bench_openloop_runner.py": "--quick",
    "bench_openloop_score.py": "--quick",
    "bench_r4.py": "--quick",
    "bench_render.py": "--quick --no-pin",
    "bench_suite_load.py": "--quick",
    "bench_sumo.py": "--quick",
    "bench_vector.py": "--quick",
    "bench_vlm_harness.py": "--quick",
    "bench_vlm_history.py": "--quick",
    "gen_pyunicode_tables.py": "--quick",
    "soak.py": "--quick --out {tmp}/soak",
    "sumo_retention.py": "--quick --traci",
    "train_baselines.py": "--quick --out {tmp}/baselines",
}
# Scripts run by another script or step of the gate, not on their own.
RUN_ELSEWHERE = {
    "wheel_smoke.py": "scripts/wheel_check.sh runs it against the built wheel in a fresh venv",
    # bench_generate.py and review_generated.py run as a pair below: the review reads the set.
    "bench_generate.py": "test_generate_then_review",
    "review_generated.py": "test_generate_then_review",
}


def _run(script: str, args: str, tmp: Path) -> subprocess.CompletedProcess[str]:
    argv = [sys.executable, str(SCRIPTS / script), *shlex.split(args.format(tmp=tmp))]
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"}
    done = subprocess.run(argv, cwd=tmp, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, (
        f"python scripts/{script} {args} exited {done.returncode}\n"
        f"stdout:\n{done.stdout[-3000:]}\nstderr:\n{done.stderr[-3000:]}"
    )
    return done


def test_every_script_has_a_quick_run() -> None:
    scripts = {p.name for p in SCRIPTS.glob("*.py")}
    assert scripts == set(QUICK) | set(RUN_ELSEWHERE), (
        "give a new script a --quick mode and list it in QUICK (or say where it runs)"
    )
    for name in QUICK:
        assert "--quick" in (SCRIPTS / name).read_text(encoding="utf-8"), name


@pytest.mark.parametrize("script", sorted(QUICK))
def test_quick_run(script: str, tmp_path: Path) -> None:
    _run(script, QUICK[script], tmp_path)


def test_generate_then_review(tmp_path: Path) -> None:
    _run("bench_generate.py", "--quick --out {tmp}/generated", tmp_path)
    done = _run("review_generated.py", "{tmp}/generated --quick --out {tmp}/review", tmp_path)
    page = (tmp_path / "review" / "index.html").read_text(encoding="utf-8")
    assert page.count("<h3>") == 3 and "<img" in page, done.stdout


def test_quick_lane_skips_only_tests_that_exist() -> None:
    text = (SCRIPTS / "test.sh").read_text(encoding="utf-8")
    block = re.search(r"^QUICK_SKIP=\((.*?)^\)", text, re.S | re.M)
    assert block, "scripts/test.sh has no QUICK_SKIP list"
    entries = re.findall(r"--(ignore|deselect)=(\S+)", block.group(1))
    assert entries
    for kind, target in entries:
        path, _, name = target.partition("::")
        assert (ROOT / path).is_file(), f"QUICK_SKIP: {target} does not exist"
        if kind == "deselect":
            source = (ROOT / path).read_text(encoding="utf-8")
            assert re.search(rf"^def {re.escape(name)}\(", source, re.M), f"QUICK_SKIP: no test {target}"


def test_heavy_first_names_only_test_files_that_exist() -> None:
    """The gate's scheduling order (tests/conftest.py `HEAVY_FIRST`) names real test files: a
    renamed file would silently fall back to collection order."""
    # Read, not imported: under pytest the name `conftest` is whichever conftest.py loaded first.
    tree = ast.parse((ROOT / "tests" / "conftest.py").read_text(encoding="utf-8"))
    values = [
        node.value
        for node in tree.body
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "HEAVY_FIRST" for t in node.targets)
    ]
    assert len(values) == 1, "tests/conftest.py has no HEAVY_FIRST"
    HEAVY_FIRST = ast.literal_eval(values[0])
    assert len(set(HEAVY_FIRST)) == len(HEAVY_FIRST)
    missing = [name for name in HEAVY_FIRST if not (ROOT / name).is_file()]
    assert not missing, f"HEAVY_FIRST names no test file: {missing}"
