"""Loader: the original catalog format, every released sample file unchanged, image-root remap."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drivehierarchy import ConfigError
from drivehierarchy.benchmark.openloop.catalog import (
    ImageRootMap,
    default_catalog,
    load_catalog,
    load_dataset,
    select_datasets,
)
from drivehierarchy.benchmark.openloop.records import TASK_FILE_STEM, TASK_IDS, TASK_KIND, task_id_from_name

# Records per sample file (the README of the samples).
SAMPLE_COUNTS = {
    "R1_1_A": 23, "R1_1_B": 21, "R1_1_C": 21, "R1_2_A": 18, "R1_2_B": 17, "R1_2_C": 21, "R1_3": 23,
    "R1_4": 18, "R2_1": 6, "R2_2_A": 7, "R2_2_B": 7, "R2_3": 13, "R3_1": 15, "R3_2": 10,
}  # fmt: skip


@pytest.fixture(scope="module")
def catalog(official_dir: Path):
    return load_catalog(official_dir / "scripts" / "configs" / "datasets" / "open_loop_all.json")


def test_original_catalog_resolves_root_relative_to_its_file(catalog, openloop_data_dir: Path) -> None:
    assert catalog.name == "open_loop_all"
    assert catalog.root == openloop_data_dir.resolve()
    assert [d.task for d in catalog.datasets] == list(TASK_IDS)
    assert all(d.kind == TASK_KIND[d.task] for d in catalog.datasets)


@pytest.mark.parametrize("task", TASK_IDS)
def test_every_sample_file_loads_unchanged(catalog, task: str) -> None:
    (spec,) = select_datasets(catalog, task)
    ld = load_dataset(catalog, spec)
    assert ld.issues == []
    assert len(ld.records) == SAMPLE_COUNTS[task]
    lines = [json.loads(line) for line in ld.path.read_text(encoding="utf-8").splitlines() if line.strip()]
    assert [r.raw for r in ld.records] == lines  # the original objects, untouched
    for rec in ld.records:
        assert rec.task == task and rec.kind == TASK_KIND[task]
        assert rec.images, rec.id
        assert all(img.path.startswith("/data/sets/") for img in rec.images)
    assert len({r.id for r in ld.records}) == len(ld.records)


def test_per_task_schema_quirks(catalog) -> None:
    def first(task: str):
        (spec,) = select_datasets(catalog, task)
        return load_dataset(catalog, spec).records[0]

    r13 = first("R1_3")
    assert r13.id == "R1_3_0"  # `task_id`, no `Question_id`
    assert r13.ground_truth == {"bbox": [1452, 738, 1560, 960], "format": "xyxy"}
    r32 = first("R3_2")
    assert r32.id == "R3_2_0" and r32.question == ""
    assert [(i.label, Path(i.path).name) for i in r32.images] == [
        ("A", "L3-2_Seq_000002_A.jpg"),
        ("B", "L3-2_Seq_000002_B.jpg"),
        ("C", "L3-2_Seq_000002_C.jpg"),
    ]
    assert r32.ground_truth == ["A", "B", "C"] and r32.labelled_images
    assert first("R2_1").id == "R2_1_A_0" and len(first("R2_1").images) == 6
    assert first("R2_2_A").id == "R2_1_B_0" and len(first("R2_2_A").images) == 10
    r22b = first("R2_2_B")
    assert r22b.ground_truth == "C. No Change (It remains moving)." and len(r22b.options) == 4
    assert first("R1_1_C").ground_truth == "B"
    assert len(first("R1_4").images) == 5
    assert first("R1_2_A").ground_truth == "52.54 m"


def test_image_root_remap(catalog, tmp_path: Path) -> None:
    roots = ImageRootMap.parse([f"/data/sets={tmp_path}/sets", f"/data/sets/nuscenes={tmp_path}/nus/"])
    (spec,) = select_datasets(catalog, "R1_1_A")
    ld = load_dataset(catalog, spec, roots)
    rec = ld.records[0]
    # The longest prefix wins; the record itself keeps the original path.
    assert rec.images[0].path == f"{tmp_path}/nus/samples/CAM_FRONT/" + Path(rec.raw["image_path"]).name
    assert rec.raw["image_path"].startswith("/data/sets/nuscenes/")
    (spec,) = select_datasets(catalog, "R1_3")
    assert load_dataset(catalog, spec, roots).records[0].images[0].path.startswith(f"{tmp_path}/sets/Drama/")


def test_remap_respects_path_boundaries() -> None:
    roots = ImageRootMap.parse(["/data/sets=/mnt/x"])
    assert roots.apply("/data/sets/a.jpg") == "/mnt/x/a.jpg"
    assert roots.apply("/data/sets2/a.jpg") == "/data/sets2/a.jpg"
    assert roots.apply("relative/a.jpg") == "relative/a.jpg"
    for bad in ("/data/sets", "=/x", "/a="):
        with pytest.raises(ConfigError, match="OLD=NEW"):
            ImageRootMap.parse([bad])


def test_dataset_selection(catalog) -> None:
    assert len(select_datasets(catalog, "all")) == 14
    names = [
        d.name for d in select_datasets(catalog, "R3_2, R1_1_A,R2_2_B_Temporal_Status_Recognition.jsonl")
    ]
    assert names == ["R1_1_A_Existence", "R2_2_B_Temporal_Status_Recognition", "R3_2_Sequential_Planning"]
    with pytest.raises(ConfigError, match="R9_9"):
        select_datasets(catalog, "R9_9")


def test_task_ids_from_file_stems() -> None:
    assert {task_id_from_name(stem) for stem in TASK_FILE_STEM.values()} == set(TASK_IDS)
    assert task_id_from_name("R1_3_Location_Questions") == "R1_3"
    assert task_id_from_name("notes") is None


def test_default_catalog_matches_original(catalog, openloop_data_dir: Path) -> None:
    mine = default_catalog(openloop_data_dir)
    assert [(d.name, d.path, d.kind) for d in mine.datasets] == [
        (d.name, d.path, d.kind) for d in catalog.datasets
    ]


def test_unusable_lines_become_issues(tmp_path: Path) -> None:
    good = {"Question_id": "R1_1_A_0", "question": "q?", "answer": "yes", "image_path": "/a.jpg"}
    lines = [
        json.dumps(good),
        '{"Question_id": "R1_1_A_1", "answ',  # torn line
        json.dumps({"question": "no id", "answer": "no", "image_path": "/b.jpg"}),
        json.dumps(good),  # duplicate id
        "",
        json.dumps({**good, "Question_id": "R1_1_A_2", "image_path": 5}),
    ]
    (tmp_path / "R1_1_A_Existence.jsonl").write_text("\n".join(lines) + "\n")
    cat = default_catalog(tmp_path)
    ld = load_dataset(cat, select_datasets(cat, "R1_1_A")[0])
    assert [r.id for r in ld.records] == ["R1_1_A_0"]
    assert [(i.line, i.id) for i in ld.issues] == [(2, None), (3, None), (4, "R1_1_A_0"), (6, "R1_1_A_2")]
    assert "invalid JSON" in ld.issues[0].detail and "image_path" in ld.issues[3].detail
    assert len(ld.sha256) == 64


def test_catalog_errors_name_file_and_field(tmp_path: Path) -> None:
    path = tmp_path / "cat.json"
    path.write_text(
        json.dumps({"name": "x", "root": ".", "datasets": [{"name": "a", "path": "a.jsonl", "task": "yes"}]})
    )
    with pytest.raises(ConfigError, match=r"cat\.json: datasets\[0\]: field 'task' = 'yes'"):
        load_catalog(path)
    path.write_text(json.dumps({"name": "x", "datasets": [], "extra": 1}))
    with pytest.raises(ConfigError, match="unknown catalog keys"):
        load_catalog(path)
    with pytest.raises(ConfigError, match="cannot read catalog"):
        load_catalog(tmp_path / "absent.json")
    cat = default_catalog(tmp_path)
    with pytest.raises(ConfigError, match="cannot read"):
        load_dataset(cat, cat.datasets[0])
