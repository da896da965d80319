//! Per-record scores s ∈ [0, 100] (docs/protocol.md#record-scores), exactly as the original scorer.

use serde_json::Value;

use crate::error::Result;
use crate::parse::{self, py_max, py_min};
use crate::pyjson::PyValue;
use crate::pyunicode as pu;
use crate::record;
use crate::task::{Scorer, TaskId};

/// Constants of the decay scorers (the original's defaults; overridable like its CLI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoreParams {
    pub count_c: f64,
    pub count_tau: f64,
    pub count_sigma: f64,
    pub distance_epsilon: f64,
    pub distance_tau: f64,
    pub distance_sigma: f64,
}

impl Default for ScoreParams {
    fn default() -> Self {
        // σ from the half-credit error E50: σ = (E50 − τ) / ln 2.
        ScoreParams {
            count_c: 1.0,
            count_tau: 0.05,
            count_sigma: (0.20 - 0.05) / 2f64.ln(),
            distance_epsilon: 0.1,
            distance_tau: 0.0,
            distance_sigma: (2f64.ln() - 0.0) / 2f64.ln(),
        }
    }
}

/// Scoring options.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ScoreOptions {
    pub params: ScoreParams,
    /// Strict R3_2 variant: the reply must name every ground-truth label, else it is
    /// unparseable (the default reproduces the original, which appends missing labels).
    pub strict_order: bool,
}

/// A record's score and whether both sides parsed (`parsed == false` → parse_fail).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RecordScore {
    pub score: f64,
    pub parsed: bool,
}

const FAIL: RecordScore = RecordScore { score: 0.0, parsed: false };

fn ok(score: f64) -> RecordScore {
    RecordScore { score, parsed: true }
}

/// `max(0, min(100, v))` with Python's NaN behaviour.
fn clamp_0_100(v: f64) -> f64 {
    py_max(0.0, py_min(100.0, v))
}

/// G(E; τ, σ) = 100 if E ≤ τ else 100·exp(−(E − τ)/σ).
pub fn decay(error: f64, tau: f64, sigma: f64) -> f64 {
    if error <= tau {
        return 100.0;
    }
    clamp_0_100(100.0 * (-(error - tau) / sigma).exp())
}

/// Round half away from zero (the original's `round_half_up`).
pub fn round_half_away(v: f64) -> f64 {
    if v >= 0.0 {
        (v + 0.5).floor()
    } else {
        (v - 0.5).ceil()
    }
}

pub fn score_yes_no(gt: &PyValue, pred: &str) -> RecordScore {
    match (parse::yes_no(&gt.py_str()), parse::yes_no(pred)) {
        (Some(g), Some(p)) => ok(if g == p { 100.0 } else { 0.0 }),
        _ => FAIL,
    }
}

pub fn score_multi_choice(gt: &PyValue, pred: &str) -> RecordScore {
    if let (Some(g), Some(p)) = (parse::choice_letter_of(gt), parse::choice_letter(pred)) {
        return ok(if g == p { 100.0 } else { 0.0 });
    }
    let g = parse::normalize_text(&parse::strip_choice_prefix(&gt.py_str()));
    let p = parse::normalize_text(&parse::strip_choice_prefix(pred));
    if g.is_empty() || p.is_empty() {
        return FAIL;
    }
    ok(if g == p { 100.0 } else { 0.0 })
}

/// Count decay. A reply of ±infinity (`1e999`, where the original crashes) scores 0 / clamps.
pub fn score_count(gt: &PyValue, pred: &str, p: &ScoreParams) -> RecordScore {
    let (Some(g), Some(x)) = (parse::number_of(gt), parse::first_number(pred)) else {
        return FAIL;
    };
    let g = py_max(0.0, round_half_away(g));
    let x = py_max(0.0, round_half_away(x));
    let error = (x - g).abs() / py_max(g, p.count_c);
    ok(decay(error, p.count_tau, p.count_sigma))
}

pub fn score_distance(gt: &PyValue, pred: &str, p: &ScoreParams) -> RecordScore {
    let (Some(g), Some(x)) = (parse::number_of(gt), parse::first_number(pred)) else {
        return FAIL;
    };
    let g = py_max(0.0, g);
    let x = py_max(0.0, x);
    let error = ((x + p.distance_epsilon) / (g + p.distance_epsilon)).ln().abs();
    ok(decay(error, p.distance_tau, p.distance_sigma))
}

pub fn score_bbox(gt: &PyValue, pred: &str) -> RecordScore {
    match (parse::bbox_of(gt), parse::bbox_of_str(pred)) {
        (Some(g), Some(b)) => ok(clamp_0_100(100.0 * parse::iou(g, b))),
        _ => FAIL,
    }
}

pub fn score_order(gt: &PyValue, pred: &str, strict: bool) -> RecordScore {
    let gt_seq = parse::label_sequence(gt);
    let pred_seq = parse::label_sequence(&PyValue::Str(pred.to_string()));
    if gt_seq.is_empty() || pred_seq.is_empty() {
        return FAIL;
    }
    // Labels outside the ground truth are dropped (already de-duplicated)...
    let mut order: Vec<char> = pred_seq.into_iter().filter(|l| gt_seq.contains(l)).collect();
    if strict && order.len() < gt_seq.len() {
        return FAIL;
    }
    // ...and missing ones appended in ground-truth order (the original's quirk).
    for l in &gt_seq {
        if !order.contains(l) {
            order.push(*l);
        }
    }
    let n = gt_seq.len();
    if n == 1 {
        return ok(if order[0] == gt_seq[0] { 100.0 } else { 0.0 });
    }
    let pos = |l: char| order.iter().position(|x| *x == l).unwrap_or(0);
    let positions: Vec<usize> = gt_seq.iter().map(|l| pos(*l)).collect();
    let mut inversions = 0usize;
    for i in 0..n {
        for j in i + 1..n {
            if positions[i] > positions[j] {
                inversions += 1;
            }
        }
    }
    let pairs = n * (n - 1) / 2;
    ok(clamp_0_100(100.0 * (1.0 - inversions as f64 / pairs as f64)))
}

/// Scores one reply against a ground truth; `None` for the judge-scored free text (R1_4).
pub fn score_answer(scorer: Scorer, gt: &PyValue, pred: &str, opts: &ScoreOptions) -> Option<RecordScore> {
    Some(match scorer {
        Scorer::YesNo => score_yes_no(gt, pred),
        Scorer::MultiChoice => score_multi_choice(gt, pred),
        Scorer::NumericCount => score_count(gt, pred, &opts.params),
        Scorer::NumericDistance => score_distance(gt, pred, &opts.params),
        Scorer::Bbox => score_bbox(gt, pred),
        Scorer::SequenceOrder => score_order(gt, pred, opts.strict_order),
        Scorer::TextLingoJudge => return None,
    })
}

/// Scores one reply to a released record (`None` for R1_4); errors name a missing field.
pub fn score_record(
    task: TaskId,
    record: &Value,
    pred: &str,
    opts: &ScoreOptions,
    ctx: &str,
) -> Result<Option<RecordScore>> {
    let gt = record::ground_truth(task, record, ctx)?;
    Ok(score_answer(task.scorer(), &gt, pred, opts))
}

/// The judge's three fields, each stripped: (question, ground truth, reply). The ground
/// truth goes through `str()`, so a null answer reads `None`, as in the original.
pub fn judge_fields(record: &Value, pred: &str) -> (String, String, String) {
    let q = record::question_text(record);
    let gt = record.get("answer").map(|v| PyValue::from_json(v).py_str()).unwrap_or_default();
    (pu::strip(&q).to_string(), pu::strip(&gt).to_string(), pu::strip(pred).to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(x: &str) -> PyValue {
        PyValue::Str(x.into())
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn yes_no_scores() {
        assert_eq!(score_yes_no(&s("No"), "no."), ok(100.0));
        assert_eq!(score_yes_no(&s("Yes"), "no"), ok(0.0));
        assert_eq!(score_yes_no(&s("Yes"), "I cannot tell"), FAIL);
        assert_eq!(score_yes_no(&s("maybe"), "yes"), FAIL);
        // A null answer reads "None" → "no" in the original.
        assert_eq!(score_yes_no(&PyValue::None, "no"), ok(100.0));
    }

    #[test]
    fn multi_choice_scores() {
        assert_eq!(score_multi_choice(&s("B"), "b"), ok(100.0));
        assert_eq!(score_multi_choice(&s("B"), "C. parked."), ok(0.0));
        // Ground truth as the full option text.
        let gt = s("C. No Change (It remains moving).");
        assert_eq!(score_multi_choice(&gt, "C"), ok(100.0));
        assert_eq!(score_multi_choice(&gt, "(c)"), ok(100.0));
        assert_eq!(score_multi_choice(&gt, "No change (it remains moving)"), ok(100.0));
        assert_eq!(score_multi_choice(&gt, "no change, it remains stopped"), ok(0.0));
        assert_eq!(score_multi_choice(&s("C. Turn left."), "Turn left."), ok(100.0));
        assert_eq!(score_multi_choice(&s("B"), "???"), FAIL);
        assert_eq!(score_multi_choice(&s("B"), ""), FAIL);
        assert_eq!(score_multi_choice(&s("Turn left."), "A car turns"), ok(0.0));
    }

    #[test]
    fn count_scores() {
        let p = ScoreParams::default();
        let sigma = 0.15 / 2f64.ln();
        assert_eq!(score_count(&s("3"), "3", &p), ok(100.0));
        assert_eq!(score_count(&s("3"), "3 vehicles", &p), ok(100.0));
        // 2.5 rounds half away from zero to 3.
        assert_eq!(score_count(&s("3"), "2.5", &p), ok(100.0));
        // E = 1/4 = 0.25 → 100·exp(−0.20/σ).
        assert!(close(score_count(&s("4"), "5", &p).score, 100.0 * (-(0.25 - 0.05) / sigma).exp()));
        // E50 = 0.20 gives half credit: g = 5, p = 6.
        assert!(close(score_count(&s("5"), "6", &p).score, 50.0));
        // g = 0 uses max(g, 1); negative replies clamp to 0.
        assert!(close(score_count(&s("0"), "2", &p).score, 100.0 * (-(2.0 - 0.05) / sigma).exp()));
        assert_eq!(score_count(&s("0"), "-3", &p), ok(100.0));
        assert_eq!(score_count(&PyValue::Int("1".into()), "1.49", &p), ok(100.0));
        assert_eq!(score_count(&s("1"), "none", &p), FAIL);
        assert_eq!(score_count(&s("2"), "1e999", &p), ok(0.0));
    }

    #[test]
    fn distance_scores() {
        let p = ScoreParams::default();
        assert_eq!(score_distance(&s("52.54 m"), "52.54", &p), ok(100.0));
        // Units after the number.
        let want = 100.0 * (-((26.37f64 + 0.1) / (52.54 + 0.1)).ln().abs()).exp();
        assert!(close(score_distance(&s("52.54 m"), "26.37 m", &p).score, want));
        // Doubling the distance (+ε) halves the score: g = 9.9, p = 19.9.
        assert!(close(score_distance(&s("9.9"), "19.9", &p).score, 50.0));
        assert!(close(score_distance(&s("9.9"), "-5", &p).score, 1.0));
        assert_eq!(score_distance(&s("3"), "far", &p), FAIL);
    }

    #[test]
    fn bbox_scores() {
        let gt = crate::pyjson::loads(r#"{"bbox": [0, 0, 10, 10], "format": "xyxy"}"#).unwrap();
        assert_eq!(score_bbox(&gt, "[0, 0, 10, 10]"), ok(100.0));
        assert!(close(score_bbox(&gt, "[[5, 0, 15, 10]]").score, 100.0 / 3.0));
        assert!(close(score_bbox(&gt, "\"[15, 10, 5, 0]\"").score, 100.0 / 3.0));
        assert!(close(score_bbox(&gt, "from (5, 0) to (15, 10)").score, 100.0 / 3.0));
        // The first four numbers of free text, digits in names included.
        assert_eq!(score_bbox(&gt, "x1=5, y1=0, x2=15, y2=10"), ok(0.0));
        assert_eq!(score_bbox(&gt, "[20, 20, 30, 30]"), ok(0.0));
        assert_eq!(score_bbox(&gt, "[5, 5, 5, 5]"), ok(0.0));
        assert_eq!(score_bbox(&gt, "no box"), FAIL);
        assert_eq!(score_bbox(&PyValue::None, "[0, 0, 1, 1]"), FAIL);
    }

    #[test]
    fn order_scores() {
        let gt = crate::pyjson::loads(r#"["A", "B", "C"]"#).unwrap();
        assert_eq!(score_order(&gt, r#"["A", "B", "C"]"#, false), ok(100.0));
        assert_eq!(score_order(&gt, r#"["C", "B", "A"]"#, false), ok(0.0));
        assert!(close(score_order(&gt, r#"["B", "A", "C"]"#, false).score, 100.0 * 2.0 / 3.0));
        // Duplicates keep the first occurrence: B, A, C.
        assert!(close(score_order(&gt, "B, A, B, C, A", false).score, 100.0 * 2.0 / 3.0));
        // Missing labels are appended in ground-truth order: C → C, A, B.
        assert!(close(score_order(&gt, "C", false).score, 100.0 / 3.0));
        // The original's quirk: "I don't know" → labels I, T → all appended → 100.
        assert_eq!(score_order(&gt, "I don't know", false), ok(100.0));
        assert_eq!(score_order(&gt, "I don't know", true), FAIL);
        assert_eq!(score_order(&gt, "C", true), FAIL);
        assert!(close(score_order(&gt, "I think B, A, C", true).score, 100.0 * 2.0 / 3.0));
        assert_eq!(score_order(&gt, "", false), FAIL);
        assert_eq!(score_order(&gt, "123", false), FAIL);
        let one = crate::pyjson::loads(r#"["A"]"#).unwrap();
        assert_eq!(score_order(&one, "A", false), ok(100.0));
        assert_eq!(score_order(&PyValue::List(vec![]), "A", false), FAIL);
    }

    #[test]
    fn judge_fields_strip_and_str() {
        let r = serde_json::json!({"question": " What? ", "answer": null});
        assert_eq!(judge_fields(&r, " go \n"), ("What?".to_string(), "None".to_string(), "go".to_string()));
    }
}
