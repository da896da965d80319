//! Road surface detail on the cameras: stop lines at signalised approaches (cameras and BEV),
//! kerbs and wheel tracks (cameras only), and the anti-aliased marking edges.

use dh_env::geom::Pose;
use dh_env::map::Network;
use dh_env::render::{render_bev, render_camera, BevConfig, CameraConfig, FrameInput, Image, RenderMap};
use dh_env::view::ActorView;
use std::path::Path;

fn net() -> Network {
    Network::from_file(Path::new("../scenarios/maps/town01/town01.net.xml")).expect("town01 net")
}

fn ego(pose: Pose) -> ActorView {
    crate::common::grey_ego(pose)
}

fn frame(e: &ActorView) -> FrameInput<'_> {
    FrameInput {
        ego: e,
        actors: &[],
        lights: &[],
        signs: &[],
        route_points: &[],
        ambience: Default::default(),
    }
}

/// Pixels (index, luma in a, luma in b) where two same-size images differ.
fn diff(a: &Image, b: &Image) -> Vec<(usize, i32, i32)> {
    let l = |p: &[u8]| p[0] as i32 + 2 * p[1] as i32 + p[2] as i32;
    a.data
        .chunks_exact(3)
        .zip(b.data.chunks_exact(3))
        .enumerate()
        .filter(|(_, (p, q))| p != q)
        .map(|(i, (p, q))| (i, l(p) / 4, l(q) / 4))
        .collect()
}

#[test]
fn stop_line_appears_at_the_signalised_approach() {
    let net = net();
    let map = RenderMap::build(&net);
    // The same net with the signalised junction C made unregulated: no stop lines there.
    let mut junctions = net.junctions.clone();
    let c = junctions.iter_mut().find(|j| j.id == "C").expect("junction C");
    assert_eq!(c.kind, "traffic_light");
    c.kind = "unregulated".into();
    let plain = RenderMap::from_parts(&net.edges, &net.lanes, &junctions);

    let lane = net.lane_by_id("W2C_1").unwrap();
    let stop = net.stop_line(lane);
    let ahead_m = 20.0;
    let e = ego(Pose::new(stop.local_to_world(-ahead_m, 0.0), stop.yaw));
    let cfg = CameraConfig::front();
    let (mut with, mut without) = (Image::default(), Image::default());
    render_camera(&map, &frame(&e), &cfg, &mut with).unwrap();
    render_camera(&plain, &frame(&e), &cfg, &mut without).unwrap();
    let d = diff(&with, &without);
    assert!(d.len() > 200, "stop line covers only {} pixels", d.len());
    // Paint: every changed pixel is brighter with the line than without.
    assert!(d.iter().all(|(_, a, b)| a > b), "a changed pixel got darker");
    // Where the ground 20 m ahead of the ego (18.5 m ahead of the camera) projects.
    let (h, pitch) = (cfg.mount_height_m, cfg.pitch_deg.to_radians());
    let dist = ahead_m - cfg.mount_forward_m;
    let (zc, yc) = (dist * pitch.cos() + h * pitch.sin(), h * pitch.cos() - dist * pitch.sin());
    let fx = cfg.width as f64 * 0.5 / (cfg.fov_deg.to_radians() * 0.5).tan();
    let want_y = cfg.height as f64 * 0.5 + fx * yc / zc;
    // (Median: the other approaches' lines show far off, near the horizon.)
    let mut rows: Vec<f64> = d.iter().map(|(i, _, _)| (i / cfg.width as usize) as f64 + 0.5).collect();
    rows.sort_by(f64::total_cmp);
    let median = rows[rows.len() / 2];
    assert!((median - want_y).abs() < 4.0, "stop line at row {median:.1}, expected {want_y:.1}");
    // Across the ego's lane, in front of it.
    let xs: Vec<usize> = d.iter().map(|(i, _, _)| i % cfg.width as usize).collect();
    let (x0, x1) = (*xs.iter().min().unwrap(), *xs.iter().max().unwrap());
    assert!(x0 < 400 && x1 > 400, "stop line spans x {x0}..{x1}, not the lane ahead");

    // The BEV shows it too.
    let bev = BevConfig::default();
    render_bev(&map, &frame(&e), &bev, &mut with).unwrap();
    render_bev(&plain, &frame(&e), &bev, &mut without).unwrap();
    let d = diff(&with, &without);
    assert!(d.len() > 20, "BEV stop line covers only {} pixels", d.len());
    assert!(d.iter().all(|(_, a, b)| a > b));
}

#[test]
fn kerbs_and_wheel_tracks_show_on_the_camera() {
    let net = net();
    let map = RenderMap::build(&net);
    let lane = net.lane_by_id("C2T_1").unwrap();
    let e = ego(net.lane_position(lane, 100.0));
    let cfg = CameraConfig::front();
    let mut img = Image::default();
    render_camera(&map, &frame(&e), &cfg, &mut img).unwrap();
    let px = |x: usize, y: usize| {
        let o = (y * cfg.width as usize + x) * 3;
        [img.data[o], img.data[o + 1], img.data[o + 2]]
    };
    // Along the bottom rows, left to right across the ego's lane: road, darker track, road,
    // darker track, road. Count the dark runs between road-coloured pixels.
    let y = cfg.height as usize - 40;
    let row: Vec<[u8; 3]> = (0..cfg.width as usize).map(|x| px(x, y)).collect();
    let road = [88u8, 88, 92];
    let track = [81u8, 81, 85];
    let mut runs = 0;
    let mut prev = None;
    for p in &row {
        let k = if *p == road {
            Some(0)
        } else if *p == track {
            Some(1)
        } else {
            None
        };
        if let (Some(1), Some(0)) = (k, prev) {
            runs += 1;
        }
        if k.is_some() {
            prev = k;
        }
    }
    assert!(runs >= 2, "wheel tracks missing in the ego lane: {runs} dark runs");
    // A kerb-coloured run right of the ego's lane (its right edge line, then the kerb).
    let kerb = [196u8, 194, 188];
    assert!(row[400..].contains(&kerb), "no kerb right of the lane");
    // (The BEV skips both: its golden images under env/tests/golden pin that.)
}
