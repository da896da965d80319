//! The expert on the project's R4 scenarios (`scenarios/r4/`), through the real world and the
//! protocol's actuation bridge at 4 Hz (a decision at tick 0 and every 5 ticks, held between),
//! scored per PROTOCOL.md §2.4–2.5. Each scenario must reach S_R4 ≥ 90.
//!
//! `sumo:` maps need SUMO_HOME (the env var, else `python3 -c "import sumo"`); scenarios on them
//! are skipped with a message when it is absent.

use dh_agents::expert::{Expert, ExpertParams, SpeedReason};
use dh_env::drive::bridge::{ActuationBridge, Decision};
use dh_env::geom::Vec2;
use dh_env::scenario::{LoadOptions, ResolvedScenario, Scenario};
use dh_env::view::ContactClass;
use dh_env::world::{Control, World};
use dh_env::{DECISION_INTERVAL_TICKS, DT_S};
use std::path::{Path, PathBuf};

fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

fn sumo_home() -> Option<PathBuf> {
    if let Some(h) = std::env::var_os("SUMO_HOME") {
        return Some(PathBuf::from(h));
    }
    let out = std::process::Command::new("python3")
        .args(["-c", "import sumo; print(sumo.SUMO_HOME)"])
        .output()
        .ok()?;
    let s = String::from_utf8(out.stdout).ok()?;
    let p = PathBuf::from(s.trim());
    (out.status.success() && p.is_dir()).then_some(p)
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
struct Score {
    reason: &'static str,
    time_s: f64,
    travel_m: f64,
    offroad_s: f64,
    s_route: f64,
    s_safety: f64,
    s_eff: f64,
    /// Decisions limited by an actor / a lead / a light, and the largest detour offset.
    obstacle_decisions: u32,
    lead_decisions: u32,
    light_decisions: u32,
    max_offset_m: f64,
}

impl Score {
    fn total(&self) -> f64 {
        self.s_route * self.s_safety * self.s_eff
    }
}

/// Drives one scenario with the expert and scores it per §2.4–2.5.
fn run(s: &ResolvedScenario) -> Score {
    let mut world = World::new(s, 0).unwrap();
    let mut bridge = ActuationBridge::new();
    let mut expert = Expert::new(ExpertParams::default()).unwrap();
    let route = &s.ego.route;
    let l = route.length();
    let t_ref = s.reference_duration_s();
    let (mut best, mut travel, mut offroad_s, mut off_run, mut still) = (0.0f64, 0.0, 0.0, 0.0, 0u32);
    let mut control = Control::default();
    let mut last: Vec2 = world.ego().pose.pos;
    let mut tick: u64 = 0;
    let (mut obstacle_decisions, mut lead_decisions, mut light_decisions, mut max_offset_m) =
        (0, 0, 0, 0.0f64);
    let (reason, penalty) = loop {
        if tick % DECISION_INTERVAL_TICKS as u64 == 0 {
            let a = expert.act_in_world(&world, route);
            match a.reason {
                SpeedReason::Obstacle { .. } => obstacle_decisions += 1,
                SpeedReason::Lead { .. } => lead_decisions += 1,
                SpeedReason::Light => light_decisions += 1,
                _ => {}
            }
            max_offset_m = max_offset_m.max(a.path_offset_m.abs());
            let c = bridge.apply(Some(Decision::from(a)), world.ego().speed_mps);
            control = Control { throttle: c.throttle, brake: c.brake, steer: c.steer };
        }
        let r = world.tick(&control).unwrap();
        tick += 1;
        let pos = r.ego.pose.pos;
        travel += pos.dist(last);
        last = pos;
        if !r.on_road {
            offroad_s += DT_S;
            off_run += DT_S;
        } else {
            off_run = 0.0;
            if let Some(pr) = route.project(pos) {
                if pr.distance <= 6.0 {
                    best = best.max(pr.s.min(best + 20.0));
                }
            }
        }
        let at_dest = pos.dist(s.ego.destination) <= 8.0;
        if at_dest {
            best = l;
        }
        if let Some(&(_, class)) = r.contacts.first() {
            break match class {
                ContactClass::Pedestrian => ("collision_pedestrian", 0.0),
                ContactClass::Vehicle => ("collision_vehicle", 0.2),
                ContactClass::Static => ("collision_static", 0.3),
            };
        }
        if off_run >= 1.5 - 1e-9 {
            break ("offroad_timeout", 0.0);
        }
        if at_dest {
            break ("destination_reached", 1.0);
        }
        still = if r.ego.speed_mps < 1.0 / 3.6 { still + 1 } else { 0 };
        if still > 100 {
            break ("blocked_timeout", 0.7);
        }
        if r.time_s >= 2.0 * t_ref - 1e-9 {
            break ("scenario_timeout", 0.7);
        }
    };
    let duration = tick as f64 * DT_S;
    let s_route = if reason == "destination_reached" { 100.0 } else { (100.0 * best / l).clamp(0.0, 100.0) };
    let s_safety = (penalty * (1.0 - offroad_s / duration)).clamp(0.0, 1.0);
    let s_eff = 0.7 * (1.10 * l / travel.max(1e-9)).min(1.0) + 0.3 * (1.50 * t_ref / duration).min(1.0);
    Score {
        reason,
        time_s: duration,
        travel_m: travel,
        offroad_s,
        s_route,
        s_safety,
        s_eff,
        obstacle_decisions,
        lead_decisions,
        light_decisions,
        max_offset_m,
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
            "{:38} {:20} t={:5.1}s (T_ref {:5.1}) travel {:6.1}/{:6.1} m offroad {:.2}s  route {:5.1} safety {:.2} eff {:.3}  S_R4 {:5.1}  [obst {} lead {} light {} offset {:.1} m]",
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
            sc.total(),
            sc.obstacle_decisions,
            sc.lead_decisions,
            sc.light_decisions,
            sc.max_offset_m
        );
        if sc.total() < 90.0 {
            failures.push(format!("{}: {sc:?}", s.id));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
    if n == 0 {
        eprintln!("skipping: no scenarios under scenarios/r4");
    }
}
