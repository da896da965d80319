//! The expert on the real-world geometry of the original benchmark: the hero route of every
//! official R4 scenario (`../shared/official/.../Scenario_Onsite/*/*/entity_sumo.json`) on the
//! tongji network, driven without traffic in the stand-in closed loop. The ego centre must stay
//! on drivable ground and the route be finished efficiently. Skips when the files are absent.

use crate::expert_support;

use dh_agents::expert::ExpertParams;
use dh_env::map::Network;
use expert_support::{efficiency, Sim};
use std::path::{Path, PathBuf};

fn official() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/official/Close_Loop_Evaluation")
}

#[test]
fn official_hero_routes_on_tongji() {
    let net_path = official().join("Carla_Simulation/Co-Simulation/Sumo/tongji/tongji.net.xml");
    let scen_dir = official().join("Scenario_Onsite");
    if !net_path.exists() || !scen_dir.is_dir() {
        eprintln!("skipping: official tongji data not found");
        return;
    }
    let net = Network::from_file(&net_path).unwrap();
    let mut files = Vec::new();
    for cat in std::fs::read_dir(&scen_dir).unwrap().flatten() {
        for sc in std::fs::read_dir(cat.path()).into_iter().flatten().flatten() {
            let f = sc.path().join("entity_sumo.json");
            if f.exists() {
                files.push(f);
            }
        }
    }
    files.sort();
    let mut failures = Vec::new();
    for f in &files {
        let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(f).unwrap()).unwrap();
        let hero = &v["hero"];
        let edges: Vec<usize> = hero["route_edges"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| net.edge_by_id(e.as_str().unwrap()).unwrap())
            .collect();
        let start_lane = hero["depart"]["lane_id"].as_str().and_then(|l| net.lane_by_id(l));
        let route = net.route_polyline(&edges, start_lane).unwrap();
        let name = f.parent().unwrap().file_name().unwrap().to_string_lossy().to_string();
        let sim = Sim { time_limit_s: 30.0 + route.length() / 3.0, ..Sim::new(route) };
        let o = sim.run(ExpertParams::default());
        // Some route starts (first lane point) lie in gaps of the drivable area: count off-road
        // ticks from the first on-road one.
        let on = |p: &dh_env::geom::Pose| net.drivable().is_drivable(p.pos);
        let first_on = o.trajectory.iter().position(|(_, p)| on(p)).unwrap_or(0);
        let offroad = o.trajectory[first_on..].iter().filter(|(_, p)| !on(p)).count();
        let eff = efficiency(&o);
        println!(
            "{name}: L={:.0} m t={:.1}s reached={} offroad_ticks={offroad} max_lat={:.2} eff={eff:.3}",
            o.route_len_m, o.time_s, o.reached, o.max_lateral_m
        );
        if !o.reached || offroad > 0 || eff < 0.95 {
            failures.push(name);
        }
    }
    assert!(failures.is_empty(), "{failures:?}");
}
