//! Every scenario in `scenarios/r4`: loads, ticks with zero control without panics,
//! deterministic, and is drivable by a simple privileged driver (pure pursuit + stop for
//! obstacles in the path and red lights) at S_R4 ≥ 90 by the protocol's score tracker; the
//! hazard scenarios make the same driver crash when it ignores actors.
//!
//! `sumo:` maps need SUMO_HOME (`SumoHome::locate`: the `sumo` package of `$PYO3_PYTHON` or
//! `python3`, else the env var); without it those scenarios are skipped with a message.

use dh_env::drive::{ActuationBridge, Control, Decision};
use dh_env::geom::{Polyline, Vec2};
use dh_env::scenario::{LoadOptions, ResolvedScenario, Scenario, CATEGORIES};
use dh_env::score::{Contact, RunInfo, ScoreParams, ScoreTracker, TerminationReason, TickInput};
use dh_env::view::{ActorKind, LightColor};
use dh_env::world::World;
use dh_env::DECISION_INTERVAL_TICKS;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};

fn repo_root() -> PathBuf {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf();
    // The suite names its maps `builtin:NAME`; the Python package registers them, a test does.
    dh_env::scenario::set_builtin_maps_dir(root.join("scenarios/maps"));
    root
}

fn sumo_home() -> Option<PathBuf> {
    dh_env::sumo_home::SumoHome::locate().map(|h| h.0)
}

fn scenario_files() -> Vec<PathBuf> {
    let mut out = Vec::new();
    let dir = repo_root().join("scenarios/r4");
    let mut cats: Vec<_> =
        std::fs::read_dir(&dir).expect("scenarios/r4 exists").flatten().map(|e| e.path()).collect();
    cats.sort();
    for c in cats.into_iter().filter(|c| c.is_dir()) {
        let mut files: Vec<_> = std::fs::read_dir(&c).unwrap().flatten().map(|e| e.path()).collect();
        files.sort();
        out.extend(files.into_iter().filter(|f| f.extension().is_some_and(|e| e == "toml")));
    }
    out
}

fn uses_sumo_map(p: &Path) -> bool {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .any(|l| l.trim_start().starts_with("map") && l.contains("\"sumo:"))
}

/// Loads every scenario that can be loaded here.
fn load_all() -> Vec<ResolvedScenario> {
    let home = sumo_home();
    let opts = LoadOptions { sumo_home: home.clone(), cache: Some(Default::default()) };
    let mut out = Vec::new();
    for f in scenario_files() {
        if home.is_none() && uses_sumo_map(&f) {
            eprintln!("skipping {} (no SUMO_HOME)", f.display());
            continue;
        }
        out.push(Scenario::load_with(&f, &opts).unwrap_or_else(|e| panic!("{e}")));
    }
    out
}

#[test]
fn suite_shape() {
    let files = scenario_files();
    assert!(files.len() >= 7, "{files:?}");
    let all = load_all();
    let mut categories: Vec<&str> = Vec::new();
    for s in &all {
        let folder = s.file.parent().unwrap().file_name().unwrap().to_str().unwrap();
        assert_eq!(folder, s.category, "{}: folder = category", s.file.display());
        assert!(CATEGORIES.contains(&folder));
        let l = s.route_length_m();
        assert!((100.0..=400.0).contains(&l), "{}: route {l:.1} m", s.id);
        let t = s.reference_duration_s();
        assert!((t - l / 7.0).abs() <= 0.1 * l / 7.0, "{}: T_ref {t} vs L/7 = {:.1}", s.id, l / 7.0);
        categories.push(folder);
    }
    for c in [
        "01_pedestrian",
        "02_obstacles",
        "03_turning",
        "04_intersection",
        "05_t_intersection",
        "07_sudden_brake",
    ] {
        assert!(categories.contains(&c), "missing {c}");
    }
    let mut ids: Vec<&str> = all.iter().map(|s| s.id.as_str()).collect();
    ids.sort();
    ids.dedup();
    assert_eq!(ids.len(), all.len(), "ids are unique");
}

#[test]
fn zero_control_runs_and_is_deterministic() {
    for s in load_all() {
        let run = || {
            let mut w = World::new(&s, s.seed).unwrap();
            let mut h = Sha256::new();
            for _ in 0..600 {
                let r = w.tick(&Control::default()).unwrap();
                if s.ego.speed_mps == 0.0 {
                    assert_eq!(r.ego.pose, s.ego.start, "{}: ego stays put", s.id);
                }
                for a in w.actors() {
                    for v in [a.pose.pos.x, a.pose.pos.y, a.pose.yaw, a.speed_mps] {
                        assert!(v.is_finite(), "{}: actor {} finite", s.id, a.id);
                        h.update(v.to_bits().to_le_bytes());
                    }
                }
                h.update([r.on_road as u8]);
            }
            h.finalize().to_vec()
        };
        assert_eq!(run(), run(), "{}", s.id);
    }
}

/// Outcome of a drive by the test driver, scored by the protocol's tracker
/// (docs/protocol.md#r4-termination, #r4-scene-score).
#[derive(Debug)]
struct Outcome {
    reached: bool,
    reason: String,
    time_s: f64,
    travel_m: f64,
    s_r4: f64,
}

/// Lateral clearance (m) the test driver keeps from actors beside its path.
const CLEARANCE_M: f64 = 0.6;

/// `careful`: sees actors and lights. Decides every tick with direct pedals, or (with
/// `bridge`) every 5 ticks through the protocol's actuation bridge (docs/protocol.md#r4-actuation)
/// like a policy does.
fn drive(s: &ResolvedScenario, careful: bool, bridge: bool) -> Outcome {
    let mut act = ActuationBridge::new();
    let mut held = Control::default();
    let mut w = World::new(s, s.seed).unwrap();
    let route: &Polyline = &s.ego.route;
    let p = *w.vehicle_params();
    let half_len = 0.5 * p.length_m;
    let mut progress = 0.0f64;
    let mut offset = 0.0f64; // lateral path offset (> 0 left) used to pass blocked lanes
    let mut tracker = ScoreTracker::new(
        s.ego.route.clone(),
        s.ego.start.pos,
        s.ego.destination,
        s.reference_duration_given_s,
        ScoreParams::default(),
    )
    .unwrap();
    loop {
        let ego = *w.ego();
        let v = ego.speed_mps;
        // Progress: projection near the previous one (routes may pass close to themselves).
        let win = route.slice(progress, progress + 30.0);
        if let Some(q) = win.project(ego.pose.pos) {
            progress += q.s;
        }
        // Obstacles in the (offset) corridor ahead.
        let mut gap = f64::INFINITY;
        let mut blocked_static_at = None;
        for a in w.actors() {
            let Some(q) = route.project(a.pose.pos) else { continue };
            let ahead = q.s - progress;
            if !(-half_len..80.0).contains(&ahead) {
                continue;
            }
            let reach = 0.5 * a.width_m.max(a.length_m.min(a.width_m * 2.0)) + 0.5 * p.width_m + CLEARANCE_M;
            // Moving actors: also where they will be in 2 s.
            let fut = a.pose.pos + Vec2::from_angle(a.pose.yaw) * (2.0 * a.speed_mps);
            let qf = route.project(fut).map_or(q.lateral, |qf| qf.lateral);
            let lat_now = q.lateral - offset;
            let lat_fut = qf - offset;
            let crosses = a.speed_mps > 0.1 && lat_now.signum() != lat_fut.signum();
            if lat_now.abs() < reach
                || lat_fut.abs() < reach && a.kind == ActorKind::Pedestrian
                || crosses && a.kind == ActorKind::Pedestrian
            {
                let g = ahead - half_len - 0.5 * a.length_m;
                gap = gap.min(g);
                if a.speed_mps < 0.1 && a.kind.is_static() {
                    blocked_static_at = Some(blocked_static_at.map_or(q.s, |b: f64| b.min(q.s)));
                }
            }
        }
        // Cross traffic: a moving vehicle whose straight-line future enters the path ahead about
        // when the ego would get there is treated as an obstacle at that point (gap acceptance).
        for a in w.actors().iter().filter(|a| a.speed_mps > 0.5 && a.kind != ActorKind::Pedestrian) {
            let window = route.slice(progress, progress + 40.0);
            let reach = 0.5 * a.width_m + 0.5 * p.width_m + 0.8;
            for k in 1..=16 {
                let t = 0.25 * k as f64;
                let at = a.pose.pos + Vec2::from_angle(a.pose.yaw) * (a.speed_mps * t);
                let Some(q) = window.project(at) else { break };
                if (q.lateral - offset).abs() >= reach || q.s < half_len {
                    continue;
                }
                let arrival = (q.s - half_len) / v.max(2.0);
                if (arrival - t).abs() < 1.5 {
                    gap = gap.min(q.s - half_len - 0.5 * a.width_m - 1.0);
                }
                break;
            }
        }
        if !careful {
            gap = f64::INFINITY;
            blocked_static_at = None;
        }
        // Pass a static blockage in the lane to the left when that lane is free of statics.
        if let Some(bs) = blocked_static_at {
            if bs - progress < 45.0 {
                offset = 3.2;
                gap = f64::INFINITY;
            }
        } else if offset > 0.0 {
            let any_static_near = w.actors().iter().any(|a| {
                a.kind.is_static()
                    && route
                        .project(a.pose.pos)
                        .is_some_and(|q| (q.s - progress).abs() < 12.0 && q.lateral.abs() < 2.5)
            });
            if !any_static_near {
                offset = 0.0;
            }
        }
        // Red / yellow lights on the route ahead.
        for l in w.lights().iter().filter(|_| careful) {
            if !matches!(l.color, LightColor::Red | LightColor::Yellow) {
                continue;
            }
            let Some(q) = route.project(l.stop_line.pos) else { continue };
            let heading_ok = (route.heading_at(q.s) - l.stop_line.yaw).cos() > 0.9;
            if q.distance < 1.0 && heading_ok && q.s > progress + half_len - 1.0 {
                gap = gap.min(q.s - progress - half_len - 1.0);
            }
        }
        // Curvature speed limit over the next 40 m.
        let mut v_max: f64 = 11.0;
        for k in 1..8 {
            let a = route.heading_at(progress + 5.0 * k as f64);
            let b = route.heading_at(progress + 5.0 * (k + 1) as f64);
            let kappa = dh_env::geom::wrap_angle(b - a).abs() / 5.0;
            if kappa > 1e-4 {
                v_max = v_max.min((2.5 / kappa).sqrt().max(3.0));
            }
        }
        let v_gap = if gap.is_finite() { (2.0 * 5.0 * (gap - 3.0).max(0.0)).sqrt() } else { f64::INFINITY };
        let target = v_max.min(v_gap);
        // Pure pursuit on the offset route.
        let ld = (4.0 + 0.6 * v).clamp(6.0, 15.0);
        let sp = progress + ld;
        let tp = route.point_at(sp) + Vec2::from_angle(route.heading_at(sp)).perp() * offset;
        let (f, r) = ego.pose.to_forward_right(tp);
        let left = -r;
        let kappa = 2.0 * left / (f * f + left * left).max(1.0);
        let delta = (p.wheelbase_m * kappa).atan();
        let steer = (-delta / p.max_steer_deg.to_radians()).clamp(-1.0, 1.0);
        let e = target - v;
        let c = if bridge {
            if w.tick_count() % DECISION_INTERVAL_TICKS as u64 == 0 {
                held = act.apply(Some(Decision { steer, target_speed_mps: target.min(30.0) }), v);
            }
            held
        } else if e >= 0.0 {
            Control { throttle: (0.3 + 0.4 * e).clamp(0.0, 1.0), brake: 0.0, steer }
        } else {
            Control { throttle: 0.0, brake: (-0.35 * e).clamp(0.0, 1.0), steer }
        };
        let r = w.tick(&c).unwrap();
        let contacts: Vec<Contact> =
            r.contacts.iter().map(|&(actor_id, class)| Contact { actor_id, class }).collect();
        let tick = TickInput {
            contacts: &contacts,
            red_light: r.ran_red_light,
            ..TickInput::new(r.ego.pose.pos, r.ego.speed_mps, r.on_road)
        };
        if let Some(t) = tracker.update(&tick) {
            let score = tracker.finish(&RunInfo { scene_id: s.id.clone(), ..Default::default() });
            let reason = match contacts.first() {
                Some(c) => format!("contact with {} ({:?})", c.actor_id, c.class),
                None => format!("{:?} at progress {progress:.1}", t.reason),
            };
            return Outcome {
                reached: t.reason == TerminationReason::DestinationReached,
                reason,
                time_s: t.time_s,
                travel_m: tracker.travel_m(),
                s_r4: score.score_composed,
            };
        }
    }
}

// Solvability of the suite is checked with the privileged expert, which also swerves around
// obstacles and waits for gaps: `agents/tests/it/expert_r4.rs` (every scenario, no live traffic) and
// `tests/scenarios/test_suite.py` (every scenario with its own traffic, through the env).

/// The hazard scenarios must actually be hazardous: the same driver blind to actors crashes.
#[test]
fn blind_driver_crashes_in_hazard_scenarios() {
    for s in load_all() {
        if !["01_pedestrian", "02_obstacles", "07_sudden_brake", "09_yielding"].contains(&s.category.as_str())
        {
            continue;
        }
        let o = drive(&s, false, false);
        eprintln!(
            "{:40} blind: {} at t = {:.1} s after {:.1} m, S_R4 {:.1}",
            s.id, o.reason, o.time_s, o.travel_m, o.s_r4
        );
        assert!(o.reason.starts_with("contact") && !o.reached, "{}: {o:?}", s.id);
    }
}
