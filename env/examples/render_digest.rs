//! Digests of every frame of a drive (front, supersampled front, chase, BEV 800 and 128, the
//! projection helper's output): run before and after a renderer refactor, equal digests mean
//! byte-identical output over the whole drive (the golden test alone tolerates 0.5 % pixels).
//!
//! `cargo run --release -p dh-env --example render_digest -- scenarios/maps/town01/town01.net.xml`

use dh_env::geom::{Pose, Vec2};
use dh_env::map::Network;
use dh_env::render::{BevConfig, CameraConfig, FrameInput, Image, RenderMap, Renderer};
use dh_env::view::{ActorKind, ActorView, LightColor, SignKind, SignView, TrafficLightView};
use std::path::Path;

/// FNV-1a, 64 bit: stable across platforms and Rust versions (unlike `DefaultHasher`).
#[derive(Clone, Copy)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn eat(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.0 = (self.0 ^ *b as u64).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: render_digest NET")?;
    let net = Network::from_file(Path::new(&path))?;
    let map = RenderMap::build(&net);
    let (lane, len) = net
        .lanes
        .iter()
        .enumerate()
        .filter(|(_, l)| l.is_drivable())
        .map(|(i, l)| (i, l.shape.length()))
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    let kinds = [
        ActorKind::Car,
        ActorKind::Bus,
        ActorKind::Truck,
        ActorKind::Pedestrian,
        ActorKind::Cyclist,
        ActorKind::Motorcycle,
        ActorKind::Cone,
        ActorKind::Barrier,
    ];
    let colors = [LightColor::Red, LightColor::Yellow, LightColor::Green, LightColor::Off];
    let names = ["front", "front_ss2", "chase", "bev_800", "bev_128", "projection"];
    let mut digests = [Fnv::new(); 6];
    let mut r = Renderer::new();
    let mut img = Image::default();
    let n_frames = 120;
    for k in 0..n_frames {
        let p = net.lane_position(lane, len * k as f64 / n_frames as f64);
        let ego = ActorView {
            id: 0,
            kind: ActorKind::Car,
            pose: p,
            speed_mps: 10.0,
            length_m: 4.6,
            width_m: 1.9,
            height_m: 1.5,
            color: [200, 200, 200],
            braking: false,
            blinkers: 0,
            beacon: false,
        };
        let actors: Vec<ActorView> = (0..24u32)
            .map(|i| ActorView {
                id: i + 1,
                kind: kinds[i as usize % kinds.len()],
                pose: Pose::new(
                    p.local_to_world(-20.0 + (i as f64 * 7.3) % 80.0, ((i % 5) as f64 - 2.0) * 3.2),
                    p.yaw + 0.3 * i as f64,
                ),
                speed_mps: 5.0,
                length_m: 0.0,
                width_m: 0.0,
                height_m: 0.0,
                color: [(i * 40 % 255) as u8, 90, 160],
                braking: i % 3 == 0,
                blinkers: 0,
                beacon: false,
            })
            .collect();
        let lights = [TrafficLightView {
            tl_id: "t".into(),
            lane_id: net.lanes[lane].id.clone(),
            stop_line: Pose::new(p.local_to_world(25.0, 0.0), p.yaw),
            lane_width_m: 3.2,
            color: colors[k % colors.len()],
        }];
        let signs = [SignView {
            kind: if k % 2 == 0 { SignKind::Stop } else { SignKind::Yield },
            pose: Pose::new(p.local_to_world(18.0, -5.5), p.yaw + std::f64::consts::PI),
        }];
        let route: Vec<Vec2> = [5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0]
            .iter()
            .map(|d| p.local_to_world(*d, 0.5 * d * (k as f64 * 0.1).sin()))
            .collect();
        let frame = FrameInput {
            ego: &ego,
            actors: &actors,
            lights: &lights,
            signs: &signs,
            route_points: &route,
            ambience: Default::default(),
        };
        let cams = [
            CameraConfig::front(),
            CameraConfig { width: 400, height: 225, supersample: 2, ..CameraConfig::front() },
            CameraConfig::chase(),
        ];
        for (d, cfg) in digests.iter_mut().zip(&cams) {
            r.render_camera(&map, &frame, cfg, &mut img)?;
            d.eat(&img.data);
        }
        for (d, cfg) in digests[3..].iter_mut().zip([BevConfig::default(), BevConfig::rl()]) {
            r.render_bev(&map, &frame, &cfg, &mut img)?;
            d.eat(&img.data);
        }
        for pa in r.project_actors(&map, &frame, &CameraConfig::front())? {
            digests[5].eat(format!("{pa:?}").as_bytes());
        }
    }
    for (name, d) in names.iter().zip(digests) {
        println!("{name:<12} {:016x}", d.0);
    }
    Ok(())
}
