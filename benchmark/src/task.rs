//! The 14 open-loop tasks: ids, release file stems, ranks, answer kinds, scorers and the
//! frozen headline weights (paper Table 1, docs/protocol.md#aggregation).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// Capability rank of an open-loop task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum Rank {
    R1,
    R2,
    R3,
}

impl Rank {
    pub const ALL: [Rank; 3] = [Rank::R1, Rank::R2, Rank::R3];

    pub fn as_str(self) -> &'static str {
        match self {
            Rank::R1 => "R1",
            Rank::R2 => "R2",
            Rank::R3 => "R3",
        }
    }

    pub fn parse(s: &str) -> Result<Rank> {
        match s {
            "R1" => Ok(Rank::R1),
            "R2" => Ok(Rank::R2),
            "R3" => Ok(Rank::R3),
            other => Err(Error::Calibration(format!("unknown rank `{other}` (expected R1, R2 or R3)"))),
        }
    }
}

/// What the model is asked to answer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AnswerKind {
    YesNo,
    Integer,
    OptionLetter,
    Metres,
    Box,
    FreeText,
    OrderedList,
}

/// The per-record scorer; `task_type()`/`metric()` are the original's names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Scorer {
    YesNo,
    MultiChoice,
    NumericCount,
    NumericDistance,
    Bbox,
    TextLingoJudge,
    SequenceOrder,
}

impl Scorer {
    /// The original's `task_type` (keys of the micro means in `final_score.json`).
    pub fn task_type(self) -> &'static str {
        match self {
            Scorer::YesNo => "yes_no",
            Scorer::MultiChoice => "multi_choice",
            Scorer::NumericCount => "numeric_count",
            Scorer::NumericDistance => "numeric_distance",
            Scorer::Bbox => "bbox",
            Scorer::TextLingoJudge => "text_lingo_judge",
            Scorer::SequenceOrder => "sequence_order",
        }
    }

    /// The original's `metric` name.
    pub fn metric(self) -> &'static str {
        match self {
            Scorer::YesNo => "em_yes_no",
            Scorer::MultiChoice => "em_multi_choice",
            Scorer::NumericCount => "count_exp_decay",
            Scorer::NumericDistance => "distance_log_ratio_exp_decay",
            Scorer::Bbox => "bbox_iou",
            Scorer::TextLingoJudge => "lingo_judge_probability",
            Scorer::SequenceOrder => "sequence_kendall",
        }
    }
}

/// One of the 14 open-loop tasks.
#[allow(non_camel_case_types)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum TaskId {
    R1_1_A,
    R1_1_B,
    R1_1_C,
    R1_2_A,
    R1_2_B,
    R1_2_C,
    R1_3,
    R1_4,
    R2_1,
    R2_2_A,
    R2_2_B,
    R2_3,
    R3_1,
    R3_2,
}

/// Static description of a task.
#[derive(Debug, Clone, Copy)]
pub struct TaskSpec {
    pub id: TaskId,
    pub name: &'static str,
    /// File stem of the released JSONL (`<stem>.jsonl`).
    pub stem: &'static str,
    /// Stem used by the original harness before the release renamed files.
    pub legacy_stem: &'static str,
    pub rank: Rank,
    pub answer: AnswerKind,
    pub scorer: Scorer,
    /// Frozen headline weight (paper Table 1).
    pub weight: f64,
}

macro_rules! spec {
    ($id:ident, $stem:literal, $legacy:literal, $rank:ident, $ans:ident, $sc:ident, $w:literal) => {
        TaskSpec {
            id: TaskId::$id,
            name: stringify!($id),
            stem: $stem,
            legacy_stem: $legacy,
            rank: Rank::$rank,
            answer: AnswerKind::$ans,
            scorer: Scorer::$sc,
            weight: $w,
        }
    };
}

/// The registry, in the paper's column order.
pub const TASKS: [TaskSpec; 14] = [
    spec!(
        R1_1_A,
        "R1_1_A_Existence",
        "R1_1_A_filtered_Existence_nuscenes_trainval_w_path",
        R1,
        YesNo,
        YesNo,
        0.030
    ),
    spec!(
        R1_1_B,
        "R1_1_B_Counting",
        "R1_1_B_filtered_Counting_nuscenes_trainval_w_path",
        R1,
        Integer,
        NumericCount,
        0.027
    ),
    spec!(
        R1_1_C,
        "R1_1_C_State_Attribute",
        "R1_1_C_filtered_State_nuscenes_trainval_w_path",
        R1,
        OptionLetter,
        MultiChoice,
        0.056
    ),
    spec!(
        R1_2_A,
        "R1_2_A_Nearest_Object",
        "R1_2_A_filtered_Distance_global_nuscenes_trainval_w_path",
        R1,
        Metres,
        NumericDistance,
        0.035
    ),
    spec!(
        R1_2_B,
        "R1_2_B_Certain_Object",
        "R1_2_B_filtered_Distance_pixel_nuscenes_trainval_w_path",
        R1,
        Metres,
        NumericDistance,
        0.036
    ),
    spec!(
        R1_2_C,
        "R1_2_C_Distance_Bucket",
        "R1_2_C_filtered_DistanceBucket_nuscenes_trainval_w_path",
        R1,
        Integer,
        NumericCount,
        0.029
    ),
    spec!(R1_3, "R1_3_Location_Questions", "R1_3_location_drama_w_path", R1, Box, Bbox, 0.056),
    spec!(
        R1_4,
        "R1_4_Situation_Description",
        "R1_4_LingoQA_situation_w_path",
        R1,
        FreeText,
        TextLingoJudge,
        0.031
    ),
    spec!(
        R2_1,
        "R2_1_Multi_view_Memory",
        "R2_1_A_filtered_Multiview_memory_nuscenes_trainval_w_paths",
        R2,
        Integer,
        NumericCount,
        0.064
    ),
    spec!(
        R2_2_A,
        "R2_2_A_Temporal_Counting",
        "R2_1_B_Temporal_Sequence_nuscenes_trainval_w_paths",
        R2,
        Integer,
        NumericCount,
        0.079
    ),
    spec!(
        R2_2_B,
        "R2_2_B_Temporal_Status_Recognition",
        "R2_1_C_nuscenes_trainval_w_paths",
        R2,
        OptionLetter,
        MultiChoice,
        0.067
    ),
    spec!(
        R2_3,
        "R2_3_Spatial_Relations",
        "R2_3_filtered_Spatial_rel_nuscenes_trainval_w_path",
        R2,
        OptionLetter,
        MultiChoice,
        0.090
    ),
    spec!(
        R3_1,
        "R3_1_Outcome_Prediction",
        "R3_1_Outcome_prediction_drivelm_trainnus_w_path",
        R3,
        OptionLetter,
        MultiChoice,
        0.233
    ),
    spec!(
        R3_2,
        "R3_2_Sequential_Planning",
        "R3_2_Sequence_planning_navsim_trainval_w_path",
        R3,
        OrderedList,
        SequenceOrder,
        0.167
    ),
];

impl TaskId {
    pub const ALL: [TaskId; 14] = [
        TaskId::R1_1_A,
        TaskId::R1_1_B,
        TaskId::R1_1_C,
        TaskId::R1_2_A,
        TaskId::R1_2_B,
        TaskId::R1_2_C,
        TaskId::R1_3,
        TaskId::R1_4,
        TaskId::R2_1,
        TaskId::R2_2_A,
        TaskId::R2_2_B,
        TaskId::R2_3,
        TaskId::R3_1,
        TaskId::R3_2,
    ];

    pub fn spec(self) -> &'static TaskSpec {
        &TASKS[self as usize]
    }

    pub fn as_str(self) -> &'static str {
        self.spec().name
    }

    pub fn rank(self) -> Rank {
        self.spec().rank
    }

    pub fn scorer(self) -> Scorer {
        self.spec().scorer
    }

    pub fn frozen_weight(self) -> f64 {
        self.spec().weight
    }

    /// A task id such as `R1_1_A` (also accepts `R1-1-A`).
    pub fn parse(s: &str) -> Result<TaskId> {
        let norm = s.trim().replace('-', "_");
        TASKS.iter().find(|t| t.name == norm).map(|t| t.id).ok_or_else(|| Error::UnknownTask(s.to_string()))
    }

    /// The task of a predictions or release file stem: the released stem, the original
    /// harness's legacy stem, either with the harness's `_pred` suffix, or a bare task id.
    pub fn from_stem(stem: &str) -> Result<TaskId> {
        let base = stem.strip_suffix(".jsonl").unwrap_or(stem);
        let base = base.strip_suffix("_pred").unwrap_or(base);
        TASKS
            .iter()
            .find(|t| t.stem == base || t.legacy_stem == base)
            .map(|t| t.id)
            .map_or_else(|| TaskId::parse(base), Ok)
            .map_err(|_| Error::UnknownTask(stem.to_string()))
    }

    /// The task of a file in the original runner's result folder: exactly the names its
    /// scorer lists, `<released stem>_pred.jsonl` or `<legacy stem>_pred.jsonl`. The original
    /// guesses only a scorer type for other names; a task id is needed here, so they are refused.
    pub fn from_original_file_name(name: &str) -> Result<TaskId> {
        let unknown = || Error::UnknownTaskFile {
            file: name.to_string(),
            expected: "the original runner writes `<task file stem>_pred.jsonl`, e.g. \
                       `R1_1_A_Existence_pred.jsonl` (or the legacy stems)"
                .to_string(),
        };
        let base = name.strip_suffix("_pred.jsonl").ok_or_else(unknown)?;
        TASKS.iter().find(|t| t.stem == base || t.legacy_stem == base).map(|t| t.id).ok_or_else(unknown)
    }

    /// The task of a released record, from `refined_subtask_id` (`R1-1-A`; the release
    /// labels R2_1/R2_2_A/R2_2_B as `R2-1-A/B/C`), else from the id prefix.
    pub fn from_record(record: &serde_json::Value) -> Result<TaskId> {
        let release_alias = |s: &str| -> Option<TaskId> {
            match s {
                "R2_1_A" => Some(TaskId::R2_1),
                "R2_1_B" => Some(TaskId::R2_2_A),
                "R2_1_C" => Some(TaskId::R2_2_B),
                _ => TaskId::parse(s).ok(),
            }
        };
        if let Some(sub) = record.get("refined_subtask_id").and_then(|v| v.as_str()) {
            if let Some(t) = release_alias(&sub.replace('-', "_")) {
                return Ok(t);
            }
        }
        for key in ["Question_id", "task_id"] {
            if let Some(id) = record.get(key).and_then(|v| v.as_str()) {
                // `R1_1_A_12` → `R1_1_A`; `R1_3_0` → `R1_3`.
                if let Some((prefix, _)) = id.rsplit_once('_') {
                    if let Some(t) = release_alias(prefix) {
                        return Ok(t);
                    }
                }
            }
        }
        Err(Error::UnknownTask(
            "record without a recognisable `refined_subtask_id`, `Question_id` or `task_id`".to_string(),
        ))
    }
}

impl std::fmt::Display for TaskId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for TaskId {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_is_consistent() {
        for (i, t) in TASKS.iter().enumerate() {
            assert_eq!(t.id as usize, i);
            assert_eq!(TaskId::parse(t.name).unwrap(), t.id);
            assert_eq!(TaskId::from_stem(t.stem).unwrap(), t.id);
            assert_eq!(TaskId::from_stem(&format!("{}_pred.jsonl", t.legacy_stem)).unwrap(), t.id);
            assert!(t.stem.starts_with(t.name));
        }
        let total: f64 = TASKS.iter().map(|t| t.weight).sum();
        assert!((total - 1.0).abs() < 1e-9);
        for r in Rank::ALL {
            let b: f64 = TASKS.iter().filter(|t| t.rank == r).map(|t| t.weight).sum();
            let want = if r == Rank::R3 { 0.4 } else { 0.3 };
            assert!((b - want).abs() < 1e-9, "{r:?} {b}");
        }
        assert!(TaskId::from_stem("R9_9_Nothing").is_err());
        for t in TASKS.iter() {
            assert_eq!(TaskId::from_original_file_name(&format!("{}_pred.jsonl", t.stem)).unwrap(), t.id);
            assert_eq!(
                TaskId::from_original_file_name(&format!("{}_pred.jsonl", t.legacy_stem)).unwrap(),
                t.id
            );
            assert!(TaskId::from_original_file_name(&format!("{}.jsonl", t.stem)).is_err());
        }
        // Bare ids and unknown stems are not names the original runner writes.
        let e = TaskId::from_original_file_name("R1_1_A_pred.jsonl").unwrap_err().to_string();
        assert!(e.contains("R1_1_A_pred.jsonl") && e.contains("R1_1_A_Existence_pred.jsonl"), "{e}");
        assert!(TaskId::from_original_file_name("R3_3_MultiAgent_Intent_pred.jsonl").is_err());
        assert_eq!(TaskId::parse("R2-2-B").unwrap(), TaskId::R2_2_B);
    }

    #[test]
    fn task_from_record_uses_release_quirks() {
        let r = serde_json::json!({"Question_id": "R2_1_B_0", "refined_subtask_id": "R2-1-B"});
        assert_eq!(TaskId::from_record(&r).unwrap(), TaskId::R2_2_A);
        let r = serde_json::json!({"task_id": "R1_3_4"});
        assert_eq!(TaskId::from_record(&r).unwrap(), TaskId::R1_3);
        let r = serde_json::json!({"Question_id": "R2_1_C_3"});
        assert_eq!(TaskId::from_record(&r).unwrap(), TaskId::R2_2_B);
        assert!(TaskId::from_record(&serde_json::json!({"x": 1})).is_err());
    }
}
