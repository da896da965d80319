"""The original harness's prompting (docs/protocol.md#open-loop-prompting), reproduced exactly.

Chat = system message + one user message: all images first (labelled images preceded by the
text `Image A`, ...), then the question text. Strings here are part of the protocol; unit tests
pin them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from .records import BBOX, MULTI_CHOICE, NUMERIC, SEQUENCE_ORDER, YES_NO, ImageRef, Record

SYSTEM_PROMPT = (
    "You are a mature and cautious driver with many years of driving experience. "
    "You now need assistance answering questions related to the driving process."
)

KIND_SUFFIX: dict[str, str] = {
    YES_NO: "Answer with only 'yes' or 'no' in lowercase. Do not output any other text.",
    NUMERIC: "Answer with only the numeric result (integer or decimal). Do not include units or extra text.",
    MULTI_CHOICE: (
        "Choose the correct option and output only the option letter (e.g., A/B/C) without any extra text."
    ),
    BBOX: "Output only the bounding box as [x1, y1, x2, y2] in pixels with no extra text.",
    SEQUENCE_ORDER: (
        'Output only the ordered list of option labels in the format ["A", "B", ...] with no extra text.'
    ),
}
FREE_TEXT_SUFFIX = "Output only the final answer without extra explanation."
DEFAULT_ORDER_QUESTION = "Please determine the correct order of the images."
ORDER_FORMAT_LINE = '\nOutput format: ["A", "B", ...].'


def system_prompt(kind: str, base: str = SYSTEM_PROMPT) -> str:
    """Base prompt + one space + the suffix of the answer kind (free text for any other kind)."""
    extra = KIND_SUFFIX.get(kind, FREE_TEXT_SUFFIX)
    base = base.strip()
    return f"{base} {extra}" if base else extra


def question_text(record: Record) -> str:
    """The text part sent after the images."""
    question = record.question
    if record.kind == MULTI_CHOICE:
        if record.options:
            options = "\n".join(record.options)
            question = f"{question}\nOptions:\n{options}" if question else f"Options:\n{options}"
    elif record.kind == SEQUENCE_ORDER:
        if not question:
            question = DEFAULT_ORDER_QUESTION
        labels = [img.label for img in record.images if img.label]
        if labels:
            question = f"{question}\nOption labels: {', '.join(labels)}."
        question = question + ORDER_FORMAT_LINE
    return question


def user_parts(record: Record) -> list[tuple[str, Any]]:
    """Ordered user content as ("text", str) / ("image", ImageRef) pairs."""
    parts: list[tuple[str, Any]] = []
    labelled = record.labelled_images and any(img.label for img in record.images)
    for img in record.images:
        if labelled and img.label:
            parts.append(("text", f"Image {img.label}"))
        parts.append(("image", img))
    parts.append(("text", question_text(record)))
    return parts


def build_messages(record: Record, image_url: Callable[[ImageRef], str]) -> list[dict[str, Any]]:
    """OpenAI chat-completions messages; `image_url` turns an image into a (data) URL."""
    content: list[dict[str, Any]] = []
    for kind, value in user_parts(record):
        if kind == "text":
            content.append({"type": "text", "text": value})
        else:
            content.append({"type": "image_url", "image_url": {"url": image_url(value)}})
    return [
        {"role": "system", "content": system_prompt(record.kind)},
        {"role": "user", "content": content},
    ]


def swift_user_text(record: Record, image_token: str = "<image>") -> str:
    """The user turn as one string with image placeholders (ms-swift's format): the same parts as
    `user_parts`, concatenated the way chat templates join content parts (no separators)."""
    out: Sequence[str] = [
        image_token if kind == "image" else str(value) for kind, value in user_parts(record)
    ]
    return "".join(out)
