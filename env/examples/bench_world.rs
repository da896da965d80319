//! Ticks per second of the world without images: the fixture crossing with 30 actors
//! (scripted cars, pedestrians, obstacles), one core.
//!
//! `cargo run --release -p dh-env --example bench_world [SCENARIO.toml] [TICKS]`

use dh_env::drive::Control;
use dh_env::scenario::{ActorMotion, AtEnd, ResolvedActor, Scenario, Trigger};
use dh_env::world::World;
use std::path::PathBuf;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/world_fixtures/cross.toml"));
    let ticks: u64 = args.next().map(|t| t.parse()).transpose()?.unwrap_or(40_000);
    let mut s = Scenario::load(&path)?;
    // Pad to 30 actors: copies of the scripted ones with staggered starts, then cones.
    let scripted: Vec<ResolvedActor> =
        s.actors.iter().filter(|a| matches!(a.motion, ActorMotion::Scripted(_))).cloned().collect();
    let mut k = 0usize;
    while s.actors.len() < 30 && !scripted.is_empty() {
        let mut a = scripted[k % scripted.len()].clone();
        if let ActorMotion::Scripted(p) = &mut a.motion {
            p.trigger = Trigger::Time(0.5 * k as f64);
            p.at_end = AtEnd::Stop;
        }
        a.name = format!("copy{k}");
        s.actors.push(a);
        k += 1;
    }
    let n_actors = s.actors.len();
    let t_new = Instant::now();
    for _ in 0..20 {
        let _ = World::new(&s, 0)?;
    }
    let new_ms = t_new.elapsed().as_secs_f64() * 1e3 / 20.0;
    let mut w1 = World::new(&s, 0)?;
    let t_first = Instant::now();
    w1.tick(&Control::default())?;
    let first_us = t_first.elapsed().as_secs_f64() * 1e6;
    let mut w = World::new(&s, 0)?;
    let mut contacts = 0usize;
    let mut off = 0usize;
    let t0 = Instant::now();
    for i in 0..ticks {
        // Gentle weave at low speed keeps the ego on the map for the whole run.
        let steer = ((i as f64) * 0.01).sin() * 0.05;
        let c = if w.ego().speed_mps < 3.0 {
            Control { throttle: 0.3, brake: 0.0, steer }
        } else {
            Control { throttle: 0.0, brake: 0.1, steer }
        };
        let r = w.tick(&c)?;
        contacts += r.contacts.len();
        off += usize::from(!r.on_road);
        if i % 800 == 799 {
            // Restart the episode periodically so the actors keep moving.
            w = World::new(&s, 0)?;
        }
    }
    let dt = t0.elapsed().as_secs_f64();
    println!("World::new {new_ms:.3} ms, first tick {first_us:.1} µs");
    println!(
        "bench_world: {ticks} ticks with {n_actors} actors in {dt:.3} s = {:.0} ticks/s (contacts {contacts}, off-road ticks {off}; includes {} World::new)",
        ticks as f64 / dt,
        ticks / 800
    );
    Ok(())
}
