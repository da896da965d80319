//! Weight calibration (docs/protocol.md#aggregation, paper appendix): Spearman correlations between tasks
//! across models, redundancy loads L_i, uniqueness u_i = 1/L_i normalised within each rank
//! and scaled by the rank budgets.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::task::{Rank, TaskId};

/// Calibration constants (the paper's by default).
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationParams {
    pub lambda_same: f64,
    pub lambda_cross: f64,
    pub gamma: f64,
    pub budgets: BTreeMap<Rank, f64>,
}

impl Default for CalibrationParams {
    fn default() -> Self {
        CalibrationParams {
            lambda_same: 1.0,
            lambda_cross: 0.35,
            gamma: 2.0,
            budgets: [(Rank::R1, 0.3), (Rank::R2, 0.3), (Rank::R3, 0.4)].into(),
        }
    }
}

/// The calibration's result and its intermediate quantities.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    pub tasks: Vec<TaskId>,
    /// Spearman ρ between tasks (tasks × tasks).
    pub rho: Vec<Vec<f64>>,
    pub load: Vec<f64>,
    pub uniqueness: Vec<f64>,
    pub weights: Vec<f64>,
}

impl Calibration {
    pub fn weight_map(&self) -> BTreeMap<TaskId, f64> {
        self.tasks.iter().copied().zip(self.weights.iter().copied()).collect()
    }
}

/// 1-based ranks, ties sharing their average rank (as `scipy.stats.rankdata`).
pub fn average_ranks(x: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..x.len()).collect();
    idx.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let mut ranks = vec![0.0; x.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && x[idx[j + 1]] == x[idx[i]] {
            j += 1;
        }
        let r = (i + j) as f64 / 2.0 + 1.0;
        for &k in &idx[i..=j] {
            ranks[k] = r;
        }
        i = j + 1;
    }
    ranks
}

fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    let d = (saa * sbb).sqrt();
    (d > 0.0).then(|| (sab / d).clamp(-1.0, 1.0))
}

/// Spearman correlation (Pearson of average ranks); `None` if either side is constant.
pub fn spearman(a: &[f64], b: &[f64]) -> Option<f64> {
    if a.len() != b.len() || a.len() < 2 {
        return None;
    }
    pearson(&average_ranks(a), &average_ranks(b))
}

/// Calibrates weights from `scores[model][task]` (task order as in `tasks`).
pub fn calibrate(tasks: &[TaskId], scores: &[Vec<f64>], params: &CalibrationParams) -> Result<Calibration> {
    let err = |m: String| Err(Error::Calibration(m));
    if tasks.is_empty() {
        return err("no tasks given".into());
    }
    for (i, t) in tasks.iter().enumerate() {
        if tasks[..i].contains(t) {
            return err(format!("task {t} appears twice"));
        }
    }
    if scores.len() < 3 {
        return err(format!(
            "need task scores of at least 3 models for rank correlations, got {}",
            scores.len()
        ));
    }
    for (m, row) in scores.iter().enumerate() {
        if row.len() != tasks.len() {
            return err(format!(
                "model row {m} has {} scores, expected {} (one per task)",
                row.len(),
                tasks.len()
            ));
        }
        if let Some((k, v)) = row.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return err(format!("model row {m}, task {}: score {v} is not finite", tasks[k]));
        }
    }
    for (name, v) in
        [("lambda_same", params.lambda_same), ("lambda_cross", params.lambda_cross), ("gamma", params.gamma)]
    {
        if !v.is_finite() || v < 0.0 {
            return err(format!("{name} must be finite and >= 0, got {v}"));
        }
    }
    for r in Rank::ALL {
        let b = params.budgets.get(&r).copied().unwrap_or(0.0);
        if !b.is_finite() || b < 0.0 {
            return err(format!("budget of {} must be finite and >= 0, got {b}", r.as_str()));
        }
        let has = tasks.iter().any(|t| t.rank() == r);
        if b > 0.0 && !has {
            return err(format!("rank {} has budget {b} but no task in the pool", r.as_str()));
        }
        if has && !params.budgets.contains_key(&r) {
            return err(format!("no budget for rank {}", r.as_str()));
        }
    }
    let columns: Vec<Vec<f64>> =
        (0..tasks.len()).map(|k| scores.iter().map(|row| row[k]).collect()).collect();
    let n = tasks.len();
    let mut rho = vec![vec![1.0; n]; n];
    for i in 0..n {
        for j in i + 1..n {
            let Some(r) = spearman(&columns[i], &columns[j]) else {
                let k = if average_ranks(&columns[i]).windows(2).all(|w| w[0] == w[1]) { i } else { j };
                return err(format!(
                    "task {} has the same score for every model; its rank correlation is undefined",
                    tasks[k]
                ));
            };
            rho[i][j] = r;
            rho[j][i] = r;
        }
    }
    let load: Vec<f64> = (0..n)
        .map(|i| {
            let mut l = 1.0;
            for j in (0..n).filter(|&j| j != i) {
                let lam =
                    if tasks[i].rank() == tasks[j].rank() { params.lambda_same } else { params.lambda_cross };
                l += lam * rho[i][j].max(0.0).powf(params.gamma);
            }
            l
        })
        .collect();
    let uniqueness: Vec<f64> = load.iter().map(|l| 1.0 / l).collect();
    let weights = (0..n)
        .map(|i| {
            let r = tasks[i].rank();
            let total: f64 = (0..n).filter(|&k| tasks[k].rank() == r).map(|k| uniqueness[k]).sum();
            params.budgets.get(&r).copied().unwrap_or(0.0) * uniqueness[i] / total
        })
        .collect();
    Ok(Calibration { tasks: tasks.to_vec(), rho, load, uniqueness, weights })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranks_and_spearman() {
        assert_eq!(average_ranks(&[10.0, 20.0, 10.0, 5.0]), vec![2.5, 4.0, 2.5, 1.0]);
        assert_eq!(spearman(&[1.0, 2.0, 3.0], &[10.0, 20.0, 30.0]), Some(1.0));
        assert_eq!(spearman(&[1.0, 2.0, 3.0], &[3.0, 2.0, 1.0]), Some(-1.0));
        assert_eq!(spearman(&[1.0, 1.0, 1.0], &[3.0, 2.0, 1.0]), None);
        // With ties: ranks (1.5, 1.5, 3) vs (1, 2, 3) → ρ = 0.866…
        let r = spearman(&[1.0, 1.0, 2.0], &[1.0, 2.0, 3.0]).unwrap();
        assert!((r - 3f64.sqrt() / 2.0).abs() < 1e-12);
    }

    #[test]
    fn hand_computed_three_tasks() {
        // R1_1_A and R1_1_B perfectly correlated, R3_1 anti-correlated with both.
        let tasks = [TaskId::R1_1_A, TaskId::R1_1_B, TaskId::R3_1];
        let scores = vec![vec![1.0, 1.0, 3.0], vec![2.0, 2.0, 2.0], vec![3.0, 3.0, 1.0]];
        let p = CalibrationParams {
            budgets: [(Rank::R1, 0.6), (Rank::R3, 0.4)].into(),
            ..CalibrationParams::default()
        };
        let c = calibrate(&tasks, &scores, &p).unwrap();
        assert_eq!(c.load, vec![2.0, 2.0, 1.0]);
        assert_eq!(c.weights, vec![0.3, 0.3, 0.4]);
        // A rank with budget but no tasks is an error, as is a constant column.
        assert!(calibrate(&tasks, &scores, &CalibrationParams::default()).is_err());
        let flat = vec![vec![1.0, 5.0, 3.0], vec![2.0, 5.0, 2.0], vec![3.0, 5.0, 1.0]];
        let e = calibrate(&tasks, &flat, &p).unwrap_err().to_string();
        assert!(e.contains("R1_1_B"), "{e}");
        assert!(calibrate(&tasks, &scores[..2], &p).is_err());
    }
}
