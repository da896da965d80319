"""`_core.sumo_home()`: the one SUMO_HOME lookup, in its documented order (docs/traffic.md,
"Where SUMO is found"): this interpreter's `sumo` package (the pinned eclipse-sumo wheel), else
`$SUMO_HOME` when set and not empty, else none."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from drivehierarchy import _core


def package_home() -> str | None:
    spec = importlib.util.find_spec("sumo")
    return None if spec is None or spec.origin is None else str(Path(spec.origin).parent)


def without_sumo_package(monkeypatch, tmp_path) -> None:
    """A `sys.path` without site-packages: no `sumo` package to find."""
    monkeypatch.setattr(sys, "path", [str(tmp_path)])
    monkeypatch.delitem(sys.modules, "sumo", raising=False)


def test_the_sumo_package_of_this_interpreter_comes_first(monkeypatch, tmp_path):
    if package_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    # What `import libsumo` does to an unset SUMO_HOME: the data-only `sumo_data` folder.
    monkeypatch.setenv("SUMO_HOME", str(tmp_path / "sumo_data"))
    assert _core.sumo_home() == package_home()


def test_else_the_environment_variable_taken_as_is(monkeypatch, tmp_path):
    without_sumo_package(monkeypatch, tmp_path)
    missing = tmp_path / "no-such-sumo"
    monkeypatch.setenv("SUMO_HOME", str(missing))
    assert _core.sumo_home() == str(missing)


def test_none_without_either(monkeypatch, tmp_path):
    without_sumo_package(monkeypatch, tmp_path)
    monkeypatch.delenv("SUMO_HOME", raising=False)
    assert _core.sumo_home() is None
    # An empty variable counts as unset.
    monkeypatch.setenv("SUMO_HOME", "")
    assert _core.sumo_home() is None


def test_package_lookup_does_not_import_sumo(monkeypatch):
    if package_home() is None:
        pytest.skip("eclipse-sumo is not installed")
    monkeypatch.delitem(sys.modules, "sumo", raising=False)
    assert _core.sumo_home() == package_home()
    assert "sumo" not in sys.modules
