//! Reading a run's prediction files and scoring them.
//!
//! Two line formats are read (a line of our runner carries both):
//! - drivehierarchy: `{"id", "task", "prediction", "record", "model", ...}` — the ground truth
//!   comes from the released `record` (its task's field, docs/protocol.md#open-loop-tasks);
//! - original: the original runner's `{"Question_id" (or "task_id"), "question",
//!   "ground_truth", "model_prediction"[, "ground_truth_order"]}` — the ground truth is
//!   `ground_truth` as written, which is what the original scorer reads.
//!
//! The folder [`Layout`] decides which fields win when a line has both and how repeated ids
//! are treated: in our layout a repeated id (crash-resume) keeps its first line; in the
//! original layout every line counts, as in the original scorer. A line that cannot be read
//! (invalid JSON, a cut last line, a missing field) is skipped and reported; a file where no
//! line can be scored is an error, never a score of 0.

use std::collections::{BTreeSet, HashSet};
use std::path::Path;

use serde_json::{Map, Value};

use crate::error::{Error, Result};
use crate::pyjson::PyValue;
use crate::pyunicode as pu;
use crate::score::{self, ScoreOptions};
use crate::task::{Scorer, TaskId};

/// Layout of a results folder.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// Ours: `RUN/predictions/<stem>.jsonl`; drivehierarchy fields win; repeated ids skipped.
    DriveHierarchy,
    /// The original runner's: `RUN/<stem>_pred.jsonl`; original fields win; all lines count.
    Original,
}

impl Layout {
    pub fn parse(s: &str) -> Result<Layout> {
        match s {
            "drivehierarchy" => Ok(Layout::DriveHierarchy),
            "original" => Ok(Layout::Original),
            other => Err(Error::Record {
                context: "layout".into(),
                field: "layout".into(),
                reason: format!("unknown layout `{other}` (expected `drivehierarchy` or `original`)"),
            }),
        }
    }
}

/// Format of one line, as it was read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum LineFormat {
    DriveHierarchy,
    Original,
}

impl LineFormat {
    pub fn as_str(self) -> &'static str {
        match self {
            LineFormat::DriveHierarchy => "drivehierarchy",
            LineFormat::Original => "original",
        }
    }
}

/// Where a line's ground truth comes from.
#[derive(Debug, Clone)]
pub enum Truth {
    /// The released record; the task's field holds the ground truth.
    Record(Value),
    /// The original runner's `ground_truth` value and `question` (`None`: key absent).
    Original { ground_truth: Value, question: Option<Value> },
}

/// One usable prediction line.
#[derive(Debug, Clone)]
pub struct PredictionEntry {
    /// 1-based line number in the file.
    pub line: usize,
    /// `None` only for an original-format line without any id field (its scorer needs none).
    pub id: Option<String>,
    pub task: Option<String>,
    pub prediction: String,
    pub truth: Truth,
    pub model: Option<String>,
    pub format: LineFormat,
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
    /// Non-blank lines in the file.
    pub lines: usize,
    /// Lines whose id was already seen, skipped (our layout: resume duplicates).
    pub duplicates: usize,
    /// Lines whose id was already seen but counted (original layout, as its scorer does).
    pub duplicate_ids: usize,
    /// Unreadable lines, skipped (includes the truncated tail).
    pub issues: Vec<LineIssue>,
    /// Whether the last line was cut short (no final newline and not valid JSON).
    pub truncated_tail: bool,
}

fn id_string(v: &Value, key: &str) -> std::result::Result<Option<String>, String> {
    match v {
        Value::String(s) => Ok(Some(s.clone())),
        Value::Number(n) => Ok(Some(n.to_string())),
        Value::Null => Ok(None),
        other => Err(format!("`{key}` is not a string: {other}")),
    }
}

fn read_ours(obj: &mut Map<String, Value>) -> std::result::Result<PredictionEntry, String> {
    let id = match obj.get("id") {
        None => return Err("missing field `id`".into()),
        Some(v) => id_string(v, "id")?.ok_or("`id` is null")?,
    };
    let prediction = match obj.get("prediction") {
        None => return Err("missing field `prediction`".into()),
        Some(Value::String(s)) => s.clone(),
        Some(other) => return Err(format!("`prediction` is not a string: {other}")),
    };
    let task = match obj.get("task") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(other) => return Err(format!("`task` is not a string: {other}")),
    };
    let record = match obj.remove("record") {
        None => return Err("missing field `record`".into()),
        Some(r) if !r.is_object() => return Err("`record` is not a JSON object".into()),
        Some(r) => r,
    };
    Ok(PredictionEntry {
        line: 0,
        id: Some(id),
        task,
        prediction,
        truth: Truth::Record(record),
        model: None,
        format: LineFormat::DriveHierarchy,
    })
}

fn read_original(obj: &mut Map<String, Value>) -> std::result::Result<PredictionEntry, String> {
    let prediction = match obj.get("model_prediction") {
        None => return Err("missing field `model_prediction`".into()),
        Some(Value::String(s)) => s.clone(),
        Some(other) => return Err(format!("`model_prediction` is not a string: {other}")),
    };
    // The original runner always writes the key (null when the record had no target).
    let ground_truth = obj.remove("ground_truth").ok_or("missing field `ground_truth`")?;
    // The original runner's id: `Question_id`, else `task_id`, else `id`.
    let mut id = None;
    for key in ["Question_id", "task_id", "id"] {
        if let Some(v) = obj.get(key) {
            id = id_string(v, key)?;
            if id.is_some() {
                break;
            }
        }
    }
    let task = match obj.get("task") {
        Some(Value::String(s)) => Some(s.clone()),
        _ => None,
    };
    Ok(PredictionEntry {
        line: 0,
        id,
        task,
        prediction,
        truth: Truth::Original { ground_truth, question: obj.remove("question") },
        model: None,
        format: LineFormat::Original,
    })
}

fn parse_line(text: &str, layout: Layout) -> std::result::Result<PredictionEntry, String> {
    let v: Value = serde_json::from_str(text).map_err(|e| format!("invalid JSON line: {e}"))?;
    let Value::Object(mut obj) = v else {
        return Err(format!("line is not a JSON object: {}", short(&v)));
    };
    let ours = obj.contains_key("record") || obj.contains_key("prediction");
    let original = obj.contains_key("model_prediction");
    let mut entry = match (layout, ours, original) {
        (Layout::DriveHierarchy, true, _) | (Layout::Original, true, false) => read_ours(&mut obj)?,
        (Layout::Original, _, _) | (Layout::DriveHierarchy, false, true) => read_original(&mut obj)?,
        (Layout::DriveHierarchy, false, false) => {
            return Err("neither `model_prediction` (original format) nor `prediction` + `record` \
                        (drivehierarchy format)"
                .into())
        }
    };
    entry.model = match obj.get("model") {
        None | Some(Value::Null) => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(other) => Some(other.to_string()),
    };
    Ok(entry)
}

fn short(v: &Value) -> String {
    let s = v.to_string();
    match s.char_indices().nth(60) {
        Some((i, _)) => format!("{}…", &s[..i]),
        None => s,
    }
}

/// Parses the text of a predictions file (never fails; bad lines become issues).
pub fn parse_predictions(text: &str, layout: Layout) -> PredictionFile {
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
        out.lines += 1;
        let line_no = i + 1;
        match parse_line(t, layout) {
            Ok(mut e) => {
                if let Some(id) = &e.id {
                    if !seen.insert(id.clone()) {
                        if layout == Layout::DriveHierarchy {
                            out.duplicates += 1;
                            continue;
                        }
                        out.duplicate_ids += 1;
                    }
                }
                e.line = line_no;
                out.entries.push(e);
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
pub fn read_predictions(path: &Path, layout: Layout) -> Result<PredictionFile> {
    let bytes =
        std::fs::read(path).map_err(|source| Error::Io { path: path.display().to_string(), source })?;
    Ok(parse_predictions(&String::from_utf8_lossy(&bytes), layout))
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
    pub ids: Vec<Option<String>>,
    /// Scores (empty for R1_4, which the judge scores from `judge_items`).
    pub scores: Vec<f64>,
    pub parsed: Vec<bool>,
    pub judge_items: Vec<JudgeItem>,
    pub models: BTreeSet<String>,
    /// Line formats seen among the scored lines.
    pub formats: BTreeSet<LineFormat>,
    pub lines: usize,
    pub duplicates: usize,
    pub duplicate_ids: usize,
    /// Skipped lines, in file order.
    pub issues: Vec<LineIssue>,
    pub truncated_tail: bool,
}

fn judge_item(e: &PredictionEntry) -> JudgeItem {
    match &e.truth {
        Truth::Record(r) => {
            let (question, answer, prediction) = score::judge_fields(r, &e.prediction);
            JudgeItem { question, answer, prediction }
        }
        // `str(line.get(key, ""))`, stripped, as the original reads its own lines.
        Truth::Original { ground_truth, question } => JudgeItem {
            question: pu::strip(
                &question.as_ref().map(|q| PyValue::from_json(q).py_str()).unwrap_or_default(),
            )
            .to_string(),
            answer: pu::strip(&PyValue::from_json(ground_truth).py_str()).to_string(),
            prediction: pu::strip(&e.prediction).to_string(),
        },
    }
}

/// Scores parsed prediction lines of `task`; `source` names the file in messages. A line that
/// cannot be scored (wrong task, record without its ground-truth field) becomes an issue; a
/// file left with nothing to score is [`Error::NothingToScore`].
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
        formats: BTreeSet::new(),
        lines: file.lines,
        duplicates: file.duplicates,
        duplicate_ids: file.duplicate_ids,
        issues: file.issues,
        truncated_tail: file.truncated_tail,
    };
    let judged = task.scorer() == Scorer::TextLingoJudge;
    for e in file.entries {
        if let Some(t) = e.task.as_deref() {
            if TaskId::parse(t).ok() != Some(task) {
                out.issues.push(LineIssue {
                    line: e.line,
                    message: format!("`task` is `{t}`, not the file's task {task}"),
                });
                continue;
            }
        }
        if judged {
            out.judge_items.push(judge_item(&e));
        } else {
            let s = match &e.truth {
                Truth::Record(r) => {
                    let ctx = format!("{source}:{} record", e.line);
                    match score::score_record(task, r, &e.prediction, opts, &ctx) {
                        Ok(s) => s,
                        Err(Error::Record { field, reason, .. }) => {
                            out.issues.push(LineIssue {
                                line: e.line,
                                message: format!("record field `{field}`: {reason}"),
                            });
                            continue;
                        }
                        Err(other) => return Err(other),
                    }
                }
                Truth::Original { ground_truth, .. } => {
                    score::score_answer(task.scorer(), &PyValue::from_json(ground_truth), &e.prediction, opts)
                }
            };
            // Only R1_4 is judge-scored, handled above.
            let Some(s) = s else { continue };
            out.scores.push(s.score);
            out.parsed.push(s.parsed);
        }
        if let Some(m) = e.model {
            out.models.insert(m);
        }
        out.formats.insert(e.format);
        out.ids.push(e.id);
    }
    out.issues.sort_by_key(|i| i.line);
    if out.ids.is_empty() {
        let reason = match out.issues.first() {
            None => "no prediction lines (empty file)".to_string(),
            Some(first) => format!(
                "none of its {} lines could be scored; first: line {}: {}",
                out.lines, first.line, first.message
            ),
        };
        return Err(Error::NothingToScore { context: source.to_string(), reason });
    }
    Ok(out)
}

/// Reads and scores `path` as part of a folder of `layout`; the task comes from `task` or
/// else the file name (the original runner's exact names in the original layout).
pub fn score_predictions_file(
    path: &Path,
    task: Option<TaskId>,
    layout: Layout,
    opts: &ScoreOptions,
) -> Result<ScoredFile> {
    let name = path.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let task = match (task, layout) {
        (Some(t), _) => t,
        (None, Layout::Original) => {
            TaskId::from_original_file_name(&name).map_err(|_| Error::UnknownTaskFile {
                file: path.display().to_string(),
                expected: "the original runner writes `<task file stem>_pred.jsonl`, e.g. \
                           `R1_1_A_Existence_pred.jsonl`"
                    .into(),
            })?
        }
        (None, Layout::DriveHierarchy) => TaskId::from_stem(&name).map_err(|_| Error::UnknownTaskFile {
            file: path.display().to_string(),
            expected: "expected `<task file stem>.jsonl`, e.g. `R1_1_A_Existence.jsonl`".into(),
        })?,
    };
    let file = read_predictions(path, layout)?;
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

    fn original(id: &str, pred: &str, gt: Value) -> String {
        serde_json::json!({"Question_id": id, "question": "q?", "ground_truth": gt, "model_prediction": pred})
            .to_string()
    }

    const DH: Layout = Layout::DriveHierarchy;

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
        let f = parse_predictions(&text, DH);
        assert_eq!(f.entries.len(), 2);
        assert_eq!(f.entries[0].prediction, "yes");
        assert_eq!(f.duplicates, 1);
        assert_eq!(f.lines, 4);
        assert!(f.truncated_tail);
        assert_eq!(f.issues.len(), 1);
        assert_eq!(f.issues[0].line, 5);
        let s = score_entries(TaskId::R1_1_A, f, &ScoreOptions::default(), "f").unwrap();
        assert_eq!(s.scores, vec![100.0, 100.0]);
        assert_eq!(s.models.iter().collect::<Vec<_>>(), vec!["m"]);
    }

    #[test]
    fn malformed_lines_and_wrong_task_are_issues() {
        let text = format!("{{oops\n{}\n{{\"id\": \"z\"}}\n", line("q1", "yes", "Yes"));
        let f = parse_predictions(&text, DH);
        assert_eq!(f.entries.len(), 1);
        assert!(!f.truncated_tail);
        assert_eq!(f.issues.iter().map(|i| i.line).collect::<Vec<_>>(), vec![1, 3]);
        assert!(f.issues[1].message.contains("neither `model_prediction`"), "{:?}", f.issues);
        let text = format!(
            "{}\n{}\n",
            line("q1", "yes", "Yes"),
            line("q2", "yes", "Yes").replace("R1_1_A", "R1_1_B")
        );
        let s = score_entries(TaskId::R1_1_A, parse_predictions(&text, DH), &ScoreOptions::default(), "f")
            .unwrap();
        assert_eq!(s.scores, vec![100.0]);
        assert_eq!(s.issues.len(), 1);
        assert!(s.issues[0].message.contains("`task` is `R1_1_B`"), "{:?}", s.issues);
    }

    #[test]
    fn nothing_to_score_names_file_and_first_reason() {
        // Every line is the original format's, read as ours without a `record`: all skipped.
        let text = r#"{"id": "a", "prediction": "3"}"#;
        let e =
            score_entries(TaskId::R1_1_B, parse_predictions(text, DH), &ScoreOptions::default(), "p.jsonl")
                .unwrap_err()
                .to_string();
        assert!(e.contains("p.jsonl") && e.contains("line 1") && e.contains("`record`"), "{e}");
        // A record without its ground-truth field is skipped, naming the field.
        let text = r#"{"id": "a", "prediction": "3", "record": {"Question_id": "a"}}"#;
        let e =
            score_entries(TaskId::R1_1_B, parse_predictions(text, DH), &ScoreOptions::default(), "p.jsonl")
                .unwrap_err()
                .to_string();
        assert!(e.contains("p.jsonl: nothing to score") && e.contains("`answer`"), "{e}");
        let e =
            score_entries(TaskId::R1_1_B, parse_predictions("\n\n", DH), &ScoreOptions::default(), "e.jsonl")
                .unwrap_err()
                .to_string();
        assert!(e.contains("e.jsonl") && e.contains("empty"), "{e}");
    }

    #[test]
    fn original_lines_score_from_ground_truth_and_count_every_line() {
        let text = [
            original("R1_1_B_0", "3", Value::from("3")),
            original("R1_1_B_0", "2", Value::from("3")),
            original("R1_1_B_1", "x", Value::Null),
            r#"{"Question_id": "R1_1_B_2", "ground_truth": "1"}"#.to_string(),
            "[1, 2]".to_string(),
        ]
        .join("\n");
        let f = parse_predictions(&text, Layout::Original);
        assert_eq!((f.entries.len(), f.duplicate_ids, f.duplicates), (3, 1, 0));
        assert_eq!(f.issues.iter().map(|i| i.line).collect::<Vec<_>>(), vec![4, 5]);
        assert!(f.issues[0].message.contains("`model_prediction`"));
        let s = score_entries(TaskId::R1_1_B, f, &ScoreOptions::default(), "f").unwrap();
        assert_eq!(s.scores.len(), 3);
        assert_eq!(s.scores[0], 100.0);
        assert_eq!(s.parsed, vec![true, true, false]);
        assert_eq!(s.formats.iter().map(|f| f.as_str()).collect::<Vec<_>>(), vec!["original"]);
        // Our runner's lines carry both; the layout decides which fields win.
        let both = serde_json::json!({
            "id": "q", "task": "R1_1_A", "prediction": "yes", "record": {"Question_id": "q", "answer": "Yes"},
            "Question_id": "q", "question": "q?", "ground_truth": "No", "model_prediction": "yes",
        })
        .to_string();
        let ours = score_entries(TaskId::R1_1_A, parse_predictions(&both, DH), &ScoreOptions::default(), "f");
        let orig = score_entries(
            TaskId::R1_1_A,
            parse_predictions(&both, Layout::Original),
            &ScoreOptions::default(),
            "f",
        );
        assert_eq!(ours.unwrap().scores, vec![100.0]);
        assert_eq!(orig.unwrap().scores, vec![0.0]);
    }

    #[test]
    fn original_judge_items_read_str_of_each_field() {
        let text =
            serde_json::json!({"question": " What? ", "ground_truth": null, "model_prediction": " go \n"})
                .to_string();
        let s = score_entries(
            TaskId::R1_4,
            parse_predictions(&text, Layout::Original),
            &ScoreOptions::default(),
            "f",
        )
        .unwrap();
        assert_eq!(
            s.judge_items,
            vec![JudgeItem { question: "What?".into(), answer: "None".into(), prediction: "go".into() }]
        );
        assert_eq!(s.ids, vec![None]);
    }
}
