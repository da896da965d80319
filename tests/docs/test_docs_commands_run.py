"""Every `drivehierarchy ...` command in the README and the docs runs, page by page, in order.

Each page gets a fresh working folder where its placeholders exist for real: the suite is linked
in as `scenarios/`, the original release as `Open_Loop_Evaluation`, `Scenario_Onsite` and
`tongji.net.xml`, a small OSM file as `city.osm`, and `http://localhost:8000/v1` is a loopback
OpenAI-compatible server (the route-following driver for R4 prompts, ground truth for open-loop
questions, over synthetic images at the `--image-root` target). Sizes are scaled so the whole
walk fits in CI (`SCALE` lists every rewrite), and what a page assumes from elsewhere (another
model's run to compare with) is made first by `GIVEN`, with the page's own commands. Each command
is a separate `drivehierarchy` process and must exit 0.
"""

from __future__ import annotations

import glob
import hashlib
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy.benchmark.openloop.catalog import ImageRootMap, default_catalog, load_dataset
from drivehierarchy.benchmark.openloop.synthetic import OraclePolicy, request_key, write_images
from drivehierarchy.scenarios import builtin_root
from drivehierarchy.testing.openai_server import ScriptedOpenAIServer, route_driver, route_points

sys.path.insert(0, str(Path(__file__).parent))
from test_docs_commands import PAGES, ROOT, _commands

DRIVEHIERARCHY = Path(sys.executable).with_name("drivehierarchy")
URL = "http://localhost:8000/v1"
# A short suite: three scenarios of three categories, SUMO traffic in one.
MINI = [
    "02_obstacles/town01_02_cones_right_lane.toml",
    "06_traffic_flow/bs3d_09_left_turner_queue.toml",
    "09_yielding/town01_09_yield_left_turn.toml",
]
# (pattern, replacement): sizes scaled for CI; nothing else about a command changes.
SCALE: list[tuple[str, str]] = [
    (r"--suite builtin", "--suite mini"),
    (r"--jobs 16", "--jobs 2"),
    (r"--episodes \d+", "--episodes 2"),
    # PPO without a step count would train for its default budget.
    (r"train ppo (?!.*--steps)", "train ppo --steps 64 "),
    (r"--steps \d+", "--steps 64"),
    (r"--envs \d+", "--envs 1"),
    (r"train (bc|dagger) ", r"train \1 --epochs 1 --iterations 1 "),
    # The probe over the whole suite is the sweep of docs/suite.md (minutes): one category here.
    (r"probe scenarios/r4 ", "probe scenarios/r4/02_obstacles --policies expert,zero --seeds 0 "),
    (
        r"probe scenarios/r4/07_sudden_brake ",
        "probe scenarios/r4/07_sudden_brake --policies expert --seeds 0 ",
    ),
    (r"r4 gallery$", "r4 gallery --out gallery"),
    (r"--port \d+", "--port 0"),  # servers: any free port
    (r"--per-task 200", "--per-task 5"),
]
# Commands a page's commands build on, run first in the page's folder (argv after the program).
GIVEN: dict[str, list[str | Callable[[Path], None]]] = {
    # A second open-loop run for the report's comparison, and the R4 scores it joins.
    "README.md": [
        f"openloop predict --base-url {URL} --model gemma-27b --data-dir Open_Loop_Evaluation"
        " --image-root /data/sets=DATASETS --out runs/gemma27b",
        "openloop score runs/gemma27b --skip-l1-4",
    ],
    "docs/openloop.md": [
        # The R4 side of the report: three models' runs (the first as the README shows it) and
        # `r4 report`'s r4_summary.csv.
        *(
            f"r4 evaluate --agent vlm --base-url {URL} --model {model} --suite builtin"
            f" --out runs/{run}_r4 --jobs 16"
            for model, run in (
                ("Qwen2.5-VL-7B", "qwen7b"),
                ("gemma-27b", "gemma27b"),
                ("internvl-8b", "internvl8b"),
            )
        ),
        "r4 report runs/qwen7b_r4 runs/gemma27b_r4 runs/internvl8b_r4 --out report/r4",
        *(
            f"openloop predict --base-url {URL} --model {model} --data-dir Open_Loop_Evaluation"
            f" --image-root /data/sets=DATASETS --out runs/{run}"
            for model, run in (("gemma-27b", "gemma27b"), ("internvl-8b", "internvl8b"))
        ),
        "openloop score runs/gemma27b --skip-l1-4",
        "openloop score runs/internvl8b --skip-l1-4",
        # The original runner's result folder: its `<task>_pred.jsonl` files, which carry the
        # same fields our prediction lines do.
        lambda folder: _as_original(folder / "runs" / "gemma27b", folder / "path/to/original/result_dir"),
    ],
    "docs/index.md": [
        f"openloop predict --base-url {URL} --model m --data-dir Open_Loop_Evaluation"
        " --image-root /data/sets=DATASETS --out path/to/predictions",
    ],
    # Three models' open-loop runs on the generated set and R4 runs (one short scenario each).
    "docs/openloop-generate.md": [
        "openloop generate --suite scenarios/r4 --out generated --per-task 200 --seed 0 --split eval",
        lambda folder: _know_generated(folder / "generated"),
        *(
            c
            for m in ("A", "B", "C")
            for c in (
                f"openloop predict --base-url {URL} --model {m} --out runs/{m} --data-dir generated",
                f"openloop score runs/{m} --skip-l1-4",
                f"r4 evaluate --agent vlm --base-url {URL} --model {m} --suite mini1 --out runs/{m}_r4",
            )
        ),
    ],
    "docs/vlm.md": [
        f"r4 evaluate --agent vlm --base-url {URL} --model gemma-27b --suite mini --out runs/gemma27b",
        f"openloop predict --base-url {URL} --model qwen3-vl-8b --data-dir Open_Loop_Evaluation"
        " --image-root /data/sets=DATASETS --out runs/ol_qwen3vl8b",
        "openloop score runs/ol_qwen3vl8b --skip-l1-4",
    ],
}

OSM = """<?xml version="1.0" encoding="UTF-8"?>
<osm version="0.6" generator="drivehierarchy test">
  <node id="1" lat="49.0000" lon="8.4000"/>
  <node id="2" lat="49.0000" lon="8.4030"/>
  <node id="3" lat="49.0020" lon="8.4030"/>
  <node id="4" lat="48.9980" lon="8.4030"/>
  <node id="5" lat="49.0000" lon="8.4060"/>
  <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="5"/>
    <tag k="highway" v="secondary"/><tag k="lanes" v="2"/></way>
  <way id="11"><nd ref="3"/><nd ref="2"/><nd ref="4"/>
    <tag k="highway" v="residential"/></way>
</osm>
"""


# Ground truth of the sets `openloop generate` writes during the walk (the server answers them).
GENERATED_ORACLES: list[OraclePolicy] = []


def _know_generated(data: Path) -> None:
    cat = default_catalog(data)
    roots = ImageRootMap.parse([])
    GENERATED_ORACLES.append(
        OraclePolicy(r for ds in cat.datasets for r in load_dataset(cat, ds, roots).records)
    )


def _as_original(run: Path, dest: Path) -> None:
    dest.mkdir(parents=True)
    for path in sorted((run / "predictions").glob("*.jsonl")):
        shutil.copy(path, dest / f"{path.stem}_pred.jsonl")


def _argv(command: str, folder: Path) -> list[str]:
    # `[...]` in a usage line is optional (`[a | b]`: alternatives): the plain command runs.
    cmd = re.sub(r"\s*\[[^\[\]]*?\]", "", command)
    for pat, rep in SCALE:
        cmd = re.sub(pat, rep, cmd)
    cmd = cmd.replace(URL, os.environ["DH_DOCS_TEST_URL"]).replace("/mnt/datasets", str(folder / "datasets"))
    out: list[str] = []
    for tok in shlex.split(cmd)[1:]:
        if tok in ("...", "…"):
            continue
        if any(c in tok for c in "*?") and not tok.startswith("-"):
            out.extend(sorted(glob.glob(tok, root_dir=folder)) or [tok])  # as the shell expands it
        else:
            out.append(tok)
    return out


def _link(src: Path, dest: Path) -> None:
    dest.parent.mkdir(parents=True, exist_ok=True)
    os.symlink(src, dest)


def _folder(base: Path, official: Path) -> Path:
    scen = builtin_root()
    _link(scen, base / "scenarios")
    (base / "mini").mkdir()
    for name in MINI:
        _link(scen / "r4" / name, base / "mini" / name)
    _link(scen / "r4" / MINI[0], base / "mini1" / MINI[0])
    _link(scen / "maps", base / "maps")
    docs = base / "docs"
    docs.mkdir()
    for name in ("suite.md", "suite_probe.csv"):
        shutil.copy(ROOT / "docs" / name, docs / name)
    onsite = official / "Close_Loop_Evaluation" / "Scenario_Onsite"
    tongji = official / "Close_Loop_Evaluation" / "Carla_Simulation" / "Co-Simulation" / "Sumo" / "tongji"
    for where in (base, base / "path" / "to"):
        _link(onsite, where / "Scenario_Onsite")
        _link(official / "Open_Loop_Evaluation", where / "Open_Loop_Evaluation")
    _link(tongji / "tongji.net.xml", base / "tongji.net.xml")
    _link(tongji, base / "path" / "to" / "tongji")
    _link(tongji / "carlavtypes13.rou.xml", base / "carlavtypes13.rou.xml")
    (base / "city.osm").write_text(OSM, encoding="utf-8")
    return base


@pytest.fixture(scope="module")
def server(official_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """The loopback model server; yields the folder its open-loop images were written under."""
    images = tmp_path_factory.mktemp("datasets")
    data = official_dir / "Open_Loop_Evaluation"
    cat = default_catalog(data)
    roots = ImageRootMap.parse([f"/data/sets={images}"])
    records = [r for ds in cat.datasets for r in load_dataset(cat, ds, roots).records]
    write_images(records)
    oracle = OraclePolicy(records)

    wrong_share = {
        "A": 0.1,
        "B": 0.4,
        "C": 0.7,
        "Qwen2.5-VL-7B": 0.2,
        "Qwen/Qwen3-VL-8B-Instruct": 0.3,
        "gemma-27b": 0.4,
        "internvl-8b": 0.6,
    }

    def policy(req: Any) -> Any:
        if route_points(req.last_text):
            return route_driver(req)
        # Models differ (a reproducible share of wrong answers each), so rank correlations exist.
        model = str(req.body.get("model"))
        digest = hashlib.sha256(f"{model}|{req.last_text}".encode()).digest()
        if digest[0] < 256 * wrong_share.get(model, 0.0):
            return "no idea"
        for known in (oracle, *GENERATED_ORACLES):
            if known.by_key.get(request_key(req.user_texts, [img.sha256 for img in req.images])):
                return known(req)
        return "no idea"

    models = ("Qwen2.5-VL-7B", "Qwen/Qwen3-VL-8B-Instruct", "qwen3-vl-8b", "gemma-27b", "internvl-8b")
    models += ("m", "M", "A", "B", "C")
    with ScriptedOpenAIServer(policy, models=models) as url:
        os.environ["DH_DOCS_TEST_URL"] = url
        yield images
        del os.environ["DH_DOCS_TEST_URL"]


PAGE_CASES = [p.relative_to(ROOT).as_posix() for p in PAGES if _commands(p)]


def test_every_page_with_commands_is_walked() -> None:
    assert "README.md" in PAGE_CASES and len(PAGE_CASES) >= 8
    assert set(GIVEN) <= set(PAGE_CASES)


# Pages walk one shared folder in order, so a command shown on two pages runs once; vlm.md has
# its own (its `runs/gemma27b` is an R4 run, the README's an open-loop one).
OWN_FOLDER = {"docs/vlm.md"}


@pytest.fixture(scope="module")
def folders(server: Path, official_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Any:
    made: dict[str, tuple[Path, set[tuple[str, ...]]]] = {}

    def get(page: str) -> tuple[Path, set[tuple[str, ...]]]:
        key = page if page in OWN_FOLDER else "shared"
        if key not in made:
            folder = _folder(tmp_path_factory.mktemp("docs_walk"), official_dir)
            _link(server, folder / "datasets")
            made[key] = (folder, set())
        return made[key]

    return get


# Commands that serve until stopped: each must print its URL and serve its page, then is stopped.
SERVERS = ("editor",)


def _serve_once(argv: list[str], folder: Path, env: dict[str, str]) -> None:
    proc = subprocess.Popen(
        [str(DRIVEHIERARCHY), *argv], cwd=folder, env=env, stdout=subprocess.PIPE, text=True
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:\d+/", line)
        assert m, f"drivehierarchy {shlex.join(argv)}: no URL printed: {line!r}"
        with urllib.request.urlopen(m.group(0), timeout=60) as r:
            assert r.status == 200 and b"<canvas" in r.read()
    finally:
        proc.terminate()
        proc.wait(timeout=30)


@pytest.mark.parametrize("page", PAGE_CASES)
def test_documented_commands_run(page: str, folders: Any) -> None:
    folder, ran = folders(page)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    steps: list[tuple[str, str | Callable[[Path], None]]] = []
    for given in GIVEN.get(page, []):
        if isinstance(given, str):
            given = f"drivehierarchy {given.replace('DATASETS', str(folder / 'datasets'))}"
        steps.append(("given", given))
    steps += [("page", c) for c in _commands(ROOT / page)]
    for kind, command in steps:
        if callable(command):
            command(folder)
            continue
        argv = _argv(command, folder)
        if tuple(argv) in ran:
            continue  # shown on an earlier page, ran there in this folder
        t0 = time.monotonic()
        if argv[0] in SERVERS:
            _serve_once(argv, folder, env)
            ran.add(tuple(argv))
            continue
        done = subprocess.run(
            [str(DRIVEHIERARCHY), *argv], cwd=folder, env=env, capture_output=True, text=True, timeout=600
        )
        assert done.returncode == 0, (
            f"{page} ({kind}): `{command}`\nran as: drivehierarchy {shlex.join(argv)}\n"
            f"exit {done.returncode}\nstdout:\n{done.stdout[-2000:]}\nstderr:\n{done.stderr[-3000:]}"
        )
        ran.add(tuple(argv))
        print(f"{time.monotonic() - t0:6.1f} s  drivehierarchy {shlex.join(argv)}")  # shown with -s
