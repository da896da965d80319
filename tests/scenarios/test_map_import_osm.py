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
    summary = _core.validate_scenario(str(scen), None)
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


def _cross_osm(path: Path, extra_tags: str = "") -> Path:
    """A 300 m primary road crossed by a secondary one at a node OSM marks as signals."""
    lat0, lon0 = 52.52, 13.40
    dlat, dlon = 150 / 111320, 150 / (111320 * 0.6088)
    nodes = {
        1: (lat0, lon0 - dlon),
        2: (lat0, lon0),
        3: (lat0, lon0 + dlon),
        4: (lat0 + dlat, lon0),
        5: (lat0 - dlat, lon0),
    }
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6">']
    for i, (la, lo) in nodes.items():
        tag = '<tag k="highway" v="traffic_signals"/>' if i == 2 else ""
        lines.append(f'<node id="{i}" lat="{la:.7f}" lon="{lo:.7f}" version="1">{tag}</node>')
    lines.append(
        '<way id="10" version="1"><nd ref="1"/><nd ref="2"/><nd ref="3"/>'
        f'<tag k="highway" v="primary"/><tag k="lanes" v="2"/>{extra_tags}</way>'
    )
    lines.append(
        '<way id="11" version="1"><nd ref="4"/><nd ref="2"/><nd ref="5"/>'
        f'<tag k="highway" v="secondary"/>{extra_tags}</way>'
    )
    lines.append("</osm>")
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


def test_import_osm_signalised_crossing_and_tagged_left_hand(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    osm = _cross_osm(tmp_path / "cross.osm")
    assert main(["map", "import-osm", str(osm), "--out", str(tmp_path / "cross.net.xml"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["traffic_light_junctions"] == 1 and s["driving_side"] == "right"
    assert s["probe_route"]["our_length_m"] == pytest.approx(s["probe_route"]["sumolib_length_m"], rel=0.05)
    left = _cross_osm(tmp_path / "left.osm", '<tag k="driving_side" v="left"/>')
    assert main(["map", "import-osm", str(left), "--out", str(tmp_path / "left.net.xml"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["driving_side"] == "left" and s["lefthand"]
