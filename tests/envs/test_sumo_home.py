"""`_core.sumo_home()`: the one SUMO_HOME lookup, in its documented order (docs/traffic.md,
"Where SUMO is found"): `$SUMO_HOME` when set and not empty, else this interpreter's `sumo`
package, else none."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from drivehierarchy import _core


def test_environment_variable_wins_and_is_taken_as_is(monkeypatch, tmp_path):
    missing = tmp_path / "no-such-sumo"
    monkeypatch.setenv("SUMO_HOME", str(missing))
    assert _core.sumo_home() == str(missing)


def test_else_the_sumo_package_of_this_interpreter(monkeypatch):
    monkeypatch.delenv("SUMO_HOME", raising=False)
    spec = importlib.util.find_spec("sumo")
    expected = None if spec is None or spec.origin is None else str(Path(spec.origin).parent)
    assert _core.sumo_home() == expected
    # An empty variable counts as unset.
    monkeypatch.setenv("SUMO_HOME", "")
    assert _core.sumo_home() == expected


def test_none_without_either(monkeypatch, tmp_path):
    monkeypatch.delenv("SUMO_HOME", raising=False)
    # A `sys.path` without site-packages: no `sumo` package to find.
    monkeypatch.setattr(sys, "path", [str(tmp_path)])
    monkeypatch.delitem(sys.modules, "sumo", raising=False)
    assert _core.sumo_home() is None


def test_package_lookup_does_not_import_sumo(monkeypatch):
    monkeypatch.delenv("SUMO_HOME", raising=False)
    if importlib.util.find_spec("sumo") is None:
        pytest.skip("eclipse-sumo is not installed")
    monkeypatch.delitem(sys.modules, "sumo", raising=False)
    assert _core.sumo_home() is not None
    assert "sumo" not in sys.modules
