//! A batch of R4 episodes stepped in parallel: the core of the native vector env.
//!
//! Each [`Sim`] owns its world, so the batch hands one `&mut Sim` to each task of a rayon pool
//! and collects the outcomes in env order. Results never depend on the pool's size or
//! scheduling: worlds share nothing mutable.

use crate::sim::{Action, Observation, Sim, StepInfo};
use crate::{Error, Result};
use rayon::prelude::*;

/// What one env of the batch does in a [`SimBatch::run`] call.
#[derive(Debug, Clone)]
pub enum BatchOp {
    /// Starts a new episode: world seed and scenario variation, as [`Sim::reset_varied`].
    Reset { seed: u64, variation: u64 },
    /// One decision of the running episode.
    Step(Action),
}

/// One env's result of a [`SimBatch::run`] call (a reset pays no reward and never terminates).
#[derive(Debug, Clone)]
pub struct BatchOutcome {
    pub observation: Observation,
    pub reward: f64,
    pub terminated: bool,
    pub info: StepInfo,
}

/// N episodes and the thread pool that steps them.
#[derive(Debug)]
pub struct SimBatch {
    sims: Vec<Sim>,
    pool: rayon::ThreadPool,
}

impl SimBatch {
    /// `threads` = 0: one per available core.
    pub fn new(sims: Vec<Sim>, threads: usize) -> Result<SimBatch> {
        if sims.is_empty() {
            return Err(Error::config("num_envs", "0", "expected at least one env"));
        }
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .thread_name(|i| format!("dh-batch-{i}"))
            .build()
            .map_err(|e| Error::Simulation(format!("cannot start the batch's thread pool: {e}")))?;
        Ok(SimBatch { sims, pool })
    }

    pub fn len(&self) -> usize {
        self.sims.len()
    }

    pub fn is_empty(&self) -> bool {
        self.sims.is_empty()
    }

    pub fn sims(&self) -> &[Sim] {
        &self.sims
    }

    /// Replaces env `index`'s episode (another scenario); it needs a reset before stepping.
    pub fn replace(&mut self, index: usize, sim: Sim) -> Result<()> {
        let n = self.sims.len();
        let slot = self
            .sims
            .get_mut(index)
            .ok_or_else(|| Error::config("index", index.to_string(), format!("the batch has {n} envs")))?;
        *slot = sim;
        Ok(())
    }

    /// Applies `ops[i]` to env i, all envs in parallel; outcomes in env order. An env's failure
    /// is returned as the first failing env's error, naming it; the other envs' ops have run.
    pub fn run(&mut self, ops: Vec<BatchOp>) -> Result<Vec<BatchOutcome>> {
        let outs = self.run_some(ops.into_iter().map(Some).collect())?;
        Ok(outs.into_iter().flatten().collect())
    }

    /// As [`SimBatch::run`], but env i is left as it is where `ops[i]` is `None` (its outcome is
    /// `None`): the partial reset of a vector env's `reset_mask`.
    pub fn run_some(&mut self, ops: Vec<Option<BatchOp>>) -> Result<Vec<Option<BatchOutcome>>> {
        if ops.len() != self.sims.len() {
            return Err(Error::config(
                "ops",
                ops.len().to_string(),
                format!("expected one op per env ({})", self.sims.len()),
            ));
        }
        let sims = &mut self.sims;
        let results: Vec<Result<Option<BatchOutcome>>> = self.pool.install(|| {
            sims.par_iter_mut()
                .zip(ops)
                .map(|(sim, op)| match op {
                    None => Ok(None),
                    Some(BatchOp::Reset { seed, variation }) => {
                        sim.reset_varied(seed, variation).map(|(observation, info)| {
                            Some(BatchOutcome { observation, reward: 0.0, terminated: false, info })
                        })
                    }
                    Some(BatchOp::Step(action)) => sim.step(action).map(|o| {
                        Some(BatchOutcome {
                            observation: o.observation,
                            reward: o.reward,
                            terminated: o.terminated,
                            info: o.info,
                        })
                    }),
                })
                .collect()
        });
        results.into_iter().enumerate().map(|(i, r)| r.map_err(|e| name_env(i, e))).collect()
    }
}

/// The error with the env index in its message (its kind, hence Python class, kept).
fn name_env(index: usize, e: Error) -> Error {
    match e {
        Error::Simulation(m) => Error::Simulation(format!("env {index} of the batch: {m}")),
        Error::Render(m) => Error::Render(format!("env {index} of the batch: {m}")),
        Error::Config { field, value, message } => {
            Error::Config { field: format!("envs[{index}].{field}"), value, message }
        }
        other => other,
    }
}
