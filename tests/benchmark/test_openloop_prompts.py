"""Prompt strings of the original harness (docs/protocol.md#open-loop-prompting), pinned character
for character."""

from __future__ import annotations

from pathlib import Path

import pytest

from drivehierarchy.benchmark.openloop.catalog import default_catalog, load_dataset, select_datasets
from drivehierarchy.benchmark.openloop.prompts import (
    build_messages,
    question_text,
    swift_user_text,
    system_prompt,
)
from drivehierarchy.benchmark.openloop.records import parse_record

BASE = (
    "You are a mature and cautious driver with many years of driving experience. "
    "You now need assistance answering questions related to the driving process."
)


@pytest.mark.parametrize(
    ("kind", "suffix"),
    [
        ("yes_no", "Answer with only 'yes' or 'no' in lowercase. Do not output any other text."),
        (
            "numeric",
            "Answer with only the numeric result (integer or decimal). Do not include units or extra text.",
        ),
        (
            "multi_choice",
            "Choose the correct option and output only the option letter (e.g., A/B/C) without any extra text.",  # noqa: E501
        ),
        ("bbox", "Output only the bounding box as [x1, y1, x2, y2] in pixels with no extra text."),
        (
            "sequence_order",
            'Output only the ordered list of option labels in the format ["A", "B", ...] with no extra text.',
        ),
        ("text", "Output only the final answer without extra explanation."),
    ],
)
def test_system_prompt_per_kind(kind: str, suffix: str) -> None:
    assert system_prompt(kind) == BASE + " " + suffix


def _rec(raw: dict, kind: str):
    return parse_record(raw, task="T", kind=kind, dataset="d", line=1)


def test_multiple_choice_question() -> None:
    rec = _rec(
        {
            "Question_id": "q",
            "question": "What next?",
            "options": ["A. Stop.", "B. Go."],
            "image_path": "/i.jpg",
        },
        "multi_choice",
    )
    assert question_text(rec) == "What next?\nOptions:\nA. Stop.\nB. Go."
    no_q = _rec({"Question_id": "q", "options": ["A. x", "B. y"], "image_path": "/i.jpg"}, "multi_choice")
    assert question_text(no_q) == "Options:\nA. x\nB. y"


def test_plain_question_is_unchanged() -> None:
    rec = _rec({"Question_id": "q", "question": "How many cars?", "image_path": "/i.jpg"}, "numeric")
    assert question_text(rec) == "How many cars?"


def test_ordering_question_and_labelled_images() -> None:
    raw = {
        "Question_id": "R3_2_0",
        "images": [
            {"label": "B", "path": "/b.jpg"},
            {"label": "A", "path": "/a.jpg"},
            {"label": "C", "path": "/c.jpg"},
        ],
        "ground_truth_order": ["A", "B", "C"],
    }
    rec = _rec(raw, "sequence_order")
    expected_q = (
        "Please determine the correct order of the images.\nOption labels: B, A, C."
        '\nOutput format: ["A", "B", ...].'
    )
    assert question_text(rec) == expected_q
    msgs = build_messages(rec, lambda img: "url:" + img.path)
    assert msgs[0] == {"role": "system", "content": system_prompt("sequence_order")}
    assert msgs[1]["role"] == "user"
    assert msgs[1]["content"] == [
        {"type": "text", "text": "Image B"},
        {"type": "image_url", "image_url": {"url": "url:/b.jpg"}},
        {"type": "text", "text": "Image A"},
        {"type": "image_url", "image_url": {"url": "url:/a.jpg"}},
        {"type": "text", "text": "Image C"},
        {"type": "image_url", "image_url": {"url": "url:/c.jpg"}},
        {"type": "text", "text": expected_q},
    ]
    assert swift_user_text(rec) == "Image B<image>Image A<image>Image C<image>" + expected_q
    with_q = _rec({**raw, "question": "Order them."}, "sequence_order")
    assert question_text(with_q).startswith("Order them.\nOption labels: B, A, C.")


def test_multi_image_records_send_all_images_first(openloop_data_dir: Path) -> None:
    cat = default_catalog(openloop_data_dir)
    rec = load_dataset(cat, select_datasets(cat, "R2_1")[0]).records[0]
    content = build_messages(rec, lambda img: img.path)[1]["content"]
    assert [p["type"] for p in content] == ["image_url"] * 6 + ["text"]
    assert [p["image_url"]["url"] for p in content[:6]] == rec.raw["image_paths"]
    assert content[-1]["text"] == rec.raw["question"]


def test_real_multiple_choice_record(openloop_data_dir: Path) -> None:
    cat = default_catalog(openloop_data_dir)
    rec = load_dataset(cat, select_datasets(cat, "R1_1_C")[0]).records[0]
    assert question_text(rec) == (
        "What is the current status of the nearest Vehicle in CAM_FRONT?"
        "\nOptions:\nA. moving.\nB. parked.\nC. stopped."
    )
    assert swift_user_text(rec) == "<image>" + question_text(rec)
