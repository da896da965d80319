#![no_main]
//! Open-loop prediction files (JSONL, both line formats and layouts): the reader never panics
//! and scoring what it read either fails cleanly or gives scores in [0, 100].

use dh_benchmark::predictions::{parse_predictions, score_entries, Layout};
use dh_benchmark::{ScoreOptions, TaskId};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    for layout in [Layout::DriveHierarchy, Layout::Original] {
        let file = parse_predictions(text, layout);
        let task = file
            .entries
            .iter()
            .find_map(|e| e.task.as_deref().and_then(|t| TaskId::parse(t).ok()))
            .unwrap_or(TaskId::ALL[0]);
        if let Ok(scored) = score_entries(task, file, &ScoreOptions::default(), "fuzz.jsonl") {
            for s in &scored.scores {
                assert!((0.0..=100.0).contains(s), "{task}: {s}");
            }
        }
    }
});
