"""The committed project maps equal what netconvert builds from their sources (header aside), so
sources and nets cannot drift apart; `scenarios/maps/build.py` is the one rebuild script."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from drivehierarchy import _core

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


# town02's routes per scenario category (scenarios/maps/README.md): our reader loads the net and
# routes each of them with the edges the README promises, over a plausible length.
TOWN02_ROUTES = [
    (["JW2MA", "MA2MB", "MB2MD", "MD2MX", "MX2ME"], None, 400.0, 1300.0),  # on-ramp merge
    (["MD2MX", "MX2X", "X2AE"], None, 500.0, 1000.0),  # off-ramp, right at X
    (["W2JW", "JW2MA"], None, 300.0, 600.0),  # left onto the ramp
    (["Z2RN", "rb_nw", "RW2AW"], "Z2RN_1", 150.0, 260.0),  # roundabout, first exit
    (["Z2RN", "RS2AS"], "Z2RN_2", 180.0, 320.0),  # second exit (inner lane)
    (["AW2RW", "RN2Z"], "AW2RW_2", 200.0, 360.0),  # third exit
    (["AE2RE", "RN2Z"], "AE2RE_0", 120.0, 260.0),  # one-lane east arm
    (["JE2J", "J2Z"], "JE2J_2", 180.0, 260.0),  # signalised T, left turn
    (["JW2J", "J2JE"], "JW2J_2", 330.0, 420.0),  # signalised T, straight
    (["AE2X"], None, 440.0, 470.0),  # winding road
]


@pytest.mark.parametrize(
    ("edges", "lane", "lo", "hi"), TOWN02_ROUTES, ids=[r[0][0] + "-" + r[0][-1] for r in TOWN02_ROUTES]
)
def test_town02_routes_load_in_our_reader(
    tmp_path: Path, edges: list[str], lane: str | None, lo: float, hi: float
) -> None:
    net = MAPS["town02"].net
    start = f'start = {{ lane = "{lane}", s = 1.0 }}\n' if lane else ""
    scen = tmp_path / "s.toml"
    scen.write_text(
        f'version = 1\nid = "t"\ncategory = "08_merging"\nmap = "{net.as_posix()}"\n\n'
        f"[ego]\n{start}route_edges = {json.dumps(edges)}\n",
        encoding="utf-8",
    )
    summary = _core.validate_scenario(str(scen), None)
    route = summary["route_edges"]
    assert route[0] == edges[0] and route[-1] == edges[-1]
    assert all(e in route for e in edges), route
    assert lo <= summary["route_length_m"] <= hi, summary["route_length_m"]
    assert summary["traffic_lights"] >= 1  # the light J
