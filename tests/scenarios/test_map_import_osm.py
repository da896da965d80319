"""`map import-osm`: netconvert on the OpenStreetMap extract shipped inside eclipse-sumo, then our
map reader loads the result and routes on it."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from drivehierarchy import _core
from drivehierarchy.cli import main
from drivehierarchy.map_cli import detect_driving_side

sumo = pytest.importorskip("sumo")
SPREEWALD = Path(sumo.SUMO_HOME) / "tools" / "game" / "racing" / "spreewaldring.osm"


def _osm(text: str) -> ET.Element:
    return ET.fromstring(f"<osm>{text}</osm>")


def test_driving_side_from_tags_then_location() -> None:
    assert detect_driving_side(_osm('<way><tag k="driving_side" v="left"/></way>'))[0] == "left"
    london = '<bounds minlat="51.50" minlon="-0.13" maxlat="51.51" maxlon="-0.12"/>'
    berlin = '<bounds minlat="52.51" minlon="13.37" maxlat="52.52" maxlon="13.38"/>'
    tokyo = '<bounds minlat="35.68" minlon="139.76" maxlat="35.69" maxlon="139.77"/>'
    assert detect_driving_side(_osm(london))[0] == "left"
    assert detect_driving_side(_osm(tokyo))[0] == "left"
    assert detect_driving_side(_osm(berlin))[0] == "right"
    # Tags win over the location.
    assert detect_driving_side(_osm(london + '<way><tag k="driving_side" v="right"/></way>'))[0] == "right"


@pytest.mark.skipif(not SPREEWALD.is_file(), reason="eclipse-sumo ships no spreewaldring.osm")
def test_import_osm_builds_a_net_our_reader_routes_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    net = tmp_path / "spreewald.net.xml"
    assert main(["map", "import-osm", str(SPREEWALD), "--out", str(net), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert net.is_file()
    assert s["driving_side"] == "right" and not s["lefthand"]  # Brandenburg, Germany
    assert s["drivable_edges"] >= 1 and s["drivable_km"] > 0.5
    r = s["probe_route"]
    assert r["our_length_m"] > 300
    # Our reader's router and sumolib agree on the route across the network.
    assert r["our_length_m"] == pytest.approx(r["sumolib_length_m"], rel=0.05)
    # Only roads open to cars are kept (the raceway is `vip`-only in OSM's rules).
    root = ET.parse(net).getroot()
    types = {e.get("type") for e in root.iter("edge") if e.get("function") is None}
    assert "highway.raceway" not in types and "highway.tertiary" in types
    # A scenario on it loads and resolves.
    scen = tmp_path / "s.toml"
    scen.write_text(
        f'version = 1\nid = "osm"\ncategory = "06_traffic_flow"\nmap = "{net.name}"\n\n'
        f'[ego]\nroute_edges = ["{r["from"]}", "{r["to"]}"]\n',
        encoding="utf-8",
    )
    summary = json.loads(_core.validate_scenario(str(scen), None))
    assert summary["route_length_m"] == pytest.approx(r["our_length_m"], abs=0.01)


def test_import_osm_lefthand_override(tmp_path: Path) -> None:
    if not SPREEWALD.is_file():
        pytest.skip("eclipse-sumo ships no spreewaldring.osm")
    net = tmp_path / "left.net.xml"
    assert main(["map", "import-osm", str(SPREEWALD), "--out", str(net), "--driving-side", "left"]) == 0
    assert ET.parse(net).getroot().get("lefthand") == "true"


def test_import_osm_bad_file_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.osm"
    bad.write_text("not xml", encoding="utf-8")
    assert main(["map", "import-osm", str(bad), "--out", str(tmp_path / "x.net.xml")]) == 2
    assert "bad.osm" in capsys.readouterr().err
