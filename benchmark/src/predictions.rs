//! Reading a run's prediction files and scoring them.
//!
//! One JSON object per line: `{"id", "task", "prediction", "record", "model", ...}` (extra keys
//! ignored). After a crash-resume an id may repeat — the first occurrence wins; a line cut by
//! a kill mid-write (the last line, no final newline) is skipped with a warning.

use std::collections::{BTreeSet, HashSet};
use std::path::Path;

use serde::Deserialize;
use serde_json::Value;

use crate::error::{Error, Result};
use crate::score::{self, ScoreOptions};
use crate::task::{Scorer, TaskId};

/// One usable prediction line.
#[derive(Debug, Clone)]
pub struct PredictionEntry {
    /// 1-based line number in the file.
    pub line: usize,
    pub id: String,
    pub task: Option<String>,
    pub prediction: String,
    pub record: Value,
    pub model: Option<String>,
}

/// A skipped line and why.
#[derive(Debug, Clone, PartialEq)]
pub struct LineIssue {
    pub line: usize,
    pub message: String,
}

/// The readable content of a predictions file.
#[derive(Debug, Clone, Default)]
pub struct PredictionFile {
    pub entries: Vec<PredictionEntry>,
    /// Lines whose id was already seen (resume duplicates), skipped.
    pub duplicates: usize,
    /// Malformed lines, skipped (includes the truncated tail).
    pub issues: Vec<LineIssue>,
    /// Whether the last line was cut short (no final newline and not valid JSON).
    pub truncated_tail: bool,
}

#[derive(Deserialize)]
struct Line {
    id: Value,
    #[serde(default)]
    task: Option<String>,
    prediction: Value,
    record: Value,
    #[serde(default)]
    model: Option<Value>,
}

fn parse_line(text: &str) -> std::result::Result<Line, String> {
    let l: Line = serde_json::from_str(text).map_err(|e| format!("invalid JSON line: {e}"))?;
    if !l.record.is_object() {
        return Err("`record` is not a JSON object".into());
    }
    if !l.prediction.is_string() {
        return Err(format!("`prediction` is not a string: {}", l.prediction));
    }
    Ok(l)
}

/// Parses the text of a predictions file (never fails; bad lines become issues).
pub fn parse_predictions(text: &str) -> PredictionFile {
    let mut out = PredictionFile::default();
    let mut seen: HashSet<String> = HashSet::new();
    let ends_with_newline = text.ends_with('\n');
    let lines: Vec<&str> = text.split('\n').collect();
    let last_nonempty = lines.iter().rposition(|l| !l.trim().is_empty());
    for (i, raw) in lines.iter().enumerate() {
        let t = raw.trim();
        if t.is_empty() {
            continue;
        }
        let line_no = i + 1;
        match parse_line(t) {
            Ok(l) => {
                let id = match &l.id {
                    Value::String(s) => s.clone(),
                    Value::Number(n) => n.to_string(),
                    other => {
                        out.issues.push(LineIssue {
                            line: line_no,
                            message: format!("`id` is not a string: {other}"),
                        });
                        continue;
                    }
                };
                if !seen.insert(id.clone()) {
                    out.duplicates += 1;
                    continue;
                }
                let Value::String(prediction) = l.prediction else {
                    continue;
                };
                out.entries.push(PredictionEntry {
                    line: line_no,
                    id,
                    task: l.task,
                    prediction,
                    record: l.record,
                    model: l.model.map(|m| match m {
                        Value::String(s) => s,
                        other => other.to_string(),
                    }),
                });
            }
            Err(message) => {
                let tail = Some(i) == last_nonempty && !ends_with_newline;
                if tail {
                    out.truncated_tail = true;
                }
                out.issues.push(LineIssue {
                    line: line_no,
                    message: if tail {
                        format!("truncated last line (interrupted write): {message}")
                    } else {
                        message
                    },
                });
            }
        }
    }
    out
}

/// Reads a predictions file; invalid UTF-8 (a cut multi-byte char) is replaced, not fatal.
pub fn read_predictions(path: &Path) -> Result<PredictionFile> {
    let bytes =
        std::fs::read(path).map_err(|source| Error::Io { path: path.display().to_string(), source })?;
    Ok(parse_predictions(&String::from_utf8_lossy(&bytes)))
}

/// The judge's inputs for one R1_4 record (each field stripped).
#[derive(Debug, Clone, PartialEq)]
pub struct JudgeItem {
    pub question: String,
    pub answer: String,
    pub prediction: String,
}

/// A scored predictions file.
#[derive(Debug, Clone)]
pub struct ScoredFile {
    pub task: TaskId,
    pub ids: Vec<String>,
    /// Scores (empty for R1_4, which the judge scores from `judge_items`).
    pub scores: Vec<f64>,
    pub parsed: Vec<bool>,
    pub judge_items: Vec<JudgeItem>,
    pub models: BTreeSet<String>,
    pub duplicates: usize,
    pub issues: Vec<LineIssue>,
    pub truncated_tail: bool,
}

/// Scores parsed prediction lines of `task`; `source` names the file in errors.
pub fn score_entries(
    task: TaskId,
    file: PredictionFile,
    opts: &ScoreOptions,
    source: &str,
) -> Result<ScoredFile> {
    let n = file.entries.len();
    let mut out = ScoredFile {
        task,
        ids: Vec::with_capacity(n),
        scores: Vec::with_capacity(n),
        parsed: Vec::with_capacity(n),
        judge_items: Vec::new(),
        models: BTreeSet::new(),
        duplicates: file.duplicates,
        issues: file.issues,
        truncated_tail: file.truncated_tail,
    };
    for e in file.entries {
        let ctx = format!("{source}:{} (id {}) record", e.line, e.id);
        if let Some(t) = e.task.as_deref() {
            if TaskId::parse(t).ok() != Some(task) {
                return Err(Error::Record {
                    context: format!("{source}:{}", e.line),
                    field: "task".into(),
                    reason: format!("`{t}` does not match the file's task {task}"),
                });
            }
        }
        if task.scorer() == Scorer::TextLingoJudge {
            let (question, answer, prediction) = score::judge_fields(&e.record, &e.prediction);
            out.judge_items.push(JudgeItem { question, answer, prediction });
        } else if let Some(s) = score::score_record(task, &e.record, &e.prediction, opts, &ctx)? {
            out.scores.push(s.score);
            out.parsed.push(s.parsed);
        }
        if let Some(m) = e.model {
            out.models.insert(m);
        }
        out.ids.push(e.id);
    }
    Ok(out)
}

/// Reads and scores `path`; the task comes from `task` or else the file stem.
pub fn score_predictions_file(path: &Path, task: Option<TaskId>, opts: &ScoreOptions) -> Result<ScoredFile> {
    let task = match task {
        Some(t) => t,
        None => TaskId::from_stem(
            path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default().as_str(),
        )?,
    };
    let file = read_predictions(path)?;
    score_entries(task, file, opts, &path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(id: &str, pred: &str, answer: &str) -> String {
        serde_json::json!({
            "id": id, "task": "R1_1_A", "prediction": pred, "model": "m",
            "record": {"Question_id": id, "answer": answer, "image_path": "x.jpg"}
        })
        .to_string()
    }

    #[test]
    fn resume_duplicates_and_truncated_tail() {
        let full = line("q2", "no", "No");
        let text = format!(
            "{}\n{}\n{}\n\n{}",
            line("q1", "yes", "Yes"),
            line("q1", "no", "Yes"),
            full,
            &full[..full.len() / 2]
        );
        let f = parse_predictions(&text);
        assert_eq!(f.entries.len(), 2);
        assert_eq!(f.entries[0].prediction, "yes");
        assert_eq!(f.duplicates, 1);
        assert!(f.truncated_tail);
        assert_eq!(f.issues.len(), 1);
        assert_eq!(f.issues[0].line, 5);
        let s = score_entries(TaskId::R1_1_A, f, &ScoreOptions::default(), "f").unwrap();
        assert_eq!(s.scores, vec![100.0, 100.0]);
        assert_eq!(s.models.iter().collect::<Vec<_>>(), vec!["m"]);
    }

    #[test]
    fn malformed_middle_lines_are_issues_and_wrong_task_is_an_error() {
        let text = format!("{{oops\n{}\n{{\"id\": \"z\"}}\n", line("q1", "yes", "Yes"));
        let f = parse_predictions(&text);
        assert_eq!(f.entries.len(), 1);
        assert!(!f.truncated_tail);
        assert_eq!(f.issues.iter().map(|i| i.line).collect::<Vec<_>>(), vec![1, 3]);
        let f = parse_predictions(&line("q1", "yes", "Yes"));
        let e = score_entries(TaskId::R1_1_B, f, &ScoreOptions::default(), "f").unwrap_err();
        assert!(e.to_string().contains("task"), "{e}");
    }

    #[test]
    fn missing_ground_truth_names_file_line_and_field() {
        let text = r#"{"id": "a", "prediction": "3", "record": {"Question_id": "a"}}"#;
        let f = parse_predictions(text);
        let e = score_entries(TaskId::R1_1_B, f, &ScoreOptions::default(), "p.jsonl").unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("p.jsonl:1") && msg.contains("`answer`"), "{msg}");
    }
}
