//! Renders a demo scene on a SUMO net: front, chase and BEV PNGs.
//!
//! `cargo run --release -p dh-env --example render_scene -- scenarios/maps/town01/town01.net.xml out_dir [lane_id] [s_m]`

use dh_env::geom::{Pose, Vec2};
use dh_env::map::Network;
use dh_env::render::{write_gallery, FrameInput, RenderMap};
use dh_env::view::{ActorKind, ActorView, LightColor, SignKind, SignView, TrafficLightView};
use std::path::Path;

fn actor(id: u32, kind: ActorKind, pose: Pose, color: [u8; 3], braking: bool) -> ActorView {
    ActorView { braking, ..ActorView::at_rest(id, kind, pose, color) }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err("usage: render_scene NET OUT_DIR [LANE_ID] [S_M]".into());
    }
    let t0 = std::time::Instant::now();
    let net = Network::from_file(Path::new(&args[1]))?;
    let t1 = std::time::Instant::now();
    let map = RenderMap::build(&net);
    println!("parse {:?}, render map {:?}, stats {:?}", t1 - t0, t1.elapsed(), map.stats());
    let lane_id = args.get(3).cloned().unwrap_or_else(|| "W2C_1".into());
    let lane = net.lane_by_id(&lane_id).ok_or(format!("no lane {lane_id}"))?;
    let len = net.lanes[lane].shape.length();
    let s: f64 = args.get(4).map(|v| v.parse()).transpose()?.unwrap_or(len - 45.0);
    let ego_pose = net.lane_position(lane, s);
    let ego = actor(0, ActorKind::Car, ego_pose, [200, 200, 200], false);
    let at = |f: f64, l: f64, dyaw: f64| Pose::new(ego_pose.local_to_world(f, l), ego_pose.yaw + dyaw);
    let actors = vec![
        actor(1, ActorKind::Car, at(14.0, 0.0, 0.0), [180, 30, 30], true),
        actor(2, ActorKind::Bus, at(24.0, 3.2, 0.0), [30, 90, 170], false),
        actor(3, ActorKind::Truck, at(40.0, 8.5, std::f64::consts::PI), [230, 230, 230], false),
        actor(4, ActorKind::Pedestrian, at(47.0, -2.0, std::f64::consts::FRAC_PI_2), [20, 130, 220], false),
        actor(5, ActorKind::Pedestrian, at(48.5, 1.5, -std::f64::consts::FRAC_PI_2), [230, 160, 20], false),
        actor(6, ActorKind::Cyclist, at(20.0, -3.3, 0.0), [40, 170, 60], false),
        actor(7, ActorKind::Cone, at(8.0, -1.6, 0.0), [255, 110, 20], false),
        actor(8, ActorKind::Cone, at(9.5, -1.6, 0.0), [255, 110, 20], false),
        actor(9, ActorKind::Barrier, at(11.0, -2.2, 0.0), [220, 30, 30], false),
        actor(10, ActorKind::Car, at(-12.0, 3.2, 0.0), [40, 40, 45], false),
        actor(11, ActorKind::Motorcycle, at(30.0, 3.2, 0.0), [250, 200, 0], false),
    ];
    let mut lights = Vec::new();
    if let Some(j) = net.edges[net.lanes[lane].edge].to {
        for &il in &net.junctions[j].inc_lanes {
            if !net.lanes[il].is_drivable() {
                continue;
            }
            let same_edge = net.lanes[il].edge == net.lanes[lane].edge;
            lights.push(TrafficLightView {
                tl_id: net.junctions[j].id.clone(),
                lane_id: net.lanes[il].id.clone(),
                stop_line: net.stop_line(il),
                lane_width_m: net.lanes[il].width_m,
                color: if same_edge { LightColor::Red } else { LightColor::Green },
            });
        }
    }
    let signs = vec![SignView {
        kind: SignKind::Stop,
        pose: Pose::new(ego_pose.local_to_world(25.0, -5.5), ego_pose.yaw + std::f64::consts::PI),
    }];
    let route: Vec<Vec2> = [5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0]
        .iter()
        .map(|d| ego_pose.local_to_world(*d, 0.0))
        .collect();
    let frame = FrameInput {
        ego: &ego,
        actors: &actors,
        lights: &lights,
        signs: &signs,
        route_points: &route,
        ambience: Default::default(),
    };
    for p in write_gallery(&map, &frame, Path::new(&args[2]), "demo", true)? {
        println!("wrote {}", p.display());
    }
    Ok(())
}
