//! The released record schema of every task, read from the loose JSON as it is.
//!
//! Ids are in `Question_id` (or `task_id` for R1_3, else `id`); ground truth in `answer`,
//! `ground_truth` (R1_3, a dict with `bbox`) or `ground_truth_order` (R3_2); images in
//! `image_path`, `image_paths` (or `meta_data.image_paths`) or labelled `images[]` (R3_2).

use serde_json::Value;

use crate::error::{Error, Result};
use crate::pyjson::PyValue;
use crate::task::{Scorer, TaskId};

/// One image of a record; `label` is set for the labelled images of R3_2.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageRef {
    pub label: Option<String>,
    pub path: String,
}

/// A released open-loop record, reduced to what prompting and scoring need.
#[derive(Debug, Clone)]
pub struct Record {
    pub task: TaskId,
    pub id: String,
    /// The question text as the original harness keeps it (`question`, else `prompt`).
    pub question: String,
    /// The ground truth as a Python value (string, number, list or dict).
    pub ground_truth: PyValue,
    pub options: Vec<String>,
    pub images: Vec<ImageRef>,
}

fn field_err(ctx: &str, field: &str, reason: impl Into<String>) -> Error {
    Error::Record { context: ctx.to_string(), field: field.to_string(), reason: reason.into() }
}

/// The record's id (`Question_id`, else `task_id`, else `id`), as a string.
pub fn record_id(record: &Value, ctx: &str) -> Result<String> {
    let obj = record.as_object().ok_or_else(|| field_err(ctx, "record", "expected a JSON object"))?;
    for key in ["Question_id", "task_id", "id"] {
        if let Some(v) = obj.get(key) {
            return match v {
                Value::String(s) => Ok(s.clone()),
                Value::Number(n) => Ok(n.to_string()),
                other => Err(field_err(ctx, key, format!("expected a string id, got {other}"))),
            };
        }
    }
    Err(field_err(ctx, "Question_id", "missing (also no `task_id` or `id`)"))
}

/// Name of the field holding the ground truth for a task's scorer.
pub fn ground_truth_field(task: TaskId) -> &'static str {
    match task.scorer() {
        Scorer::SequenceOrder => "ground_truth_order",
        Scorer::Bbox => "ground_truth",
        _ => "answer",
    }
}

/// The ground truth as the original harness extracts it; the field must be present
/// (a present but unusable value scores 0 as unparseable, like the original).
pub fn ground_truth(task: TaskId, record: &Value, ctx: &str) -> Result<PyValue> {
    let field = ground_truth_field(task);
    record
        .get(field)
        .map(PyValue::from_json)
        .ok_or_else(|| field_err(ctx, field, format!("missing ground truth for task {task}")))
}

/// `normalize_to_text(record.question or record.prompt or "")`.
pub fn question_text(record: &Value) -> String {
    for key in ["question", "prompt"] {
        if let Some(v) = record.get(key).map(PyValue::from_json) {
            if v.is_truthy() {
                return match v {
                    PyValue::Str(s) => s,
                    PyValue::List(_) | PyValue::Dict(_) => v.dumps(),
                    other => other.py_str(),
                };
            }
        }
    }
    String::new()
}

fn images_of(task: TaskId, record: &Value, ctx: &str) -> Result<Vec<ImageRef>> {
    let as_path = |v: &Value, field: &str| -> Result<String> {
        v.as_str()
            .map(str::to_string)
            .ok_or_else(|| field_err(ctx, field, format!("expected a path string, got {v}")))
    };
    if task.scorer() == Scorer::SequenceOrder {
        let items = record
            .get("images")
            .and_then(Value::as_array)
            .ok_or_else(|| field_err(ctx, "images", "expected a list of {label, path}"))?;
        return items
            .iter()
            .map(|it| {
                let label = it.get("label").and_then(|l| match l {
                    Value::Null => None,
                    Value::String(s) => Some(s.clone()),
                    other => Some(other.to_string()),
                });
                let path = it.get("path").unwrap_or(&Value::Null);
                Ok(ImageRef { label, path: as_path(path, "images[].path")? })
            })
            .collect();
    }
    let list = record
        .get("image_paths")
        .filter(|v| !matches!(v, Value::Null) && v.as_array().is_none_or(|a| !a.is_empty()))
        .or_else(|| record.get("meta_data").and_then(|m| m.get("image_paths")));
    if let Some(list) = list.filter(|v| !v.is_null()) {
        let items =
            list.as_array().ok_or_else(|| field_err(ctx, "image_paths", "expected a list of paths"))?;
        return items
            .iter()
            .map(|p| Ok(ImageRef { label: None, path: as_path(p, "image_paths[]")? }))
            .collect();
    }
    match record.get("image_path") {
        Some(Value::Null) | None => {
            Err(field_err(ctx, "image_path", "missing (also no `image_paths`/`images`)"))
        }
        Some(p) => Ok(vec![ImageRef { label: None, path: as_path(p, "image_path")? }]),
    }
}

impl Record {
    /// Reads a released record of `task`; `ctx` names the source (file and line) in errors.
    pub fn from_value(task: TaskId, record: &Value, ctx: &str) -> Result<Record> {
        let id = record_id(record, ctx)?;
        let ground_truth = ground_truth(task, record, ctx)?;
        let options = match record.get("options") {
            None | Some(Value::Null) => Vec::new(),
            Some(Value::Array(items)) => items.iter().map(|o| PyValue::from_json(o).py_str()).collect(),
            Some(other) => return Err(field_err(ctx, "options", format!("expected a list, got {other}"))),
        };
        Ok(Record {
            task,
            id,
            question: question_text(record),
            ground_truth,
            options,
            images: images_of(task, record, ctx)?,
        })
    }

    /// Parses one JSONL line of a release file.
    pub fn from_json(task: TaskId, line: &str, ctx: &str) -> Result<Record> {
        let v: Value =
            serde_json::from_str(line).map_err(|e| field_err(ctx, "record", format!("invalid JSON: {e}")))?;
        Record::from_value(task, &v, ctx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn official_dir() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/official/Open_Loop_Evaluation")
    }

    #[test]
    fn every_sample_file_loads_unchanged() {
        let dir = official_dir();
        if !dir.is_dir() {
            eprintln!("skipped: {} not found", dir.display());
            return;
        }
        for spec in crate::task::TASKS.iter() {
            let path = dir.join(format!("{}.jsonl", spec.stem));
            let text = std::fs::read_to_string(&path).unwrap();
            let mut n = 0;
            for (i, line) in text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()) {
                let ctx = format!("{}:{}", path.display(), i + 1);
                let v: Value = serde_json::from_str(line).unwrap();
                assert_eq!(TaskId::from_record(&v).unwrap(), spec.id, "{ctx}");
                let r = Record::from_value(spec.id, &v, &ctx).unwrap();
                assert!(!r.id.is_empty() && !r.images.is_empty(), "{ctx}");
                match spec.scorer {
                    Scorer::MultiChoice => assert!(r.options.len() >= 2, "{ctx}"),
                    Scorer::SequenceOrder => {
                        assert!(r.images.iter().all(|i| i.label.is_some()), "{ctx}");
                        assert!(r.question.is_empty(), "{ctx}");
                    }
                    _ => assert!(!r.question.is_empty(), "{ctx}"),
                }
                n += 1;
            }
            assert!(n > 0, "{}", path.display());
        }
    }

    #[test]
    fn errors_name_the_field() {
        let v = serde_json::json!({"question": "q", "image_path": "a.jpg"});
        let e = Record::from_value(TaskId::R1_1_A, &v, "f.jsonl:3").unwrap_err();
        assert!(e.to_string().contains("f.jsonl:3") && e.to_string().contains("Question_id"));
        let v = serde_json::json!({"Question_id": "x", "image_path": "a.jpg"});
        let e = Record::from_value(TaskId::R1_1_A, &v, "f").unwrap_err();
        assert!(e.to_string().contains("`answer`"), "{e}");
        let v = serde_json::json!({"task_id": "R1_3_0", "image_path": "a.jpg", "ground_truth": {"bbox": [1, 2, 3, 4]}});
        let r = Record::from_value(TaskId::R1_3, &v, "f").unwrap();
        assert_eq!(r.id, "R1_3_0");
        let v = serde_json::json!({"Question_id": "x", "answer": "A", "options": "A. x"});
        assert!(Record::from_value(TaskId::R2_3, &v, "f").unwrap_err().to_string().contains("options"));
    }
}
