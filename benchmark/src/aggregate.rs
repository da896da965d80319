//! Aggregation (docs/protocol.md#aggregation): task means with n and parse_fail, p50/p90, the original's
//! micro means per scorer type and overall, rank means and the weighted headline S_open.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::task::{Rank, TaskId};

/// Linear-interpolation percentile (numpy's default), as the original computes it.
pub fn percentile(values: &[f64], p: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    if p <= 0.0 {
        return v[0];
    }
    if p >= 100.0 {
        return v[v.len() - 1];
    }
    let rank = (v.len() - 1) as f64 * (p / 100.0);
    let (lo, hi) = (rank.floor() as usize, rank.ceil() as usize);
    if lo == hi {
        return v[lo];
    }
    let frac = rank - lo as f64;
    v[lo] * (1.0 - frac) + v[hi] * frac
}

/// Plain left-to-right mean (0 for no values, like the original).
pub fn mean(values: &[f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.iter().fold(0.0, |a, b| a + b) / values.len() as f64
}

/// n, parse_fail, mean, p50, p90 of a set of scores.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Stats {
    pub n: usize,
    pub parse_fail: usize,
    pub mean: f64,
    pub p50: f64,
    pub p90: f64,
}

impl Stats {
    pub fn of(scores: &[f64], parse_fail: usize) -> Stats {
        Stats {
            n: scores.len(),
            parse_fail,
            mean: mean(scores),
            p50: percentile(scores, 50.0),
            p90: percentile(scores, 90.0),
        }
    }
}

/// The scored records of one task.
#[derive(Debug, Clone)]
pub struct TaskOutcome {
    pub task: TaskId,
    /// Name of the predictions file it came from.
    pub source_file: String,
    pub scores: Vec<f64>,
    pub parse_fail: usize,
    /// Share of records passing the judge's threshold (R1_4 only).
    pub pass_rate: Option<f64>,
}

/// Per-file entry, as in the original's `per_file`.
#[derive(Debug, Clone, Serialize)]
pub struct FileSummary {
    pub source_file: String,
    pub task: TaskId,
    pub task_type: &'static str,
    pub metric: &'static str,
    #[serde(flatten)]
    pub stats: Stats,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pass_rate: Option<f64>,
}

/// Micro mean over all records of one scorer type (the original's `per_task`).
#[derive(Debug, Clone, Serialize)]
pub struct TypeSummary {
    pub task_type: &'static str,
    #[serde(flatten)]
    pub stats: Stats,
}

/// One task's score S_t and its weight.
#[derive(Debug, Clone, Serialize)]
pub struct TaskSummary {
    pub rank: Rank,
    pub task_type: &'static str,
    pub metric: &'static str,
    #[serde(flatten)]
    pub stats: Stats,
    pub weight: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pass_rate: Option<f64>,
}

/// A rank score S_r: plain mean of its tasks' scores.
#[derive(Debug, Clone, Serialize)]
pub struct RankSummary {
    /// Mean over the tasks present; `None` when none is.
    pub mean: Option<f64>,
    pub tasks: Vec<TaskId>,
    /// Tasks of the rank without a score (not predicted, or the judge skipped).
    pub missing: Vec<TaskId>,
    pub complete: bool,
}

/// The weighted headline over the tasks that have a score, renormalised by their weight.
#[derive(Debug, Clone, Serialize)]
pub struct PartialHeadline {
    pub value: Option<f64>,
    pub weight_covered: f64,
    pub missing: Vec<TaskId>,
}

/// Everything `final_score.json` reports about the scores.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    pub overall: Stats,
    pub per_task: Vec<TypeSummary>,
    pub per_file: Vec<FileSummary>,
    pub tasks: BTreeMap<TaskId, TaskSummary>,
    pub ranks: BTreeMap<Rank, RankSummary>,
    /// S_open = Σ w_t S_t over all 14 tasks; `None` unless every task has a score.
    #[serde(rename = "S_open")]
    pub s_open: Option<f64>,
    #[serde(rename = "S_open_partial")]
    pub s_open_partial: PartialHeadline,
    pub weights: BTreeMap<TaskId, f64>,
}

/// The frozen weights of the paper's Table 1.
pub fn frozen_weights() -> BTreeMap<TaskId, f64> {
    TaskId::ALL.iter().map(|t| (*t, t.frozen_weight())).collect()
}

/// Aggregates task outcomes (several outcomes of one task are pooled) with `weights`.
pub fn summarize(outcomes: &[TaskOutcome], weights: &BTreeMap<TaskId, f64>) -> Summary {
    let mut all = Vec::new();
    let mut all_fail = 0;
    let mut by_type: BTreeMap<&'static str, (Vec<f64>, usize)> = BTreeMap::new();
    // task → (scores, parse_fail, Σ pass_rate·n and n over judged files)
    type Acc = (Vec<f64>, usize, Option<(f64, usize)>);
    let mut by_task: BTreeMap<TaskId, Acc> = BTreeMap::new();
    let mut per_file = Vec::new();
    for o in outcomes {
        let sc = o.task.scorer();
        all.extend_from_slice(&o.scores);
        all_fail += o.parse_fail;
        let e = by_type.entry(sc.task_type()).or_default();
        e.0.extend_from_slice(&o.scores);
        e.1 += o.parse_fail;
        let t = by_task.entry(o.task).or_default();
        t.0.extend_from_slice(&o.scores);
        t.1 += o.parse_fail;
        if let Some(rate) = o.pass_rate {
            let acc = t.2.get_or_insert((0.0, 0));
            acc.0 += rate * o.scores.len() as f64;
            acc.1 += o.scores.len();
        }
        per_file.push(FileSummary {
            source_file: o.source_file.clone(),
            task: o.task,
            task_type: sc.task_type(),
            metric: sc.metric(),
            stats: Stats::of(&o.scores, o.parse_fail),
            pass_rate: o.pass_rate,
        });
    }
    let per_task =
        by_type.iter().map(|(ty, (s, f))| TypeSummary { task_type: ty, stats: Stats::of(s, *f) }).collect();
    let tasks: BTreeMap<TaskId, TaskSummary> = by_task
        .iter()
        .map(|(t, (s, f, pass))| {
            (
                *t,
                TaskSummary {
                    rank: t.rank(),
                    task_type: t.scorer().task_type(),
                    metric: t.scorer().metric(),
                    stats: Stats::of(s, *f),
                    weight: weights.get(t).copied().unwrap_or(0.0),
                    pass_rate: pass.map(|(sum, n)| if n > 0 { sum / n as f64 } else { 0.0 }),
                },
            )
        })
        .collect();
    let ranks = Rank::ALL
        .iter()
        .map(|r| {
            let of_rank: Vec<TaskId> = TaskId::ALL.iter().copied().filter(|t| t.rank() == *r).collect();
            let present: Vec<TaskId> = of_rank.iter().copied().filter(|t| tasks.contains_key(t)).collect();
            let missing: Vec<TaskId> = of_rank.iter().copied().filter(|t| !tasks.contains_key(t)).collect();
            let means: Vec<f64> = present.iter().map(|t| tasks[t].stats.mean).collect();
            (
                *r,
                RankSummary {
                    mean: (!means.is_empty()).then(|| mean(&means)),
                    complete: missing.is_empty(),
                    tasks: present,
                    missing,
                },
            )
        })
        .collect();
    let missing: Vec<TaskId> = weights.keys().copied().filter(|t| !tasks.contains_key(t)).collect();
    let (mut num, mut covered) = (0.0, 0.0);
    for (t, w) in weights {
        if let Some(ts) = tasks.get(t) {
            num += w * ts.stats.mean;
            covered += w;
        }
    }
    Summary {
        overall: Stats::of(&all, all_fail),
        per_task,
        per_file,
        s_open: missing.is_empty().then_some(num),
        s_open_partial: PartialHeadline {
            value: (covered > 0.0).then(|| num / covered),
            weight_covered: covered,
            missing,
        },
        tasks,
        ranks,
        weights: weights.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_match_numpy_linear() {
        let v = [10.0, 0.0, 30.0, 20.0];
        assert_eq!(percentile(&v, 50.0), 15.0);
        assert!((percentile(&v, 90.0) - 27.0).abs() < 1e-12);
        assert_eq!(percentile(&[5.0], 90.0), 5.0);
        assert_eq!(percentile(&[], 50.0), 0.0);
        assert_eq!(percentile(&v, 0.0), 0.0);
        assert_eq!(percentile(&v, 100.0), 30.0);
    }

    fn outcome(task: TaskId, scores: &[f64], fail: usize) -> TaskOutcome {
        TaskOutcome {
            task,
            source_file: format!("{}.jsonl", task.spec().stem),
            scores: scores.to_vec(),
            parse_fail: fail,
            pass_rate: None,
        }
    }

    #[test]
    fn summary_levels() {
        let all: Vec<TaskOutcome> = TaskId::ALL
            .iter()
            .enumerate()
            .map(|(i, t)| outcome(*t, &[i as f64, i as f64 + 2.0], 1))
            .collect();
        let s = summarize(&all, &frozen_weights());
        assert_eq!(s.overall.n, 28);
        assert_eq!(s.overall.parse_fail, 14);
        assert_eq!(s.tasks[&TaskId::R1_1_B].stats.mean, 2.0);
        // R1 = mean of tasks 0..8 means (1..8) = 4.5; R3 = mean(13, 14) = 13.5.
        assert_eq!(s.ranks[&Rank::R1].mean, Some(4.5));
        assert_eq!(s.ranks[&Rank::R3].mean, Some(13.5));
        let want: f64 =
            TaskId::ALL.iter().enumerate().map(|(i, t)| t.frozen_weight() * (i as f64 + 1.0)).sum();
        assert!((s.s_open.unwrap() - want).abs() < 1e-12);
        // Micro mean per scorer type: numeric_count pools R1_1_B, R1_2_C, R2_1, R2_2_A.
        let count = s.per_task.iter().find(|t| t.task_type == "numeric_count").unwrap();
        assert_eq!(count.stats.n, 8);
        assert_eq!(count.stats.mean, (2.0 + 6.0 + 9.0 + 10.0) / 4.0);

        let partial: Vec<TaskOutcome> = all.into_iter().filter(|o| o.task != TaskId::R1_4).collect();
        let s = summarize(&partial, &frozen_weights());
        assert_eq!(s.s_open, None);
        assert_eq!(s.s_open_partial.missing, vec![TaskId::R1_4]);
        assert!((s.s_open_partial.weight_covered - 0.969).abs() < 1e-9);
        assert!(!s.ranks[&Rank::R1].complete);
        let json = serde_json::to_value(&s).unwrap();
        assert!(json["tasks"]["R1_1_A"]["mean"].is_number());
        assert_eq!(json["ranks"]["R1"]["missing"][0], "R1_4");
    }
}
