"""Config defaults have one definition, the Rust core's `SimConfig::default()`
(`_core.default_sim_config()`): the Python dataclasses must agree with it field by field."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from drivehierarchy import _core
from drivehierarchy.envs.config import R4Config

# Settings only the Python env has (`R4Config.to_json` drops them; the Rust config has none).
PYTHON_ONLY = {"scenario", "traffic", "sumo_backend"}


def _flatten(d: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


RUST = _flatten(_core.default_sim_config())


def _python_defaults() -> dict[str, Any]:
    d = dataclasses.asdict(R4Config())
    for k in PYTHON_ONLY:
        d.pop(k)
    return _flatten(d)


def test_python_and_rust_configs_have_the_same_fields() -> None:
    py = _python_defaults()
    assert sorted(set(RUST) - set(py)) == [], "Rust settings without a Python field"
    assert sorted(set(py) - set(RUST)) == [], "Python settings the Rust config does not have"


@pytest.mark.parametrize("key", sorted(RUST))
def test_python_default_equals_rust_default(key: str) -> None:
    py = _python_defaults().get(key, "<missing>")
    rust = RUST[key]
    assert py == rust and type(py) is type(rust), f"default of `{key}`: Python {py!r}, Rust {rust!r}"


def test_default_config_json_is_the_rust_default() -> None:
    assert R4Config().to_core() == _core.default_sim_config()
