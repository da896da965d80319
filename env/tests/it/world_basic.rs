//! World tick pipeline on the fixture crossing: dynamics, lights, actors, triggers,
//! collisions, off-road, external actors and determinism.

use dh_env::drive::Control;
use dh_env::geom::{Pose, Vec2};
use dh_env::scenario::{ActorMotion, ResolvedScenario, Scenario};
use dh_env::view::{ActorKind, ContactClass, LightColor};
use dh_env::world::{ExternalSpawn, TickReport, World};
use dh_env::DT_S;
use sha2::{Digest, Sha256};
use std::path::PathBuf;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/world_fixtures").join(name)
}

fn load() -> ResolvedScenario {
    Scenario::load(fixture("cross.toml")).expect("fixture loads")
}

fn ctl(throttle: f64, brake: f64, steer: f64) -> Control {
    Control { throttle, brake, steer }
}

fn hash_report(h: &mut Sha256, r: &TickReport, w: &World) {
    h.update(r.tick.to_le_bytes());
    for v in [r.ego.pose.pos.x, r.ego.pose.pos.y, r.ego.pose.yaw, r.ego.speed_mps] {
        h.update(v.to_bits().to_le_bytes());
    }
    for a in w.actors() {
        h.update(a.id.to_le_bytes());
        for v in [a.pose.pos.x, a.pose.pos.y, a.pose.yaw, a.speed_mps] {
            h.update(v.to_bits().to_le_bytes());
        }
    }
    for (id, _) in &r.contacts {
        h.update(id.to_le_bytes());
    }
    h.update([r.on_road as u8]);
}

#[test]
fn resolves_fixture_geometry() {
    let s = load();
    assert_eq!(s.ego.start.pos, Vec2::new(20.0, 115.2));
    assert!(s.ego.start.yaw.abs() < 1e-9);
    assert!((s.ego.destination.x - 210.4).abs() < 1e-6);
    let l = s.route_length_m();
    assert!(l > 175.0 && l < 200.0, "route length {l}");
    assert_eq!(s.actors.len(), 4);
    assert_eq!(s.signs.len(), 1);
    assert_eq!(s.reference_duration_s(), 30.0);
}

#[test]
fn zero_control_keeps_ego_still_and_time_runs() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let start = w.ego().pose;
    let mut last = None;
    for _ in 0..100 {
        last = Some(w.tick(&Control::default()).unwrap());
    }
    let r = last.unwrap();
    assert_eq!(r.tick, 100);
    assert!((r.time_s - 100.0 * DT_S).abs() < 1e-12);
    assert_eq!(r.ego.pose, start);
    assert_eq!(r.ego.speed_mps, 0.0);
    assert!(r.on_road);
    assert!(r.contacts.is_empty());
}

#[test]
fn lights_follow_the_program() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let head = |w: &World, lane: &str| w.lights().iter().find(|l| l.lane_id == lane).unwrap().color;
    // 4 arms × 2 lanes, sorted by (light, lane).
    assert_eq!(w.lights().len(), 8);
    let (we0, ns0) = (head(&w, "W_in_0"), head(&w, "N_in_0"));
    assert_ne!(we0, ns0, "crossing directions start with different colours");
    // Phase durations 42 / 3 / 42 / 3: at t = 43 s the first phase group shows yellow, at t = 46 red.
    for _ in 0..(43.0 / DT_S) as usize {
        w.tick(&Control::default()).unwrap();
    }
    let first_green = if we0 == LightColor::Green { "W_in_0" } else { "N_in_0" };
    assert_eq!(head(&w, first_green), LightColor::Yellow);
    for _ in 0..(3.0 / DT_S) as usize {
        w.tick(&Control::default()).unwrap();
    }
    assert_eq!(head(&w, first_green), LightColor::Red);
    let stop = w.lights().iter().find(|l| l.lane_id == "W_in_0").unwrap().stop_line;
    assert!((stop.pos.x - 109.6).abs() < 1e-6 && (stop.pos.y - 115.2).abs() < 1e-6);
}

#[test]
fn scripted_car_moves_and_leaves() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let p0 = w.actors().iter().find(|a| a.id == 2).unwrap().pose;
    w.tick(&Control::default()).unwrap();
    let a = *w.actors().iter().find(|a| a.id == 2).unwrap();
    assert!((a.speed_mps - 8.0).abs() < 1e-12);
    assert!((p0.pos.dist(a.pose.pos) - 8.0 * DT_S).abs() < 1e-9);
    // Heading south (−90°).
    assert!((a.pose.yaw + std::f64::consts::FRAC_PI_2).abs() < 1e-6);
    // Path ≈ 240 m at 8 m/s: gone after 35 s.
    for _ in 0..700 {
        w.tick(&Control::default()).unwrap();
    }
    assert!(w.actors().iter().all(|a| a.id != 2));
    assert!(w.actors().windows(2).all(|p| p[0].id < p[1].id));
}

#[test]
fn lead_car_brakes_holds_and_resumes() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let lead = |w: &World| *w.actors().iter().find(|a| a.id == 3).unwrap();
    let mut saw_braking = false;
    let mut stopped_at = None;
    for k in 0..400 {
        w.tick(&Control::default()).unwrap();
        let a = lead(&w);
        saw_braking |= a.braking;
        if a.speed_mps == 0.0 && stopped_at.is_none() {
            stopped_at = Some(k);
        }
    }
    assert!(saw_braking);
    // Braking starts at s = 60 (10 s at 6 m/s) and lasts 1 s at 6 m/s².
    let k = stopped_at.expect("lead stops");
    // Triggered on tick 1 at 6 m/s: s = 60 after 200 ticks, then 20 ticks of braking.
    assert!((218..=222).contains(&k), "stopped at tick {k}");
    assert!(lead(&w).speed_mps > 5.0, "resumed after hold");
}

#[test]
fn throttle_reaches_lead_car_and_collides() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let mut hit = None;
    for _ in 0..600 {
        let r = w.tick(&ctl(1.0, 0.0, 0.0)).unwrap();
        if let Some(&(id, class)) = r.contacts.first() {
            hit = Some((id, class, r.time_s));
            break;
        }
    }
    let (id, class, t) = hit.expect("ego runs into something");
    assert_eq!((id, class), (3, ContactClass::Vehicle), "at t = {t}");
}

#[test]
fn pedestrian_trigger_fires_on_ego_distance() {
    let mut s = load();
    // Without the lead car the lane ahead is free up to the pedestrian.
    s.actors.retain(|a| a.name != "lead");
    let mut w = World::new(&s, 0).unwrap();
    let mut fired_at = None;
    for _ in 0..2000 {
        let c = if w.ego().speed_mps < 8.0 { ctl(0.6, 0.0, 0.0) } else { ctl(0.0, 0.0, 0.0) };
        let r = w.tick(&c).unwrap();
        if r.triggered.contains(&1) {
            fired_at = Some(r.ego.pose.pos);
            break;
        }
        assert!(r.contacts.is_empty(), "nothing to hit before the trigger");
        assert!(w.actors().iter().find(|a| a.id == 1).unwrap().speed_mps == 0.0, "waits for its trigger");
    }
    let p = fired_at.expect("pedestrian triggered");
    w.tick(&Control::default()).unwrap();
    assert!((w.actors().iter().find(|a| a.id == 1).unwrap().speed_mps - 1.5).abs() < 1e-12);
    assert!(p.dist(Vec2::new(180.0, 108.0)) <= 40.0 + 1.0);
    assert!(p.dist(Vec2::new(180.0, 108.0)) > 39.0);
}

#[test]
fn steering_off_the_road_is_detected() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let mut off = false;
    for _ in 0..200 {
        let r = w.tick(&ctl(0.5, 0.0, 1.0)).unwrap();
        if !r.on_road {
            off = true;
            // Steer > 0 is right = clockwise.
            assert!(r.ego.pose.yaw < 0.0);
            break;
        }
    }
    assert!(off);
}

#[test]
fn nan_control_is_an_error() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let e = w.tick(&ctl(f64::NAN, 0.0, 0.0)).unwrap_err().to_string();
    assert!(e.contains("control.throttle") && e.contains("NaN"), "{e}");
    assert_eq!(w.tick_count(), 0);
}

#[test]
fn external_actor_pose_and_contact() {
    let s = load();
    let mut w = World::new(&s, 0).unwrap();
    let start = w.ego().pose;
    let truck = ExternalSpawn {
        kind: ActorKind::Truck,
        length_m: 8.0,
        width_m: 2.5,
        height_m: 3.5,
        color: [1, 2, 3],
        pose: Pose::new(Vec2::new(60.0, 115.2), 0.0),
        speed_mps: 0.0,
    };
    let id = w.spawn_external(&truck).unwrap();
    assert_eq!(id, 5);
    let r = w.tick(&Control::default()).unwrap();
    assert!(r.contacts.is_empty());
    // Place it across the ego: a contact classed vehicle.
    w.set_external_pose(id, Pose::new(start.pos + Vec2::new(3.0, 0.0), 0.3), 2.0).unwrap();
    let r = w.tick(&Control::default()).unwrap();
    assert_eq!(r.contacts, vec![(id, ContactClass::Vehicle)]);
    assert!(w.set_external_pose(1, start, 0.0).is_err(), "scripted actors are not external");
    assert!(w.set_external_pose(id, Pose::new(Vec2::new(f64::NAN, 0.0), 0.0), 0.0).is_err());
    w.remove_actor(id).unwrap();
    let r = w.tick(&Control::default()).unwrap();
    assert!(r.contacts.is_empty());
    assert!(w.actors().iter().all(|a| a.id != id));
}

#[test]
fn cone_contact_is_static_and_actor_overlaps_are_ignored() {
    let mut s = load();
    // Put the cone 6 m ahead of the ego on its lane.
    let ahead = Pose::new(s.ego.start.pos + Vec2::new(6.0, 0.0), 0.0);
    let cone = s.actors.iter_mut().find(|a| a.kind == ActorKind::Cone).unwrap();
    cone.motion = ActorMotion::Static { pose: ahead };
    let mut w = World::new(&s, 0).unwrap();
    // An external car parked on the cone: actor–actor overlaps are not ego contacts.
    let car = ExternalSpawn {
        kind: ActorKind::Car,
        length_m: 4.5,
        width_m: 1.9,
        height_m: 1.5,
        color: [0, 0, 0],
        pose: Pose::new(ahead.pos + Vec2::new(3.0, 0.0), 0.0),
        speed_mps: 0.0,
    };
    w.spawn_external(&car).unwrap();
    assert!(w.tick(&Control::default()).unwrap().contacts.is_empty());
    let mut first = None;
    for _ in 0..100 {
        let r = w.tick(&ctl(0.5, 0.0, 0.0)).unwrap();
        if !r.contacts.is_empty() {
            first = Some(r.contacts);
            break;
        }
    }
    // Ego front (2.45 m) meets the cone (0.2 m) after ~3.35 m of travel.
    assert_eq!(first.expect("ego hits the cone"), vec![(4, ContactClass::Static)]);
}

#[test]
fn same_controls_same_trajectory() {
    let s = load();
    let run = |seed: u64| {
        let mut w = World::new(&s, seed).unwrap();
        let mut h = Sha256::new();
        for k in 0..800u32 {
            let steer = ((k as f64) * 0.013).sin() * 0.3;
            let c = if k % 97 < 60 { ctl(0.5, 0.0, steer) } else { ctl(0.0, 0.4, steer) };
            let r = w.tick(&c).unwrap();
            hash_report(&mut h, &r, &w);
        }
        h.finalize().to_vec()
    };
    assert_eq!(run(7), run(7));
}

#[test]
fn running_the_red_light_is_reported() {
    // The fixture's first phase gives W_in green or red; drive through and compare with the
    // head's colour at the crossing tick.
    let s = load();
    let mut s2 = s.clone();
    s2.actors.clear();
    let mut w = World::new(&s2, 0).unwrap();
    let mut crossing = None;
    for _ in 0..600 {
        let before = w.ego().pose.pos.x;
        let r = w.tick(&ctl(0.5, 0.0, 0.0)).unwrap();
        if before < 109.6 && r.ego.pose.pos.x >= 109.6 {
            let head = w.lights().iter().find(|l| l.lane_id == "W_in_0").unwrap().color;
            crossing = Some((head, r.ran_red_light));
        } else {
            assert!(!r.ran_red_light);
        }
    }
    let (color, ran) = crossing.expect("ego crosses the stop line");
    assert_eq!(ran, color == LightColor::Red, "colour {color:?}");
    // Stop before the line, wait for red, then cross: reported on the crossing tick only.
    let mut w = World::new(&s2, 0).unwrap();
    let red = |w: &World| w.lights().iter().find(|l| l.lane_id == "W_in_0").unwrap().color == LightColor::Red;
    while w.ego().pose.pos.x < 95.0 {
        w.tick(&ctl(0.4, 0.0, 0.0)).unwrap();
    }
    while w.ego().speed_mps > 0.0 || !red(&w) {
        assert!(!w.tick(&ctl(0.0, 1.0, 0.0)).unwrap().ran_red_light);
    }
    assert!(w.ego().pose.pos.x < 109.6);
    let mut reports = Vec::new();
    while w.ego().pose.pos.x < 115.0 {
        let before = w.ego().pose.pos.x;
        let r = w.tick(&ctl(1.0, 0.0, 0.0)).unwrap();
        assert!(red(&w));
        if r.ran_red_light {
            reports.push((before, r.ego.pose.pos.x));
        }
    }
    assert_eq!(reports.len(), 1);
    assert!(reports[0].0 < 109.6 && reports[0].1 >= 109.6, "{reports:?}");
}

#[test]
fn core_types_are_send() {
    fn send<T: Send>() {}
    fn send_sync<T: Send + Sync>() {}
    send::<World>();
    send_sync::<ResolvedScenario>();
    send_sync::<TickReport>();
}
