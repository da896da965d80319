//! A second [`RasterBackend`] that records the primitive stream instead of drawing it: tests
//! check what the views draw (kinds, colours, places, order) without looking at pixels, which
//! also proves the views reach the rasterizer only through the trait.

use super::bev::{EGO_OUTLINE, EGO_YELLOW, ROUTE_RED};
use super::camera::Cam;
use super::frame::{FrameInput, Renderer};
use super::raster::{RasterBackend, SV};
use super::{BevConfig, CameraConfig, RenderMap};
use crate::geom::{Pose, Vec2};
use crate::map::Network;
use crate::view::{ActorKind, ActorView, LightColor, TrafficLightView};
use std::path::Path;

#[derive(Debug, Clone, PartialEq)]
enum Prim {
    /// One colour per pixel row.
    Rows(Vec<[u8; 3]>),
    Convex {
        n: usize,
        col: [u8; 3],
        bbox: [f32; 4],
    },
    ConvexDepth {
        n: usize,
        col: [u8; 3],
        id: u32,
        bbox: [f32; 4],
    },
    Segment {
        a: [f32; 2],
        b: [f32; 2],
        hw: f32,
        col: [u8; 3],
    },
    Polyline {
        pts: Vec<[f32; 2]>,
        hw: f32,
        col: [u8; 3],
    },
    Disc {
        c: [f32; 2],
        r: f32,
        col: [u8; 3],
    },
}

/// Records every call; strokes and discs are kept as shapes (their default tessellation is
/// the software backend's business).
struct Recorder {
    height: usize,
    prims: Vec<Prim>,
}

fn bbox(pts: &[SV]) -> [f32; 4] {
    pts.iter().fold([f32::MAX, f32::MAX, f32::MIN, f32::MIN], |b, p| {
        [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)]
    })
}

impl RasterBackend for Recorder {
    fn fill_rows(&mut self, row_colour: &dyn Fn(usize) -> [u8; 3]) {
        self.prims.push(Prim::Rows((0..self.height).map(row_colour).collect()));
    }
    fn fill_convex(&mut self, pts: &[SV], col: [u8; 3]) {
        if pts.len() >= 3 {
            self.prims.push(Prim::Convex { n: pts.len(), col, bbox: bbox(pts) });
        }
    }
    fn fill_convex_depth(&mut self, pts: &[SV], col: [u8; 3], id: u32) {
        if pts.len() >= 3 {
            self.prims.push(Prim::ConvexDepth { n: pts.len(), col, id, bbox: bbox(pts) });
        }
    }
    fn stroke_segment(&mut self, a: SV, b: SV, hw: f32, col: [u8; 3]) {
        self.prims.push(Prim::Segment { a: [a.x, a.y], b: [b.x, b.y], hw, col });
    }
    fn stroke_polyline(&mut self, pts: &[SV], hw: f32, col: [u8; 3]) {
        self.prims.push(Prim::Polyline { pts: pts.iter().map(|p| [p.x, p.y]).collect(), hw, col });
    }
    fn fill_disc(&mut self, c: SV, r: f32, col: [u8; 3]) {
        self.prims.push(Prim::Disc { c: [c.x, c.y], r, col });
    }
}

/// Counts what reaches the required fills when strokes and discs use their defaults.
#[derive(Default)]
struct FillCounter {
    convex: Vec<(usize, [u8; 3])>,
}

impl RasterBackend for FillCounter {
    fn fill_rows(&mut self, _: &dyn Fn(usize) -> [u8; 3]) {}
    fn fill_convex(&mut self, pts: &[SV], col: [u8; 3]) {
        self.convex.push((pts.len(), col));
    }
    fn fill_convex_depth(&mut self, pts: &[SV], col: [u8; 3], _: u32) {
        self.convex.push((pts.len(), col));
    }
}

fn town01() -> (Network, RenderMap) {
    let net = Network::from_file(Path::new("../scenarios/maps/town01/town01.net.xml")).expect("town01 net");
    let map = RenderMap::build(&net);
    (net, map)
}

fn car(id: u32, pose: Pose, color: [u8; 3]) -> ActorView {
    ActorView {
        id,
        kind: ActorKind::Car,
        pose,
        speed_mps: 0.0,
        length_m: 4.6,
        width_m: 1.9,
        height_m: 1.5,
        color,
        braking: false,
        blinkers: 0,
        beacon: false,
    }
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() < 1e-2
}

#[test]
fn bev_issues_route_polyline_dots_and_ego_disc_in_protocol_colours() {
    let (net, map) = town01();
    let ep = net.lane_position(net.lane_by_id("C2T_1").expect("lane C2T_1"), 100.0);
    let ego = car(0, ep, [200, 200, 200]);
    let actors = [car(7, Pose::new(ep.local_to_world(10.0, 0.0), ep.yaw), [40, 90, 200])];
    let lights = [TrafficLightView {
        tl_id: "t".into(),
        lane_id: "C2T_1".into(),
        stop_line: Pose::new(ep.local_to_world(20.0, 0.0), ep.yaw),
        lane_width_m: 3.2,
        color: LightColor::Red,
    }];
    let dists = [5.0, 10.0, 20.0, 40.0];
    let route: Vec<Vec2> = dists.iter().map(|d| ep.local_to_world(*d, 0.0)).collect();
    let frame = FrameInput {
        ego: &ego,
        actors: &actors,
        lights: &lights,
        signs: &[],
        route_points: &route,
        ambience: Default::default(),
    };
    let cfg = BevConfig::default(); // 800 px, 8 px/m
    let mut rec = Recorder { height: 800, prims: Vec::new() };
    Renderer::new().draw_bev(&map, &frame, &cfg, &mut rec);
    let p = &rec.prims;

    // Backdrop first, then road fills.
    assert!(matches!(&p[0], Prim::Rows(rows) if rows.len() == 800 && rows.iter().all(|c| *c == rows[0])));
    assert!(p.iter().filter(|q| matches!(q, Prim::Convex { n: 3, .. })).count() > 10, "no road drawn");

    // One route polyline (255, 90, 90), 3 px, from the ego centre through every slice vertex.
    let lines: Vec<_> = p.iter().filter(|q| matches!(q, Prim::Polyline { .. })).collect();
    assert_eq!(lines.len(), 1, "{lines:?}");
    let Prim::Polyline { pts, hw, col } = lines[0] else { unreachable!() };
    assert_eq!(*col, [255, 90, 90]);
    assert!(close(*hw, 1.5), "half width {hw}");
    assert_eq!(pts.len(), dists.len() + 1);
    assert!(close(pts[0][0], 400.0) && close(pts[0][1], 400.0), "starts at the ego centre: {:?}", pts[0]);
    for (q, d) in pts[1..].iter().zip(dists) {
        assert!(close(q[0], 400.0) && close(q[1], 400.0 - 8.0 * d as f32), "{q:?} for {d} m");
    }

    // After it: on every vertex a (255, 90, 90) disc with a white disc 2 px smaller inside,
    // radius 4 (the last 5); then the ego: a dark disc of radius 6 with a yellow one of 4.
    let at = p.iter().position(|q| matches!(q, Prim::Polyline { .. })).unwrap();
    let tail = &p[at + 1..];
    assert_eq!(tail.len(), dists.len() * 2 + 2, "{tail:?}");
    for (k, d) in dists.iter().enumerate() {
        let y = 400.0 - 8.0 * *d as f32;
        let r = if k + 1 == dists.len() { 5.0 } else { 4.0 };
        let (outline, white) = (&tail[2 * k], &tail[2 * k + 1]);
        assert!(
            matches!(outline, Prim::Disc { c, r: rr, col } if close(c[1], y) && close(*rr, r) && *col == ROUTE_RED),
            "{outline:?}"
        );
        assert!(
            matches!(white, Prim::Disc { c, r: rr, col } if close(c[1], y) && close(*rr, r - 2.0) && *col == [255, 255, 255]),
            "{white:?}"
        );
    }
    let n = tail.len();
    assert!(
        matches!(tail[n - 2], Prim::Disc { c, r, col } if c == [400.0, 400.0] && close(r, 6.0) && col == EGO_OUTLINE),
        "{:?}",
        tail[n - 2]
    );
    assert!(
        matches!(tail[n - 1], Prim::Disc { c, r, col } if c == [400.0, 400.0] && close(r, 4.0) && col == EGO_YELLOW && col == [255, 230, 80]),
        "{:?}",
        tail[n - 1]
    );

    // The actor 10 m ahead: its body quad centred 80 px above the ego, under the route.
    let body = p
        .iter()
        .position(|q| matches!(q, Prim::Convex { n: 4, col, .. } if *col == [40, 90, 200]))
        .expect("actor body");
    let Prim::Convex { bbox, .. } = p[body] else { unreachable!() };
    assert!(close((bbox[0] + bbox[2]) * 0.5, 400.0) && close((bbox[1] + bbox[3]) * 0.5, 320.0), "{bbox:?}");
    assert!(body < at);
    // The red light: a bar across the lane at its stop line, 20 m ahead.
    assert!(p.iter().any(|q| matches!(q, Prim::Segment { a, b, col, .. }
        if *col == [235, 30, 30] && close(a[1], 240.0) && close(b[1], 240.0) && close((a[0] - b[0]).abs(), 3.2 * 8.0))));
}

#[test]
fn camera_paints_ground_before_depth_tested_actors_tagged_with_their_ids() {
    let (net, map) = town01();
    let ep = net.lane_position(net.lane_by_id("C2T_1").expect("lane C2T_1"), 100.0);
    let ego = car(0, ep, [200, 200, 200]);
    let actors = [
        car(5, Pose::new(ep.local_to_world(15.0, 0.0), ep.yaw), [40, 90, 200]),
        // Behind the camera: must issue nothing.
        car(6, Pose::new(ep.local_to_world(-30.0, 0.0), ep.yaw), [10, 200, 10]),
    ];
    let frame = FrameInput {
        ego: &ego,
        actors: &actors,
        lights: &[],
        signs: &[],
        route_points: &[],
        ambience: Default::default(),
    };
    let cfg = CameraConfig { width: 160, height: 90, ..CameraConfig::front() };
    let cam = Cam::new(&map, &frame, &cfg, 1);
    let mut rec = Recorder { height: 90, prims: Vec::new() };
    Renderer::new().draw_scene(&map, &frame, &cfg, &cam, &mut rec);
    let p = &rec.prims;

    // Sky at the top, darker green-grey ground at the bottom.
    let Prim::Rows(rows) = &p[0] else { panic!("no backdrop first: {:?}", p[0]) };
    assert_eq!(rows.len(), 90);
    assert!(rows[0][2] > rows[0][1] && rows[0][2] > 180, "sky {:?}", rows[0]);
    assert!(rows[89][1] > rows[89][2], "ground {:?}", rows[89]);
    // Painter's fills (ground, markings) all come before the first depth-tested one.
    let first_depth = p.iter().position(|q| matches!(q, Prim::ConvexDepth { .. })).expect("3-D drawn");
    assert!(first_depth > 1);
    assert!(p[first_depth..].iter().all(|q| matches!(q, Prim::ConvexDepth { .. })));
    // Only the actor ahead (index 0 → id 1) is drawn, around the image centre line.
    let ids: Vec<u32> = p
        .iter()
        .filter_map(|q| match q {
            // Ids carry the paint flag on body-colour faces; the actor is the rest.
            Prim::ConvexDepth { id, .. } if *id != 0 => Some(*id & !super::mesh::PAINT_BIT),
            _ => None,
        })
        .collect();
    assert!(!ids.is_empty() && ids.iter().all(|i| *i == 1), "{ids:?}");
    let bb = p.iter().fold([f32::MAX, f32::MAX, f32::MIN, f32::MIN], |b, q| match q {
        Prim::ConvexDepth { id, bbox, .. } if *id & !super::mesh::PAINT_BIT == 1 => {
            [b[0].min(bbox[0]), b[1].min(bbox[1]), b[2].max(bbox[2]), b[3].max(bbox[3])]
        }
        _ => b,
    });
    assert!(bb[0] < 80.0 && bb[2] > 80.0 && bb[1] < 45.0 + 10.0 && bb[3] > 45.0, "{bb:?}");
    // Its body in its own (shaded) blue: blue over green over red, as [40, 90, 200].
    assert!(p
        .iter()
        .any(|q| matches!(q, Prim::ConvexDepth { id: 1, col, .. } if col[2] > col[1] && col[1] > col[0])));
}

#[test]
fn default_strokes_and_discs_tessellate_into_convex_fills() {
    let sv = |x, y| SV { x, y, w: 1.0 };
    let mut f = FillCounter::default();
    f.fill_disc(sv(10.0, 10.0), 3.0, [1, 2, 3]);
    assert_eq!(f.convex, vec![(3, [1, 2, 3]); 12]);
    f.convex.clear();
    f.fill_disc(sv(10.0, 10.0), 7.0, [1, 2, 3]);
    assert_eq!(f.convex.len(), 24);
    f.convex.clear();
    f.stroke_segment(sv(0.0, 0.0), sv(0.0, 0.0), 2.0, [9, 9, 9]);
    assert!(f.convex.is_empty(), "a zero-length segment draws nothing");
    // Polyline of 3 points: 2 quads, each followed by a round join/cap (12-gon).
    f.stroke_polyline(&[sv(0.0, 0.0), sv(10.0, 0.0), sv(10.0, 10.0)], 1.0, [9, 9, 9]);
    let quads = f.convex.iter().filter(|c| c.0 == 4).count();
    assert_eq!((quads, f.convex.len()), (2, 2 + 2 * 12));
}
