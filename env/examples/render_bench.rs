//! Render throughput on one core: front 800×450 + BEV 800×800 pairs, front 400×225, BEV 128×128.
//!
//! `cargo run --release -p dh-env --example render_bench -- NET [NET...] [--conditions=NAME]`
//! Each net gets a drive along its longest drivable lane with 30 actors scattered around.

use dh_env::geom::Pose;
use dh_env::map::Network;
use dh_env::render::{BevConfig, CameraConfig, FrameInput, Image, RenderMap, Renderer};
use dh_env::view::{ActorKind, ActorView};
use std::path::Path;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let conditions = match args.iter().find_map(|a| a.strip_prefix("--conditions=")) {
        Some(n) => dh_env::conditions::Conditions::parse(n)?,
        None => Default::default(),
    };
    let nets: Vec<String> = args.into_iter().filter(|a| !a.starts_with("--")).collect();
    if nets.is_empty() {
        return Err("usage: render_bench NET [NET...]".into());
    }
    for path in nets {
        let t0 = Instant::now();
        let net = Network::from_file(Path::new(&path))?;
        let t1 = Instant::now();
        let map = RenderMap::build(&net);
        let build = t1.elapsed();
        let (lane, _) = net
            .lanes
            .iter()
            .enumerate()
            .filter(|(_, l)| l.is_drivable())
            .map(|(i, l)| (i, l.shape.length()))
            .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        let len = net.lanes[lane].shape.length();
        println!("{path}: parse {:.0} ms, render map {:.0} ms, (tris, segs, prop tris) = {:?}, drive lane {} ({len:.0} m)", (t1 - t0).as_secs_f64() * 1e3, build.as_secs_f64() * 1e3, map.stats(), net.lanes[lane].id);
        let n_frames = 300;
        let poses: Vec<Pose> =
            (0..n_frames).map(|k| net.lane_position(lane, len * k as f64 / n_frames as f64)).collect();
        let kinds = [
            ActorKind::Car,
            ActorKind::Car,
            ActorKind::Bus,
            ActorKind::Truck,
            ActorKind::Pedestrian,
            ActorKind::Cyclist,
        ];
        let actors_at = |p: &Pose| -> Vec<ActorView> {
            (0..30)
                .map(|i| {
                    let f = -20.0 + (i as f64 * 7.3) % 80.0;
                    let l = ((i % 5) as f64 - 2.0) * 3.2;
                    ActorView {
                        id: i + 1,
                        kind: kinds[i as usize % kinds.len()],
                        pose: Pose::new(p.local_to_world(f, l), p.yaw),
                        speed_mps: 10.0,
                        length_m: 0.0,
                        width_m: 0.0,
                        height_m: 0.0,
                        color: [(i * 40 % 255) as u8, 90, 160],
                        braking: i % 3 == 0,
                        blinkers: 0,
                        beacon: false,
                    }
                })
                .collect()
        };
        let actor_sets: Vec<Vec<ActorView>> = poses.iter().map(actors_at).collect();
        let egos: Vec<ActorView> = poses
            .iter()
            .map(|p| ActorView {
                id: 0,
                kind: ActorKind::Car,
                pose: *p,
                speed_mps: 10.0,
                length_m: 4.6,
                width_m: 1.9,
                height_m: 1.5,
                color: [200, 200, 200],
                braking: false,
                blinkers: 0,
                beacon: false,
            })
            .collect();
        let route: Vec<Vec<dh_env::geom::Vec2>> = poses
            .iter()
            .map(|p| {
                [5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0]
                    .iter()
                    .map(|d| p.local_to_world(*d, 0.0))
                    .collect()
            })
            .collect();
        let frame = |k: usize| FrameInput {
            ego: &egos[k],
            actors: &actor_sets[k],
            lights: &[],
            signs: &[],
            route_points: &route[k],
            ambience: dh_env::render::Ambience { conditions, seed: 0, tick: k as u64 },
        };
        let mut r = Renderer::new();
        let (mut a, mut b) = (Image::default(), Image::default());
        let front = CameraConfig::front();
        let small = CameraConfig { width: 400, height: 225, ..CameraConfig::front() };
        let bev = BevConfig::default();
        let bev_rl = BevConfig::rl();
        // Wall time and this thread's CPU time: on a loaded machine the CPU figure is the
        // one-core throughput.
        let time = |name: &str, reps: usize, f: &mut dyn FnMut(usize)| {
            f(0);
            let (t, c) = (Instant::now(), thread_cpu_s());
            for k in 0..reps {
                f(k % n_frames);
            }
            let dt = t.elapsed().as_secs_f64();
            let dc = thread_cpu_s().zip(c).map(|(b, a)| b - a);
            let cpu = dc.map_or("n/a".to_string(), |d| format!("{:.0}", reps as f64 / d.max(1e-9)));
            println!("  {name:<34} {:>8.0} /s wall {:>8} /s cpu", reps as f64 / dt, cpu);
        };
        time("front 800x450 + BEV 800x800 pairs", 1000, &mut |k| {
            r.render_camera(&map, &frame(k), &front, &mut a).unwrap();
            r.render_bev(&map, &frame(k), &bev, &mut b).unwrap();
        });
        time("front 800x450", 600, &mut |k| r.render_camera(&map, &frame(k), &front, &mut a).unwrap());
        time("front 800x450 supersample 2", 200, &mut |k| {
            r.render_camera(&map, &frame(k), &CameraConfig { supersample: 2, ..front }, &mut a).unwrap()
        });
        time("BEV 800x800", 600, &mut |k| r.render_bev(&map, &frame(k), &bev, &mut b).unwrap());
        time("front 400x225", 3000, &mut |k| r.render_camera(&map, &frame(k), &small, &mut a).unwrap());
        time("BEV 128x128", 20000, &mut |k| r.render_bev(&map, &frame(k), &bev_rl, &mut b).unwrap());
    }
    Ok(())
}

/// CPU seconds used by the calling thread (Linux `/proc/thread-self/stat`), if available.
fn thread_cpu_s() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/thread-self/stat").ok()?;
    let rest = stat.rsplit_once(')')?.1;
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
