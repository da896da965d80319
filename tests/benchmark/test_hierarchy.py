"""`drivehierarchy hierarchy report` on real runs: open-loop runs of three scripted models on the
released samples (loopback server, `openloop predict` + `openloop score`) and R4 evaluations of
three built-in drivers on one short scenario; plus the error paths."""

from __future__ import annotations

import csv
import hashlib
import json
import shutil
from pathlib import Path

import pytest
from scipy.stats import spearmanr

from drivehierarchy import ConfigError
from drivehierarchy.benchmark import hierarchy
from drivehierarchy.benchmark.openloop.catalog import ImageRootMap, default_catalog, load_dataset
from drivehierarchy.benchmark.openloop.runner import RunConfig, predict
from drivehierarchy.benchmark.openloop.scoring import score_run
from drivehierarchy.benchmark.openloop.synthetic import (
    OraclePolicy,
    oracle_answer,
    write_images,
    wrong_answer,
)
from drivehierarchy.benchmark.r4 import runner as r4_runner
from drivehierarchy.cli import main
from drivehierarchy.scenarios import builtin_root, sumo_home
from drivehierarchy.testing.openai_server import ScriptedOpenAIServer

# One short scenario without SUMO traffic: the three drivers finish it in seconds.
SCENARIO = "02_obstacles/town01_02_cones_right_lane.toml"
# Open-loop model → share of records it answers right (the rest gets a wrong answer).
OPEN_LOOP_MODELS = {"sharp": 1.0, "middling": 0.6, "poor": 0.2}
# Paired in this order: the best open-loop model is not the best driver (ρ = 0.5, not 1).
R4_AGENTS = ("constant8", "expert", "zero")


def _right(record_id: str, share: float) -> bool:
    """Deterministic per record: the same records are right for a model on every run."""
    h = int(hashlib.sha256(record_id.encode()).hexdigest()[:8], 16) / 0xFFFFFFFF
    return h < share


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory, openloop_data_dir: Path) -> dict[str, Path]:
    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    tmp = tmp_path_factory.mktemp("hier")
    root_arg = f"/data/sets={tmp}/sets"
    cat = default_catalog(openloop_data_dir)
    records = [
        r for spec in cat.datasets for r in load_dataset(cat, spec, ImageRootMap.parse([root_arg])).records
    ]
    write_images(records)
    out: dict[str, Path] = {}
    for model, share in OPEN_LOOP_MODELS.items():
        policy = OraclePolicy(
            records,
            answer=lambda rec, s=share: oracle_answer(rec) if _right(rec.id, s) else wrong_answer(rec),
        )
        run = tmp / f"ol_{model}"
        with ScriptedOpenAIServer(policy) as url:
            summary = predict(
                RunConfig(
                    base_url=url, model=model, out=run, data_dir=openloop_data_dir,
                    image_roots=(root_arg,), progress=False, concurrency=8,
                )
            )  # fmt: skip
        assert summary.complete and policy.unmatched == 0
        score_run(run)  # R1_4 skipped: no judge model
        out[f"ol_{model}"] = run
    for agent in R4_AGENTS:
        run = tmp / f"r4_{agent}"
        r4_runner.evaluate(
            [builtin_root() / "r4" / SCENARIO], run, r4_runner.RunOptions(agent=agent), log=lambda _: None
        )
        out[f"r4_{agent}"] = run
    return out


def _pairs(runs: dict[str, Path]) -> list[str]:
    """Each open-loop model paired with one driver by NAME=PATH (their own names differ)."""
    args = []
    for model, agent in zip(OPEN_LOOP_MODELS, R4_AGENTS, strict=True):
        args += [f"{model}={runs[f'ol_{model}']}", f"{model}={runs[f'r4_{agent}']}"]
    return args


def test_report_from_real_runs(runs: dict[str, Path], tmp_path: Path, capsys) -> None:
    out = tmp_path / "report"
    assert main(["hierarchy", "report", *_pairs(runs), "--partial", "--out", str(out)]) == 0
    md = capsys.readouterr().out
    assert md == (out / "hierarchy.md").read_text()
    data = json.loads((out / "hierarchy.json").read_text())
    assert [m["model"] for m in data["models"]] == list(OPEN_LOOP_MODELS)
    # Every number is the tools' own: the scorer's rank means and headline, the R4 summary's score.
    for m, agent in zip(data["models"], R4_AGENTS, strict=True):
        fs = json.loads((runs[f"ol_{m['model']}"] / "evaluation" / "final_score.json").read_text())
        assert [m[r] for r in ("R1", "R2", "R3")] == [fs["ranks"][r]["mean"] for r in ("R1", "R2", "R3")]
        assert m["S_open"] == fs["S_open_partial"]["value"] and m["missing_tasks"] == ["R1_4"]
        r4 = json.loads((runs[f"r4_{agent}"] / "summary.json").read_text())
        assert m["R4"] == r4["r4_score"]
    sharp, middling, poor = data["models"]
    assert sharp["R2"] == sharp["R3"] == 100.0
    assert sharp["S_open"] > middling["S_open"] > poor["S_open"]
    assert middling["R4"] > sharp["R4"] > poor["R4"], "expert > constant8 > zero on this scenario"
    assert [m["r4_rank"] for m in data["models"]] == [2, 1, 3]
    assert data["spearman_with_r4"]["S_open"]["rho"] == pytest.approx(0.5)
    # ρ is scipy's on the same columns (an independent implementation).
    r4 = [m["R4"] for m in data["models"]]
    assert len(set(r4)) > 1, f"the drivers' R4 scores should differ: {r4}"
    for col in ("R1", "R2", "R3", "S_open"):
        expect = spearmanr([m[col] for m in data["models"]], r4).statistic
        assert data["spearman_with_r4"][col]["rho"] == pytest.approx(expect, abs=1e-12)
    with open(out / "hierarchy.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:6] == ["model", "R1", "R2", "R3", "S_open", "R4"]
    assert [r[0] for r in rows[1:]] == [*OPEN_LOOP_MODELS, "spearman_with_r4"]
    assert md.splitlines()[0] == "| Models | R1 | R2 | R3 | S_open | R4 | Rank |"
    assert "*Spearman ρ with R4*" in md


def test_fewer_than_three_models_leave_rho_undefined(runs: dict[str, Path], tmp_path: Path) -> None:
    _, md = hierarchy.build_report(_pairs(runs)[:4], tmp_path / "two", partial=True)
    data = json.loads((tmp_path / "two" / "hierarchy.json").read_text())
    assert data["n_models"] == 2
    assert all(
        v == {"rho": None, "reason": "2 models (needs ≥ 3)"} for v in data["spearman_with_r4"].values()
    )
    assert "| *Spearman ρ with R4* | undefined | undefined | undefined | undefined |" in md
    assert "0.000" not in md.splitlines()[-4]


def test_missing_pieces_are_named(runs: dict[str, Path], tmp_path: Path) -> None:
    # Without --partial, the judge-less R1 is refused with the file, field and value.
    with pytest.raises(ConfigError, match=r"final_score\.json: field `ranks\.R1\.missing` = \['R1_4'\]"):
        hierarchy.collect(_pairs(runs))
    # A model with an open-loop run but no R4 run.
    with pytest.raises(ConfigError, match=r"model 'poor': open-loop run .* has no R4 run"):
        hierarchy.collect(_pairs(runs)[:5], partial=True)
    # Unscored open-loop run.
    unscored = tmp_path / "unscored"
    shutil.copytree(runs["ol_poor"], unscored)
    shutil.rmtree(unscored / "evaluation")
    with pytest.raises(ConfigError, match=r"final_score\.json: not found.*openloop score"):
        hierarchy.collect([*_pairs(runs)[:4], f"poor={unscored}", f"poor={runs['r4_zero']}"], partial=True)
    # A corrupted field.
    broken = tmp_path / "broken"
    shutil.copytree(runs["r4_zero"], broken)
    summary = json.loads((broken / "summary.json").read_text())
    summary["r4_score"] = "high"
    (broken / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(ConfigError, match=r"summary\.json: field `r4_score` = 'high' is not a finite number"):
        hierarchy.collect([*_pairs(runs)[:4], f"poor={runs['ol_poor']}", f"poor={broken}"], partial=True)
    # Two runs of one model of the same kind.
    with pytest.raises(ConfigError, match="model 'sharp' already has an open-loop run"):
        hierarchy.collect([*_pairs(runs), f"sharp={runs['ol_poor']}"], partial=True)
    # Not a run folder.
    with pytest.raises(ConfigError, match="neither a scored open-loop run"):
        hierarchy.collect([str(tmp_path)], partial=True)
    # The CLI turns these into one line on stderr and exit status 2.
    assert main(["hierarchy", "report", str(tmp_path), "--out", str(tmp_path / "x")]) == 2


def test_r4_runs_of_different_suites_are_refused(runs: dict[str, Path], tmp_path: Path) -> None:
    other = tmp_path / "other"
    shutil.copytree(runs["r4_zero"], other)
    summary = json.loads((other / "summary.json").read_text())
    summary["categories"]["99_made_up"] = 1.0
    summary["counts"]["99_made_up"] = 1
    (other / "summary.json").write_text(json.dumps(summary))
    with pytest.raises(ConfigError, match="the models drove different R4 suites"):
        hierarchy.collect([*_pairs(runs)[:4], f"poor={runs['ol_poor']}", f"poor={other}"], partial=True)


# -- end to end on a generated set ---------------------------------------------------------------
GENERATED_SUITE = (
    "06_traffic_flow/town01_03_stop_and_go_queue.toml",
    "04_intersection/town01_04_straight_cross_traffic.toml",
    "01_pedestrian/town01_01_midblock_crossing.toml",
)


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`openloop generate` over three suite scenarios (maps linked beside them, as a suite folder)."""
    if sumo_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    root = tmp_path_factory.mktemp("gen_suite")
    (root / "maps").symlink_to(builtin_root() / "maps")
    for name in GENERATED_SUITE:
        (root / "r4" / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(builtin_root() / "r4" / name, root / "r4" / name)
    out = root / "gen"
    assert main(["openloop", "generate", "--suite", str(root / "r4"), "--out", str(out), "--per-task", "10",
                 "--jobs", "1", "--no-progress"]) == 0  # fmt: skip
    return out


def test_generate_predict_score_report_end_to_end(
    generated: Path, runs: dict[str, Path], tmp_path: Path, capsys
) -> None:
    cat = default_catalog(generated)
    records = [r for spec in cat.datasets for r in load_dataset(cat, spec).records]
    assert {r.task for r in records} >= {"R2_1", "R2_2_A", "R2_2_B", "R2_3", "R3_1", "R3_2"}
    args = []
    for (model, share), agent in zip(OPEN_LOOP_MODELS.items(), R4_AGENTS, strict=True):
        policy = OraclePolicy(
            records,
            answer=lambda rec, s=share: oracle_answer(rec) if _right(rec.id, s) else wrong_answer(rec),
        )
        run = tmp_path / model
        with ScriptedOpenAIServer(policy) as url:
            # The generated folder as it is: no --image-root (paths are relative to it).
            argv = ["openloop", "predict", "--base-url", url, "--model", model, "--data-dir", str(generated),
                    "--out", str(run), "--concurrency", "8", "--no-progress"]  # fmt: skip
            assert main(argv) == 0
        assert policy.unmatched == 0
        assert main(["openloop", "score", str(run)]) == 0
        args += [str(run), f"{model}={runs[f'r4_{agent}']}"]
    capsys.readouterr()
    out = tmp_path / "report"
    assert main(["hierarchy", "report", *args, "--partial", "--out", str(out)]) == 0
    data = json.loads((out / "hierarchy.json").read_text())
    sharp, middling, poor = data["models"]
    # The oracle answers every generated question right: full marks on every scored rank.
    assert sharp["R1"] == sharp["R2"] == sharp["R3"] == sharp["S_open"] == 100.0
    assert sharp["S_open"] > middling["S_open"] > poor["S_open"]
    assert data["spearman_with_r4"]["S_open"]["rho"] == pytest.approx(0.5)
    assert data["models"][0]["missing_tasks"] == ["R1_4"]
