"""`openloop generate` end to end on the R4 suite (a small --per-task): the original's file names
and fields, the oracle check through `openloop score`, byte-identical output for the same
options, the loader resolving the relative image paths, balance and quality rules."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from drivehierarchy.benchmark.openloop.catalog import default_catalog, load_dataset, select_datasets
from drivehierarchy.benchmark.openloop.generate import quality
from drivehierarchy.benchmark.openloop.generate.rollout import MIN_VISIBLE_FRACTION, builders
from drivehierarchy.benchmark.openloop.generate.writer import EVAL_SEEDS, generate, plan_episodes, suite_files
from drivehierarchy.benchmark.openloop.records import TASK_FILE_STEM, TASK_KIND, record_id
from drivehierarchy.benchmark.openloop.scoring import score_run

REPO = Path(__file__).resolve().parents[3]
SUITE = REPO / "scenarios" / "r4"
PER_TASK = 6
SPARSE_TASKS = {"R1_1_C", "R2_2_B", "R2_3"}
SEED = 7


def _read(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines()]


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("gen") / "set"
    summary = generate(SUITE, out, per_task=PER_TASK, seed=SEED, split="eval", jobs=2)
    return out, summary


def test_every_registered_task_has_a_full_file_under_the_original_name(generated) -> None:
    out, summary = generated
    assert set(summary["tasks"]) == set(builders())
    assert {"R1_1_A", "R1_1_B", "R1_1_C", "R1_2_A", "R1_2_B", "R1_2_C", "R1_3", "R1_4"} <= set(
        summary["tasks"]
    )
    for task, info in summary["tasks"].items():
        assert info["file"] == f"{TASK_FILE_STEM[task]}.jsonl"
        recs = _read(out / info["file"])
        # R1_1_C asks only where one frame shows the status (a lit brake lamp, a kerb-parked
        # car, a person's gait), R2_2_B only about objects within 40 m with states balanced
        # within each class, R2_3 one pair with a same-heading reference: a small set has fewer
        # such moments.
        assert len(recs) == PER_TASK or (task in SPARSE_TASKS and len(recs) >= 2), task


def test_records_have_the_original_fields(generated, openloop_data_dir: Path) -> None:
    out, summary = generated
    for task, info in summary["tasks"].items():
        original = _read(openloop_data_dir / info["file"])[0]
        for rec in _read(out / info["file"]):
            assert list(rec) == list(original), f"{task}: fields {list(rec)} != {list(original)}"
            if isinstance(original.get("meta_data"), dict):
                missing = set(original["meta_data"]) - set(rec["meta_data"])
                assert not missing, f"{task}: meta_data lacks {missing}"


def _oracle_prediction(task: str, rec: dict[str, Any]) -> str:
    kind = TASK_KIND[task]
    if kind == "bbox":
        return json.dumps(rec["ground_truth"]["bbox"])
    if kind == "sequence_order":
        return json.dumps(rec["ground_truth_order"])
    return str(rec["answer"])


def test_oracle_answers_score_full_marks(generated, tmp_path: Path) -> None:
    out, summary = generated
    run = tmp_path / "oracle"
    (run / "predictions").mkdir(parents=True)
    for task, info in summary["tasks"].items():
        lines = [
            json.dumps(
                {
                    "id": record_id(r),
                    "task": task,
                    "prediction": _oracle_prediction(task, r),
                    "record": r,
                    "model": "oracle",
                }
            )
            for r in _read(out / info["file"])
        ]
        (run / "predictions" / info["file"]).write_text("\n".join(lines) + "\n", encoding="utf-8")
    result = score_run(run)
    scored = {f["source_file"] for f in result["per_file"]}
    assert f"{TASK_FILE_STEM['R1_4']}.jsonl" not in scored  # the judge task, skipped without a judge
    per_record = _read(run / "evaluation" / "per_record.jsonl")
    assert len(per_record) == sum(i["records"] for t, i in summary["tasks"].items() if t != "R1_4")
    bad = [r for r in per_record if r["score"] != 100.0]
    assert not bad, bad[:3]


def test_loader_resolves_relative_images_without_image_root(generated) -> None:
    out, summary = generated
    catalog = default_catalog(out)
    for spec in select_datasets(catalog, list(summary["tasks"])):
        ds = load_dataset(catalog, spec)
        written = {i["file"]: i["records"] for i in summary["tasks"].values()}
        assert not ds.issues and len(ds.records) == written[spec.path]
        for rec in ds.records:
            assert rec.images
            for img in rec.images:
                assert Path(img.path).is_file(), img.path
                assert Path(img.path).parent == out / "images"
        for raw in (r.raw for r in ds.records):  # the files themselves keep relative paths
            paths = (
                [i["path"] for i in raw["images"]]
                if "images" in raw
                else raw.get("image_paths") or [raw["image_path"]]
            )
            assert all(not Path(p).is_absolute() and p.startswith("images/") for p in paths)


def test_same_options_give_byte_identical_files(generated, tmp_path: Path) -> None:
    out, _ = generated
    again = tmp_path / "again"
    generate(SUITE, again, per_task=PER_TASK, seed=SEED, split="eval", jobs=1)
    files = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for rel in files:
        assert (out / rel).read_bytes() == (again / rel).read_bytes(), rel
    # Regenerating over the set with another seed replaces it (no stale images left).
    generate(SUITE, again, per_task=PER_TASK, seed=SEED + 1, split="eval", jobs=2)
    assert (again / "R1_1_A_Existence.jsonl").read_bytes() != (out / "R1_1_A_Existence.jsonl").read_bytes()
    used = set()
    for f in again.glob("*.jsonl"):
        text = f.read_text(encoding="utf-8")
        used |= {p.name for p in (again / "images").iterdir() if p.name in text}
    assert used == {p.name for p in (again / "images").iterdir()}


def test_balance_and_visibility(generated) -> None:
    out, _ = generated
    yn = Counter(r["answer"] for r in _read(out / "R1_1_A_Existence.jsonl"))
    assert abs(yn["Yes"] - yn["No"]) <= 1
    # Correct letters cycle over each record's options (vehicles 3, people 2).
    for k in (2, 3):
        letters = Counter(
            r["answer"] for r in _read(out / "R1_1_C_State_Attribute.jsonl") if len(r["options"]) == k
        )
        assert not letters or max(letters.values()) - min(letters.get(c, 0) for c in "ABC"[:k]) <= 2
    for name in ("R1_1_B_Counting.jsonl", "R1_2_C_Distance_Bucket.jsonl"):
        recs = _read(out / name)
        assert sum(r["answer"] == "0" for r in recs) <= quality.MAX_ZERO_SHARE * len(recs) + 1e-9
        for r in recs:
            assert len(r["meta_data"]["object_ids"]) == int(r["answer"])
            assert all(f >= MIN_VISIBLE_FRACTION for f in r["meta_data"]["visible_fractions"])
    for r in _read(out / "R1_3_Location_Questions.jsonl"):
        x0, y0, x1, y1 = r["ground_truth"]["bbox"]
        assert 0 <= x0 < x1 < 1600 and 0 <= y0 < y1 < 900
        assert r["meta_data"]["visible_fraction"] >= 0.8


def test_quality_check_rejects_bad_records(tmp_path: Path) -> None:
    (tmp_path / "images").mkdir()
    (tmp_path / "images" / "a.jpg").write_bytes(b"x")
    box = {
        "task_id": "R1_3_0",
        "image_path": "images/a.jpg",
        "question": "q",
        "ground_truth": {"bbox": [10, 10, 1700, 20]},
    }
    with pytest.raises(quality.QualityError, match="not inside 1600x900"):
        quality.check("R1_3", [box], tmp_path, (1600, 900))
    yn = {"Question_id": "a", "image_path": "images/a.jpg", "question": "q", "answer": "Yes"}
    with pytest.raises(quality.QualityError, match="duplicate"):
        quality.check("R1_1_A", [yn, {**yn, "Question_id": "b"}], tmp_path, (1600, 900))
    with pytest.raises(quality.QualityError, match="not a file"):
        quality.check("R1_1_A", [{**yn, "image_path": "images/missing.jpg"}], tmp_path, (1600, 900))
    mc = {
        "Question_id": "a",
        "image_path": "images/a.jpg",
        "question": "q",
        "options": ["A. x.", "B. y."],
        "answer": "C",
    }
    with pytest.raises(quality.QualityError, match="not one of the options"):
        quality.check("R1_1_C", [mc], tmp_path, (1600, 900))


def test_train_split_never_plays_an_eval_episode() -> None:
    files = suite_files(SUITE)
    train = plan_episodes(files, 200, 0, "train", ("expert", "noisy_expert"))
    evals = plan_episodes(files, 200, 0, "eval", ("expert", "noisy_expert"))
    assert all(e.seed in EVAL_SEEDS for e in evals)
    assert not {e.seed for e in train} & set(EVAL_SEEDS)
    assert {Path(e.scenario).parent.name for e in train} == {p.name for p in SUITE.iterdir() if p.is_dir()}


def test_bad_options_name_the_option(tmp_path: Path) -> None:
    from drivehierarchy import ConfigError

    with pytest.raises(ConfigError, match="--suite"):
        generate(tmp_path / "nope", tmp_path / "out", per_task=1)
    with pytest.raises(ConfigError, match="--per-task"):
        generate(SUITE, tmp_path / "out", per_task=0)
    with pytest.raises(ConfigError, match="--split"):
        plan_episodes(suite_files(SUITE), 1, 0, "test", ("expert",))


def test_predict_and_score_through_the_loopback_server(generated, tmp_path: Path) -> None:
    """`openloop predict --data-dir DIR` (no --image-root) then `openloop score`, end to end."""
    from drivehierarchy.benchmark.openloop.report import extract_task_scores
    from drivehierarchy.benchmark.openloop.runner import RunConfig, predict
    from drivehierarchy.benchmark.openloop.synthetic import OraclePolicy
    from drivehierarchy.testing.openai_server import ScriptedOpenAIServer

    out, summary = generated
    catalog = default_catalog(out)
    records = [
        r
        for spec in select_datasets(catalog, list(summary["tasks"]))
        for r in load_dataset(catalog, spec).records
    ]
    policy = OraclePolicy(records)
    run = tmp_path / "run"
    with ScriptedOpenAIServer(policy, latency_s=0.0) as url:
        cfg = RunConfig(
            base_url=url,
            model="oracle",
            out=run,
            data_dir=out,
            datasets=",".join(summary["tasks"]),
            progress=False,
        )
        s = predict(cfg)
    assert s.complete and s.failed == 0 and s.written == len(records) and policy.unmatched == 0
    scores = extract_task_scores(score_run(run))
    # R1_4 needs the learned judge (not installed in tests): listed as skipped, as today.
    assert set(scores) == set(summary["tasks"]) - {"R1_4"}
    for task, score in scores.items():
        assert score == pytest.approx(100.0), task


def test_train_split_plays_shifted_starts_reproducibly(tmp_path: Path) -> None:
    runs = []
    for name in ("a", "b"):
        out = tmp_path / name
        summary = generate(SUITE, out, per_task=2, seed=5, split="train", tasks=["R1_1_A", "R1_2_A"], jobs=2)
        runs.append((out, summary))
    (a, sa), (b, _) = runs
    assert all(e["seed"] not in EVAL_SEEDS and e["start_back_m"] > 0 for e in sa["episodes"])
    for rel in sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file()):
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    # The shifted start is in the scenario the rollout played: the ego starts farther back.
    first = Path(SUITE / sa["episodes"][0]["scenario"])
    from drivehierarchy.benchmark.openloop.generate.writer import shifted_scenario

    text = shifted_scenario(first, 5.0)
    assert text != first.read_text(encoding="utf-8") and "[ego]" in text


def test_an_empty_task_fails_with_the_rules_that_emptied_it(tmp_path: Path, monkeypatch, capsys) -> None:
    from drivehierarchy.benchmark.openloop.generate import rollout
    from drivehierarchy.cli import main

    def nothing(moments, n, rng):  # every candidate removed by one rule
        quality.dropped("the frame shows no cue of the status", len(moments))
        return []

    monkeypatch.setitem(rollout._REGISTRY, "R1_1_C", (nothing, rollout.Needs()))
    one = sorted((SUITE / "02_obstacles").glob("*.toml"))[0]
    out = tmp_path / "set"
    args = ["openloop", "generate", "--suite", str(one), "--out", str(out), "--per-task", "1"]
    rc = main([*args, "--tasks", "R1_1_A,R1_1_C", "--jobs", "1", "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "R1_1_C: 0 of 1 records: no candidate passed the rules" in err
    assert "the frame shows no cue of the status" in err
    assert "R1_1_A: " not in err  # a full task is not named
    summary = json.loads((out / "generation.json").read_text(encoding="utf-8"))
    assert summary["tasks"]["R1_1_C"]["records"] == 0
    assert summary["tasks"]["R1_1_A"]["records"] == 1
    assert summary["tasks"]["R1_1_C"]["candidates"]["the frame shows no cue of the status"] > 0
    # A timing run (strict=False) reports it in the table instead.
    again = generate(one, out, per_task=1, seed=0, tasks=["R1_1_C"], jobs=1, strict=False)
    assert again["quality"][0]["problems"][0].startswith("0 of 1 records")
