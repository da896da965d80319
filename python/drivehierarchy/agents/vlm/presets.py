"""Presets for the paper's 15 models, read from one table (`models.json` beside this module):
served model id, images per prompt, and the paper's Table 2 row for comparison."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from drivehierarchy._core import ConfigError

TABLE = Path(__file__).with_name("models.json")
CATEGORY_COUNT = 10


@dataclass(frozen=True)
class ModelPreset:
    key: str
    paper_name: str
    served_model_id: str
    images_per_prompt: int
    group: str
    paper_r4: tuple[float, ...]  # Sce 1..10, then the average

    @property
    def paper_r4_average(self) -> float:
        return self.paper_r4[-1]


@lru_cache(maxsize=1)
def _load() -> dict[str, ModelPreset]:
    data = json.loads(TABLE.read_text(encoding="utf-8"))
    out: dict[str, ModelPreset] = {}
    for i, row in enumerate(data["models"]):
        where = f"{TABLE.name}: models[{i}]"
        preset = ModelPreset(
            key=row["key"],
            paper_name=row["paper_name"],
            served_model_id=row["served_model_id"],
            images_per_prompt=int(row["images_per_prompt"]),
            group=row["group"],
            paper_r4=tuple(float(v) for v in row["paper_r4"]),
        )
        if preset.images_per_prompt not in (1, 2):
            raise ConfigError(f"{where}.images_per_prompt = {preset.images_per_prompt!r}: expected 1 or 2")
        if len(preset.paper_r4) != CATEGORY_COUNT + 1:
            raise ConfigError(f"{where}.paper_r4: expected {CATEGORY_COUNT + 1} values")
        if preset.key in out:
            raise ConfigError(f"{where}.key = {preset.key!r}: duplicated")
        out[preset.key] = preset
    return out


PRESETS: dict[str, ModelPreset] = _load()


def resolve_model(name: str) -> tuple[str, ModelPreset | None]:
    """`--model NAME`: a preset key or a served id of a preset gives that preset; anything else is
    sent to the server as is (with the protocol's 2 images). Returns (served id, preset)."""
    if name in PRESETS:
        p = PRESETS[name]
        return p.served_model_id, p
    for p in PRESETS.values():
        if name == p.served_model_id:
            return name, p
    return name, None
