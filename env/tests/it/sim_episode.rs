//! The episode core from Rust: determinism, misuse errors, rewards, and re-scoring from the log.

use dh_env::drive::Decision;
use dh_env::scenario::LoadOptions;
use dh_env::score::RunLog;
use dh_env::sim::{Action, ActionMode, Sim, SimConfig, STATE_FIELDS};
use dh_env::Error;
use std::path::PathBuf;

fn scenario(rel: &str) -> PathBuf {
    // The suite names its maps `builtin:NAME`; the Python package registers them, a test does.
    dh_env::scenario::set_builtin_maps_dir(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps"),
    );
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
    let mut s = sim("01_pedestrian/town01_01_midblock_crossing.toml", config);
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
        bev: Some(dh_env::render::BevConfig { size_px: 64, px_per_m: 2.0 }),
        ..SimConfig::default()
    };
    assert_eq!(drive(small).0, a.0);
}

#[test]
fn observation_has_state_prompt_and_images_as_configured() {
    let mut s = sim("03_turning/town01_03_right_turn_signalised.toml", SimConfig::default());
    let (obs, info) = s.reset(0).unwrap();
    assert_eq!(obs.state.len(), STATE_FIELDS.len());
    let front = obs.front.expect("front image");
    assert_eq!((front.width, front.height, front.data.len()), (800, 450, 800 * 450 * 3));
    let bev = obs.bev.expect("bev image");
    assert_eq!((bev.width, bev.height), (800, 800));
    assert!(obs.prompt.contains("Remaining route distance to destination is approximately"));
    // The original's warm-up: zero control on ticks 1–4, first decision with the state after tick 4.
    assert_eq!(info.tick, 4);
    assert_eq!(info.decision, 0);
    let mut s =
        sim("03_turning/town01_03_right_turn_signalised.toml", SimConfig { warmup_ticks: 0, ..no_images() });
    assert_eq!(s.reset(0).unwrap().1.tick, 0);
    let out = s.step(Action::Decision(Decision { steer: 0.0, target_speed_mps: 5.0 })).unwrap();
    assert_eq!((out.info.tick, out.info.decision), (5, 1));
}

#[test]
fn misuse_is_a_named_error_not_a_panic() {
    let mut s = sim("03_turning/town01_03_right_turn_signalised.toml", no_images());
    let act = Action::Decision(Decision { steer: 0.0, target_speed_mps: 1.0 });
    assert!(matches!(s.step(act), Err(Error::Simulation(m)) if m.contains("reset")));
    s.reset(0).unwrap();
    let nan = Action::Decision(Decision { steer: f64::NAN, target_speed_mps: 1.0 });
    assert!(matches!(s.step(nan), Err(Error::Config { field, .. }) if field == "action.steer"));
    let raw = Action::Raw(dh_env::drive::Control { throttle: 1.0, brake: 0.0, steer: 0.0 });
    assert!(matches!(s.step(raw), Err(Error::Config { .. })));
    let bad = SimConfig { decision_interval_ticks: 0, ..no_images() };
    assert!(Sim::new(
        &scenario("03_turning/town01_03_right_turn_signalised.toml"),
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
    let mut s = sim("07_sudden_brake/town01_07_lead_brakes.toml", config);
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
    let mut s = sim("01_pedestrian/town01_01_midblock_crossing.toml", no_images());
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

#[test]
fn a_failed_reply_holds_the_previous_control_verbatim() {
    use dh_env::drive::{Control, DecisionFailure};
    let ok = |raw: &str, steer: f64, target: f64| Action::Reply {
        raw: Some(raw.into()),
        parsed: Ok(Decision { steer, target_speed_mps: target }),
    };
    let scenario = "07_sudden_brake/town01_07_lead_brakes.toml";
    let mut s = sim(scenario, no_images());
    s.reset(0).unwrap();
    let first = s.step(ok("steer: 0.3\ntarget_speed_mps: 6", 0.3, 6.0)).unwrap();
    let held = first.info.control;
    assert_eq!(held.steer, 0.12); // rate-limited from 0
    let bad =
        Action::Reply { raw: Some("I would slow down.".into()), parsed: Err(DecisionFailure::MissingBoth) };
    let second = s.step(bad).unwrap();
    assert_eq!(second.info.control, held, "the control is held verbatim");
    assert_eq!(second.info.parse_failures, 1);
    let r = second.info.reply.as_ref().unwrap();
    assert_eq!((r.decision, r.tick, r.failure), (2, 9, Some(DecisionFailure::MissingBoth)));
    assert_eq!(r.raw.as_deref(), Some("I would slow down."));
    assert_eq!(r.parsed, None);
    // No reply at all (a transport error) is held and counted the same way.
    let none = Action::Reply { raw: None, parsed: Err(DecisionFailure::NoReply) };
    assert_eq!(s.step(none).unwrap().info.control, held);
    // The next valid reply rate-limits from the last *valid* steer (0.12), not from a failure.
    let next = s.step(ok("steer: 1", 1.0, 6.0)).unwrap();
    assert!((next.info.control.steer - 0.24).abs() < 1e-12);
    assert_eq!(s.score_record().unwrap().parse_failures, 2);
    let log = s.decision_log().unwrap();
    assert_eq!(log.len(), 4);
    assert_eq!(log.iter().map(|d| d.tick).collect::<Vec<_>>(), vec![4, 9, 14, 19]);

    // The ticks after the failure ran with exactly the held control: a raw-mode run applying
    // it twice has the same trajectory.
    let mut raw = sim(scenario, SimConfig { action_mode: ActionMode::Raw, ..no_images() });
    raw.reset(0).unwrap();
    let c = Control { ..held };
    raw.step(Action::Raw(c)).unwrap();
    let raw_second = raw.step(Action::Raw(c)).unwrap();
    assert_eq!(raw_second.info.trajectory_hash, second.info.trajectory_hash);
}

#[test]
fn scenario_duration_sets_the_timeout_and_defaults_to_the_longest_actor() {
    // Default: the longest estimated duration over the actors, at least T_ref.
    let s = sim("07_sudden_brake/town01_07_lead_brakes.toml", no_images());
    let sc = s.scenario();
    assert_eq!(sc.duration_given_s, None);
    assert!(sc.scenario_duration_s() >= sc.reference_duration_s());

    // Given: `duration_s` is the scenario duration; T_ref stays the efficiency reference.
    // Its actors dropped: the lead paces itself ahead of the ego and would brake in front of the
    // creeping ego below.
    let text = std::fs::read_to_string(scenario("07_sudden_brake/town01_07_lead_brakes.toml")).unwrap();
    let text = text.split("[[actors]]").next().unwrap();
    let map = scenario("../maps/town01/town01.net.xml").canonicalize().unwrap();
    let text = text
        .replace("map = \"builtin:town01\"", &format!("map = {:?}\nduration_s = 12.5", map))
        .replace("reference_duration_s = 44.0", "reference_duration_s = 5.0");
    let dir = std::env::temp_dir().join(format!("dh-duration-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("short.toml");
    std::fs::write(&path, text).unwrap();
    let mut s = Sim::new(&path, no_images(), &LoadOptions::default()).unwrap();
    assert_eq!(s.scenario().scenario_duration_s(), 12.5);
    s.reset(0).unwrap();
    // Creep at 2 m/s so neither the blocked timeout nor the destination ends it first.
    let mut end = None;
    for _ in 0..200 {
        let out = s.step(Action::Decision(Decision { steer: 0.0, target_speed_mps: 2.0 })).unwrap();
        if out.terminated {
            end = Some(out.info);
            break;
        }
    }
    let info = end.expect("terminates");
    assert_eq!(info.termination_reason.as_deref(), Some("scenario_timeout"));
    assert_eq!(info.tick, 500); // 2 × 12.5 s, not 2 × T_ref = 10 s
    let rec = s.score_record().unwrap();
    assert_eq!((rec.meta.scenario_duration_s, rec.meta.max_sim_time_s), (12.5, 25.0));
    assert_eq!(rec.meta.reference_duration_s, 5.0);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_frame_snapshot_renders_its_moment_after_the_world_moved_on() {
    use dh_env::render::{BevConfig, CameraConfig, Image};
    let cam = CameraConfig { width: 160, height: 90, ..Default::default() };
    let bev = BevConfig { size_px: 128, px_per_m: 2.0 };
    let mut s = sim("01_pedestrian/town01_01_midblock_crossing.toml", no_images());
    s.reset(0).unwrap();
    let mut kept = Vec::new();
    for i in 0..40 {
        if i % 10 == 0 {
            let (mut front, mut top) = (Image::default(), Image::default());
            s.render_camera(&cam, &mut front).unwrap();
            s.render_bev(&bev, &mut top).unwrap();
            kept.push((s.frame_snapshot().unwrap(), front, top));
        }
        s.step(Action::Decision(Decision { steer: 0.0, target_speed_mps: 6.0 })).unwrap();
    }
    let mut now = Image::default();
    s.render_camera(&cam, &mut now).unwrap();
    for (snap, front, top) in &kept {
        let (mut f, mut b) = (Image::default(), Image::default());
        snap.render_camera(&cam, &mut f).unwrap();
        snap.render_bev(&bev, &mut b).unwrap();
        assert_eq!(f.data, front.data);
        assert_eq!(b.data, top.data);
        assert_ne!(f.data, now.data, "the ego moved on: the snapshot is not the present");
    }
    assert!(Sim::new(
        &scenario("01_pedestrian/town01_01_midblock_crossing.toml"),
        no_images(),
        &LoadOptions::default()
    )
    .unwrap()
    .frame_snapshot()
    .is_err());
}
