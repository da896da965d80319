//! The expert on the project's R4 scenarios (`scenarios/r4/`), through the real world and the
//! protocol's actuation bridge at 4 Hz (a decision at tick 0 and every 5 ticks, held between),
//! scored per docs/protocol.md#r4-termination, #r4-scene-score. Each scenario must reach S_R4 ≥ 90.
//!
//! `sumo:` maps need SUMO_HOME (the env var, else `python3 -c "import sumo"`); scenarios on them
//! are skipped with a message when it is absent.

use dh_agents::expert::{
    network_drivable, network_speed_limit, Expert, ExpertInput, ExpertParams, SpeedReason,
};
use dh_env::drive::bridge::{ActuationBridge, Decision};
use dh_env::scenario::{LoadOptions, ResolvedScenario, Scenario};
use dh_env::score::{Contact, RunInfo, ScoreParams, ScoreTracker, TerminationReason, TickInput};
use dh_env::view::LightColor;
use dh_env::world::{Control, World};
use dh_env::DECISION_INTERVAL_TICKS;
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
    let Ok(dirs) = std::fs::read_dir(repo_root().join("scenarios/r4")) else { return out };
    let mut cats: Vec<_> = dirs.flatten().map(|e| e.path()).filter(|p| p.is_dir()).collect();
    cats.sort();
    for c in cats {
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

#[derive(Debug)]
struct Run {
    reason: TerminationReason,
    time_s: f64,
    travel_m: f64,
    offroad_s: f64,
    s_route: f64,
    s_safety: f64,
    s_eff: f64,
    s_r4: f64,
    red_lights_run: u32,
    /// Decisions limited by an actor / a lead / a light, and the largest detour offset.
    obstacle_decisions: u32,
    lead_decisions: u32,
    light_decisions: u32,
    max_offset_m: f64,
    /// Mean wall time of one expert decision (this build's profile), µs.
    decision_us: f64,
}

/// The protocol's warm-up (`SimConfig::warmup_ticks`): ticks 1–4 run with zero control.
const WARMUP: u64 = dh_env::sim::WARMUP_TICKS as u64;

/// Drives one scenario with the expert; scored by the protocol's score tracker.
fn run(s: &ResolvedScenario) -> Run {
    let mut world = World::new(s, s.seed).unwrap();
    let mut bridge = ActuationBridge::new();
    let mut expert = Expert::new(ExpertParams::default()).unwrap();
    let route = &s.ego.route;
    let mut tracker = ScoreTracker::new(
        route.clone(),
        s.ego.start.pos,
        s.ego.destination,
        s.reference_duration_given_s,
        ScoreParams::default(),
    )
    .unwrap();
    let mut control = Control::default();
    let (mut obstacle_decisions, mut lead_decisions, mut light_decisions) = (0, 0, 0);
    let (mut max_offset_m, mut red_lights_run, mut decisions) = (0.0f64, 0, 0u32);
    let mut think = std::time::Duration::ZERO;
    loop {
        // As the protocol runs it: zero control for the warm-up ticks, then a decision every 5.
        let tick_no = world.tick_count();
        if tick_no >= WARMUP && (tick_no - WARMUP) % DECISION_INTERVAL_TICKS as u64 == 0 {
            let t0 = std::time::Instant::now();
            let a = expert.act_in_world(&world, route);
            think += t0.elapsed();
            decisions += 1;
            match a.reason {
                SpeedReason::Obstacle { .. } => obstacle_decisions += 1,
                SpeedReason::Lead { .. } => lead_decisions += 1,
                SpeedReason::Light => light_decisions += 1,
                _ => {}
            }
            max_offset_m = max_offset_m.max(a.path_offset_m.abs());
            // The env's action space is float32: a policy's decision arrives rounded to f32.
            let d = Decision::from(a);
            let d =
                Decision { steer: d.steer as f32 as f64, target_speed_mps: d.target_speed_mps as f32 as f64 };
            let c = bridge.apply(Some(d), world.ego().speed_mps);
            control = Control { throttle: c.throttle, brake: c.brake, steer: c.steer };
        }
        let r = world.tick(&control).unwrap();
        let contacts: Vec<Contact> =
            r.contacts.iter().map(|&(actor_id, class)| Contact { actor_id, class }).collect();
        red_lights_run += u32::from(r.ran_red_light);
        let tick = TickInput {
            contacts: &contacts,
            red_light: r.ran_red_light,
            ..TickInput::new(r.ego.pose.pos, r.ego.speed_mps, r.on_road)
        };
        if let Some(t) = tracker.update(&tick) {
            let score = tracker.finish(&RunInfo { scene_id: s.id.clone(), ..Default::default() });
            return Run {
                reason: t.reason,
                time_s: t.time_s,
                travel_m: tracker.travel_m(),
                offroad_s: tracker.offroad_time_s(),
                s_route: score.score_route,
                s_safety: score.score_safety,
                s_eff: score.score_efficiency,
                s_r4: score.score_composed,
                red_lights_run,
                obstacle_decisions,
                lead_decisions,
                light_decisions,
                max_offset_m,
                decision_us: think.as_secs_f64() * 1e6 / f64::from(decisions.max(1)),
            };
        }
    }
}

#[test]
fn expert_scores_at_least_90_on_every_project_scenario() {
    let home = sumo_home();
    let opts = LoadOptions { sumo_home: home.clone(), cache: Some(Default::default()) };
    let mut failures = Vec::new();
    let mut n = 0;
    for f in scenario_files() {
        if home.is_none() && uses_sumo_map(&f) {
            eprintln!("skipping {} (no SUMO_HOME)", f.display());
            continue;
        }
        let s = Scenario::load_with(&f, &opts).unwrap_or_else(|e| panic!("{e}"));
        let sc = run(&s);
        n += 1;
        println!(
            "{:36} {:?} t={:5.1}s (T_ref {:5.1}) travel {:6.1}/{:6.1} m offroad {:.2}s route {:5.1} safety {:.2} eff {:.3} S_R4 {:5.1} [obst {} lead {} light {} offset {:.1} m, red run {}, {:.0} µs/decision]",
            s.id,
            sc.reason,
            sc.time_s,
            s.reference_duration_s(),
            sc.travel_m,
            s.route_length_m(),
            sc.offroad_s,
            sc.s_route,
            sc.s_safety,
            sc.s_eff,
            sc.s_r4,
            sc.obstacle_decisions,
            sc.lead_decisions,
            sc.light_decisions,
            sc.max_offset_m,
            sc.red_lights_run,
            sc.decision_us
        );
        if sc.s_r4 < 90.0 || sc.red_lights_run > 0 {
            failures.push(format!("{}: {sc:?}", s.id));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
    if n == 0 {
        eprintln!("skipping: no scenarios under scenarios/r4");
    }
}

/// With every signal head forced to red in what the expert sees, it must stop before the stop
/// line on its route at the signalised crossing and wait there, creeping just enough never to
/// trip the blocked timeout, for a minute.
#[test]
fn forced_red_at_the_signalised_crossing_holds_the_ego() {
    let f = repo_root().join("scenarios/r4/03_turning/town01_03_right_turn_signalised.toml");
    if !f.exists() {
        eprintln!("skipping: {} not found", f.display());
        return;
    }
    let s = Scenario::load(&f).unwrap();
    let mut world = World::new(&s, s.seed).unwrap();
    let mut bridge = ActuationBridge::new();
    let mut expert = Expert::new(ExpertParams::default()).unwrap();
    let route = &s.ego.route;
    let net = world.map().clone();
    let oracle = network_drivable(&net);
    // Stop lines of heads controlling the route (within 1.5 m of it, same direction).
    let lines: Vec<f64> = world
        .lights()
        .iter()
        .filter_map(|l| {
            let q = route.project(l.stop_line.pos)?;
            (q.distance < 1.5 && (route.heading_at(q.s) - l.stop_line.yaw).cos() > 0.8).then_some(q.s)
        })
        .collect();
    assert!(!lines.is_empty(), "no signal head on the route");
    let line = lines.iter().copied().fold(f64::INFINITY, f64::min);
    let half_len = world.ego().length_m * 0.5;
    let (mut control, mut still, mut max_still, mut max_front) =
        (Control::default(), 0u32, 0u32, f64::NEG_INFINITY);
    let mut light_decisions = 0;
    while world.time_s() < 60.0 {
        // As the protocol runs it: zero control for the warm-up ticks, then a decision every 5.
        let tick_no = world.tick_count();
        if tick_no >= WARMUP && (tick_no - WARMUP) % DECISION_INTERVAL_TICKS as u64 == 0 {
            let ego = *world.ego();
            let mut lights = world.lights().to_vec();
            for l in &mut lights {
                l.color = LightColor::Red;
            }
            let input = ExpertInput {
                ego: &ego,
                route,
                actors: world.actors(),
                lights: &lights,
                speed_limit_mps: network_speed_limit(&net, ego.pose.pos),
                drivable: Some(&oracle),
                follow_lane: None,
            };
            let a = expert.act(&input);
            light_decisions += u32::from(a.reason == SpeedReason::Light);
            let c = bridge.apply(Some(Decision::from(a)), ego.speed_mps);
            control = Control { throttle: c.throttle, brake: c.brake, steer: c.steer };
        }
        let r = world.tick(&control).unwrap();
        assert!(r.contacts.is_empty(), "contact at t = {:.1}", r.time_s);
        assert!(r.on_road, "off road at t = {:.1}", r.time_s);
        let front = route.project(r.ego.pose.pos).unwrap().s + half_len;
        max_front = max_front.max(front);
        still = if r.ego.speed_mps < 1.0 / 3.6 { still + 1 } else { 0 };
        max_still = max_still.max(still);
    }
    println!(
        "forced red: front stopped {:.2} m before the line, longest rest {} ticks",
        line - max_front,
        max_still
    );
    assert!(max_front < line, "front passed the stop line by {:.2} m", max_front - line);
    assert!(line - max_front < 5.0, "stopped {:.1} m short of the line", line - max_front);
    assert!(max_still <= 100, "at rest for {max_still} ticks: blocked timeout");
    assert!(light_decisions > 100);
}
