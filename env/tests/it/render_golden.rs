//! Golden images of one fixed scene on the project map (town01): small front camera, chase
//! camera and BEV frames compared with committed PNGs under `tests/golden/`.
//!
//! Re-bless after an intended change (then look at the PNGs before committing):
//! `DH_BLESS=1 cargo test -p dh-env --test it render_golden`
//!
//! Tolerance: rendering is deterministic, but float rounding may differ across CPUs/compilers
//! at triangle edges, so up to 0.5 % of pixels may differ (by any amount).

use dh_env::geom::{Pose, Vec2};
use dh_env::map::Network;
use dh_env::render::{render_bev, render_camera, BevConfig, CameraConfig, FrameInput, Image, RenderMap};
use dh_env::view::{ActorKind, ActorView, LightColor, SignKind, SignView, TrafficLightView};
use std::path::{Path, PathBuf};

fn actor(id: u32, kind: ActorKind, pose: Pose, color: [u8; 3], braking: bool) -> ActorView {
    ActorView { braking, ..ActorView::at_rest(id, kind, pose, color) }
}

fn check(name: &str, img: &Image) {
    let path = PathBuf::from("tests/golden").join(format!("{name}.png"));
    if std::env::var_os("DH_BLESS").is_some() {
        img.save(&path).unwrap();
        return;
    }
    let want = Image::load(&path).unwrap_or_else(|e| panic!("{e} (bless with DH_BLESS=1)"));
    assert_eq!((want.width, want.height), (img.width, img.height), "{name}: size");
    let differing = want.data.chunks_exact(3).zip(img.data.chunks_exact(3)).filter(|(a, b)| a != b).count();
    let allowed = (img.width * img.height) as usize / 200;
    if differing > allowed {
        let got = std::env::temp_dir().join(format!("{name}_got.png"));
        img.save(&got).unwrap();
        panic!("{name}: {differing} pixels differ (allowed {allowed}); got {}", got.display());
    }
}

#[test]
fn golden_scene() {
    let net = Network::from_file(Path::new("../scenarios/maps/town01/town01.net.xml")).unwrap();
    let map = RenderMap::build(&net);
    let lane = net.lane_by_id("W2C_1").unwrap();
    let ego_pose = net.lane_position(lane, net.lanes[lane].shape.length() - 30.0);
    let at = |f: f64, l: f64, dyaw: f64| Pose::new(ego_pose.local_to_world(f, l), ego_pose.yaw + dyaw);
    let ego = actor(0, ActorKind::Car, ego_pose, [200, 200, 200], false);
    let actors = [
        actor(1, ActorKind::Car, at(12.0, 0.0, 0.0), [180, 30, 30], true),
        actor(2, ActorKind::Bus, at(20.0, 3.2, 0.0), [30, 90, 170], false),
        actor(3, ActorKind::Pedestrian, at(33.0, -1.0, std::f64::consts::FRAC_PI_2), [20, 130, 220], false),
        actor(4, ActorKind::Cone, at(7.0, -1.7, 0.0), [255, 110, 20], false),
        actor(5, ActorKind::Truck, at(45.0, 9.0, std::f64::consts::PI), [230, 230, 230], false),
    ];
    let lights: Vec<TrafficLightView> = ["W2C_1", "W2C_2"]
        .iter()
        .map(|id| {
            let l = net.lane_by_id(id).unwrap();
            TrafficLightView {
                tl_id: "C".into(),
                lane_id: id.to_string(),
                stop_line: net.stop_line(l),
                lane_width_m: net.lanes[l].width_m,
                color: LightColor::Red,
            }
        })
        .collect();
    let signs = [SignView { kind: SignKind::Yield, pose: at(18.0, -6.0, std::f64::consts::PI) }];
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
    let mut img = Image::default();
    render_camera(&map, &frame, &CameraConfig { width: 160, height: 90, ..CameraConfig::front() }, &mut img)
        .unwrap();
    check("front_160x90", &img);
    render_camera(
        &map,
        &frame,
        &CameraConfig { width: 160, height: 90, supersample: 2, ..CameraConfig::chase() },
        &mut img,
    )
    .unwrap();
    check("chase_160x90_ss2", &img);
    render_bev(&map, &frame, &BevConfig::rl(), &mut img).unwrap();
    check("bev_128", &img);
    render_bev(&map, &frame, &BevConfig { size_px: 128, px_per_m: 8.0 }, &mut img).unwrap();
    check("bev_128_8ppm", &img);
}
