//! Places known actors and signals in front of the camera and checks, through
//! `project_actors` and pixel colours, that each shows where it should.

use dh_env::geom::{Pose, Vec2};
use dh_env::map::Network;
use dh_env::render::{
    project_actors, render_bev, render_camera, BevConfig, CameraConfig, FrameInput, Image, RenderMap,
    Renderer,
};
use dh_env::view::{ActorKind, ActorView, LightColor, TrafficLightView};
use std::path::Path;
use std::sync::OnceLock;

fn world() -> &'static (Network, RenderMap) {
    static W: OnceLock<(Network, RenderMap)> = OnceLock::new();
    W.get_or_init(|| {
        let net =
            Network::from_file(Path::new("../scenarios/maps/town01/town01.net.xml")).expect("town01 net");
        let map = RenderMap::build(&net);
        (net, map)
    })
}

/// Ego on the long straight C→T, 100 m after the junction, heading east.
fn ego_pose() -> Pose {
    let (net, _) = world();
    let lane = net.lane_by_id("C2T_1").expect("lane C2T_1");
    net.lane_position(lane, 100.0)
}

fn actor(id: u32, kind: ActorKind, fwd: f64, left: f64) -> ActorView {
    let e = ego_pose();
    ActorView::at_rest(id, kind, Pose::new(e.local_to_world(fwd, left), e.yaw), [40, 90, 200])
}

fn ego() -> ActorView {
    crate::common::grey_ego(ego_pose())
}

fn frame<'a>(
    ego: &'a ActorView,
    actors: &'a [ActorView],
    lights: &'a [TrafficLightView],
    route: &'a [Vec2],
) -> FrameInput<'a> {
    FrameInput { ego, actors, lights, signs: &[], route_points: route, ambience: Default::default() }
}

#[test]
fn actors_ahead_project_where_expected() {
    let (_, map) = world();
    let e = ego();
    let actors = [
        actor(1, ActorKind::Car, 20.0, 0.0),
        actor(2, ActorKind::Pedestrian, 15.0, 4.0),
        actor(3, ActorKind::Cyclist, 25.0, -4.0),
    ];
    let cfg = CameraConfig::front();
    let p = project_actors(map, &frame(&e, &actors, &[], &[]), &cfg).unwrap();
    let get = |id| p.iter().find(|a| a.id == id).unwrap_or_else(|| panic!("actor {id} not projected: {p:?}"));
    let car = get(1);
    assert!((car.center_px[0] - 400.0).abs() < 5.0, "{car:?}");
    assert!(car.visible_fraction > 0.95 && car.pixel_count > 500, "{car:?}");
    assert!((car.distance_m - 20.0).abs() < 1e-9);
    let ped = get(2);
    assert!(ped.center_px[0] < 330.0 && ped.visible_fraction > 0.9 && ped.pixel_count > 100, "{ped:?}");
    let cyc = get(3);
    assert!(cyc.center_px[0] > 440.0 && cyc.visible_fraction > 0.9, "{cyc:?}");
    // The box contains the centre.
    for a in &p {
        assert!(a.bbox_px[0] <= a.center_px[0] && a.center_px[0] <= a.bbox_px[2], "{a:?}");
        assert!(a.bbox_px[1] <= a.center_px[1] && a.center_px[1] <= a.bbox_px[3], "{a:?}");
    }
}

#[test]
fn occluded_actor_has_low_visible_fraction() {
    let (_, map) = world();
    let e = ego();
    let actors = [actor(1, ActorKind::Bus, 15.0, 0.0), actor(2, ActorKind::Car, 35.0, 0.0)];
    let p = project_actors(map, &frame(&e, &actors, &[], &[]), &CameraConfig::front()).unwrap();
    let bus = p.iter().find(|a| a.id == 1).unwrap();
    assert!(bus.visible_fraction > 0.95);
    if let Some(car) = p.iter().find(|a| a.id == 2) {
        assert!(car.visible_fraction < 0.2, "{car:?}");
    }
}

#[test]
fn border_cut_pixels_count_as_hidden() {
    // A car whose centre sits on the image's left border shows about half its silhouette: its
    // visible fraction says so, and its pixel count is that of the whole car.
    let (_, map) = world();
    let e = ego();
    let cfg = CameraConfig::front();
    let whole =
        project_actors(map, &frame(&e, &[actor(1, ActorKind::Car, 15.0, 0.0)], &[], &[]), &cfg).unwrap();
    let whole = whole[0];
    let mut left = 0.0;
    let cut = loop {
        left += 0.1;
        assert!(left < 30.0, "no offset puts the car on the border");
        let p =
            project_actors(map, &frame(&e, &[actor(1, ActorKind::Car, 15.0, left)], &[], &[]), &cfg).unwrap();
        if p[0].center_px[0] <= 0.0 {
            break p[0];
        }
    };
    assert!(whole.visible_fraction > 0.95, "{whole:?}");
    // (Seen from the side at the frame's edge, the car shows more than its back: the share is an
    // estimate from projected areas, not exactly a half.)
    assert!((0.25..0.7).contains(&cut.visible_fraction), "{cut:?}");
    // The whole silhouette is counted: more pixels than the in-image box could hold.
    let [x0, y0, x1, y1] = cut.bbox_px;
    assert!(cut.pixel_count as f32 > (x1 - x0) * (y1 - y0), "{cut:?}");
}

#[test]
fn actor_behind_camera_is_not_drawn() {
    let (_, map) = world();
    let e = ego();
    let behind = [actor(1, ActorKind::Truck, -15.0, 0.0)];
    let cfg = CameraConfig { width: 320, height: 180, ..CameraConfig::front() };
    let p = project_actors(map, &frame(&e, &behind, &[], &[]), &cfg).unwrap();
    assert!(p.is_empty(), "{p:?}");
    let (mut a, mut b) = (Image::default(), Image::default());
    render_camera(map, &frame(&e, &behind, &[], &[]), &cfg, &mut a).unwrap();
    render_camera(map, &frame(&e, &[], &[], &[]), &cfg, &mut b).unwrap();
    assert_eq!(a, b);
    // ...while the same truck ahead changes the picture.
    let ahead = [actor(1, ActorKind::Truck, 15.0, 0.0)];
    render_camera(map, &frame(&e, &ahead, &[], &[]), &cfg, &mut a).unwrap();
    assert_ne!(a, b);
}

fn lamp_pixels(img: &Image) -> (usize, usize, usize) {
    let (mut red, mut yellow, mut green) = (0, 0, 0);
    for px in img.data.chunks_exact(3) {
        let (r, g, b) = (px[0] as i32, px[1] as i32, px[2] as i32);
        if r > 230 && g < 60 && b < 60 {
            red += 1;
        }
        if r > 230 && g > 180 && b < 40 {
            yellow += 1;
        }
        if g > 230 && r < 60 && b < 120 {
            green += 1;
        }
    }
    (red, yellow, green)
}

#[test]
fn traffic_light_colour_reads_at_30_m() {
    let (_, map) = world();
    let e = ego();
    let ep = ego_pose();
    // Unknown lane: the head hangs 15 m past the stop line, so 15 + 15 = 30 m from the ego.
    let light = |color| TrafficLightView {
        tl_id: "t".into(),
        lane_id: "no-such-lane".into(),
        stop_line: Pose::new(ep.local_to_world(15.0, 0.0), ep.yaw),
        lane_width_m: 3.2,
        color,
    };
    let mut img = Image::default();
    for (color, want) in [(LightColor::Red, 0), (LightColor::Yellow, 1), (LightColor::Green, 2)] {
        render_camera(map, &frame(&e, &[], &[light(color)], &[]), &CameraConfig::front(), &mut img).unwrap();
        let counts = lamp_pixels(&img);
        let arr = [counts.0, counts.1, counts.2];
        assert!(arr[want] >= 12, "{color:?}: {counts:?}");
        for (k, n) in arr.iter().enumerate() {
            if k != want {
                assert_eq!(*n, 0, "{color:?}: {counts:?}");
            }
        }
    }
}

#[test]
fn a_cross_street_signal_seen_side_on_shows_no_lit_lamp() {
    let (_, map) = world();
    let e = ego();
    let ep = ego_pose();
    // A head 25 m ahead and 8 m to the right whose lamps face left, across the ego's path (it
    // controls the cross street): the ego sees its face 72° off axis, so the visor hides it.
    let side_yaw = ep.yaw - std::f64::consts::FRAC_PI_2;
    let head = ep.local_to_world(25.0, -8.0);
    let stop_line = Pose::new(head - Vec2::from_angle(side_yaw) * 15.0, side_yaw);
    let light = TrafficLightView {
        tl_id: "t".into(),
        lane_id: "no-such-lane".into(),
        stop_line,
        lane_width_m: 3.2,
        color: LightColor::Red,
    };
    let mut img = Image::default();
    render_camera(map, &frame(&e, &[], &[light], &[]), &CameraConfig::front(), &mut img).unwrap();
    assert_eq!(lamp_pixels(&img), (0, 0, 0));
}

#[test]
fn bev_draws_route_and_ego_as_the_protocol_says() {
    let (_, map) = world();
    let e = ego();
    let ep = ego_pose();
    let route: Vec<Vec2> =
        [5.0, 10.0, 15.0, 20.0, 30.0, 40.0].iter().map(|d| ep.local_to_world(*d, 0.0)).collect();
    let mut img = Image::default();
    render_bev(map, &frame(&e, &[], &[], &route), &BevConfig::default(), &mut img).unwrap();
    assert_eq!((img.width, img.height), (800, 800));
    // Ego disc: (255, 230, 80), radius 6 with a 2 px (20, 20, 20) outline.
    assert_eq!(img.pixel(400, 400).unwrap(), [255, 230, 80]);
    assert_eq!(img.pixel(400 + 5, 400).unwrap(), [20, 20, 20]);
    // Route line (255, 90, 90), 3 px wide, from the ego centre: at 1.25 m and 7.5 m ahead.
    assert_eq!(img.pixel(400, 400 - 10).unwrap(), [255, 90, 90]);
    assert_eq!(img.pixel(400, 400 - 60).unwrap(), [255, 90, 90]);
    assert_eq!(img.pixel(400 + 3, 400 - 60).unwrap(), [100, 100, 106]);
    // Every vertex: white dot with a 2 px outline, radius 4 (5 m, y = 360) …
    assert_eq!(img.pixel(400, 360).unwrap(), [255, 255, 255]);
    assert_eq!(img.pixel(400 + 3, 360).unwrap(), [255, 90, 90]);
    assert_eq!(img.pixel(400 + 5, 360).unwrap(), [100, 100, 106]);
    // … and radius 5 on the last one (40 m, y = 80).
    assert_eq!(img.pixel(400, 80).unwrap(), [255, 255, 255]);
    assert_eq!(img.pixel(400 + 4, 80).unwrap(), [255, 90, 90]);
}

#[test]
fn rendering_is_deterministic_regardless_of_history() {
    let (_, map) = world();
    let e = ego();
    let actors = [actor(1, ActorKind::Car, 12.0, 0.0), actor(2, ActorKind::Pedestrian, 9.0, -3.0)];
    let f = frame(&e, &actors, &[], &[]);
    let cfg = CameraConfig { supersample: 2, width: 200, height: 112, ..CameraConfig::front() };
    let mut r1 = Renderer::new();
    let mut r2 = Renderer::new();
    let (mut a, mut b, mut junk) = (Image::default(), Image::default(), Image::default());
    r1.render_camera(map, &f, &cfg, &mut a).unwrap();
    r2.render_camera(map, &frame(&e, &[], &[], &[]), &CameraConfig::chase(), &mut junk).unwrap();
    r2.render_bev(map, &f, &BevConfig::default(), &mut junk).unwrap();
    r2.render_camera(map, &f, &cfg, &mut b).unwrap();
    assert_eq!(a, b);
}

#[test]
fn invalid_configs_are_errors() {
    let (_, map) = world();
    let e = ego();
    let mut img = Image::default();
    let bad = CameraConfig { fov_deg: 0.0, ..CameraConfig::front() };
    let err = render_camera(map, &frame(&e, &[], &[], &[]), &bad, &mut img).unwrap_err();
    assert!(err.to_string().contains("fov_deg"), "{err}");
    let bad = BevConfig { px_per_m: f64::NAN, ..BevConfig::default() };
    assert!(render_bev(map, &frame(&e, &[], &[], &[]), &bad, &mut img).is_err());
    let mut nan_ego = e;
    nan_ego.pose.yaw = f64::NAN;
    assert!(render_camera(map, &frame(&nan_ego, &[], &[], &[]), &CameraConfig::front(), &mut img).is_err());
}

#[test]
fn surround_rig_sees_an_actor_in_the_back_camera_only() {
    let (_, map) = world();
    let e = ego();
    let behind = [actor(1, ActorKind::Car, -15.0, 0.0)];
    for (name, cfg) in CameraConfig::surround_rig() {
        let p = project_actors(map, &frame(&e, &behind, &[], &[]), &cfg).unwrap();
        assert_eq!(!p.is_empty(), name == "CAM_BACK", "{name}: {p:?}");
    }
}

#[test]
fn gif_writer_writes_frames_and_rejects_size_changes() {
    let dir = std::env::temp_dir().join(format!("dh_render_gif_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("v.gif");
    let mut w = dh_env::render::GifWriter::create(&path, 10).unwrap();
    let mut img = Image::new(32, 18);
    w.push(&img).unwrap();
    img.data.iter_mut().for_each(|v| *v = 200);
    w.push(&img).unwrap();
    assert!(w.push(&Image::new(16, 16)).is_err());
    assert_eq!(w.frames(), 2);
    drop(w);
    assert!(std::fs::metadata(&path).unwrap().len() > 0);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn empty_network_renders_sky_ground_and_actors() {
    let map = RenderMap::from_parts(&[], &[], &[]);
    let e = ego();
    let actors = [actor(1, ActorKind::Car, 10.0, 0.0)];
    let mut img = Image::default();
    let cfg = CameraConfig { width: 160, height: 90, ..CameraConfig::front() };
    render_camera(&map, &frame(&e, &actors, &[], &[]), &cfg, &mut img).unwrap();
    let p = project_actors(&map, &frame(&e, &actors, &[], &[]), &cfg).unwrap();
    assert_eq!(p.len(), 1);
    render_bev(&map, &frame(&e, &actors, &[], &[]), &BevConfig::rl(), &mut img).unwrap();
    assert_eq!(img.pixel(64, 64).unwrap(), [255, 230, 80]);
}

#[test]
fn real_net_builds_when_present() {
    let path = Path::new("../../shared/official/Close_Loop_Evaluation/Carla_Simulation/Co-Simulation/Sumo/tongji/tongji.net.xml");
    if !path.exists() {
        eprintln!("skipping: {} not present", path.display());
        return;
    }
    let net = Network::from_file(path).unwrap();
    // Its build time (~70 ms in release) is a benchmark figure, not asserted: no test here
    // decides by the clock.
    let map = RenderMap::build(&net);
    let (tris, segs, props) = map.stats();
    assert!(tris > 10_000 && segs > 5_000 && props > 0, "{:?}", map.stats());
}

/// Lit turn indicators (SUMO's blinker bits) show as amber lamps on the signalling side.
#[test]
fn lit_indicators_show_on_their_side() {
    let (_, map) = world();
    let e = ego();
    let cfg = CameraConfig::front();
    let render = |blinkers: u8| {
        let car = ActorView { blinkers, ..actor(1, ActorKind::Car, 12.0, 0.0) };
        let mut img = Image::default();
        render_camera(map, &frame(&e, &[car], &[], &[]), &cfg, &mut img).unwrap();
        img
    };
    let base = render(0);
    // Amber pixels that the same car without indicators does not have, per image half.
    let amber = |blinkers: u8| {
        let img = render(blinkers);
        let (mut left, mut right) = (0, 0);
        for y in 0..img.height {
            for x in 0..img.width {
                let [r, g, b] = img.pixel(x, y).unwrap();
                if img.pixel(x, y) != base.pixel(x, y) && r > 220 && (120..=210).contains(&g) && b < 80 {
                    if x < img.width / 2 {
                        left += 1;
                    } else {
                        right += 1;
                    }
                }
            }
        }
        (left, right)
    };
    assert_eq!(amber(0), (0, 0));
    let (l, r) = amber(dh_env::view::BLINKER_LEFT);
    assert!(l > 4 && r == 0, "left indicator: {l} left / {r} right amber pixels");
    let (l, r) = amber(dh_env::view::BLINKER_RIGHT);
    assert!(r > 4 && l == 0, "right indicator: {l} left / {r} right amber pixels");
    let (l, r) = amber(dh_env::view::BLINKER_LEFT | dh_env::view::BLINKER_RIGHT);
    assert!(l > 4 && r > 4, "hazard lights: {l} / {r}");
}

/// Pixels of the bright beacon red and blue in `img` within `bbox`: (red count, red mean x,
/// blue count, blue mean x).
fn beacon_pixels(img: &Image, bbox: [f32; 4]) -> (usize, f32, usize, f32) {
    let (mut nr, mut xr, mut nb, mut xb) = (0usize, 0.0f32, 0usize, 0.0f32);
    for y in bbox[1] as u32..(bbox[3] as u32).min(img.height) {
        for x in bbox[0] as u32..(bbox[2] as u32).min(img.width) {
            let [r, g, b] = img.pixel(x, y).unwrap();
            if r >= 215 && g <= 60 && b <= 60 {
                nr += 1;
                xr += x as f32;
            } else if b >= 215 && r <= 70 && (70..=140).contains(&g) {
                nb += 1;
                xb += x as f32;
            }
        }
    }
    (nr, xr / nr.max(1) as f32, nb, xb / nb.max(1) as f32)
}

/// An emergency vehicle's light bar shows its bright half in red or blue, the two swapping
/// every 5 ticks (2 Hz), on the vehicle's left (red) and right (blue); an unflagged vehicle of
/// the same colour shows neither, and a frame is the same bytes for the same tick.
#[test]
fn emergency_light_bar_flashes_red_and_blue_on_flagged_vehicles_only() {
    let (_, map) = world();
    let e = ego();
    let cfg = CameraConfig::front();
    let ambience = |tick: u64, night: bool| dh_env::render::Ambience {
        conditions: dh_env::conditions::Conditions {
            time_of_day: if night {
                dh_env::conditions::TimeOfDay::Night
            } else {
                dh_env::conditions::TimeOfDay::Noon
            },
            ..Default::default()
        },
        seed: 7,
        tick,
    };
    let vehicles = [
        (ActorKind::Car, 14.0, 0.0),
        (ActorKind::Truck, 16.0, 0.0),
        (ActorKind::Bus, 18.0, 0.0),
        // Facing the camera: its left is the image's right.
        (ActorKind::Truck, 30.0, 3.5),
    ];
    for (k, (kind, fwd, left)) in vehicles.into_iter().enumerate() {
        let facing = k == 3;
        let mut v = actor(1, kind, fwd, left);
        v.color = [245, 245, 245];
        if facing {
            v.pose.yaw += std::f64::consts::PI;
        }
        let render = |beacon: bool, tick: u64, night: bool| {
            let actors = [ActorView { beacon, ..v }];
            let f = FrameInput { ambience: ambience(tick, night), ..frame(&e, &actors, &[], &[]) };
            let mut img = Image::default();
            render_camera(map, &f, &cfg, &mut img).unwrap();
            let p = project_actors(map, &f, &cfg).unwrap();
            (img, p[0].bbox_px)
        };
        for night in [false, true] {
            let (plain, bbox) = render(false, 0, night);
            let (nr, _, nb, _) = beacon_pixels(&plain, bbox);
            assert_eq!((nr, nb), (0, 0), "{kind:?} #{k} without beacons (night {night})");
            let (red, bbox) = render(true, 0, night);
            let (nr, xr, nb, _) = beacon_pixels(&red, bbox);
            assert!(nr >= 6 && nb == 0, "{kind:?} #{k} tick 0 (night {night}): {nr} red, {nb} blue");
            let (blue, bbox) = render(true, 5, night);
            let (nr2, _, nb2, xb) = beacon_pixels(&blue, bbox);
            assert!(nb2 >= 6 && nr2 == 0, "{kind:?} #{k} tick 5 (night {night}): {nr2} red, {nb2} blue");
            // Red on the vehicle's left: the image's left seen from behind, its right head-on.
            assert_eq!(xr > xb, facing, "{kind:?} #{k}: red at x {xr}, blue at x {xb}");
            // The phase is a pure function of the tick: the same frame within a half period
            // and one period later, and the same bytes on a fresh renderer.
            assert_eq!(render(true, 4, night).0.data, red.data);
            assert_eq!(render(true, 10, night).0.data, red.data);
            assert_eq!(render(true, 15, night).0.data, blue.data);
            assert_ne!(red.data, blue.data);
            let actors = [ActorView { beacon: true, ..v }];
            let f = FrameInput { ambience: ambience(0, night), ..frame(&e, &actors, &[], &[]) };
            let mut fresh = Image::default();
            Renderer::new().render_camera(map, &f, &cfg, &mut fresh).unwrap();
            assert_eq!(fresh.data, red.data);
        }
    }
}

/// The BEV marks an emergency vehicle with a red and a blue half, the bright one swapping
/// with the camera's; an unflagged one has neither colour.
#[test]
fn emergency_mark_on_the_bev() {
    let (_, map) = world();
    let e = ego();
    let mut v = actor(1, ActorKind::Truck, 12.0, 0.0);
    v.color = [245, 245, 245];
    let count = |beacon: bool, tick: u64| {
        let actors = [ActorView { beacon, ..v }];
        let f = FrameInput {
            ambience: dh_env::render::Ambience { tick, ..Default::default() },
            ..frame(&e, &actors, &[], &[])
        };
        let mut img = Image::default();
        render_bev(map, &f, &BevConfig::rl(), &mut img).unwrap();
        let n = img.width as f32;
        beacon_pixels(&img, [0.0, 0.0, n, img.height as f32])
    };
    let (nr, _, nb, _) = count(false, 0);
    assert_eq!((nr, nb), (0, 0));
    let (nr, _, nb, _) = count(true, 0);
    assert!(nr > 0 && nb == 0, "{nr} red, {nb} blue");
    let (nr, _, nb, _) = count(true, 5);
    assert!(nb > 0 && nr == 0, "{nr} red, {nb} blue");
}
