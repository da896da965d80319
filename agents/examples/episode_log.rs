//! `cargo run -p dh-agents --example episode_log -- SCENARIO.toml [MAX_DECISIONS] [reckless]`:
//! drives the scenario through the protocol's env (no rendering) with the privileged expert, or
//! with `reckless` straight ahead at 15 m/s (to get contacts and violations), and prints the
//! episode's run log (JSONL, what `r4 rescore` reads). Used to make the fuzzing seeds of the
//! run-log reader (`fuzz/seeds/run_log/`).

use dh_agents::expert::{Expert, ExpertParams};
use dh_env::drive::bridge::Decision;
use dh_env::scenario::LoadOptions;
use dh_env::sim::{Action, Sim, SimConfig};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let file = args.next().ok_or("usage: episode_log SCENARIO.toml [MAX_DECISIONS] [reckless]")?;
    let max_decisions: u64 = args.next().map_or(Ok(u64::MAX), |s| s.parse())?;
    let reckless = args.next().is_some_and(|s| s == "reckless");
    let config = SimConfig { front: None, bev: None, prompt: false, ..SimConfig::default() };
    let mut sim = Sim::new(Path::new(&file), config, &LoadOptions::default())?;
    let mut expert = Expert::new(ExpertParams::default())?;
    sim.reset(sim.scenario().seed)?;
    let route = sim.scenario().ego.route.clone();
    let mut decisions = 0;
    while !sim.is_terminated() && decisions < max_decisions {
        let d = if reckless {
            Decision { steer: 0.0, target_speed_mps: 15.0 }
        } else {
            expert.act_in_world(sim.world()?, &route).into()
        };
        sim.step(Action::Decision(d))?;
        decisions += 1;
    }
    print!("{}", sim.episode_log()?);
    Ok(())
}
