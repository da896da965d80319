"""The decision message (docs/protocol.md#r4-loop): layout, images, question text, controls, presets."""

from __future__ import annotations

import base64
import io

import numpy as np
import pytest
from PIL import Image

from drivehierarchy import ConfigError
from drivehierarchy.agents.vlm import PRESETS, PayloadOptions, build_messages, resolve_model
from drivehierarchy.agents.vlm.payload import (
    bev_descriptor,
    corrupt_image,
    front_descriptor,
    prompt_hash,
    question_text,
)
from drivehierarchy.envs.r4 import DriveHierarchyR4Env

SCENARIO = "01_pedestrian/town01_01_midblock_crossing"


@pytest.fixture(scope="module")
def obs() -> dict:
    env = DriveHierarchyR4Env(scenario=SCENARIO)
    o, _ = env.reset(seed=0)
    return o


def _decode(part: dict) -> np.ndarray:
    url = part["image_url"]["url"]
    assert url.startswith("data:image/jpeg;base64,")
    data = base64.b64decode(url.split(",", 1)[1], validate=True)
    with Image.open(io.BytesIO(data)) as im:
        assert im.format == "JPEG"
        return np.asarray(im.convert("RGB"))


def test_layout_is_the_original_services(obs: dict) -> None:
    (msg,) = build_messages(obs, 7)
    assert msg["role"] == "user"
    parts = msg["content"]
    assert [p["type"] for p in parts] == ["text", "image_url", "text", "image_url", "text"]
    assert parts[0]["text"] == front_descriptor(800, 450)
    assert parts[2]["text"] == bev_descriptor(800)
    assert parts[4]["text"] == "Q(frame 7): " + obs["prompt"]
    front, bev = _decode(parts[1]), _decode(parts[3])
    assert front.shape == obs["front"].shape and bev.shape == obs["bev"].shape
    # Lossy but faithful: JPEG at quality 90 stays close to the rendered frame.
    assert np.abs(front.astype(int) - obs["front"].astype(int)).mean() < 4.0
    assert np.abs(bev.astype(int) - obs["bev"].astype(int)).mean() < 4.0


def test_question_is_the_protocol_text(obs: dict) -> None:
    text = question_text(obs["prompt"], 1)
    assert text.startswith("Q(frame 1): The ego vehicle is driving at the speed of 0.0 m/s, and it wants to ")
    assert text.endswith(
        "Output only the final action decision without explanation in the exact format:\n"
        "steer: <float in [-1.0, 1.0]>\ntarget_speed_mps: <float in [0.0, 30.0]>"
    )


def test_controls_drop_or_degrade_images(obs: dict) -> None:
    blind = build_messages(obs, 1, PayloadOptions(blind=True))[0]["content"]
    assert [p["type"] for p in blind] == ["text"] and blind[0]["text"].startswith("Q(frame 1): ")
    no_bev = build_messages(obs, 1, PayloadOptions(no_bev=True))[0]["content"]
    assert [p["type"] for p in no_bev] == ["text", "image_url", "text"]
    assert build_messages(obs, 1, PayloadOptions(max_images=1)) == build_messages(
        obs, 1, PayloadOptions(no_bev=True)
    )
    clean = obs["front"]
    for kind in ("noise", "blur", "dark"):
        a = corrupt_image(clean, kind, seed=3)
        assert a.shape == clean.shape and a.dtype == np.uint8
        assert np.abs(a.astype(int) - clean.astype(int)).mean() > 5.0, kind
        assert np.array_equal(a, corrupt_image(clean, kind, seed=3)), "corruption must be reproducible"
    dark = _decode(build_messages(obs, 1, PayloadOptions(corrupt="dark"))[0]["content"][1])
    assert dark.mean() < obs["front"].mean() * 0.4
    with pytest.raises(ConfigError, match="corrupt"):
        PayloadOptions(corrupt="fog")


def test_prompt_hash_covers_texts_not_images(obs: dict) -> None:
    a = build_messages(obs, 1)
    assert prompt_hash(a) == prompt_hash(build_messages(obs, 1, PayloadOptions(corrupt="noise")))
    assert prompt_hash(a) != prompt_hash(build_messages(obs, 2))
    assert len(prompt_hash(a)) == 16


def test_missing_observation_is_a_clear_error(obs: dict) -> None:
    with pytest.raises(ConfigError, match="bev"):
        build_messages({"front": obs["front"], "prompt": obs["prompt"]}, 1)


def test_presets_are_the_papers_fifteen_models() -> None:
    assert len(PRESETS) == 15
    best = max(PRESETS.values(), key=lambda p: p.paper_r4_average)
    assert best.paper_name == "Gemma-3-it(27B)" and best.paper_r4_average == pytest.approx(12.619)
    for p in PRESETS.values():
        assert p.images_per_prompt == 2
        # The paper's average is the mean of its ten category columns (to rounding).
        assert np.mean(p.paper_r4[:10]) == pytest.approx(p.paper_r4_average, abs=2e-3), p.key
    assert resolve_model("qwen3-vl-8b")[0] == "Qwen/Qwen3-VL-8B-Instruct"
    assert resolve_model("Qwen/Qwen3-VL-8B-Instruct")[1] is PRESETS["qwen3-vl-8b"]
    assert resolve_model("my-finetune") == ("my-finetune", None)
