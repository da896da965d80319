"""The message one R4 decision sends to a VLM (docs/protocol.md#r4-loop): one user turn, no history
(`history.py` adds past frames, ego states and decisions, this project's extension).

Laid out as the original's VLM service wraps it: a front-camera descriptor text, the front image,
a BEV descriptor text, the BEV image, then `Q(frame {n}): ` + the decision text the env produced
(docs/protocol.md#r4-prompt, `obs["prompt"]`), n = 1, 2, … the decision count. The descriptor
wording was not released; ours is one neutral line per image, naming what it shows (documented in
docs/vlm.md). Images travel as base64 JPEG data URLs.

Controls (ablations, docs/vlm.md): `blind` sends only the question text, `no_bev` drops the BEV
descriptor and image, `max_images=1` (a model preset that takes one image) behaves like `no_bev`,
`corrupt` degrades both images the same way (noise | blur | dark) before encoding.
"""

from __future__ import annotations

import base64
import hashlib
import io
from dataclasses import dataclass
from typing import Any

import numpy as np

from drivehierarchy._core import ConfigError

CORRUPTIONS = ("noise", "blur", "dark")
JPEG_QUALITY = 90


def front_descriptor(width: int, height: int) -> str:
    return (
        f"Front camera image ({width}x{height}, looking forward from the ego vehicle's roof, "
        "100 degree field of view):"
    )


def bev_descriptor(size: int) -> str:
    return (
        f"Bird's-eye view image ({size}x{size}, top-down, ego vehicle at the centre facing up, "
        "local route drawn in red):"
    )


@dataclass(frozen=True)
class PayloadOptions:
    blind: bool = False
    no_bev: bool = False
    max_images: int = 2
    corrupt: str | None = None
    jpeg_quality: int = JPEG_QUALITY

    def __post_init__(self) -> None:
        if self.corrupt is not None and self.corrupt not in CORRUPTIONS:
            raise ConfigError(
                f"config `corrupt` = {self.corrupt!r}: expected one of {', '.join(CORRUPTIONS)}"
            )
        if self.max_images not in (1, 2):
            raise ConfigError(f"config `max_images` = {self.max_images!r}: expected 1 or 2")
        if not 1 <= self.jpeg_quality <= 100:
            raise ConfigError(f"config `jpeg_quality` = {self.jpeg_quality!r}: expected 1..100")

    @property
    def images(self) -> tuple[str, ...]:
        """Which observation images the message carries, in order."""
        if self.blind:
            return ()
        if self.no_bev or self.max_images == 1:
            return ("front",)
        return ("front", "bev")


def corrupt_image(img: np.ndarray, kind: str, seed: int) -> np.ndarray:
    """Deterministic degradations: `noise` (Gaussian, σ = 40 grey levels, seeded), `blur`
    (Gaussian, radius 6 px), `dark` (brightness × 0.25, what a night-time exposure looks like)."""
    if kind == "noise":
        rng = np.random.default_rng(seed)
        noisy = img.astype(np.int16) + rng.normal(0.0, 40.0, img.shape).astype(np.int16)
        return np.clip(noisy, 0, 255).astype(np.uint8)
    if kind == "blur":
        from PIL import Image, ImageFilter

        return np.asarray(Image.fromarray(img).filter(ImageFilter.GaussianBlur(6)))
    if kind == "dark":
        return (img.astype(np.uint16) * 64 // 256).astype(np.uint8)
    raise ConfigError(f"config `corrupt` = {kind!r}: expected one of {', '.join(CORRUPTIONS)}")


def jpeg_bytes(img: np.ndarray, quality: int = JPEG_QUALITY) -> bytes:
    """Baseline JPEG, 4:2:0 chroma. simplejpeg (libjpeg-turbo) when installed: about twice as fast
    as Pillow, which matters at one encode pair per decision; Pillow otherwise."""
    img = np.ascontiguousarray(img)
    try:
        import simplejpeg
    except ImportError:  # pragma: no cover - simplejpeg is a dependency
        from PIL import Image

        buf = io.BytesIO()
        Image.fromarray(img).save(buf, format="JPEG", quality=quality)
        return buf.getvalue()
    return bytes(simplejpeg.encode_jpeg(img, quality=quality, colorspace="RGB", colorsubsampling="420"))


class DataURL(str):
    """A base64 data URL: none of its characters needs escaping in JSON, so the transport writes
    it into a request body as it is (`transport.encode_body`), without scanning it again each time
    it is sent (a past frame is sent with every decision that carries it)."""

    __slots__ = ()


def jpeg_data_url(img: np.ndarray, quality: int = JPEG_QUALITY) -> DataURL:
    return DataURL("data:image/jpeg;base64," + base64.b64encode(jpeg_bytes(img, quality)).decode("ascii"))


def question_text(prompt: str, decision: int) -> str:
    return f"Q(frame {decision}): {prompt}"


def encode_images(
    obs: dict[str, Any], decision: int, options: PayloadOptions, *, seed: int = 0
) -> list[tuple[str, int, int, str]]:
    """The message's images of `obs`, in order, as (key, width, height, data URL)."""
    images: list[tuple[str, int, int, str]] = []
    for key in options.images:
        if key not in obs:
            raise ConfigError(
                f"config `{key}` = None: the VLM agent sends the {key} image (use --no-bev/--blind "
                "to drop it)"
            )
        img = obs[key]
        if options.corrupt is not None:
            # Seeded by episode seed and decision, so a corrupted run is reproducible.
            img = corrupt_image(img, options.corrupt, seed * 1_000_003 + decision * 2 + (key == "bev"))
        h, w = img.shape[:2]
        images.append((key, int(w), int(h), jpeg_data_url(img, options.jpeg_quality)))
    return images


def build_messages(
    obs: dict[str, Any], decision: int, options: PayloadOptions | None = None, *, seed: int = 0
) -> list[dict[str, Any]]:
    """The chat messages of decision `decision` (1-based) for observation `obs`."""
    opts = options or PayloadOptions()
    if "prompt" not in obs:
        raise ConfigError("config `prompt` = False: the VLM agent needs the env's prompt observation")
    content: list[dict[str, Any]] = []
    for key, w, h, url in encode_images(obs, decision, opts, seed=seed):
        text = front_descriptor(w, h) if key == "front" else bev_descriptor(w)
        content.append({"type": "text", "text": text})
        content.append({"type": "image_url", "image_url": {"url": url}})
    content.append({"type": "text", "text": question_text(obs["prompt"], decision)})
    return [{"role": "user", "content": content}]


def prompt_hash(messages: list[dict[str, Any]]) -> str:
    """sha256 (first 16 hex digits) of the message's text parts, in order (images excluded)."""
    h = hashlib.sha256()
    for msg in messages:
        for part in msg["content"]:
            if part["type"] == "text":
                h.update(part["text"].encode("utf-8"))
                h.update(b"\x00")
    return h.hexdigest()[:16]
