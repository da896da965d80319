//! The scenario-format features of issue 9 on town01: time-to-conflict and chained triggers,
//! lane changes (cut-ins), traffic-light overrides and per-vehicle traffic speeds — parsing,
//! validation errors (file, TOML path, value) and runtime behaviour, and determinism.

use crate::common;

use common::{cruise, Town01Scenarios};
use dh_env::drive::Control;
use dh_env::scenario::{ActorMotion, ResolvedScenario};
use dh_env::view::LightColor;
use dh_env::world::idm::IdmTraffic;
use dh_env::world::World;
use sha2::{Digest, Sha256};

const FILES: Town01Scenarios = Town01Scenarios { id: "features", category: "01_pedestrian" };

fn load(tag: &str, speed: f64, body: &str) -> ResolvedScenario {
    FILES.load(tag, speed, body)
}

fn load_err(tag: &str, body: &str) -> String {
    let (p, e) = FILES.load_err(tag, body);
    assert!(e.contains(&p.display().to_string()), "error names the file: {e}");
    e
}

/// Runs until actor `id` is triggered; returns (time, ego x) at that tick.
fn run_until_triggered(w: &mut World, id: u32, v: f64, max_ticks: usize) -> Option<(f64, f64)> {
    for _ in 0..max_ticks {
        let c = cruise(w, v);
        let r = w.tick(&c).unwrap();
        if r.triggered.contains(&id) {
            return Some((r.time_s, r.ego.pose.pos.x));
        }
    }
    None
}

const WALKER_ETA: &str = r#"
[[actors]]
name = "walker"
kind = "pedestrian"
speed_mps = 1.5
waypoints = [{ x = 200.0, y = -9.0 }, { x = 200.0, y = 3.0 }]
start = { ego_eta_s = 3.0, of = [200.0, -4.8] }
"#;

#[test]
fn ego_eta_trigger_fires_three_seconds_ahead_at_any_speed() {
    for v in [5.0, 10.0, 14.0] {
        let s = load(&format!("eta_{v}"), v, WALKER_ETA);
        let mut w = World::new(&s, 0).unwrap();
        let (_, x) = run_until_triggered(&mut w, 1, v, 2000).expect("fires");
        // The ego centre is ~3 s · v before x = 200 (within one tick of travel and the speed
        // controller's ripple).
        let expected = 200.0 - 3.0 * v;
        assert!((x - expected).abs() < 0.1 * v + 0.3, "v = {v}: fired at x = {x}, expected ≈ {expected}");
    }
    // A standing ego counts as moving at 0.5 m/s: the trigger waits until it is 1.5 m away.
    let s = load("eta_stand", 0.0, WALKER_ETA);
    let mut w = World::new(&s, 0).unwrap();
    for _ in 0..200 {
        assert!(w.tick(&Control::default()).unwrap().triggered.is_empty());
    }
}

#[test]
fn ego_eta_point_behind_the_start_is_rejected() {
    let e = load_err(
        "eta_behind",
        r#"
[[actors]]
kind = "pedestrian"
waypoints = [{ x = 20.0, y = -9.0 }, { x = 20.0, y = 3.0 }]
start = { ego_eta_s = 3.0, of = [5.0, -4.8] }
"#,
    );
    assert!(e.contains("actors[0].start.of") && e.contains("does not project onto the ego route"), "{e}");
}

#[test]
fn ego_eta_errors_name_field_and_value() {
    let e = load_err(
        "eta_far",
        r#"
[[actors]]
kind = "pedestrian"
waypoints = [{ x = 200.0, y = -9.0 }, { x = 200.0, y = 3.0 }]
start = { ego_eta_s = 3.0, of = [200.0, 80.0] }
"#,
    );
    assert!(e.contains("actors[0].start.of") && e.contains("(200.00, 80.00)"), "{e}");
    let e = load_err(
        "eta_beyond",
        r#"
[[actors]]
kind = "pedestrian"
waypoints = [{ x = 200.0, y = -9.0 }, { x = 200.0, y = 3.0 }]
start = { ego_eta_s = 3.0, of = { lane = "T2E_1", s = 30.0 } }
"#,
    );
    assert!(e.contains("actors[0].start.of") && e.contains("does not project"), "{e}");
    let e = load_err(
        "eta_negative",
        r#"
[[actors]]
kind = "pedestrian"
waypoints = [{ x = 200.0, y = -9.0 }, { x = 200.0, y = 3.0 }]
start = { ego_eta_s = -1.0, of = [200.0, -4.8] }
"#,
    );
    assert!(e.contains("actors[0].start.ego_eta_s") && e.contains("-1"), "{e}");
    let e = load_err(
        "eta_and_time",
        r#"
[[actors]]
kind = "pedestrian"
waypoints = [{ x = 200.0, y = -9.0 }, { x = 200.0, y = 3.0 }]
start = { ego_eta_s = 3.0, time_s = 1.0 }
"#,
    );
    assert!(e.contains("actors[0].start") && e.contains("exactly one"), "{e}");
}

const CHAIN: &str = r#"
[[actors]]
name = "lead"
kind = "car"
route = { lanes = ["C2T_1"], start_s = 60.0, end_s = 200.0 }
speed_mps = 10.0
start = { time_s = 1.0 }
brake = { after_s = 2.0, decel_mps2 = 5.0, to_speed_mps = 5.0 }

[[actors]]
name = "follows start"
kind = "pedestrian"
waypoints = [{ x = 300.0, y = -9.0 }, { x = 300.0, y = -8.5 }]
start = { after = "lead", delay_s = 1.5 }

[[actors]]
name = "follows brake"
kind = "pedestrian"
waypoints = [{ x = 302.0, y = -9.0 }, { x = 302.0, y = -8.5 }]
start = { after = "lead", event = "brake", delay_s = 0.5 }

[[actors]]
name = "follows end"
kind = "pedestrian"
waypoints = [{ x = 304.0, y = -9.0 }, { x = 304.0, y = -8.5 }]
start = { after = "lead", event = "end" }

[[actors]]
name = "chained twice"
kind = "pedestrian"
waypoints = [{ x = 306.0, y = -9.0 }, { x = 306.0, y = -8.5 }]
start = { after = "follows start", delay_s = 0.25 }
"#;

#[test]
fn chained_triggers_fire_after_the_event_plus_delay() {
    let s = load("chain", 0.0, CHAIN);
    let mut w = World::new(&s, 0).unwrap();
    let mut fired = [f64::NAN; 5];
    let mut lead_end = f64::NAN;
    for _ in 0..1000 {
        let r = w.tick(&Control::default()).unwrap();
        for &id in &r.triggered {
            fired[id as usize - 1] = r.time_s;
        }
        let lead = w.actors().iter().find(|a| a.id == 1).unwrap();
        if lead_end.is_nan() && lead.speed_mps == 0.0 && !fired[0].is_nan() && r.time_s > 3.0 {
            lead_end = r.time_s;
        }
    }
    let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
    assert!(close(fired[0], 1.0), "{fired:?}");
    assert!(close(fired[1], 2.5), "{fired:?}");
    assert!(close(fired[2], 3.5), "brake at 1 + 2 s, +0.5: {fired:?}");
    assert!(close(fired[3], lead_end), "at the lead's path end {lead_end}: {fired:?}");
    assert!(close(fired[4], 2.75), "{fired:?}");
    // The estimate of the scenario duration follows the chain: the end-chained walker starts
    // after the lead's whole trip.
    let starts = s.estimated_start_times_s();
    assert!(close(starts[1], 2.5) && close(starts[2], 3.5) && close(starts[4], 2.75), "{starts:?}");
    assert!(starts[3] > 14.0, "{starts:?}");
}

#[test]
fn chain_errors_name_the_field() {
    let e = load_err(
        "chain_unknown",
        r#"
[[actors]]
name = "a"
kind = "pedestrian"
waypoints = [{ x = 300.0, y = -9.0 }, { x = 300.0, y = -8.5 }]
start = { after = "nobody" }
"#,
    );
    assert!(e.contains("actors[0].start.after") && e.contains("\"nobody\""), "{e}");
    let e = load_err(
        "chain_cycle",
        r#"
[[actors]]
name = "a"
kind = "pedestrian"
waypoints = [{ x = 300.0, y = -9.0 }, { x = 300.0, y = -8.5 }]
start = { after = "b" }

[[actors]]
name = "b"
kind = "pedestrian"
waypoints = [{ x = 302.0, y = -9.0 }, { x = 302.0, y = -8.5 }]
start = { after = "a", delay_s = 1.0 }
"#,
    );
    assert!(e.contains("actors[0].start.after") && e.contains("cycle"), "{e}");
    let e = load_err(
        "chain_brake_without_brake",
        r#"
[[actors]]
name = "a"
kind = "pedestrian"
waypoints = [{ x = 300.0, y = -9.0 }, { x = 300.0, y = -8.5 }]

[[actors]]
name = "b"
kind = "pedestrian"
waypoints = [{ x = 302.0, y = -9.0 }, { x = 302.0, y = -8.5 }]
start = { after = "a", event = "brake" }
"#,
    );
    assert!(e.contains("actors[1].start.after") && e.contains("no `brake`"), "{e}");
    let e = load_err(
        "chain_bad_event",
        r#"
[[actors]]
name = "a"
kind = "pedestrian"
waypoints = [{ x = 300.0, y = -9.0 }, { x = 300.0, y = -8.5 }]
start = { after = "a", event = "stop" }
"#,
    );
    assert!(e.contains("actors[0].start.event") && e.contains("stop"), "{e}");
}

const CUT_IN: &str = r#"
[[actors]]
name = "cutter"
kind = "car"
route = { lanes = ["C2T_2", "T2E_1"], start_s = 40.0 }
speed_mps = 10.0
lane_changes = [{ at_s = 40.0, to_lane = "C2T_1", length_m = 20.0 }]
"#;

#[test]
fn lane_change_moves_smoothly_into_the_neighbour_lane_and_stays_there() {
    let s = load("cut_in", 0.0, CUT_IN);
    let ActorMotion::Scripted(p) = &s.actors[0].motion else { panic!() };
    // Path starts at x = 10.4 + 40 = 50.4 on C2T_2 (y = −1.6); from s = 40 it moves over
    // 20 m to C2T_1 (y = −4.8) and follows it on.
    let y_at = |s: f64| p.path.point_at(s).y;
    assert!((y_at(0.0) + 1.6).abs() < 1e-6 && (y_at(39.9) + 1.6).abs() < 1e-3);
    assert!((y_at(50.0) + 3.2).abs() < 0.05, "half-way between the lanes: {}", y_at(50.0));
    assert!((y_at(61.0) + 4.8).abs() < 1e-3 && (y_at(200.0) + 4.8).abs() < 1e-3);
    // Smooth: the lateral slope is continuous and at most π/2 · 3.2 / 20 ≈ 0.25.
    let mut prev_slope = 0.0;
    let mut at = 35.0;
    while at < 65.0 {
        let slope = (y_at(at + 0.5) - y_at(at)) / 0.5;
        assert!(slope.abs() < 0.26 && (slope - prev_slope).abs() < 0.05, "at s = {at}: {slope}");
        prev_slope = slope;
        at += 0.5;
    }
    // At run time the actor's heading follows the path (turned right during the change).
    let mut w = World::new(&s, 0).unwrap();
    let mut min_yaw: f64 = 0.0;
    for _ in 0..200 {
        w.tick(&Control::default()).unwrap();
        let a = w.actors().iter().find(|a| a.id == 1).unwrap();
        min_yaw = min_yaw.min(a.pose.yaw);
    }
    assert!(min_yaw < -0.1 && min_yaw > -0.3, "heading during the change {min_yaw}");
    let a = w.actors().iter().find(|a| a.id == 1).unwrap();
    assert!((a.pose.pos.y + 4.8).abs() < 1e-3 && a.pose.yaw.abs() < 1e-3, "{a:?}");
    // Lane changes continue over the junction on the new lane's connections: the path ends
    // on T2E_0 (the lane C2T_1 leads to), not T2E_1.
    let end = p.path.point_at(p.path.length());
    let t2e0 = s.map.lane_by_id("T2E_0").unwrap();
    let t2e1 = s.map.lane_by_id("T2E_1").unwrap();
    let d = |l: usize| s.map.lanes[l].shape.project(end).unwrap().distance;
    assert!(d(t2e0) < 0.01 || d(t2e1) < 0.01, "ends on a T2E lane: {end:?}");
}

#[test]
fn lane_change_errors_name_the_field() {
    let e = load_err(
        "lc_not_neighbour",
        r#"
[[actors]]
kind = "car"
route = { lanes = ["C2T_2", "T2E_1"], start_s = 40.0 }
lane_changes = [{ at_s = 40.0, to_lane = "W2C_1" }]
"#,
    );
    assert!(e.contains("actors[0].lane_changes[0].to_lane") && e.contains("W2C_1"), "{e}");
    assert!(e.contains("neighbours: C2T_1"), "{e}");
    let e = load_err(
        "lc_sidewalk",
        r#"
[[actors]]
kind = "car"
route = { lanes = ["C2T_1"], start_s = 40.0 }
lane_changes = [{ at_s = 40.0, to_lane = "C2T_0" }]
"#,
    );
    assert!(e.contains("actors[0].lane_changes[0].to_lane") && e.contains("vClass"), "{e}");
    let e = load_err(
        "lc_past_end",
        r#"
[[actors]]
kind = "car"
route = { lanes = ["C2T_2"], start_s = 40.0, end_s = 100.0 }
lane_changes = [{ at_s = 50.0, to_lane = "C2T_1", length_m = 20.0 }]
"#,
    );
    assert!(e.contains("actors[0].lane_changes[0].at_s") && e.contains("past the end"), "{e}");
    let e = load_err(
        "lc_waypoints",
        r#"
[[actors]]
kind = "car"
waypoints = [{ x = 50.0, y = -1.6 }, { x = 150.0, y = -1.6 }]
lane_changes = [{ at_s = 10.0, to_lane = "C2T_1" }]
"#,
    );
    assert!(e.contains("actors[0].lane_changes"), "{e}");
}

/// Colour of W2C_1's straight link at light C, sampled every second for `secs` s.
fn w2c_colors(s: &ResolvedScenario, secs: usize) -> Vec<LightColor> {
    let mut w = World::new(s, 0).unwrap();
    let from = s.map.lane_by_id("W2C_1").unwrap();
    let to = s.map.lane_by_id("C2T_1").unwrap();
    let mut out = vec![w.connection_color(from, to).unwrap()];
    for k in 1..=secs * 20 {
        w.tick(&Control::default()).unwrap();
        if k % 20 == 0 {
            out.push(w.connection_color(from, to).unwrap());
        }
    }
    out
}

/// Index of the first sample ≥ `from` with colour `c`.
fn first(cols: &[LightColor], from: usize, c: LightColor) -> usize {
    from + cols[from..].iter().position(|&x| x == c).unwrap()
}

#[test]
fn light_overrides_shift_restart_and_replace_the_program() {
    use LightColor::*;
    // Map program of C: east–west green 0–42 s, yellow 42–45, red 45–90.
    let base = w2c_colors(&load("lights_base", 0.0, ""), 100);
    assert_eq!((base[0], base[41], base[43], base[46], base[91]), (Green, Green, Yellow, Red, Green));
    // offset_s = 10: the program runs 10 s late (t = 0 shows the map's t = −10 = 80 s: red).
    let c = w2c_colors(&load("lights_offset", 0.0, "[[lights]]\ntls = \"C\"\noffset_s = 10.0\n"), 100);
    assert_eq!(c[..10], [Red; 10]);
    assert_eq!((first(&c, 0, Green), first(&c, 10, Yellow), first(&c, 10, Red)), (10, 52, 55));
    // start_phase = 3 (north–south green) with 30 s of it gone: red for 7 + 5 + 3 s.
    let c = w2c_colors(
        &load("lights_phase", 0.0, "[[lights]]\ntls = \"C\"\nstart_phase = 3\nphase_elapsed_s = 30.0\n"),
        60,
    );
    assert_eq!((first(&c, 0, Green), first(&c, 15, Yellow)), (15, 57));
    // phases: a two-phase replacement, 8 s all-green then 4 s all-red.
    let g = "G".repeat(20);
    let r = "r".repeat(20);
    let c = w2c_colors(
        &load(
            "lights_phases",
            0.0,
            &format!("[[lights]]\ntls = \"C\"\nphases = [{{ state = \"{g}\", duration_s = 8.0 }}, {{ state = \"{r}\", duration_s = 4.0 }}]\n"),
        ),
        30,
    );
    let want: Vec<LightColor> = (0..=30).map(|t| if t % 12 < 8 { Green } else { Red }).collect();
    assert_eq!(c, want);
}

#[test]
fn light_override_errors_name_the_field() {
    let e = load_err("l_unknown", "[[lights]]\ntls = \"Q\"\noffset_s = 3.0\n");
    assert!(e.contains("lights[0].tls") && e.contains("\"Q\"") && e.contains("C"), "{e}");
    let e =
        load_err("l_len", "[[lights]]\ntls = \"C\"\nphases = [{ state = \"GGrr\", duration_s = 30.0 }]\n");
    assert!(e.contains("lights[0].phases[0].state") && e.contains("GGrr") && e.contains("20 links"), "{e}");
    let e = load_err("l_both", "[[lights]]\ntls = \"C\"\noffset_s = 3.0\nstart_phase = 1\n");
    assert!(e.contains("lights[0]") && e.contains("not both"), "{e}");
    let e = load_err("l_phase", "[[lights]]\ntls = \"C\"\nstart_phase = 6\n");
    assert!(e.contains("lights[0].start_phase") && e.contains("6 phases"), "{e}");
    let e = load_err("l_none", "[[lights]]\ntls = \"C\"\n");
    assert!(e.contains("lights[0]") && e.contains("give one of"), "{e}");
    let e = load_err("l_elapsed", "[[lights]]\ntls = \"C\"\nstart_phase = 1\nphase_elapsed_s = 5.0\n");
    assert!(e.contains("lights[0].phase_elapsed_s") && e.contains("duration 5"), "{e}");
    let e = load_err(
        "l_dur",
        &format!(
            "[[lights]]\ntls = \"C\"\nphases = [{{ state = \"{}\", duration_s = 0.0 }}]\n",
            "G".repeat(20)
        ),
    );
    assert!(e.contains("lights[0].phases[0].duration_s"), "{e}");
}

const TRAFFIC_SPEEDS: &str = r#"
[traffic]
mode = "idm"

[[traffic.vehicles]]
id = "slow"
route = ["C2T", "T2E"]
depart_pos_m = 120.0
depart_lane = 2
depart_speed = 0.0
max_speed_mps = 6.0

[[traffic.flows]]
id = "fast"
from = "C2T"
to = "T2E"
vehs_per_hour = 600
number = 1
begin_s = 0.0
depart_lane = 1
depart_pos_m = 200.0
speed_factor = 0.5
"#;

#[test]
fn per_vehicle_speeds_reach_sumo_routes_and_the_idm_model() {
    let s = load("speeds", 0.0, TRAFFIC_SPEEDS);
    let xml = s.traffic.sumo_routes_xml(&s.map, 0, &s.ego, &[]);
    assert!(xml.contains("<vType id=\"car@slow\"") && xml.contains("maxSpeed=\"6\""), "{xml}");
    assert!(xml.contains("type=\"car@slow\""), "{xml}");
    assert!(
        xml.contains("<flow id=\"fast\" type=\"car@fast\"") && xml.contains("speedFactor=\"0.5\""),
        "{xml}"
    );
    // Native: the slow one settles at 6 m/s; the flow vehicle at 0.5 × 13.89 m/s.
    let mut w = World::new(&s, 0).unwrap();
    w.attach_traffic(Box::new(IdmTraffic::new(&s).unwrap())).unwrap();
    for _ in 0..400 {
        w.tick(&Control::default()).unwrap();
    }
    let mut speeds: Vec<(f64, f64)> =
        w.actors().iter().filter(|a| w.is_traffic_actor(a.id)).map(|a| (a.pose.pos.y, a.speed_mps)).collect();
    speeds.sort_by(|a, b| a.0.total_cmp(&b.0));
    assert_eq!(speeds.len(), 2, "{speeds:?}");
    // Lane 1 (y = −4.8) is the flow, lane 2 (y = −1.6) the slow vehicle.
    assert!((speeds[0].1 - 0.5 * 13.89).abs() < 0.2, "{speeds:?}");
    assert!((speeds[1].1 - 6.0).abs() < 0.2, "{speeds:?}");
    let e = load_err("speed_bad", &TRAFFIC_SPEEDS.replace("max_speed_mps = 6.0", "max_speed_mps = -6.0"));
    assert!(e.contains("traffic.vehicles[0].max_speed_mps") && e.contains("-6"), "{e}");
    let e = load_err("factor_bad", &TRAFFIC_SPEEDS.replace("speed_factor = 0.5", "speed_factor = 0.0"));
    assert!(e.contains("traffic.flows[0].speed_factor"), "{e}");
}

fn trajectory_hash(s: &ResolvedScenario) -> [u8; 32] {
    let mut w = World::new(s, s.seed).unwrap();
    let mut h = Sha256::new();
    for _ in 0..600 {
        let c = cruise(&w, 8.0);
        let r = w.tick(&c).unwrap();
        h.update(r.triggered.iter().flat_map(|i| i.to_le_bytes()).collect::<Vec<_>>());
        for a in std::iter::once(&r.ego).chain(w.actors()) {
            for v in [a.pose.pos.x, a.pose.pos.y, a.pose.yaw, a.speed_mps] {
                h.update(v.to_bits().to_le_bytes());
            }
        }
        for l in w.lights() {
            h.update([l.color as u8]);
        }
    }
    h.finalize().into()
}

#[test]
fn all_features_together_are_deterministic_and_estimated() {
    let body = format!(
        "{WALKER_ETA}{CUT_IN}\n[[actors]]\nname = \"late\"\nkind = \"cyclist\"\nroute = {{ lanes = [\"C2T_1\"], start_s = 250.0 }}\nstart = {{ after = \"walker\", delay_s = 2.0 }}\n\n[[lights]]\ntls = \"C\"\nstart_phase = 3\n"
    );
    let s = load("all", 8.0, &body);
    let a = trajectory_hash(&s);
    assert_eq!(a, trajectory_hash(&load("all", 8.0, &body)));
    // Different trigger timing changes the episode (the hash sees the features).
    assert_ne!(a, trajectory_hash(&load("all2", 8.0, &body.replace("delay_s = 2.0", "delay_s = 3.0"))));
    // Estimated starts: the ego at L / T_ref = 310 m / 55.8 s reaches x = 200 (s ≈ 170 m on
    // its route) after 30.6 s; the walker 3 s earlier, the cyclist 2 s after it.
    let st = s.estimated_start_times_s();
    let v = s.route_length_m() / s.reference_duration_s();
    let s_point = 200.0 - 30.4;
    assert!((st[0] - (s_point / v - 3.0)).abs() < 0.05, "{st:?}");
    assert!((st[2] - st[0] - 2.0).abs() < 1e-9, "{st:?}");
    assert!(s.scenario_duration_s() >= st[2]);
}

#[test]
fn unknown_keys_in_the_new_tables_are_named() {
    let e = load_err("uk_lights", "[[lights]]\ntls = \"C\"\noffset = 3.0\n");
    assert!(e.contains("lights[0].offset"), "{e}");
    let e = load_err(
        "uk_lane_change",
        "[[actors]]\nkind = \"car\"\nroute = { lanes = [\"C2T_2\"] }\nlane_changes = [{ at_s = 5.0, lane = \"C2T_1\" }]\n",
    );
    assert!(e.contains("actors[0].lane_changes[0].lane"), "{e}");
    let e = load_err(
        "uk_speed",
        "[traffic]\nmode = \"idm\"\n[[traffic.vehicles]]\nroute = [\"C2T\"]\nmax_speed = 5.0\n",
    );
    assert!(e.contains("traffic.vehicles[0].max_speed"), "{e}");
}

#[test]
fn idm_traffic_obeys_the_overridden_light() {
    // A car approaching C from the west: the map's program is green for it, the override
    // (north–south green first) red for 45 s.
    let body = r#"
[traffic]
mode = "idm"

[[traffic.vehicles]]
route = ["W2C", "C2T"]
depart_lane = 1
depart_pos_m = 150.0
depart_speed = 10.0
"#;
    let x_after = |s: &ResolvedScenario, secs: usize| {
        let mut w = World::new(s, 0).unwrap();
        w.attach_traffic(Box::new(IdmTraffic::new(s).unwrap())).unwrap();
        for _ in 0..secs * 20 {
            w.tick(&Control::default()).unwrap();
        }
        let v: Vec<_> = w.actors().iter().filter(|a| w.is_traffic_actor(a.id)).collect();
        assert_eq!(v.len(), 1);
        (v[0].pose.pos.x, v[0].speed_mps)
    };
    let (x, _) = x_after(&load("idm_green", 0.0, body), 20);
    assert!(x > 0.0, "passes C on the map's green: x = {x}");
    let red = load("idm_red", 0.0, &format!("{body}\n[[lights]]\ntls = \"C\"\nstart_phase = 3\n"));
    let (x, v) = x_after(&red, 30);
    assert!(x < -10.4 && x > -25.0 && v < 0.1, "waits at the stop line (x = −10.4): x = {x}, v = {v}");
}

/// `emergency = true` reaches the actor's view as `beacon` (actors and obstacles) and changes
/// nothing else: the same episode with and without it has identical poses and speeds.
#[test]
fn emergency_flag_reaches_the_view_and_not_the_dynamics() {
    let body = |flag: &str| {
        format!(
            r#"
[[actors]]
name = "ambulance"
kind = "truck"
{flag}
waypoints = [{{ x = 150.0, y = -4.8 }}, {{ x = 250.0, y = -4.8 }}]
speed_mps = 9.0
start = {{ ego_eta_s = 3.0, of = [200.0, -4.8] }}

[[obstacles]]
name = "parked police car"
kind = "car"
at = {{ x = 260.0, y = -9.5 }}
{flag}
"#
        )
    };
    let plain = load("emergency_off", 8.0, &body(""));
    let flagged = load("emergency_on", 8.0, &body("emergency = true"));
    assert!(plain.actors.iter().all(|a| !a.emergency));
    assert!(flagged.actors.iter().all(|a| a.emergency));
    let (mut a, mut b) = (World::new(&plain, 3).unwrap(), World::new(&flagged, 3).unwrap());
    let mut moved = false;
    for _ in 0..400 {
        let (ca, cb) = (cruise(&a, 8.0), cruise(&b, 8.0));
        a.tick(&ca).unwrap();
        b.tick(&cb).unwrap();
        assert_eq!(a.ego(), b.ego());
        assert_eq!(a.actors().len(), b.actors().len());
        for (x, y) in a.actors().iter().zip(b.actors()) {
            assert!(!x.beacon && y.beacon, "{x:?} / {y:?}");
            assert_eq!(*x, dh_env::view::ActorView { beacon: false, ..*y });
            moved |= y.speed_mps > 1.0;
        }
    }
    assert!(moved, "the ambulance never started");
}

#[test]
fn emergency_on_a_kind_without_a_roof_is_rejected() {
    let e = load_err(
        "emergency_walker",
        r#"
[[actors]]
name = "a"
kind = "pedestrian"
emergency = true
waypoints = [{ x = 300.0, y = -9.0 }, { x = 300.0, y = -8.5 }]
"#,
    );
    assert!(e.contains("actors[0].emergency") && e.contains("pedestrian"), "{e}");
    let e = load_err(
        "emergency_cone",
        r#"
[[obstacles]]
kind = "cone"
at = { x = 260.0, y = -9.5 }
emergency = true
"#,
    );
    assert!(e.contains("obstacles[0].emergency") && e.contains("cone"), "{e}");
}
