"""`_core.Network` and `_core.OrientedBox`: the world's road network and footprint geometry as
Python tools (the official-scene importer) see them."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from drivehierarchy import ConfigError, ScenarioError, _core
from drivehierarchy._core import Network, OrientedBox
from drivehierarchy.scenarios import builtin_root

TOWN01 = builtin_root() / "maps" / "town01" / "town01.net.xml"

# A (two lanes east, the left one cars only) → J1 → B (north, bending), a sidewalk S and a
# 0.1 m lane D whose shape points coincide (SUMO writes such stubs).
NET = """<?xml version="1.0" encoding="UTF-8"?>
<net version="1.20">
    <location netOffset="100.00,-50.00" convBoundary="0,0,100,100" origBoundary="0,0,1,1"
        projParameter="+proj=utm +zone=51 +ellps=WGS84"/>
    <edge id=":J1_0" function="internal">
        <lane id=":J1_0_0" index="0" speed="10" length="5" shape="50,0 55,5"/>
    </edge>
    <edge id="A" from="J0" to="J1">
        <lane id="A_0" index="0" disallow="pedestrian" speed="13.89" length="50" shape="0,0 50,0"/>
        <lane id="A_1" index="1" allow="passenger" speed="13.89" length="50" width="3.5"
            shape="0,3.2 50,3.2"/>
    </edge>
    <edge id="B" from="J1" to="J2">
        <lane id="B_0" index="0" speed="13.89" length="60" shape="55,5 55,35 85,35"/>
    </edge>
    <edge id="S" from="J0" to="J1">
        <lane id="S_0" index="0" allow="pedestrian" speed="2" length="50" width="2" shape="0,-3 50,-3"/>
    </edge>
    <edge id="D" from="J2" to="J1">
        <lane id="D_0" index="0" speed="13.89" length="0.10" shape="85,35 85,35"/>
    </edge>
    <junction id="J0" type="dead_end" x="0" y="0" incLanes="" intLanes="" shape="0,4 0,-4"/>
    <junction id="J1" type="priority" x="52" y="2" incLanes="A_0 A_1" intLanes=":J1_0_0"
        shape="50,5 55,5 55,-4 50,-4"/>
    <junction id="J2" type="dead_end" x="85" y="35" incLanes="B_0" intLanes=""/>
    <connection from="A" to="B" fromLane="0" toLane="0" via=":J1_0_0" dir="l" state="M"/>
    <connection from=":J1_0" to="B" fromLane="0" toLane="0" dir="l" state="M"/>
</net>
"""


@pytest.fixture(scope="module")
def net(tmp_path_factory: pytest.TempPathFactory) -> Network:
    path = tmp_path_factory.mktemp("net") / "small.net.xml"
    path.write_text(NET, encoding="utf-8")
    return Network.load(path)


def test_edges_and_lanes(net: Network) -> None:
    assert net.path.endswith("small.net.xml")
    assert net.offset == (100.0, -50.0)
    assert net.proj_parameter == "+proj=utm +zone=51 +ellps=WGS84"
    assert net.edge("A") == {"id": "A", "function": "normal", "lanes": ["A_0", "A_1"], "successors": ["B"]}
    internal = {"id": ":J1_0", "function": "internal", "lanes": [":J1_0_0"], "successors": []}
    assert net.edge(":J1_0") == internal
    assert net.edge("nope") is None and net.lane("nope") is None
    a1 = net.lane("A_1")
    assert a1 is not None
    assert a1 == {
        "id": "A_1",
        "edge": "A",
        "function": "normal",
        "index": 1,
        "width_m": 3.5,
        "length_m": 50.0,
        "shape_length_m": 50.0,
        "speed_mps": 13.89,
        "allow": ["passenger"],
        "shape": [(0.0, 3.2), (50.0, 3.2)],
    }
    # Default width is SUMO's 3.2 m; a lane's SUMO length may differ from its shape's.
    d0 = net.lane("D_0")
    assert d0 is not None and (d0["width_m"], d0["length_m"], d0["shape_length_m"]) == (3.2, 0.1, 0.0)
    # File order; internal lanes only on request; one edge's lanes by index.
    assert [ln["id"] for ln in net.lanes()] == ["A_0", "A_1", "B_0", "S_0", "D_0"]
    assert net.lanes(internal=True)[0]["id"] == ":J1_0_0"
    assert [ln["id"] for ln in net.lanes(edge="A")] == ["A_0", "A_1"]
    # Class filters, with SUMO's allow / disallow semantics.
    assert [ln["id"] for ln in net.lanes(edge="A", vclass="truck")] == ["A_0"]
    assert [ln["id"] for ln in net.lanes(vclass="pedestrian")] == ["B_0", "S_0", "D_0"]
    assert net.lanes(edge="S", vclass="passenger") == []
    assert "pedestrian" not in net.lanes(edge="A")[0]["allow"]


def test_projection_is_signed_and_continues_past_the_ends(net: Network) -> None:
    # Left of the direction of travel is positive.
    assert net.project("A_0", 20.0, 1.5) == pytest.approx((20.0, 1.5))
    assert net.project("A_0", 20.0, -1.0) == pytest.approx((20.0, -1.0))
    # Before the start and past the end, s continues and the offset stays square to the end
    # segment (not the distance to the end point).
    assert net.project("A_0", -4.0, 1.0) == pytest.approx((-4.0, 1.0))
    assert net.project("B_0", 90.0, 34.0) == pytest.approx((65.0, -1.0))
    # On the bend of B: the nearest segment decides.
    assert net.project("B_0", 54.0, 20.0) == pytest.approx((15.0, 1.0))


def test_position_and_projection_agree(net: Network) -> None:
    for s in (-3.0, 0.0, 12.5, 27.0, 44.0, 60.0, 63.0):  # 2 m or more from the bend
        for off in (-1.2, 0.0, 0.7):
            x, y, heading = net.position("B_0", s, off)
            assert net.project("B_0", x, y) == pytest.approx((s, off), abs=1e-9), (s, off)
            assert heading == pytest.approx(math.pi / 2 if s < 30.0 else 0.0)
    assert net.position("A_1", 10.0) == pytest.approx((10.0, 3.2, 0.0))


def test_lane_boxes_and_overlap(net: Network) -> None:
    box = net.lane_box("A_0", 10.0, 0.5, 4.0, 2.0)
    assert (box.x, box.y, box.heading, box.length, box.width) == pytest.approx((10.0, 0.5, 0.0, 4.0, 2.0))
    corners = [c for xy in box.corners() for c in xy]  # counter-clockwise from front-left
    assert corners == pytest.approx([12.0, 1.5, 8.0, 1.5, 8.0, -0.5, 12.0, -0.5])
    # A box on the neighbouring lane (3.2 m to the left) clears it when narrow, not when wide.
    assert not box.overlaps(net.lane_box("A_1", 10.0, 0.0, 4.0, 1.0))
    assert box.overlaps(net.lane_box("A_1", 10.0, 0.0, 4.0, 3.6))
    # Touching counts as overlapping.
    assert box.overlaps(OrientedBox(10.0, 3.0, 0.0, 4.0, 3.0))
    assert box.overlaps(box)
    # Rotated boxes: axis-aligned bounds would overlap, the boxes do not.
    q = math.pi / 4
    assert not OrientedBox(0.0, 0.0, q, 4.0, 2.0).overlaps(OrientedBox(2.4, -2.4, q, 4.0, 2.0))
    assert OrientedBox(0.0, 0.0, q, 4.0, 2.0).overlaps(OrientedBox(0.9, -0.9, q, 4.0, 2.0))
    # Along the bend of B the box turns with the lane.
    up = net.lane_box("B_0", 20.0, 0.0, 4.0, 2.0)
    assert up.heading == pytest.approx(math.pi / 2) and (up.x, up.y) == pytest.approx((55.0, 25.0))


def test_snapping(net: Network) -> None:
    assert net.snap(20.0, 2.5) == ("A_1", pytest.approx(20.0), pytest.approx(0.7))
    assert net.snap(20.0, -2.5) == ("S_0", pytest.approx(20.0), pytest.approx(0.5))
    assert net.snap(20.0, -2.5, vclass="passenger") == ("A_0", pytest.approx(20.0), pytest.approx(2.5))
    assert net.snap(20.0, 40.0) is None
    assert net.snap(52.0, 2.0, internal=True)[0] == ":J1_0_0"  # type: ignore[index]
    assert net.snap(52.0, 2.0)[0] != ":J1_0_0"  # type: ignore[index]


def test_snapping_agrees_with_the_editors_snap_to_lane() -> None:
    net = Network.load(TOWN01)
    for x in range(-250, 660, 37):
        for y in range(-430, 200, 41):
            for vclass in (None, "passenger", "pedestrian"):
                ours = net.snap(float(x), float(y), 8.0, vclass=vclass)
                theirs = _core.snap_to_lane(str(TOWN01), float(x), float(y), 8.0, vclass=vclass)
                assert ours == theirs, (x, y, vclass)


def test_errors_name_file_field_and_value(net: Network, tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"small\.net\.xml.*no lane \"Z_0\""):
        net.project("Z_0", 0.0, 0.0)
    with pytest.raises(ScenarioError, match=r"small\.net\.xml.*no edge \"Z\""):
        net.lanes(edge="Z")
    # A lane whose shape points coincide has no direction: refused, not placed at its start.
    with pytest.raises(ScenarioError, match=r"lane \"D_0\": every point of its shape coincides"):
        net.project("D_0", 85.0, 35.0)
    with pytest.raises(ScenarioError, match="D_0"):
        net.lane_box("D_0", 0.0, 0.0, 4.0, 2.0)
    with pytest.raises(ConfigError, match=r"vclass.*car.*not a SUMO vehicle class"):
        net.lanes(vclass="car")
    with pytest.raises(ConfigError, match="vclass"):
        net.snap(0.0, 0.0, vclass="car")
    with pytest.raises(ConfigError, match=r"point.*NaN"):
        net.project("A_0", float("nan"), 0.0)
    with pytest.raises(ConfigError, match=r"box.*must not be negative"):
        OrientedBox(0.0, 0.0, 0.0, -1.0, 2.0)
    with pytest.raises(ScenarioError, match=r"missing\.net\.xml.*not found"):
        Network.load(tmp_path / "missing.net.xml")
    broken = tmp_path / "broken.net.xml"
    broken.write_text("<net><edge id='A'><lane id='A_0' index='0' shape='0,0'/></edge></net>")
    with pytest.raises(ScenarioError, match=r"broken\.net\.xml"):
        Network.load(broken)
