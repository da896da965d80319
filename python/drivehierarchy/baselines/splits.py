"""What a learned baseline may train on, and what it is tested on.

Two splits, both recorded in every saved model (`model_io.save_model(..., split=...)`) and in the
run folder's `split.json`:

- **seeds** (the benchmark's split): train on every suite scenario at episode seeds
  ≥ `TRAIN_SEED_MIN` (each seed jitters the scenario within its `[variation]` bounds); test on
  seeds `TEST_SEEDS` = 0–4 of every scenario, which training never draws.
- **scenarios** (transfer): `stratified_split` holds out a fixed share of each category's
  files (30 %: 3 of 10), ranked by a stable hash of `<category>/<name>`; training draws the
  other files at seeds ≥ `TRAIN_SEED_MIN`, testing plays the held-out files at seeds 0–4.

The training samplers (`wrappers.SuiteEnv(train_seeds=...)`, `vec_sb3.NativeSuiteVecEnv`) draw
every episode seed from `[TRAIN_SEED_MIN, TRAIN_SEED_MAX)` even when reset with an explicit seed
(which then only seeds the draw), so no training path can reach a test seed.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from drivehierarchy._core import ConfigError

TRAIN_SEED_MIN = 100_000
TRAIN_SEED_MAX = 2**31 - 1
TEST_SEEDS = (0, 1, 2, 3, 4)
SplitKind = Literal["seeds", "scenarios"]


def scenario_id(path: str | Path) -> str:
    """`<category>/<file stem>`: how splits name a scenario file."""
    p = Path(path)
    return f"{p.parent.name}/{p.stem}"


def _rank(ids: Sequence[str]) -> list[str]:
    return sorted(ids, key=lambda i: hashlib.sha256(i.encode()).hexdigest())


def stratified_split(
    scenarios: Sequence[str | Path], test_fraction: float = 0.3
) -> tuple[list[Path], list[Path]]:
    """(train, test) files: `round(n_c · test_fraction)` files of each category c held out, the
    first by a SHA-256 ranking of their ids (stable across machines, file order and suite growth
    in other categories). With the suite's 10 files per category: 70 train, 30 test."""
    if not 0.0 < float(test_fraction) < 1.0:
        raise ConfigError(f"config `test_fraction` = {test_fraction!r}: expected a fraction in (0, 1)")
    paths = [Path(p) for p in scenarios]
    by_cat: dict[str, list[str]] = {}
    for p in paths:
        by_cat.setdefault(p.parent.name, []).append(scenario_id(p))
    held: set[str] = set()
    for cat, ids in sorted(by_cat.items()):
        n_out = round(len(ids) * float(test_fraction))
        if n_out >= len(ids):
            raise ConfigError(
                f"config `test_fraction` = {test_fraction!r}: holds out every file of category {cat!r}"
            )
        held.update(_rank(ids)[:n_out])
    train = [p for p in paths if scenario_id(p) not in held]
    test = [p for p in paths if scenario_id(p) in held]
    return train, test


@dataclass(frozen=True)
class Split:
    """Training and test scenario files and seeds (see the module docs)."""

    kind: SplitKind
    train: tuple[str, ...]
    test: tuple[str, ...]
    train_seeds: tuple[int, int] = (TRAIN_SEED_MIN, TRAIN_SEED_MAX)
    test_seeds: tuple[int, ...] = TEST_SEEDS

    def __post_init__(self) -> None:
        lo, hi = self.train_seeds
        if not (0 <= lo < hi):
            raise ConfigError(f"config `train_seeds` = {self.train_seeds!r}: expected 0 ≤ lo < hi")
        clash = sorted(s for s in self.test_seeds if lo <= s < hi)
        if clash:
            raise ConfigError(
                f"config `train_seeds` = {self.train_seeds!r}: contains test seed {clash[0]} "
                "(training must never play a test seed)"
            )
        if not self.train:
            raise ConfigError(f"config `split` = {self.kind!r}: no training scenario")

    @property
    def train_paths(self) -> list[Path]:
        return [Path(p) for p in self.train]

    @property
    def test_paths(self) -> list[Path]:
        return [Path(p) for p in self.test]

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "train": [scenario_id(p) for p in self.train],
            "test": [scenario_id(p) for p in self.test],
            "train_seeds": list(self.train_seeds),
            "test_seeds": list(self.test_seeds),
        }


def make_split(
    scenarios: Sequence[str | Path], kind: SplitKind = "seeds", test_fraction: float = 0.3
) -> Split:
    """The `seeds` split (train on all files at seeds ≥ 100 000, test on all at 0–4) or the
    `scenarios` split (`stratified_split` of the files, same seeds)."""
    paths = [Path(p) for p in scenarios]
    if not paths:
        raise ConfigError("config `suite` = []: the suite has no scenario files")
    if kind == "seeds":
        return Split("seeds", tuple(map(str, paths)), tuple(map(str, paths)))
    if kind == "scenarios":
        train, test = stratified_split(paths, test_fraction)
        return Split("scenarios", tuple(map(str, train)), tuple(map(str, test)))
    raise ConfigError(f"config `split` = {kind!r}: expected 'seeds' or 'scenarios'")
