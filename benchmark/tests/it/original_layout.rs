//! The original runner's line format scores exactly like our format on the released sample
//! records (`../shared/official/Open_Loop_Evaluation`, skipped when absent): the same replies
//! through `ground_truth` (original) and through `record` (ours) give the same scores.

use std::path::PathBuf;

use dh_benchmark::predictions::{parse_predictions, score_entries, Layout};
use dh_benchmark::record::ground_truth_field;
use dh_benchmark::{ScoreOptions, TaskId, TASKS};
use serde_json::{json, Value};

const REPLIES: [&str; 7] = ["yes", "No.", "B", "3 cars", "12.5 m", "[100, 200, 300, 400]", "I don't know"];

#[test]
fn original_lines_score_like_ours_on_the_release_samples() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/official/Open_Loop_Evaluation");
    if !dir.is_dir() {
        eprintln!("skipped: {} not found", dir.display());
        return;
    }
    let opts = ScoreOptions::default();
    for spec in TASKS.iter().filter(|t| t.id != TaskId::R1_4) {
        let text = std::fs::read_to_string(dir.join(format!("{}.jsonl", spec.stem))).unwrap();
        let records: Vec<Value> =
            text.lines().filter(|l| !l.trim().is_empty()).map(|l| serde_json::from_str(l).unwrap()).collect();
        let (mut ours, mut original) = (String::new(), String::new());
        for rec in &records {
            let id = rec.get("Question_id").or_else(|| rec.get("task_id")).unwrap().as_str().unwrap();
            let mut replies: Vec<String> = REPLIES.iter().map(|r| r.to_string()).collect();
            replies.push(rec[ground_truth_field(spec.id)].to_string());
            if let Some(Value::String(a)) = rec.get("answer") {
                replies.push(a.clone());
            }
            for (k, reply) in replies.iter().enumerate() {
                let rid = format!("{id}#{k}");
                let ours_line = json!({"id": rid, "task": spec.name, "prediction": reply, "record": rec});
                let orig_line = json!({
                    "Question_id": rid, "question": rec.get("question"),
                    "ground_truth": rec[ground_truth_field(spec.id)], "model_prediction": reply,
                });
                ours.push_str(&format!("{ours_line}\n"));
                original.push_str(&format!("{orig_line}\n"));
            }
        }
        let a =
            score_entries(spec.id, parse_predictions(&ours, Layout::DriveHierarchy), &opts, "ours").unwrap();
        let b =
            score_entries(spec.id, parse_predictions(&original, Layout::Original), &opts, "orig").unwrap();
        assert!(a.issues.is_empty() && b.issues.is_empty(), "{}", spec.stem);
        assert_eq!(a.scores.len(), b.scores.len(), "{}", spec.stem);
        assert_eq!(a.ids, b.ids, "{}", spec.stem);
        assert_eq!(a.parsed, b.parsed, "{}", spec.stem);
        // Bit for bit.
        for (x, y) in a.scores.iter().zip(&b.scores) {
            assert_eq!(x.to_bits(), y.to_bits(), "{}", spec.stem);
        }
        // The replies really exercise the scorer: some right, some wrong or unparseable.
        assert!(a.scores.contains(&100.0) && a.scores.iter().any(|s| *s < 100.0), "{}", spec.stem);
    }
}
