//! Open-loop (R1–R3) scoring and calibration: thin wrappers over `dh-benchmark`.

use std::collections::BTreeMap;
use std::path::PathBuf;

use dh_benchmark::aggregate::{self, TaskOutcome};
use dh_benchmark::calibrate::{self, CalibrationParams};
use dh_benchmark::predictions::{self, Layout};
use dh_benchmark::pyjson::PyValue;
use dh_benchmark::{Rank, ScoreOptions, TaskId, TASKS};
use pyo3::exceptions::PyOSError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use pythonize::{depythonize, pythonize};

/// Data errors become `drivehierarchy.ConfigError` (a ValueError); I/O errors `OSError`.
fn to_pyerr(py: Python<'_>, err: dh_benchmark::Error) -> PyErr {
    if let dh_benchmark::Error::Io { .. } = err {
        return PyOSError::new_err(err.to_string());
    }
    config_error(py, err.to_string())
}

fn config_error(py: Python<'_>, msg: String) -> PyErr {
    match py.import("drivehierarchy._core").and_then(|m| m.getattr("ConfigError")) {
        Ok(cls) => match cls.call1((msg,)) {
            Ok(v) => PyErr::from_value(v),
            Err(e) => e,
        },
        Err(e) => e,
    }
}

fn task_of(py: Python<'_>, id: &str) -> PyResult<TaskId> {
    TaskId::parse(id).map_err(|e| to_pyerr(py, e))
}

fn options(strict_order: bool) -> ScoreOptions {
    ScoreOptions { strict_order, ..ScoreOptions::default() }
}

/// The 14 tasks: id, name (file stem), rank, answer kind, scorer, task_type, metric, weight.
#[pyfunction]
fn openloop_tasks(py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
    let out = PyList::empty(py);
    for t in TASKS.iter() {
        let d = PyDict::new(py);
        d.set_item("id", t.name)?;
        d.set_item("stem", t.stem)?;
        d.set_item("legacy_stem", t.legacy_stem)?;
        d.set_item("rank", t.rank.as_str())?;
        d.set_item(
            "answer_kind",
            serde_json::to_value(t.answer).ok().and_then(|v| v.as_str().map(str::to_string)),
        )?;
        d.set_item("scorer", t.scorer.task_type())?;
        d.set_item("metric", t.scorer.metric())?;
        d.set_item("weight", t.weight)?;
        out.append(d)?;
    }
    Ok(out)
}

/// Task id of a file stem (released, legacy, `_pred`-suffixed or a bare id).
#[pyfunction]
fn openloop_task_from_stem(py: Python<'_>, stem: &str) -> PyResult<&'static str> {
    TaskId::from_stem(stem).map(TaskId::as_str).map_err(|e| to_pyerr(py, e))
}

/// A released record (or an answer) as the JSON value it was read from.
fn json_value(py: Python<'_>, what: &str, obj: &Bound<'_, PyAny>) -> PyResult<serde_json::Value> {
    depythonize(obj).map_err(|e| config_error(py, format!("{what}: not plain JSON data: {e}")))
}

/// Task id of a released record (a dict as `json.loads` reads it).
#[pyfunction]
fn openloop_task_from_record(py: Python<'_>, record: &Bound<'_, PyAny>) -> PyResult<&'static str> {
    let v = json_value(py, "record", record)?;
    TaskId::from_record(&v).map(TaskId::as_str).map_err(|e| to_pyerr(py, e))
}

/// Scores one reply against a ground truth (the record's `answer`, `ground_truth` or
/// `ground_truth_order` value, as `json.loads` reads it). Returns (score, parsed).
#[pyfunction]
#[pyo3(signature = (task_id, ground_truth, prediction, strict_order = false))]
fn openloop_score_answer(
    py: Python<'_>,
    task_id: &str,
    ground_truth: &Bound<'_, PyAny>,
    prediction: &str,
    strict_order: bool,
) -> PyResult<(f64, bool)> {
    let task = task_of(py, task_id)?;
    let gt = json_value(py, "ground truth", ground_truth)?;
    dh_benchmark::score_answer(task.scorer(), &PyValue::from_json(&gt), prediction, &options(strict_order))
        .map(|s| (s.score, s.parsed))
        .ok_or_else(|| config_error(py, format!("{task} is scored by the judge, not by rules")))
}

/// Scores a batch of one task: records as dicts (as `json.loads` reads them), replies as
/// strings. Returns (scores, parsed). R1_4 (judge-scored) is refused.
#[pyfunction]
#[pyo3(signature = (task_id, records, predictions, strict_order = false))]
fn openloop_score_task(
    py: Python<'_>,
    task_id: &str,
    records: Vec<Bound<'_, PyAny>>,
    predictions: Vec<String>,
    strict_order: bool,
) -> PyResult<(Vec<f64>, Vec<bool>)> {
    let task = task_of(py, task_id)?;
    if records.len() != predictions.len() {
        return Err(config_error(
            py,
            format!("{} records but {} predictions", records.len(), predictions.len()),
        ));
    }
    let records = records
        .iter()
        .enumerate()
        .map(|(i, r)| json_value(py, &format!("records[{i}]"), r))
        .collect::<PyResult<Vec<_>>>()?;
    let opts = options(strict_order);
    let res: Result<(Vec<f64>, Vec<bool>), String> = py.detach(|| {
        let mut scores = Vec::with_capacity(records.len());
        let mut parsed = Vec::with_capacity(records.len());
        for (i, (v, p)) in records.iter().zip(&predictions).enumerate() {
            let ctx = format!("records[{i}]");
            match dh_benchmark::score_record(task, v, p, &opts, &ctx) {
                Ok(Some(s)) => {
                    scores.push(s.score);
                    parsed.push(s.parsed);
                }
                Ok(None) => return Err(format!("{task} is scored by the judge, not by rules")),
                Err(e) => return Err(e.to_string()),
            }
        }
        Ok((scores, parsed))
    });
    res.map_err(|m| config_error(py, m))
}

/// Reads and scores one predictions file of a folder of `layout` (`"drivehierarchy"`:
/// `predictions/<stem>.jsonl`; `"original"`: the original runner's `<stem>_pred.jsonl`); the
/// task from `task_id` or the file name. Returns a dict: task, ids (None for an original line
/// without id), scores, parsed, judge_items [(question, answer, prediction)] for R1_4, models,
/// formats, lines, duplicates (skipped), duplicate_ids (counted), issues [(line, message)]
/// (skipped lines), truncated_tail. A file with nothing to score raises ConfigError.
#[pyfunction]
#[pyo3(signature = (path, task_id = None, strict_order = false, layout = "drivehierarchy"))]
fn openloop_score_file<'py>(
    py: Python<'py>,
    path: PathBuf,
    task_id: Option<&str>,
    strict_order: bool,
    layout: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let task = task_id.map(|t| task_of(py, t)).transpose()?;
    let layout = Layout::parse(layout).map_err(|e| to_pyerr(py, e))?;
    let opts = options(strict_order);
    let scored = py
        .detach(|| predictions::score_predictions_file(&path, task, layout, &opts))
        .map_err(|e| to_pyerr(py, e))?;
    let d = PyDict::new(py);
    d.set_item("task", scored.task.as_str())?;
    d.set_item("ids", scored.ids)?;
    d.set_item("scores", scored.scores)?;
    d.set_item("parsed", scored.parsed)?;
    let items: Vec<(String, String, String)> =
        scored.judge_items.into_iter().map(|j| (j.question, j.answer, j.prediction)).collect();
    d.set_item("judge_items", items)?;
    d.set_item("models", scored.models.into_iter().collect::<Vec<_>>())?;
    d.set_item("formats", scored.formats.iter().map(|f| f.as_str()).collect::<Vec<_>>())?;
    d.set_item("lines", scored.lines)?;
    d.set_item("duplicates", scored.duplicates)?;
    d.set_item("duplicate_ids", scored.duplicate_ids)?;
    let issues: Vec<(usize, String)> = scored.issues.into_iter().map(|i| (i.line, i.message)).collect();
    d.set_item("issues", issues)?;
    d.set_item("truncated_tail", scored.truncated_tail)?;
    Ok(d)
}

/// Task id of a file of the original runner's result folder (`<stem>_pred.jsonl`, its exact
/// names only); ConfigError naming the file otherwise.
#[pyfunction]
fn openloop_task_from_original_file(py: Python<'_>, name: &str) -> PyResult<&'static str> {
    TaskId::from_original_file_name(name).map(TaskId::as_str).map_err(|e| to_pyerr(py, e))
}

fn weights_of(py: Python<'_>, w: Option<BTreeMap<String, f64>>) -> PyResult<BTreeMap<TaskId, f64>> {
    match w {
        None => Ok(aggregate::frozen_weights()),
        Some(m) => m
            .into_iter()
            .map(|(k, v)| {
                if !v.is_finite() || v < 0.0 {
                    return Err(config_error(py, format!("weight of {k} must be finite and >= 0, got {v}")));
                }
                Ok((task_of(py, &k)?, v))
            })
            .collect(),
    }
}

/// Aggregates task outcomes `[(task_id, source_file, scores, parse_fail, pass_rate|None)]`
/// with `weights` (frozen weights when None). Returns the summary (final_score.json's content).
#[pyfunction]
#[pyo3(signature = (outcomes, weights = None))]
#[allow(clippy::type_complexity)]
fn openloop_summarize(
    py: Python<'_>,
    outcomes: Vec<(String, String, Vec<f64>, usize, Option<f64>)>,
    weights: Option<BTreeMap<String, f64>>,
) -> PyResult<Bound<'_, PyAny>> {
    let weights = weights_of(py, weights)?;
    let outcomes = outcomes
        .into_iter()
        .map(|(t, source_file, scores, parse_fail, pass_rate)| {
            Ok(TaskOutcome { task: task_of(py, &t)?, source_file, scores, parse_fail, pass_rate })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let summary = aggregate::summarize(&outcomes, &weights);
    let v = serde_json::to_value(&summary).map_err(|e| config_error(py, format!("summary: {e}")))?;
    Ok(pythonize(py, &v)?)
}

/// The scorers' constants (the original's `config` block of `final_score.json`).
#[pyfunction]
fn openloop_score_params() -> BTreeMap<&'static str, f64> {
    let p = dh_benchmark::ScoreParams::default();
    BTreeMap::from([
        ("count_c", p.count_c),
        ("count_tau", p.count_tau),
        ("count_sigma", p.count_sigma),
        ("distance_epsilon", p.distance_epsilon),
        ("distance_tau", p.distance_tau),
        ("distance_sigma", p.distance_sigma),
    ])
}

/// The frozen weights of the paper's Table 1.
#[pyfunction]
fn openloop_frozen_weights() -> BTreeMap<&'static str, f64> {
    TASKS.iter().map(|t| (t.name, t.weight)).collect()
}

/// The calibration's defaults (docs/protocol.md#aggregation): λ_same, λ_cross, γ and the rank budgets.
#[pyfunction]
fn openloop_calibration_defaults<'py>(py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
    let p = CalibrationParams::default();
    let d = PyDict::new(py);
    d.set_item("lambda_same", p.lambda_same)?;
    d.set_item("lambda_cross", p.lambda_cross)?;
    d.set_item("gamma", p.gamma)?;
    let budgets: BTreeMap<&str, f64> = p.budgets.iter().map(|(r, b)| (r.as_str(), *b)).collect();
    d.set_item("budgets", budgets)?;
    Ok(d)
}

/// Calibrates task weights from `scores[model][task]` (tasks in `tasks` order); a parameter
/// left as None takes its default (`openloop_calibration_defaults`). Returns a dict: tasks,
/// weights {task: w}, rho, load, uniqueness.
#[pyfunction]
#[pyo3(signature = (tasks, scores, lambda_same = None, lambda_cross = None, gamma = None, budgets = None))]
fn openloop_calibrate<'py>(
    py: Python<'py>,
    tasks: Vec<String>,
    scores: Vec<Vec<f64>>,
    lambda_same: Option<f64>,
    lambda_cross: Option<f64>,
    gamma: Option<f64>,
    budgets: Option<BTreeMap<String, f64>>,
) -> PyResult<Bound<'py, PyDict>> {
    let ids = tasks.iter().map(|t| task_of(py, t)).collect::<PyResult<Vec<_>>>()?;
    let mut params = CalibrationParams::default();
    params.lambda_same = lambda_same.unwrap_or(params.lambda_same);
    params.lambda_cross = lambda_cross.unwrap_or(params.lambda_cross);
    params.gamma = gamma.unwrap_or(params.gamma);
    if let Some(b) = budgets {
        params.budgets = b
            .into_iter()
            .map(|(k, v)| Rank::parse(&k).map(|r| (r, v)))
            .collect::<Result<_, _>>()
            .map_err(|e| to_pyerr(py, e))?;
    }
    let cal = calibrate::calibrate(&ids, &scores, &params).map_err(|e| to_pyerr(py, e))?;
    let d = PyDict::new(py);
    d.set_item("tasks", tasks)?;
    let w: BTreeMap<&str, f64> =
        cal.tasks.iter().map(|t| t.as_str()).zip(cal.weights.iter().copied()).collect();
    d.set_item("weights", w)?;
    d.set_item("rho", cal.rho)?;
    d.set_item("load", cal.load)?;
    d.set_item("uniqueness", cal.uniqueness)?;
    Ok(d)
}

/// Spearman's ρ of two equally long samples (average ranks for ties, as the calibration uses);
/// NaN for fewer than 2 pairs, unequal lengths or a constant side.
#[pyfunction]
fn openloop_spearman(x: Vec<f64>, y: Vec<f64>) -> f64 {
    calibrate::spearman(&x, &y).unwrap_or(f64::NAN)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(openloop_tasks, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_task_from_stem, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_task_from_record, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_task_from_original_file, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_score_answer, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_score_task, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_score_file, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_summarize, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_frozen_weights, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_score_params, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_calibration_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(openloop_spearman, m)?)?;
    m.add("OPENLOOP_UNICODE_VERSION", dh_benchmark::pyunicode::UNICODE_VERSION)?;
    Ok(())
}
