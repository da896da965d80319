//! The episode core from Rust: determinism, misuse errors, rewards, and re-scoring from the log.

use dh_env::drive::Decision;
use dh_env::scenario::LoadOptions;
use dh_env::score::RunLog;
use dh_env::sim::{Action, ActionMode, Sim, SimConfig, STATE_FIELDS};
use dh_env::Error;
use std::path::PathBuf;

fn scenario(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/r4").join(rel)
}

fn no_images() -> SimConfig {
    SimConfig { front: None, bev: None, ..SimConfig::default() }
}

fn sim(rel: &str, config: SimConfig) -> Sim {
    Sim::new(&scenario(rel), config, &LoadOptions::default()).expect("scenario loads")
}

/// Drives a fixed, seeded action sequence; returns (trajectory hash, rewards, state bits).
fn drive(config: SimConfig) -> (String, Vec<f64>, Vec<u32>) {
    let mut s = sim("01_pedestrian/town01_midblock_crossing.toml", config);
    let (obs, _) = s.reset(42).unwrap();
    let mut state_bits: Vec<u32> = obs.state.iter().map(|v| v.to_bits()).collect();
    let mut rewards = Vec::new();
    for i in 0..60 {
        let steer = ((i * 37) % 11) as f64 / 100.0 - 0.05;
        let out = s.step(Action::Decision(Decision { steer, target_speed_mps: 7.0 })).unwrap();
        rewards.push(out.reward);
        state_bits.extend(out.observation.state.iter().map(|v| v.to_bits()));
        if out.terminated {
            break;
        }
    }
    (s.trajectory_hash().unwrap(), rewards, state_bits)
}

#[test]
fn same_seed_and_actions_give_identical_episodes() {
    let a = drive(no_images());
    let b = drive(no_images());
    assert_eq!(a, b);
    assert_eq!(a.0.len(), 64);
    // Rendering does not change the trajectory.
    let small = SimConfig {
        front: Some(dh_env::render::CameraConfig { width: 96, height: 54, ..Default::default() }),
        bev: Some(dh_env::render::BevConfig { size_px: 64, px_per_m: 2.0, route_dots_last: 3 }),
        ..SimConfig::default()
    };
    assert_eq!(drive(small).0, a.0);
}

#[test]
fn observation_has_state_prompt_and_images_as_configured() {
    let mut s = sim("03_turning/town01_right_turn_signalised.toml", SimConfig::default());
    let (obs, info) = s.reset(0).unwrap();
    assert_eq!(obs.state.len(), STATE_FIELDS.len());
    let front = obs.front.expect("front image");
    assert_eq!((front.width, front.height, front.data.len()), (800, 450, 800 * 450 * 3));
    let bev = obs.bev.expect("bev image");
    assert_eq!((bev.width, bev.height), (800, 800));
    assert!(obs.prompt.contains("Remaining route distance to destination is approximately"));
    assert_eq!(info.tick, 0);
}

#[test]
fn misuse_is_a_named_error_not_a_panic() {
    let mut s = sim("03_turning/town01_right_turn_signalised.toml", no_images());
    let act = Action::Decision(Decision { steer: 0.0, target_speed_mps: 1.0 });
    assert!(matches!(s.step(act), Err(Error::Simulation(m)) if m.contains("reset")));
    s.reset(0).unwrap();
    let nan = Action::Decision(Decision { steer: f64::NAN, target_speed_mps: 1.0 });
    assert!(matches!(s.step(nan), Err(Error::Config { field, .. }) if field == "action.steer"));
    let raw = Action::Raw(dh_env::drive::Control { throttle: 1.0, brake: 0.0, steer: 0.0 });
    assert!(matches!(s.step(raw), Err(Error::Config { .. })));
    let bad = SimConfig { decision_interval_ticks: 0, ..no_images() };
    assert!(Sim::new(
        &scenario("03_turning/town01_right_turn_signalised.toml"),
        bad,
        &LoadOptions::default()
    )
    .is_err());
    assert!(matches!(
        SimConfig::from_json(r#"{"action_mode": "decision", "zoom": 3}"#),
        Err(Error::Config { .. })
    ));
}

#[test]
fn raw_mode_applies_pedals_directly_and_rewards_sum_to_the_score() {
    let config = SimConfig { action_mode: ActionMode::Raw, ..no_images() };
    let mut s = sim("07_sudden_brake/town01_lead_brakes.toml", config);
    s.reset(0).unwrap();
    let mut total = 0.0;
    let mut terminated = false;
    for _ in 0..400 {
        let out =
            s.step(Action::Raw(dh_env::drive::Control { throttle: 0.0, brake: 1.0, steer: 0.0 })).unwrap();
        total += out.reward;
        assert_eq!(out.info.control.brake, 1.0);
        if out.terminated {
            terminated = true;
            break;
        }
    }
    assert!(terminated);
    let record = s.score_record().unwrap();
    assert_eq!(record.termination_reason.as_str(), "blocked_timeout");
    assert!((total - record.score_composed / 100.0).abs() < 1e-12);
}

#[test]
fn the_run_log_rescores_to_the_live_record() {
    let mut s = sim("01_pedestrian/town01_midblock_crossing.toml", no_images());
    s.reset(3).unwrap();
    for _ in 0..40 {
        let out = s.step(Action::Decision(Decision { steer: 0.0, target_speed_mps: 6.0 })).unwrap();
        if out.terminated {
            break;
        }
    }
    let live = s.score_record().unwrap();
    let log = RunLog::from_jsonl(&s.episode_log().unwrap(), "test").unwrap();
    let again = log.rescore().unwrap();
    assert_eq!(again.score_composed.to_bits(), live.score_composed.to_bits());
    assert_eq!(again.events, live.events);
    assert_eq!(again.termination_reason, live.termination_reason);
}
