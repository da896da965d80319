"""Open-loop side of the chat transport: image files as data URLs.

The client itself is the project's one transport (`drivehierarchy.agents.vlm.transport`, on the
official `openai` SDK), re-exported here: 429, 5xx, timeouts and connection errors are retried with
capped exponential back-off; anything else fails at once with a typed `RequestFailure.kind`, so
the runner logs failure records, never predictions.
"""

from __future__ import annotations

import base64
import io
import os

from drivehierarchy.agents.vlm.transport import (
    AsyncChatTransport,
    ChatClient,
    Completion,
    ConnectionFailure,
    DecodingConfig,
    HttpStatusError,
    MalformedResponse,
    RequestFailure,
    RequestTimeout,
    ServerUnavailable,
)

__all__ = [
    "AsyncChatTransport",
    "ChatClient",
    "Completion",
    "ConnectionFailure",
    "DecodingConfig",
    "HttpStatusError",
    "ImageError",
    "MalformedResponse",
    "RequestFailure",
    "RequestTimeout",
    "ServerUnavailable",
    "image_data_url",
]


class ImageError(Exception):
    """An input image is missing (`kind` = missing_image) or cannot be decoded (unreadable_image)."""

    def __init__(self, kind: str, path: str, detail: str):
        super().__init__(f"{path}: {detail}")
        self.kind = kind
        self.path = path
        self.detail = detail


_MAGIC = (
    (b"\xff\xd8\xff", "image/jpeg"),
    (b"\x89PNG\r\n\x1a\n", "image/png"),
    (b"GIF87a", "image/gif"),
    (b"GIF89a", "image/gif"),
)


def _sniff_mime(data: bytes) -> str | None:
    for magic, mime in _MAGIC:
        if data.startswith(magic):
            return mime
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "image/webp"
    return None


def image_data_url(path: str) -> str:
    """`data:<mime>;base64,...` of an image file, mime from its content. Formats servers may not
    accept (BMP, TIFF, ...) are re-encoded as PNG. Raises `ImageError`."""
    try:
        data = open(path, "rb").read()  # noqa: SIM115 - one short read
    except FileNotFoundError:
        raise ImageError("missing_image", path, "file not found") from None
    except OSError as exc:
        raise ImageError(
            "missing_image" if not os.path.exists(path) else "unreadable_image", path, str(exc)
        ) from exc
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as im:
            im.verify()  # header + structure check without a full decode
        mime = _sniff_mime(data)
        if mime is None:
            with Image.open(io.BytesIO(data)) as im:
                buf = io.BytesIO()
                im.convert("RGB").save(buf, format="PNG")
            data, mime = buf.getvalue(), "image/png"
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as exc:
        raise ImageError("unreadable_image", path, f"not a decodable image: {exc}") from exc
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"
