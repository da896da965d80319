//! Tests of the palette that render actors through the camera (a module of their own: the
//! palette sits below the camera, which names colours with it).

use super::palette::*;
use crate::geom::{Pose, Vec2};
use crate::map::Network;
use crate::render::mesh::{dot, LIT_MIN_COS, PAINT_BIT, SUN};
use crate::render::{CameraConfig, FrameInput, RenderMap, Renderer};
use crate::view::{ActorKind, ActorView};

#[test]
fn every_colour_has_exactly_one_name() {
    for r in (0..=255u32).step_by(5) {
        for g in (0..=255u32).step_by(5) {
            for b in (0..=255u32).step_by(5) {
                let c = [r as u8, g as u8, b as u8];
                // Black (any dark colour) overlaps the others by design: it is tried first.
                let n = PALETTE[1..].iter().filter(|p| p.range.contains(c)).count();
                let dark = PALETTE[0].range.contains(c);
                assert!(n == 1 || (dark && n <= 1), "{c:?} is in {n} ranges");
            }
        }
    }
}

#[test]
fn palette_entries_are_named_by_their_own_range() {
    for c in PALETTE {
        assert_eq!(name_of(c.rgb), c.name, "{c:?}");
    }
}

fn view(kind: ActorKind, rgb: [u8; 3], yaw: f64, (l, w, h): (f64, f64, f64)) -> ActorView {
    ActorView {
        id: 1,
        kind,
        pose: Pose::new(Vec2::new(12.0, -0.5), yaw),
        speed_mps: 0.0,
        length_m: l,
        width_m: w,
        height_m: h,
        color: rgb,
        braking: false,
        blinkers: 0,
        beacon: false,
    }
}

const BODIES: [(ActorKind, (f64, f64, f64)); 8] = [
    (ActorKind::Car, (4.6, 1.85, 1.45)),
    (ActorKind::Car, (4.8, 1.95, 1.75)),
    (ActorKind::Car, (5.4, 2.05, 2.35)),
    (ActorKind::Bus, (0.0, 0.0, 0.0)),
    (ActorKind::Truck, (0.0, 0.0, 0.0)),
    (ActorKind::Motorcycle, (0.0, 0.0, 0.0)),
    (ActorKind::Cyclist, (0.0, 0.0, 0.0)),
    (ActorKind::Pedestrian, (0.0, 0.0, 0.0)),
];

/// Every sunlit painted face of every body, in every palette colour, at any heading, is
/// shaded into its colour's range.
#[test]
fn sunlit_paint_stays_in_its_name_range() {
    let sun = {
        let n = dot(SUN, SUN).sqrt();
        SUN.map(|v| v / n)
    };
    let mut tris = Vec::new();
    for c in PALETTE {
        for (kind, dims) in BODIES {
            for k in 0..16 {
                tris.clear();
                let yaw = k as f64 * std::f64::consts::TAU / 16.0;
                crate::render::actors::actor(
                    &mut tris,
                    &view(kind, c.rgb, yaw, dims),
                    Vec2::new(0.0, 0.0),
                    1,
                    true,
                    false,
                    0,
                );
                let mut lit = 0;
                for t in tris.iter().filter(|t| t.id & PAINT_BIT != 0 && dot(t.n, sun) >= LIT_MIN_COS) {
                    assert!(
                        c.range.contains(t.col),
                        "{} {kind:?} yaw {yaw:.2}: lit face {:?}",
                        c.name,
                        t.col
                    );
                    lit += 1;
                }
                assert!(lit > 0, "{} {kind:?} yaw {yaw:.2}: no sunlit paint", c.name);
            }
        }
    }
}

/// Rendered through the front camera at 12 m on town01 at noon, each palette colour is named
/// by its own name from the actor's visible paint, from several headings.
#[test]
fn rendered_actors_are_named_by_their_colour() {
    let net = Network::from_file(std::path::Path::new("../scenarios/maps/town01/town01.net.xml")).unwrap();
    let map = RenderMap::build(&net);
    let lane = net.lane_by_id("W2C_1").unwrap();
    let ego_pose = net.lane_position(lane, net.lanes[lane].shape.length() - 75.0);
    let ego =
        ActorView { id: 0, pose: ego_pose, ..view(ActorKind::Car, [30, 110, 230], 0.0, (0.0, 0.0, 0.0)) };
    let mut r = Renderer::new();
    let mut failures = Vec::new();
    for c in PALETTE {
        for (kind, dims) in BODIES {
            for dyaw in [0.0, 0.6, 1.6, 2.6, 3.1] {
                let d = if kind == ActorKind::Bus || kind == ActorKind::Truck { 20.0 } else { 12.0 };
                let pose = Pose::new(ego_pose.local_to_world(d, -0.5), ego_pose.yaw + dyaw);
                let a = ActorView { pose, ..view(kind, c.rgb, 0.0, dims) };
                let frame = FrameInput {
                    ego: &ego,
                    actors: &[a],
                    lights: &[],
                    signs: &[],
                    route_points: &[],
                    ambience: Default::default(),
                };
                let found = r.project_actors(&map, &frame, &CameraConfig::front()).unwrap();
                let got = found.first().and_then(|p| p.colour_name);
                if got != Some(c.name) {
                    failures.push(format!("{} {kind:?} {dims:?} dyaw {dyaw}: named {got:?}", c.name));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{} misnamed:\n{}", failures.len(), failures.join("\n"));
}

#[test]
fn brightest_pixels_decide() {
    let white = [240, 240, 238];
    let glass = [40, 55, 75];
    let px = [white, white, white, glass, glass, [20, 20, 20]];
    assert_eq!(name_pixels(&px), Some("white"));
    assert_eq!(name_pixels(&[]), None);
}
