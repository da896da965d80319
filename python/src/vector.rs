//! `SimBatch`: N R4 episodes stepped on a rayon pool with the GIL released (`dh_env::batch`),
//! for the native vector env (`drivehierarchy.envs.vector_native`). Observations leave as one
//! (N, …) numpy array per key; infos as one dict per env, shaped exactly like `Sim`'s.

use crate::env::{err, map_cache};
use crate::json::{from_py, to_py};
use dh_env::batch::{BatchOp, BatchOutcome, SimBatch};
use dh_env::render::Image;
use dh_env::scenario::LoadOptions;
use dh_env::sim::{Sim, SimConfig};
use dh_env::world::TrafficModel;
use numpy::ndarray::{Array2, Array4};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use std::path::{Path, PathBuf};

#[pyclass(name = "SimBatch", module = "drivehierarchy._core")]
pub struct PySimBatch {
    inner: SimBatch,
    config: SimConfig,
    traffic: Option<String>,
    sumo_home: Option<PathBuf>,
}

/// One env's episode with its background traffic; SUMO is refused (see `docs/baselines.md`).
fn load_sim(
    path: &str,
    config: SimConfig,
    traffic: Option<&str>,
    sumo_home: Option<PathBuf>,
) -> dh_env::Result<Sim> {
    let load = LoadOptions { sumo_home, cache: Some(map_cache()) };
    let mut sim = Sim::new(Path::new(path), config, &load)?;
    let mode = traffic.unwrap_or(sim.scenario().traffic.mode.as_str());
    let model: Option<Box<dyn TrafficModel>> = match mode {
        "none" => None,
        "idm" => Some(Box::new(dh_env::world::idm::IdmTraffic::new(sim.scenario())?)),
        "sumo" => {
            return Err(dh_env::Error::config(
                "traffic",
                format!("'sumo' (scenario {})", sim.scenario().id),
                "the native vector env runs no SUMO (every world would need its own SUMO \
                 process): pass traffic=\"idm\" for the Rust IDM traffic, or vectorise SUMO \
                 envs over processes with drivehierarchy.envs.traffic.sumo_vector_env",
            ))
        }
        other => return Err(dh_env::Error::config("traffic", other, "expected 'sumo', 'idm' or 'none'")),
    };
    sim.set_traffic(model);
    Ok(sim)
}

#[pymethods]
impl PySimBatch {
    /// One env per entry of `scenarios` (paths), all with `config` (an `R4Config`'s core settings
    /// as a dataclass or dict); `traffic` = None
    /// takes each scenario's own mode; `threads` = 0: one worker per core.
    #[new]
    #[pyo3(signature = (scenarios, config, traffic=None, sumo_home=None, threads=0))]
    fn new(
        py: Python<'_>,
        scenarios: Vec<String>,
        config: &Bound<'_, PyAny>,
        traffic: Option<String>,
        sumo_home: Option<PathBuf>,
        threads: usize,
    ) -> PyResult<Self> {
        let config: SimConfig = from_py("config", config).map_err(|e| err(py, e))?;
        config.validate().map_err(|e| err(py, e))?;
        let inner = py
            .detach(|| {
                let sims = scenarios
                    .iter()
                    .map(|p| load_sim(p, config.clone(), traffic.as_deref(), sumo_home.clone()))
                    .collect::<dh_env::Result<Vec<Sim>>>()?;
                SimBatch::new(sims, threads)
            })
            .map_err(|e| err(py, e))?;
        Ok(PySimBatch { inner, config, traffic, sumo_home })
    }

    /// Env `index` plays the scenario at `path` from its next reset.
    fn load(&mut self, py: Python<'_>, index: usize, path: &str) -> PyResult<()> {
        let (config, traffic, home) = (self.config.clone(), self.traffic.clone(), self.sumo_home.clone());
        let sim = py.detach(|| load_sim(path, config, traffic.as_deref(), home)).map_err(|e| err(py, e))?;
        self.inner.replace(index, sim).map_err(|e| err(py, e))
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// Each env's scenario id.
    #[getter]
    fn scenario_ids(&self) -> Vec<String> {
        self.inner.sims().iter().map(|s| s.scenario().id.clone()).collect()
    }

    /// Each env's traffic model ("native") or None.
    #[getter]
    fn traffic(&self) -> Vec<Option<String>> {
        self.inner.sims().iter().map(|s| s.traffic_name().map(str::to_owned)).collect()
    }

    /// Env `index`'s scene score record so far (final once terminated), as a dict.
    fn score<'py>(&self, py: Python<'py>, index: usize) -> PyResult<Bound<'py, PyAny>> {
        let sim = self.sim(py, index)?;
        let rec = sim.score_record().map_err(|e| err(py, e))?;
        let v = serde_json::to_value(&rec).map_err(|e| err(py, dh_env::Error::Simulation(e.to_string())))?;
        to_py(py, &v)
    }

    /// One parallel pass: env i resets with `resets[i]` = (world seed, variation) when given,
    /// else steps with row i of `actions` (N × 2 decisions or N × 3 raw controls). Returns
    /// `(observations, rewards, terminated, infos)`: observations a dict of (N, …) arrays plus
    /// `prompt` (a tuple of N str), infos a list of N dicts. A reset pays 0 and is not terminal.
    #[allow(clippy::type_complexity)]
    #[pyo3(signature = (resets, actions=None))]
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        resets: Vec<Option<(u64, u64)>>,
        actions: Option<PyReadonlyArray2<'py, f64>>,
    ) -> PyResult<(
        Bound<'py, PyDict>,
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<bool>>,
        Bound<'py, PyList>,
    )> {
        let n = self.inner.len();
        if resets.len() != n {
            return Err(err(
                py,
                dh_env::Error::config("resets", resets.len(), format!("expected {n} entries")),
            ));
        }
        let mode = self.config.action_mode;
        let width = crate::env::action_width(&self.config, mode);
        let view = actions.as_ref().map(|a| a.as_array());
        if let Some(v) = &view {
            if v.shape() != [n, width] {
                return Err(err(
                    py,
                    dh_env::Error::config(
                        "actions",
                        format!("{:?}", v.shape()),
                        format!("expected shape ({n}, {width})"),
                    ),
                ));
            }
        }
        let mut ops = Vec::with_capacity(n);
        for (i, reset) in resets.into_iter().enumerate() {
            ops.push(match (reset, &view) {
                (Some((seed, variation)), _) => BatchOp::Reset { seed, variation },
                (None, Some(v)) => {
                    let row: Vec<f64> = v.row(i).iter().copied().collect();
                    BatchOp::Step(crate::env::action_from_row(&self.config, &row).map_err(|e| err(py, e))?)
                }
                (None, None) => {
                    return Err(err(
                        py,
                        dh_env::Error::config(
                            "actions",
                            "None",
                            format!("env {i} steps and needs an action"),
                        ),
                    ));
                }
            });
        }
        let inner = &mut self.inner;
        let outs = py.detach(|| inner.run(ops)).map_err(|e| err(py, e))?;
        let rewards: Vec<f64> = outs.iter().map(|o| o.reward).collect();
        let terminated: Vec<bool> = outs.iter().map(|o| o.terminated).collect();
        let infos = PyList::empty(py);
        for o in &outs {
            let v = serde_json::to_value(&o.info)
                .map_err(|e| err(py, dh_env::Error::Simulation(e.to_string())))?;
            infos.append(to_py(py, &v)?)?;
        }
        let obs = batch_obs(py, outs)?;
        Ok((obs, PyArray1::from_vec(py, rewards), PyArray1::from_vec(py, terminated), infos))
    }

    /// Resets env i with `resets[i]` = (world seed, variation) where given and leaves the
    /// others as they are (a vector env's `reset_mask`). Returns `(observations, infos)` of the
    /// reset envs only, in env order: a dict of (k, …) arrays and a list of k dicts.
    fn reset_some<'py>(
        &mut self,
        py: Python<'py>,
        resets: Vec<Option<(u64, u64)>>,
    ) -> PyResult<(Bound<'py, PyDict>, Bound<'py, PyList>)> {
        let n = self.inner.len();
        if resets.len() != n {
            return Err(err(
                py,
                dh_env::Error::config("resets", resets.len(), format!("expected {n} entries")),
            ));
        }
        if resets.iter().all(Option::is_none) {
            return Err(err(py, dh_env::Error::config("resets", "all None", "expected at least one reset")));
        }
        let ops = resets
            .into_iter()
            .map(|r| r.map(|(seed, variation)| BatchOp::Reset { seed, variation }))
            .collect();
        let inner = &mut self.inner;
        let outs: Vec<BatchOutcome> =
            py.detach(|| inner.run_some(ops)).map_err(|e| err(py, e))?.into_iter().flatten().collect();
        let infos = PyList::empty(py);
        for o in &outs {
            let v = serde_json::to_value(&o.info)
                .map_err(|e| err(py, dh_env::Error::Simulation(e.to_string())))?;
            infos.append(to_py(py, &v)?)?;
        }
        Ok((batch_obs(py, outs)?, infos))
    }
}

impl PySimBatch {
    fn sim(&self, py: Python<'_>, index: usize) -> PyResult<&Sim> {
        let n = self.inner.len();
        self.inner
            .sims()
            .get(index)
            .ok_or_else(|| err(py, dh_env::Error::config("index", index, format!("the batch has {n} envs"))))
    }
}

/// Stacks the N observations: `state` (N, F) float32, images (N, H, W, 3) uint8.
fn batch_obs(py: Python<'_>, outs: Vec<BatchOutcome>) -> PyResult<Bound<'_, PyDict>> {
    let n = outs.len();
    let d = PyDict::new(py);
    let width = outs.first().map_or(0, |o| o.observation.state.len());
    let mut state = Vec::with_capacity(n * width);
    let mut prompts = Vec::with_capacity(n);
    let mut fronts = Vec::new();
    let mut bevs = Vec::new();
    for o in outs {
        let ob = o.observation;
        state.extend_from_slice(&ob.state);
        prompts.push(ob.prompt);
        fronts.extend(ob.front);
        bevs.extend(ob.bev);
    }
    let state = Array2::from_shape_vec((n, width), state)
        .map_err(|e| err(py, dh_env::Error::Simulation(format!("state batch: {e}"))))?;
    d.set_item("state", state.into_pyarray(py))?;
    d.set_item("prompt", PyTuple::new(py, prompts)?)?;
    if !fronts.is_empty() {
        d.set_item("front", stack_images(py, fronts)?)?;
    }
    if !bevs.is_empty() {
        d.set_item("bev", stack_images(py, bevs)?)?;
    }
    Ok(d)
}

fn stack_images(py: Python<'_>, imgs: Vec<Image>) -> PyResult<Bound<'_, PyAny>> {
    let (w, h) = (imgs[0].width as usize, imgs[0].height as usize);
    let mut data = Vec::with_capacity(imgs.len() * w * h * 3);
    for img in &imgs {
        data.extend_from_slice(&img.data);
    }
    let arr = Array4::from_shape_vec((imgs.len(), h, w, 3), data)
        .map_err(|e| err(py, dh_env::Error::Render(format!("image batch: {e}"))))?;
    Ok(arr.into_pyarray(py).into_any())
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySimBatch>()
}
