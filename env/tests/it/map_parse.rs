//! The net reader, routing and drivable index on a small hand-written network, plus the
//! error messages for broken input.

use dh_env::geom::Vec2;
use dh_env::map::{EdgeFunction, Network, TurnDir, VClass, VClassSet};
use dh_env::Error;
use smallvec::SmallVec;
use std::io::Write;
use std::path::{Path, PathBuf};

/// A (two lanes) → J1 (traffic light) → B (straight, one lane) or C (right turn, south).
const NET: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<net version="1.20" junctionCornerDetail="5">
    <location netOffset="10.00,-5.50" convBoundary="0.00,-100.00,200.00,0.00" origBoundary="1,2,3,4" projParameter="!"/>
    <edge id=":J1_0" function="internal">
        <lane id=":J1_0_0" index="0" speed="13.89" length="20.00" shape="90.00,-1.60 110.00,-1.60"/>
    </edge>
    <edge id=":J1_1" function="internal">
        <lane id=":J1_1_0" index="0" disallow="pedestrian" speed="6.00" length="12.00" shape="90.00,-4.80 95.00,-6.00 98.40,-10.00"/>
    </edge>
    <edge id=":J1_c0" function="crossing" crossingEdges="B">
        <lane id=":J1_c0_0" index="0" allow="pedestrian" speed="2.78" length="6.4" width="4.00" shape="112.00,0.00 112.00,-6.40"/>
    </edge>
    <edge id="A" from="J0" to="J1" priority="2" name="Main &amp; First">
        <lane id="A_0" index="0" disallow="pedestrian bicycle" speed="13.89" length="90.00" shape="0.00,-4.80 90.00,-4.80"/>
        <lane id="A_1" index="1" allow="passenger bus" speed="13.89" length="90.00" shape="0.00,-1.60,0.00 90.00,-1.60,0.00"/>
    </edge>
    <edge id="B" from="J1" to="J2" priority="2">
        <lane id="B_0" index="0" speed="13.89" length="90.00" shape="110.00,-1.60 200.00,-1.60">
            <param key="x" value="y"/>
        </lane>
    </edge>
    <edge id="C" from="J1" to="J3" priority="1">
        <lane id="C_0" index="0" allow="all" speed="8.00" length="90.00" width="3.00" shape="98.40,-10.00 98.40,-100.00"/>
    </edge>
    <edge id="P" from="J2" to="J0">
        <lane id="P_0" index="0" allow="pedestrian" speed="2.00" length="200.00" width="2.00" shape="200.00,20.00 0.00,20.00"/>
    </edge>
    <tlLogic id="J1" type="static" programID="0" offset="5">
        <phase duration="30" state="GG"/>
        <phase duration="3" state="yy"/>
        <phase duration="27" state="rr"/>
    </tlLogic>
    <junction id="J0" type="dead_end" x="0.00" y="0.00" incLanes="" intLanes="" shape="0.00,0.00 0.00,-6.40"/>
    <junction id="J1" type="traffic_light" x="100.00" y="0.00" incLanes="A_0 A_1" intLanes=":J1_0_0 :J1_1_0" shape="90.00,10.00 110.00,10.00 110.00,-10.00 90.00,-10.00">
        <request index="0" response="00" foes="00" cont="0"/>
    </junction>
    <junction id="J2" type="dead_end" x="200.00" y="0.00" incLanes="B_0" intLanes=""/>
    <junction id="J3" type="dead_end" x="100.00" y="-100.00" incLanes="C_0" intLanes=""/>
    <connection from="A" to="B" fromLane="1" toLane="0" via=":J1_0_0" tl="J1" linkIndex="1" dir="s" state="O"/>
    <connection from="A" to="C" fromLane="0" toLane="0" via=":J1_1_0" tl="J1" linkIndex="0" dir="r" state="O"/>
    <connection from="A" to="C" fromLane="0" toLane="0" via=":J1_1_0" tl="J1" linkIndex="0" dir="r" state="O"/>
    <connection from=":J1_0" to="B" fromLane="0" toLane="0" dir="s" state="M"/>
    <connection from=":J1_1" to="C" fromLane="0" toLane="0" dir="r" state="M"/>
    <roundabout nodes="J1" edges="A"/>
</net>
"#;

fn net() -> Network {
    Network::from_xml_str(Path::new("inline.net.xml"), NET).unwrap_or_else(|e| panic!("{e}"))
}

fn parse_err(xml: &str) -> String {
    match Network::from_xml_str(Path::new("bad.net.xml"), xml) {
        Ok(_) => panic!("expected an error"),
        Err(e) => {
            assert!(matches!(e, Error::Map { .. }), "{e:?}");
            e.to_string()
        }
    }
}

fn temp_file(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dh-map-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn parses_every_element() {
    let n = net();
    assert_eq!(n.file, "inline.net.xml");
    assert_eq!(n.edges.len(), 7);
    assert_eq!(n.lanes.len(), 8);
    assert_eq!(n.junctions.len(), 4);
    let a = n.edge_by_id("A").unwrap();
    assert_eq!(n.edges[a].function, EdgeFunction::Normal);
    assert_eq!(n.edges[a].name.as_deref(), Some("Main & First"));
    assert_eq!(n.edges[a].priority, 2);
    assert_eq!(n.edges[a].from, n.junction_by_id("J0"));
    assert_eq!(n.edges[a].to, n.junction_by_id("J1"));
    let internal = n.edge_by_id(":J1_0").unwrap();
    assert_eq!(n.edges[internal].function, EdgeFunction::Internal);
    assert_eq!(n.edges[internal].junction, n.junction_by_id("J1"));
    let crossing = n.edge_by_id(":J1_c0").unwrap();
    assert_eq!(n.edges[crossing].function, EdgeFunction::Crossing);
    assert_eq!(n.edges[crossing].junction, n.junction_by_id("J1"));

    let a0 = &n.lanes[n.lane_by_id("A_0").unwrap()];
    assert_eq!((a0.index, a0.edge, a0.speed_mps, a0.length_m), (0, a, 13.89, 90.0));
    assert_eq!(a0.width_m, 3.2, "SUMO default width");
    assert!(a0.allow.contains(VClass::Passenger) && a0.allow.contains(VClass::Truck));
    assert!(!a0.allow.contains(VClass::Pedestrian) && !a0.allow.contains(VClass::Bicycle));
    let a1 = &n.lanes[n.lane_by_id("A_1").unwrap()];
    assert_eq!(a1.allow, VClassSet::NONE.with(VClass::Passenger).with(VClass::Bus));
    assert_eq!(a1.shape.points(), &[Vec2::new(0.0, -1.6), Vec2::new(90.0, -1.6)], "z dropped");
    assert_eq!(n.lanes[n.lane_by_id("B_0").unwrap()].allow, VClassSet::ALL);
    assert_eq!(n.lanes[n.lane_by_id("C_0").unwrap()].width_m, 3.0);
    assert!(!n.lanes[n.lane_by_id("P_0").unwrap()].is_drivable());

    let j1 = &n.junctions[n.junction_by_id("J1").unwrap()];
    assert_eq!(j1.kind, "traffic_light");
    assert_eq!(j1.pos, Vec2::new(100.0, 0.0));
    assert_eq!(j1.shape.len(), 4);
    assert_eq!(j1.inc_lanes.len(), 2);
    assert_eq!(j1.int_lanes, vec![n.lane_by_id(":J1_0_0").unwrap(), n.lane_by_id(":J1_1_0").unwrap()]);
    assert!(n.junctions[n.junction_by_id("J2").unwrap()].shape.is_empty());

    // The duplicated A→C connection is kept once.
    assert_eq!(n.connections.len(), 4);
    let from_a1 = n.connections_from_lane(n.lane_by_id("A_1").unwrap());
    assert_eq!(from_a1.len(), 1);
    let c = &n.connections[from_a1[0]];
    assert_eq!(c.to_lane, n.lane_by_id("B_0").unwrap());
    assert_eq!(c.via, n.lane_by_id(":J1_0_0"));
    assert_eq!(
        (c.tl.as_deref(), c.link_index, c.dir, c.state),
        (Some("J1"), Some(1), TurnDir::Straight, 'O')
    );
    assert_eq!(n.connections_to_lane(n.lane_by_id("C_0").unwrap()).len(), 2);

    let tl = n.tl_logic("J1").unwrap();
    assert_eq!((tl.kind.as_str(), tl.program_id.as_str(), tl.offset_s), ("static", "0", 5.0));
    assert_eq!(tl.phases.len(), 3);
    assert_eq!(tl.phases[1].state, "yy");
    assert_eq!(tl.cycle_s(), 60.0);
    assert_eq!(n.tl_ids(), vec!["J1"]);
    let links = n.tl_links("J1");
    assert_eq!(links.len(), 2);
    assert_eq!(links[0].link_index, 0);
    assert_eq!(links[0].from_lane, n.lane_by_id("A_0").unwrap());
    assert_eq!(links[0].via, n.lane_by_id(":J1_1_0"));
    assert!(n.tl_links("nope").is_empty());

    assert_eq!(n.location.net_offset, Vec2::new(10.0, -5.5));
    assert_eq!(n.location.conv_boundary, [0.0, -100.0, 200.0, 0.0]);
    assert_eq!(n.location.orig_boundary, [1.0, 2.0, 3.0, 4.0]);
    assert_eq!(n.location.proj_parameter, "!");
    assert_eq!(n.roundabouts.len(), 1);

    let b = n.bounds();
    assert_eq!((b.min, b.max), (Vec2::new(0.0, -100.0), Vec2::new(200.0, 20.0)));

    let stop = n.stop_line(n.lane_by_id("A_1").unwrap());
    assert_eq!(stop.pos, Vec2::new(90.0, -1.6));
    assert!(stop.yaw.abs() < 1e-12);
    let p = n.lane_position(n.lane_by_id("C_0").unwrap(), 10.0);
    assert!((p.pos.y + 20.0).abs() < 1e-9 && (p.yaw + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
}

#[test]
fn routing_and_route_lanes() {
    let n = net();
    let (a, b, c) = (n.edge_by_id("A").unwrap(), n.edge_by_id("B").unwrap(), n.edge_by_id("C").unwrap());
    let l = |id: &str| n.lane_by_id(id).unwrap();
    assert_eq!(n.edge_route(a, b, VClass::Passenger), Some(vec![a, b]));
    assert_eq!(n.edge_route(a, c, VClass::Passenger), Some(vec![a, c]));
    assert_eq!(n.edge_route(a, a, VClass::Passenger), Some(vec![a]));
    assert_eq!(n.edge_route(b, a, VClass::Passenger), None, "no way back");
    // A_1 → B is the only path to B and A_1 does not admit trucks.
    assert_eq!(n.edge_route(a, b, VClass::Truck), None);
    assert_eq!(n.edge_route(a, c, VClass::Truck), Some(vec![a, c]));
    assert_eq!(n.edge_route(a, 999, VClass::Passenger), None);

    // Straight: keeps to A_1 (the only lane that reaches B).
    assert_eq!(n.route_lanes(&[a, b], None).unwrap(), vec![l("A_1"), l(":J1_0_0"), l("B_0")]);
    // Starting on A_0 the route changes lane on A: both lanes appear.
    assert_eq!(
        n.route_lanes(&[a, b], Some(l("A_0"))).unwrap(),
        vec![l("A_0"), l("A_1"), l(":J1_0_0"), l("B_0")]
    );
    assert_eq!(n.route_lanes(&[a, c], None).unwrap(), vec![l("A_0"), l(":J1_1_0"), l("C_0")]);

    // Polyline continuity through the junction.
    let pl = n.route_polyline(&[a, c], None).unwrap();
    let pts = pl.points();
    assert_eq!(pts.first(), Some(&Vec2::new(0.0, -4.8)));
    assert_eq!(pts.last(), Some(&Vec2::new(98.4, -100.0)));
    assert!(pts.windows(2).all(|w| w[0].dist(w[1]) < 100.0));
    assert!((pl.length() - (90.0 + 5.0f64.hypot(1.2) + 3.4f64.hypot(4.0) + 90.0)).abs() < 1e-9);
    // The lane-change ramp is continuous and ends on the target lane.
    let pl = n.route_polyline(&[a, b], Some(l("A_0"))).unwrap();
    assert_eq!(pl.points()[0], Vec2::new(0.0, -4.8));
    assert!(pl.project(Vec2::new(89.0, -1.6)).unwrap().distance < 1e-9);
    assert!(pl.project(Vec2::new(20.0, -4.8)).unwrap().distance < 1e-9);

    // Errors name both unconnected edges; bad start lanes and empty routes are refused.
    let e = n.route_lanes(&[b, a], None).unwrap_err().to_string();
    assert!(e.contains("\"B\"") && e.contains("\"A\"") && e.contains("not connected"), "{e}");
    let e = n.route_lanes(&[a, b], Some(l("B_0"))).unwrap_err().to_string();
    assert!(e.contains("start lane \"B_0\""), "{e}");
    assert!(n.route_lanes(&[], None).is_err());
    let e = n.route_lanes(&[n.edge_by_id(":J1_0").unwrap()], None).unwrap_err().to_string();
    assert!(e.contains("not a normal edge"), "{e}");
    let e = n.route_lanes(&[n.edge_by_id("P").unwrap()], None).unwrap_err().to_string();
    assert!(e.contains("no lane allowing vehicle class passenger"), "{e}");
    assert!(n.route_lanes_for(&[n.edge_by_id("P").unwrap()], None, VClass::Pedestrian).is_ok());
}

#[test]
fn successors_and_nearest_lane_by_class() {
    let n = net();
    let e = |id: &str| n.edge_by_id(id).unwrap();
    let l = |id: &str| n.lane_by_id(id).unwrap();
    assert_eq!(n.successors(e("A")).collect::<Vec<_>>(), vec![e("B"), e("C")]);
    assert_eq!(n.successors(e("B")).count(), 0);
    assert_eq!(n.successors(e(":J1_0")).count(), 0, "internal edges have none");
    assert_eq!(n.successors(999).count(), 0);
    // Nearest lane: any class, then only those allowing it; internal lanes on request.
    let p = Vec2::new(45.0, 10.0);
    let (lane, pr) = n.nearest_lane(p, 20.0, None, false).unwrap();
    assert_eq!(lane, l("P_0"));
    assert!((pr.s - 155.0).abs() < 1e-9 && (pr.distance - 10.0).abs() < 1e-9, "{pr:?}");
    let (lane, pr) = n.nearest_lane(p, 20.0, Some(VClass::Passenger), false).unwrap();
    assert_eq!(lane, l("A_1"));
    assert!((pr.distance - 11.6).abs() < 1e-9 && pr.lateral > 0.0);
    assert_eq!(n.nearest_lane(p, 20.0, Some(VClass::Truck), false).unwrap().0, l("A_0"));
    assert!(n.nearest_lane(p, 5.0, Some(VClass::Passenger), false).is_none());
    let on_internal = Vec2::new(100.0, -1.0);
    assert_eq!(n.nearest_lane(on_internal, 20.0, None, true).unwrap().0, l(":J1_0_0"));
    assert_ne!(n.nearest_lane(on_internal, 20.0, None, false).unwrap().0, l(":J1_0_0"));
}

#[test]
fn drivable_index() {
    let n = net();
    let d = n.drivable();
    let l = |id: &str| n.lane_by_id(id).unwrap();
    let mut out = SmallVec::new();
    d.lanes_at(Vec2::new(45.0, -2.0), &mut out);
    assert_eq!(out.as_slice(), &[l("A_1")]);
    d.lanes_at(Vec2::new(45.0, -5.0), &mut out);
    assert_eq!(out.as_slice(), &[l("A_0")]);
    d.lanes_at(Vec2::new(45.0, -3.2), &mut out);
    assert_eq!(out.as_slice(), &[l("A_0"), l("A_1")], "shared border belongs to both");
    for off in [Vec2::new(45.0, 0.5), Vec2::new(45.0, -6.5), Vec2::new(-0.5, -1.6), Vec2::new(150.0, 20.0)] {
        d.lanes_at(off, &mut out);
        assert!(out.is_empty(), "{off:?}");
        assert!(!d.is_drivable(off), "{off:?} (square lane ends; pedestrian lanes excluded)");
    }
    // Inside the junction outline but off every internal lane: drivable, no lane.
    let corner = Vec2::new(105.0, 8.0);
    d.lanes_at(corner, &mut out);
    assert!(out.is_empty());
    assert!(d.is_drivable(corner));
    assert_eq!(d.junction_at(corner), n.junction_by_id("J1"));
    // On the internal lane.
    d.lanes_at(Vec2::new(100.0, -1.0), &mut out);
    assert_eq!(out.as_slice(), &[l(":J1_0_0")]);
    // Nearest lane with its projection.
    let (lane, pr) = d.nearest_lane(Vec2::new(45.0, 5.0), 10.0).unwrap();
    assert_eq!(lane, l("A_1"));
    assert!((pr.s - 45.0).abs() < 1e-9 && (pr.distance - 6.6).abs() < 1e-9 && pr.lateral > 0.0);
    let (lane, pr) = d.nearest_lane(Vec2::new(97.0, -50.0), 10.0).unwrap();
    assert_eq!(lane, l("C_0"));
    assert!((pr.s - 40.0).abs() < 1e-9 && pr.lateral < 0.0, "{pr:?}");
    assert!(d.nearest_lane(Vec2::new(45.0, 5.0), 6.0).is_none());
    assert!(d.nearest_lane(Vec2::new(f64::NAN, 0.0), 6.0).is_none());
    assert!(!d.is_drivable(Vec2::new(f64::NAN, 0.0)));
    // Far outside the grid with a large radius still finds the closest lane.
    let (lane, _) = d.nearest_lane(Vec2::new(-500.0, -3.0), 1.0e9).unwrap();
    assert!(lane == l("A_0") || lane == l("A_1"));
}

#[test]
fn gzip_and_plain_files_load_alike() {
    let plain = temp_file("small.net.xml");
    std::fs::write(&plain, NET).unwrap();
    let gz = temp_file("small.net.xml.gz");
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    enc.write_all(NET.as_bytes()).unwrap();
    std::fs::write(&gz, enc.finish().unwrap()).unwrap();
    let a = Network::from_file(&plain).unwrap();
    let b = Network::from_file(&gz).unwrap();
    assert_eq!(a.lanes.len(), b.lanes.len());
    assert_eq!(a.lanes[3].shape, b.lanes[3].shape);
    assert_eq!(b.file, gz.display().to_string());
    // A truncated gzip stream is an error, not a panic.
    let bytes = std::fs::read(&gz).unwrap();
    let cut = temp_file("cut.net.xml.gz");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = Network::from_file(&cut).unwrap_err().to_string();
    assert!(e.contains("cut.net.xml.gz") && e.contains("gzip"), "{e}");
}

#[test]
fn missing_file_is_a_clear_error() {
    let e = Network::from_file(Path::new("no/such/dir/town.net.xml")).unwrap_err();
    assert!(matches!(e, Error::Map { .. }));
    let s = e.to_string();
    assert!(s.contains("no/such/dir/town.net.xml") && s.contains("not found"), "{s}");
}

#[test]
fn malformed_input_names_element_attribute_and_value() {
    let s = parse_err(&NET.replace("0.00,-4.80 90.00,-4.80", "abc"));
    assert!(s.starts_with("bad.net.xml: line "), "{s}");
    assert!(s.contains(r#"edge "A" lane "A_0": attribute shape = "abc": not a coordinate list"#), "{s}");
    let s = parse_err(&NET.replace(r#"speed="8.00""#, r#"speed="fast""#));
    assert!(s.contains(r#"edge "C" lane "C_0": attribute speed = "fast": not a finite number"#), "{s}");
    let s = parse_err(&NET.replace(r#"allow="all""#, r#"allow="passenger hovercraft""#));
    assert!(
        s.contains(r#"attribute allow = "passenger hovercraft": unknown vehicle class "hovercraft""#),
        "{s}"
    );
    let s = parse_err(&NET.replace(r#"from="A" to="B""#, r#"from="A" to="Z""#));
    assert!(s.contains(r#"connection from "A" to "Z": attribute to = "Z": no such edge"#), "{s}");
    let s = parse_err(
        &NET.replace(r#"fromLane="1" toLane="0" via=":J1_0_0""#, r#"fromLane="7" toLane="0" via=":J1_0_0""#),
    );
    assert!(s.contains(r#"attribute fromLane = "7": edge "A" has 2 lane(s)"#), "{s}");
    let s = parse_err(&NET.replace(r#"from="J0" to="J1""#, r#"from="J9" to="J1""#));
    assert!(s.contains(r#"edge "A": attribute from = "J9": no such junction"#), "{s}");
    let s = parse_err(&NET.replace(r#"duration="3""#, r#"duration="x""#));
    assert!(s.contains(r#"tlLogic "J1" phase 1: attribute duration = "x""#), "{s}");
    let s = parse_err(&NET.replace(r#"netOffset="10.00,-5.50""#, r#"netOffset="10.00""#));
    assert!(
        s.contains(r#"location: attribute netOffset = "10.00": expected 2 comma-separated numbers"#),
        "{s}"
    );
    let s = parse_err(&NET.replace(r#"dir="r""#, r#"dir="q""#));
    assert!(s.contains(r#"attribute dir = "q": unknown direction"#), "{s}");
    let s = parse_err(&NET.replace(r#"index="1" allow"#, r#"index="5" allow"#));
    assert!(s.contains(r#"lane "A_1": attribute index = "5""#), "{s}");
    let s = parse_err(&NET.replace(r#"<lane id="B_0" index="0" speed"#, r#"<lane index="0" speed"#));
    assert!(s.contains(r#"edge "B" lane: missing attribute id"#), "{s}");
    // Broken XML: a mismatched end tag and a truncated document.
    let s = parse_err(&NET.replace("</tlLogic>", "</tlLogik>"));
    assert!(s.contains("malformed XML"), "{s}");
    let s = parse_err(&NET[..NET.len() / 2]);
    assert!(s.contains("malformed XML") || s.contains("line"), "{s}");
    let s = parse_err("<routes><vehicle id=\"v\"/></routes>");
    assert!(s.contains("no <net> element"), "{s}");
    let s = parse_err("");
    assert!(s.contains("no <net> element"), "{s}");
}

#[test]
fn vclass_names() {
    assert_eq!(VClass::from_sumo("passenger"), Some(VClass::Passenger));
    assert_eq!(VClass::from_sumo("rail_urban"), Some(VClass::RailUrban));
    assert_eq!(VClass::from_sumo("public_transport"), Some(VClass::Bus), "deprecated alias");
    assert_eq!(VClass::from_sumo("car"), None);
    assert_eq!(VClass::Taxi.sumo_name(), "taxi");
    let s = VClassSet::from_allow_disallow(None, Some("all")).unwrap();
    assert!(s.is_empty());
    let s = VClassSet::from_allow_disallow(Some("private taxi"), None).unwrap();
    assert!(s.contains(VClass::Taxi) && !s.contains(VClass::Passenger));
    assert_eq!(VClassSet::parse_sumo("bus nope"), Err("nope".to_string()));
}
