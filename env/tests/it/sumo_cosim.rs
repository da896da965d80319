//! The SUMO orchestration (`world::sumo`) with live traffic, on every shim transport: libsumo
//! in this process and TraCI to a `sumo` subprocess. Skips (passing, with a note) when this
//! build has no SUMO shims or no SUMO installation is found (`SumoHome::locate`, docs/traffic.md
//! "Where SUMO is found").

use dh_env::drive::{Control, Decision};
use dh_env::scenario::LoadOptions;
use dh_env::sim::{Action, ActionMode, Sim, SimConfig};
use dh_env::world::sumo::{shim, Flavour, ShimTransport, SumoCoSim, SumoHome, SumoSession};
use sha2::{Digest, Sha256};
use std::path::PathBuf;
use std::sync::Mutex;

/// libsumo runs one simulation per process: tests using it take turns.
static LIBSUMO: Mutex<()> = Mutex::new(());

fn bench() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/bench/town01_sumo_traffic.toml")
}

fn home() -> Option<SumoHome> {
    if shim::BUILT_SHIM_DIR.is_none() {
        eprintln!("skipped: this build has no SUMO shims (no SUMO headers at build time)");
        return None;
    }
    let home = SumoHome::locate();
    if home.as_ref().is_none_or(|h| !h.binary().is_file()) {
        eprintln!("skipped: no SUMO installation (SUMO_HOME or the `sumo` Python package)");
        return None;
    }
    home
}

fn session(flavour: Flavour, home: &SumoHome) -> dh_env::world::sumo::SharedSession {
    let t = ShimTransport::built(flavour, home).expect("the shim loads");
    SumoSession::new(Box::new(t), home.binary(), Vec::new()).shared()
}

fn sim(flavour: Flavour, home: &SumoHome, mode: ActionMode) -> Sim {
    let config = SimConfig { front: None, bev: None, action_mode: mode, ..SimConfig::default() };
    let mut s = Sim::new(&bench(), config, &LoadOptions::default()).expect("scenario loads");
    let model = SumoCoSim::new(session(flavour, home), s.scenario());
    s.set_traffic(Some(Box::new(model)));
    s
}

/// SUMO vehicles in the world now.
fn traffic(s: &Sim) -> usize {
    let w = s.world().unwrap();
    w.actors().iter().filter(|a| w.is_traffic_actor(a.id)).count()
}

/// Digest of every actor (traffic included) after each step, the vehicle counts and the
/// trajectory hash of a fixed drive.
fn drive(s: &mut Sim, seed: u64, steps: usize) -> (String, Vec<usize>, String) {
    s.reset(seed).expect("SUMO starts");
    let mut digest = Sha256::new();
    let mut counts = vec![traffic(s)];
    for i in 0..steps {
        let steer = ((i * 37) % 11) as f64 / 200.0 - 0.025;
        let out = s.step(Action::Decision(Decision { steer, target_speed_mps: 7.0 })).expect("a step");
        for a in s.world().unwrap().actors() {
            digest.update(a.id.to_le_bytes());
            for v in [a.pose.pos.x, a.pose.pos.y, a.pose.yaw, a.speed_mps] {
                digest.update(v.to_bits().to_le_bytes());
            }
        }
        counts.push(traffic(s));
        if out.terminated {
            break;
        }
    }
    let hex: String = digest.finalize().iter().map(|b| format!("{b:02x}")).collect();
    (hex, counts, s.trajectory_hash().unwrap())
}

#[test]
fn libsumo_and_traci_give_the_same_live_traffic() {
    let Some(home) = home() else { return };
    let _one = LIBSUMO.lock().unwrap_or_else(|p| p.into_inner());
    let a = drive(&mut sim(Flavour::Libsumo, &home, ActionMode::Decision), 5, 60);
    assert!(a.1[0] >= 40, "SUMO's start traffic: {:?}", &a.1[..3]);
    let b = drive(&mut sim(Flavour::Libsumo, &home, ActionMode::Decision), 5, 60);
    assert_eq!(a, b, "deterministic across runs");
    let c = drive(&mut sim(Flavour::Traci, &home, ActionMode::Decision), 5, 60);
    assert_eq!(a, c, "TraCI gives libsumo's traffic");
    let d = drive(&mut sim(Flavour::Libsumo, &home, ActionMode::Decision), 6, 60);
    assert_ne!(a.0, d.0, "another seed, other traffic");
}

#[test]
fn several_simulations_run_side_by_side_over_traci() {
    let Some(home) = home() else { return };
    let _one = LIBSUMO.lock().unwrap_or_else(|p| p.into_inner());
    // One libsumo and two TraCI simulations, stepped in turn in one process.
    let mut sims = [
        sim(Flavour::Libsumo, &home, ActionMode::Decision),
        sim(Flavour::Traci, &home, ActionMode::Decision),
        sim(Flavour::Traci, &home, ActionMode::Decision),
    ];
    for (i, s) in sims.iter_mut().enumerate() {
        s.reset(5 + i as u64).expect("SUMO starts");
    }
    for _ in 0..20 {
        for s in sims.iter_mut() {
            s.step(Action::Decision(Decision { steer: 0.0, target_speed_mps: 7.0 })).expect("a step");
        }
    }
    let counts: Vec<usize> = sims.iter().map(traffic).collect();
    assert!(counts.iter().all(|&n| n >= 40), "{counts:?}");
    // A second libsumo simulation is refused while the first runs.
    let mut second = sim(Flavour::Libsumo, &home, ActionMode::Decision);
    let e = second.reset(0).expect_err("one libsumo per process");
    assert!(e.to_string().contains("one simulation per process"), "{e}");
}

#[test]
fn full_lock_off_the_network_steps_to_a_termination() {
    let Some(home) = home() else { return };
    let _one = LIBSUMO.lock().unwrap_or_else(|p| p.into_inner());
    for flavour in [Flavour::Libsumo, Flavour::Traci] {
        let mut s = sim(flavour, &home, ActionMode::Raw);
        s.reset(0).expect("SUMO starts");
        let mut reason = None;
        for _ in 0..2000 {
            let out = s.step(Action::Raw(Control { throttle: 1.0, brake: 0.0, steer: 1.0 })).expect("a step");
            if out.terminated {
                reason = out.info.termination_reason;
                break;
            }
        }
        let reason = reason.expect("the protocol ends the episode");
        assert!(!reason.contains("system_error"), "{flavour:?}: {reason}");
    }
}
