#![no_main]
//! Every parser and scorer on arbitrary UTF-8: must not panic, scores stay in [0, 100].

use dh_benchmark::pyjson::{self, PyValue};
use dh_benchmark::{parse, score_answer, ScoreOptions, TaskId};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(s) = std::str::from_utf8(data) else { return };
    let (gt, pred) = s.split_once('\u{0}').unwrap_or((s, s));
    let _ = parse::first_number(pred);
    let _ = parse::strip_choice_prefix(pred);
    let gt = pyjson::loads(gt).unwrap_or(PyValue::Str(gt.to_string()));
    for strict in [false, true] {
        let opts = ScoreOptions { strict_order: strict, ..ScoreOptions::default() };
        for task in TaskId::ALL {
            if let Some(r) = score_answer(task.scorer(), &gt, pred, &opts) {
                assert!((0.0..=100.0).contains(&r.score));
            }
        }
    }
});
