//! The expert against the scenario-format features of issue 9 on town01, through the real world
//! and the protocol's actuation bridge at 4 Hz: a pedestrian released by a time-to-conflict
//! trigger, a cut-in (lane change) and a red light that exists only through a `[[lights]]`
//! override. In each the expert must avoid the hazard and finish, while a hazard-blind driver
//! holding 10 m/s straight on meets it (so the hazard is real).

use dh_agents::expert::{Expert, ExpertParams, SpeedReason};
use dh_env::drive::bridge::{ActuationBridge, Decision};
use dh_env::scenario::{ResolvedScenario, Scenario};
use dh_env::score::{Contact, RunInfo, ScoreParams, ScoreTracker, TerminationReason, TickInput};
use dh_env::view::ContactClass;
use dh_env::world::{Control, World};
use dh_env::DECISION_INTERVAL_TICKS;
use std::path::PathBuf;

fn load(tag: &str, ego: &str, body: &str) -> ResolvedScenario {
    let map = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps/town01/town01.net.xml");
    let text = format!(
        "version = 1\nid = \"{tag}\"\ncategory = \"01_pedestrian\"\nmap = {:?}\n\n[ego]\n{ego}\n{body}\n",
        map.display().to_string()
    );
    let dir = std::env::temp_dir().join(format!("dh_expert_features_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(format!("{tag}.toml"));
    std::fs::write(&p, text).unwrap();
    Scenario::load(&p).unwrap_or_else(|e| panic!("{e}"))
}

#[derive(Debug)]
struct Run {
    reason: TerminationReason,
    s_r4: f64,
    contacts: Vec<ContactClass>,
    red_lights_run: u32,
    obstacle_decisions: u32,
    lead_decisions: u32,
    light_decisions: u32,
}

/// Drives `s` with the expert (`blind = false`) or at a held 10 m/s straight on (`blind`).
fn run(s: &ResolvedScenario, blind: bool) -> Run {
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
    let mut out = Run {
        reason: TerminationReason::Incomplete,
        s_r4: 0.0,
        contacts: Vec::new(),
        red_lights_run: 0,
        obstacle_decisions: 0,
        lead_decisions: 0,
        light_decisions: 0,
    };
    loop {
        if world.tick_count() % DECISION_INTERVAL_TICKS as u64 == 0 {
            let d = if blind {
                Decision { steer: 0.0, target_speed_mps: 10.0 }
            } else {
                let a = expert.act_in_world(&world, route);
                match a.reason {
                    SpeedReason::Obstacle { .. } => out.obstacle_decisions += 1,
                    SpeedReason::Lead { .. } => out.lead_decisions += 1,
                    SpeedReason::Light => out.light_decisions += 1,
                    _ => {}
                }
                Decision::from(a)
            };
            let c = bridge.apply(Some(d), world.ego().speed_mps);
            control = Control { throttle: c.throttle, brake: c.brake, steer: c.steer };
        }
        let r = world.tick(&control).unwrap();
        for &(_, class) in &r.contacts {
            if !out.contacts.contains(&class) {
                out.contacts.push(class);
            }
        }
        let contacts: Vec<Contact> =
            r.contacts.iter().map(|&(actor_id, class)| Contact { actor_id, class }).collect();
        out.red_lights_run += u32::from(r.ran_red_light);
        let tick = TickInput {
            contacts: &contacts,
            red_light: r.ran_red_light,
            ..TickInput::new(r.ego.pose.pos, r.ego.speed_mps, r.on_road)
        };
        if let Some(t) = tracker.update(&tick) {
            out.reason = t.reason;
            out.s_r4 =
                tracker.finish(&RunInfo { scene_id: s.id.clone(), ..Default::default() }).score_composed;
            return out;
        }
    }
}

const EAST: &str =
    "start = { lane = \"C2T_1\", s = 20.0 }\ndestination = { lane = \"C2T_1\", s = 330.0 }\nspeed_mps = 10.0";

#[test]
fn expert_stops_for_a_pedestrian_released_by_time_to_conflict() {
    let s = load(
        "eta_walker",
        EAST,
        r#"
[[actors]]
kind = "pedestrian"
speed_mps = 1.5
waypoints = [{ x = 200.0, y = -8.5 }, { x = 200.0, y = 3.0 }]
start = { ego_eta_s = 3.5, of = [200.0, -4.8] }
at_end = "remove"
"#,
    );
    let e = run(&s, false);
    println!("expert {e:?}");
    assert!(e.reason == TerminationReason::DestinationReached && e.contacts.is_empty(), "{e:?}");
    assert!(e.obstacle_decisions > 0 && e.s_r4 >= 90.0, "{e:?}");
    let b = run(&s, true);
    println!("blind {b:?}");
    assert!(b.contacts.contains(&ContactClass::Pedestrian), "{b:?}");
}

#[test]
fn expert_brakes_for_a_cut_in() {
    // A slower car in the left lane moves into the ego's lane 15 m ahead of the ego's path.
    let s = load(
        "cut_in",
        EAST,
        r#"
[[actors]]
name = "cutter"
kind = "car"
route = { lanes = ["C2T_2", "T2E_1"], start_s = 45.0 }
speed_mps = 7.0
lane_changes = [{ at_s = 15.0, to_lane = "C2T_1", length_m = 15.0 }]
at_end = "remove"
"#,
    );
    let e = run(&s, false);
    println!("expert {e:?}");
    assert!(e.reason == TerminationReason::DestinationReached && e.contacts.is_empty(), "{e:?}");
    assert!(e.lead_decisions + e.obstacle_decisions > 0 && e.s_r4 >= 90.0, "{e:?}");
    let b = run(&s, true);
    println!("blind {b:?}");
    assert!(b.contacts.contains(&ContactClass::Vehicle), "{b:?}");
}

#[test]
fn expert_stops_at_a_red_that_only_the_override_makes() {
    // West approach to C, straight on; the map's program is east–west green for the first 42 s,
    // the override starts north–south green with 30 s gone: red for the ego until t = 15 s.
    let ego = "start = { lane = \"W2C_1\", s = 130.0 }\ndestination = { lane = \"C2T_1\", s = 60.0 }\nspeed_mps = 8.0";
    let lights = "[[lights]]\ntls = \"C\"\nstart_phase = 3\nphase_elapsed_s = 30.0\n";
    let s = load("red_override", ego, lights);
    let e = run(&s, false);
    println!("expert {e:?}");
    assert!(e.reason == TerminationReason::DestinationReached && e.red_lights_run == 0, "{e:?}");
    assert!(e.light_decisions > 0 && e.s_r4 >= 90.0, "{e:?}");
    let b = run(&s, true);
    println!("blind {b:?}");
    assert!(b.red_lights_run > 0, "the blind driver runs the override's red: {b:?}");
    // Without the override the light is green and the expert never stops for it.
    let free = run(&load("green_map", ego, ""), false);
    assert!(free.light_decisions == 0 && free.red_lights_run == 0, "{free:?}");
}
