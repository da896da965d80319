"""The committed project maps equal what netconvert builds from their sources (header aside), so
sources and nets cannot drift apart; `scenarios/maps/build.py` is the one rebuild script."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
BUILD_PY = REPO_ROOT / "scenarios" / "maps" / "build.py"


def _load_build():
    spec = importlib.util.spec_from_file_location("maps_build", BUILD_PY)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    sys.modules["maps_build"] = mod  # dataclasses resolve annotations through sys.modules
    spec.loader.exec_module(mod)
    return mod


build = _load_build()
MAPS = build.load_table()
NETCONVERT = build.find_netconvert()
needs_netconvert = pytest.mark.skipif(NETCONVERT is None, reason="netconvert not found (eclipse-sumo)")


def test_table_names_every_map_folder_with_sources() -> None:
    assert {"town01", "town02"} <= set(MAPS)
    for spec in MAPS.values():
        assert spec.net.is_file(), spec.net
        for file in spec.sources.values():
            assert (spec.folder / file).is_file(), file


@pytest.fixture(scope="module")
def rebuilt(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Every map built once into a temp folder."""
    out_dir = tmp_path_factory.mktemp("maps")
    return {name: build.build(spec, out_dir, NETCONVERT) for name, spec in MAPS.items()}


@needs_netconvert
@pytest.mark.parametrize("name", sorted(MAPS))
def test_rebuild_equals_committed_net(name: str, rebuilt: dict[str, Path]) -> None:
    spec = MAPS[name]
    out = rebuilt[name]
    assert out.is_file() and out.parent.name == name
    # The header differs (time, output path); the body must not.
    assert out.read_text(encoding="utf-8") != spec.net.read_text(encoding="utf-8")
    assert build.differences(spec, out) is None


@needs_netconvert
def test_a_changed_net_is_reported(rebuilt: dict[str, Path], tmp_path: Path) -> None:
    spec = MAPS["town02"]
    text = rebuilt["town02"].read_text(encoding="utf-8")
    out = tmp_path / "town02.net.xml"
    assert 'id="MA2MB_0"' in text
    out.write_text(text.replace('speed="22.22"', 'speed="22.23"', 1), encoding="utf-8")
    diff = build.differences(spec, out)
    assert diff is not None and "differs" in diff and "22.23" in diff


def test_bad_table_and_unknown_map_name_the_field(tmp_path: Path) -> None:
    bad = tmp_path / "build.toml"
    bad.write_text("[town09]\nsources = { node-files = 3 }\n", encoding="utf-8")
    with pytest.raises(build.BuildError, match=r"\[town09\]\.sources"):
        build.load_table(bad)
    with pytest.raises(build.BuildError, match="unknown map"):
        build.select(MAPS, ["town99"])
