//! Loading real networks: the official tongji net, SUMO's shipped nets and our town01.
//! Each test skips (with a note on stderr) when its file is absent.

use dh_env::geom::Vec2;
use dh_env::map::{EdgeFunction, Network, VClass};
use smallvec::SmallVec;
use std::path::{Path, PathBuf};

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_path_buf()
}

fn tongji_path() -> PathBuf {
    repo_root().join(
        "../shared/official/Close_Loop_Evaluation/Carla_Simulation/Co-Simulation/Sumo/tongji/tongji.net.xml",
    )
}

fn sumo_home() -> Option<PathBuf> {
    dh_env::sumo_home::SumoHome::locate().map(|h| h.0)
}

fn load_or_skip(path: &Path) -> Option<Network> {
    if !path.exists() {
        eprintln!("skipping: {} not found", path.display());
        return None;
    }
    Some(Network::from_file(path).unwrap_or_else(|e| panic!("{e}")))
}

/// Structural invariants every loaded net must satisfy.
fn check_invariants(net: &Network) {
    assert!(!net.edges.is_empty() && !net.lanes.is_empty() && !net.junctions.is_empty());
    for (i, l) in net.lanes.iter().enumerate() {
        assert_eq!(net.edges[l.edge].lanes[l.index], i, "lane {} indexed", l.id);
        assert!(!l.shape.is_empty() && l.width_m > 0.0 && l.speed_mps > 0.0, "lane {}", l.id);
        assert_eq!(net.lane_by_id(&l.id), Some(i));
    }
    for (ci, c) in net.connections.iter().enumerate() {
        assert!(net.connections_from_lane(c.from_lane).contains(&ci));
        assert!(net.connections_to_lane(c.to_lane).contains(&ci));
    }
    let b = net.bounds();
    assert!(!b.is_empty());
    // Every drivable normal lane's midpoint is drivable and found on that lane.
    let idx = net.drivable();
    let mut out = SmallVec::new();
    for (i, l) in net.lanes.iter().enumerate() {
        if !l.is_drivable() || net.edges[l.edge].function != EdgeFunction::Normal || l.shape.length() < 1.0 {
            continue;
        }
        let mid = l.shape.point_at(0.5 * l.shape.length());
        idx.lanes_at(mid, &mut out);
        assert!(out.contains(&i), "lane {} not found at its own midpoint", l.id);
        assert!(idx.is_drivable(mid));
        let (nl, pr) = idx.nearest_lane(mid, 1.0).expect("nearest lane");
        assert!(pr.distance < 1e-6, "lane {}: nearest {} at {}", l.id, net.lanes[nl].id, pr.distance);
    }
    // Far outside the network nothing is drivable.
    let far = Vec2::new(b.max.x + 1000.0, b.max.y + 1000.0);
    assert!(!idx.is_drivable(far));
    assert!(idx.nearest_lane(far, 10.0).is_none());
}

/// Consecutive lanes of different edges must join (end of one ≈ start of the next).
fn assert_continuous(net: &Network, lanes: &[usize]) {
    for w in lanes.windows(2) {
        let (la, lb) = (&net.lanes[w[0]], &net.lanes[w[1]]);
        if la.edge == lb.edge {
            continue; // lane change
        }
        let gap = la.shape.points().last().unwrap().dist(lb.shape.points()[0]);
        assert!(gap < 0.5, "gap {gap:.2} m between {} and {}", la.id, lb.id);
    }
}

/// Routes between many pairs of normal edges; every found route must give a continuous
/// polyline (joints between consecutive lanes < 0.5 m, lane-change ramps excepted).
fn check_routes(net: &Network, pairs: usize) -> usize {
    let normal: Vec<usize> = (0..net.edges.len())
        .filter(|&e| {
            net.edges[e].function == EdgeFunction::Normal
                && net.edges[e].lanes.iter().any(|&l| net.lanes[l].is_drivable())
        })
        .collect();
    let mut found = 0;
    let step = (normal.len() / pairs.max(1)).max(1);
    for (k, &a) in normal.iter().enumerate().step_by(step) {
        let b = normal[(k * 7919 + 13) % normal.len()];
        let Some(route) = net.edge_route(a, b, VClass::Passenger) else { continue };
        found += 1;
        assert_eq!(route.first(), Some(&a));
        assert_eq!(route.last(), Some(&b));
        let lanes = net.route_lanes(&route, None).unwrap_or_else(|e| panic!("{e}"));
        assert_continuous(net, &lanes);
        let pl = net.route_polyline(&route, None).unwrap();
        assert!(pl.length() > 0.0);
    }
    found
}

#[test]
fn tongji_loads_and_routes_official_scenario() {
    let Some(net) = load_or_skip(&tongji_path()) else { return };
    check_invariants(&net);
    assert!(check_routes(&net, 60) > 10);
    assert_eq!(net.location.net_offset, Vec2::new(761.28, 488.05));
    assert!(net.location.proj_parameter.starts_with("+proj=tmerc"));
    assert!(!net.tl_logics.is_empty());
    for tl in net.tl_ids() {
        let n_links = net.tl_links(tl).len();
        assert!(n_links > 0);
        let logic = net.tl_logic(tl).expect("program for every controlling light");
        let max_index = net.tl_links(tl).iter().map(|l| l.link_index).max().unwrap();
        assert!(logic.phases.iter().all(|p| p.state.len() > max_index), "tl {tl}");
    }
    // The hero route of an official scenario (ids copied from its entity_sumo.json).
    let scen = repo_root().join(
        "../shared/official/Close_Loop_Evaluation/Scenario_Onsite/01_pedestrain_recognition/SC20260319211139GNGY/entity_sumo.json",
    );
    let ids: Vec<String> = match std::fs::read_to_string(&scen) {
        Ok(text) => {
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            v["hero"]["route_edges"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_str().unwrap().to_string())
                .collect()
        }
        Err(_) => vec!["-68".into(), "-70".into()],
    };
    let edges: Vec<usize> = ids.iter().map(|id| net.edge_by_id(id).expect(id)).collect();
    let start = net.lane_by_id("-68_0");
    let lanes = net.route_lanes(&edges, start).unwrap();
    assert_eq!(lanes[0], start.unwrap());
    let pl = net.route_polyline(&edges, start).unwrap();
    assert!(pl.length() > 20.0);
    // The scenario's start and end reference points lie near the route.
    for p in [Vec2::new(44.907, 288.082), Vec2::new(17.356, 323.321)] {
        assert!(pl.project(p).unwrap().distance < 3.0);
    }
    // Routing finds a route between the same edges.
    let r = net.edge_route(edges[0], *edges.last().unwrap(), VClass::Passenger).unwrap();
    assert_eq!(r.first(), edges.first());
}

#[test]
fn sumo_shipped_nets_load() {
    let Some(home) = sumo_home() else {
        eprintln!("skipping: SUMO_HOME not found");
        return;
    };
    for rel in [
        "tools/game/fkk_in/ingolstadt.net.xml.gz",
        "tools/game/bs3d/bs.net.xml",
        "tools/game/A10KW/osm.net.xml",
    ] {
        let Some(net) = load_or_skip(&home.join(rel)) else { continue };
        check_invariants(&net);
        assert!(check_routes(&net, 40) > 5, "{rel}: too few routes found");
    }
}

#[test]
fn town01_map_has_the_advertised_features() {
    let Some(net) = load_or_skip(&repo_root().join("scenarios/maps/town01/town01.net.xml")) else { return };
    check_invariants(&net);
    let c = net.junction_by_id("C").unwrap();
    assert_eq!(net.junctions[c].kind, "traffic_light");
    assert_eq!(net.junctions[net.junction_by_id("T").unwrap()].kind, "priority");
    assert_eq!(net.roundabouts.len(), 1);
    assert!(net.edges.iter().any(|e| e.function == EdgeFunction::Crossing));
    let e = |id: &str| net.edge_by_id(id).unwrap_or_else(|| panic!("edge {id}"));
    // Two car lanes per direction on the main roads (lane 0 is the sidewalk near C).
    let cars = |id: &str| net.edges[e(id)].lanes.iter().filter(|&&l| net.lanes[l].is_drivable()).count();
    for id in ["W2C", "C2W", "N2C", "C2N", "S2C", "C2S", "C2T", "T2C", "T2E", "E2T"] {
        assert_eq!(cars(id), 2, "{id}");
    }
    assert!(net.lanes[net.edges[e("C2T")].lanes[1]].length_m >= 300.0);
    // Every turn at C and a trip through T, the curve and around the roundabout.
    for (a, b) in
        [("W2C", "C2N"), ("W2C", "C2T"), ("W2C", "C2S"), ("S2C", "C2W"), ("W2C", "R2AE"), ("AE2R", "C2N")]
    {
        let r = net.edge_route(e(a), e(b), VClass::Passenger).unwrap_or_else(|| panic!("{a}->{b}"));
        assert_continuous(&net, &net.route_lanes(&r, None).unwrap());
        let pl = net.route_polyline(&r, None).unwrap();
        let lane_sum: f64 = r.iter().map(|&x| net.lanes[*net.edges[x].lanes.last().unwrap()].length_m).sum();
        assert!(pl.length() >= 0.9 * lane_sum, "{a}->{b}: polyline shorter than its edges");
    }
    let tl = net.tl_logic("C").unwrap();
    assert!(tl.phases.len() >= 4);
    assert!(!net.tl_links("C").is_empty());
}

/// Every official scenario's hero route (its `route_edges`, from its depart lane) must give
/// lanes and a route polyline on tongji.
#[test]
fn tongji_every_official_hero_route() {
    let Some(net) = load_or_skip(&tongji_path()) else { return };
    let root = repo_root().join("../shared/official/Close_Loop_Evaluation/Scenario_Onsite");
    let Ok(cats) = std::fs::read_dir(&root) else { return };
    let mut checked = 0;
    for cat in cats.flatten() {
        let Ok(scens) = std::fs::read_dir(cat.path()) else { continue };
        for sc in scens.flatten() {
            let Ok(text) = std::fs::read_to_string(sc.path().join("entity_sumo.json")) else { continue };
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            let hero = &v["hero"];
            let edges: Vec<usize> = hero["route_edges"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| {
                    net.edge_by_id(x.as_str().unwrap()).unwrap_or_else(|| panic!("{x} in {:?}", sc.path()))
                })
                .collect();
            let start = hero["depart"]["lane_id"].as_str().and_then(|id| net.lane_by_id(id));
            let pl =
                net.route_polyline(&edges, start).unwrap_or_else(|e| panic!("{}: {e}", sc.path().display()));
            assert!(pl.length() > 0.0);
            checked += 1;
        }
    }
    eprintln!("checked {checked} official hero routes");
}
