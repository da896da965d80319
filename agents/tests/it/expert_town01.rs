//! The expert on real SUMO route geometry: every route between pairs of normal edges of the
//! project's town01 map (junction internal lanes, lane-change ramps, the curved road, the
//! roundabout), driven in the stand-in closed loop. The ego centre must never leave the
//! drivable area (the protocol's off-road rule) and the efficiency must stay high.

use crate::expert_support;

use dh_agents::expert::ExpertParams;
use dh_env::map::{EdgeFunction, Network, VClass};
use expert_support::{efficiency, Sim};
use std::path::Path;

#[test]
fn town01_all_routes_stay_on_road() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps/town01/town01.net.xml");
    if !path.exists() {
        eprintln!("skipping: {} not found", path.display());
        return;
    }
    let net = Network::from_file(&path).unwrap();
    let edges: Vec<usize> =
        (0..net.edges.len()).filter(|&e| net.edges[e].function == EdgeFunction::Normal).collect();
    // Every 4th pair by default (debug builds are slow); DH_EXPERT_ALL_ROUTES=1 drives all.
    let all = std::env::var_os("DH_EXPERT_ALL_ROUTES").is_some();
    let (mut runs, mut worst_eff, mut worst_lat) = (0, f64::INFINITY, 0.0f64);
    for &from in &edges {
        for &to in &edges {
            if from == to || (!all && (from * 7 + to) % 4 != 0) {
                continue;
            }
            let Some(route_edges) = net.edge_route(from, to, VClass::Passenger) else { continue };
            let route = net.route_polyline(&route_edges, None).unwrap();
            if route.length() < 60.0 {
                continue;
            }
            let name = format!("{} -> {}", net.edges[from].id, net.edges[to].id);
            let sim = Sim { time_limit_s: 30.0 + route.length() / 4.0, ..Sim::new(route) };
            let o = sim.run(ExpertParams::default());
            let offroad = o.trajectory.iter().filter(|(_, p)| !net.drivable().is_drivable(p.pos)).count();
            let eff = efficiency(&o);
            runs += 1;
            worst_eff = worst_eff.min(eff);
            worst_lat = worst_lat.max(o.max_lateral_m);
            if !(o.reached && offroad == 0 && eff >= 0.95 && o.max_lateral_m < 1.2) {
                panic!(
                    "{name}: reached={} offroad_ticks={offroad} eff={eff:.3} max_lat={:.2} t={:.1}",
                    o.reached, o.max_lateral_m, o.time_s
                );
            }
        }
    }
    println!("town01: {runs} routes, worst efficiency {worst_eff:.3}, worst lateral error {worst_lat:.2} m");
    assert!(runs > 30, "only {runs} routes");
}

#[test]
fn drivable_oracle_rejects_oncoming_lanes() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps/town01/town01.net.xml");
    if !path.exists() {
        eprintln!("skipping: {} not found", path.display());
        return;
    }
    let net = Network::from_file(&path).unwrap();
    let oracle = dh_agents::expert::network_drivable(&net);
    // Mid-lane points of every lane of the 400 m straight: usable along the lane's direction,
    // not against it.
    let mut checked = 0;
    for id in ["C2T_1", "C2T_2", "T2C_1", "T2C_2"] {
        let lane = &net.lanes[net.lane_by_id(id).unwrap()];
        let s = lane.shape.length() * 0.5;
        let (p, h) = (lane.shape.point_at(s), lane.shape.heading_at(s));
        assert!(oracle(p, h), "{id} along");
        assert!(!oracle(p, h + std::f64::consts::PI), "{id} against");
        checked += 1;
    }
    assert_eq!(checked, 4);
    // Lane 0 of the main roads is the sidewalk.
    let walk = &net.lanes[net.lane_by_id("C2T_0").unwrap()];
    let s = walk.shape.length() * 0.5;
    assert!(!oracle(walk.shape.point_at(s), walk.shape.heading_at(s)), "sidewalk");
    assert!(!oracle(dh_env::geom::Vec2::new(-5000.0, -5000.0), 0.0));
}

#[test]
fn lane_follower_follows_the_lane_and_only_a_vehicle_along_it() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps/town01/town01.net.xml");
    if !path.exists() {
        eprintln!("skipping: {} not found", path.display());
        return;
    }
    let net = Network::from_file(&path).unwrap();
    let follow = dh_agents::expert::network_lane_follower(&net);
    // Every drivable lane longer than 30 m: 10 m on from its middle along its own shape (on the
    // curved road not on the tangent), and past its end straight on along its last heading.
    let mut checked = 0;
    for l in
        (0..net.lanes.len()).filter(|&l| net.lanes[l].shape.length() > 30.0 && net.lanes[l].is_drivable())
    {
        let shape = &net.lanes[l].shape;
        let len = shape.length();
        let s = len * 0.5 - 5.0;
        let (p, h) = (shape.point_at(s), shape.heading_at(s));
        let got = follow(p, h, 10.0).unwrap();
        let want = shape.point_at(s + 10.0);
        assert!(got.pos.dist(want) < 1e-6, "lane {}: {:?} != {want:?}", net.lanes[l].id, got.pos);
        assert!((got.yaw - shape.heading_at(s + 10.0)).abs() < 1e-9);
        let end = follow(p, h, len - s + 7.0).unwrap();
        let want = shape.point_at(len) + dh_env::geom::Vec2::from_angle(shape.heading_at(len)) * 7.0;
        assert!(
            end.pos.dist(want) < 1e-6,
            "lane {}: past the end {:?} != {want:?}",
            net.lanes[l].id,
            end.pos
        );
        // Turned across the lane or off its centreline: not following it.
        assert!(follow(p, h + 0.5, 10.0).is_none_or(|q| q.pos.dist(got.pos) > 1e-6));
        checked += 1;
    }
    assert!(checked > 20, "only {checked} lanes checked");
    assert!(follow(dh_env::geom::Vec2::new(-5000.0, -5000.0), 0.0, 10.0).is_none());
}
