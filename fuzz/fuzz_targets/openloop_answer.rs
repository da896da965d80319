#![no_main]
//! Open-loop answer parsers and scorers on arbitrary UTF-8: never panic, scores stay in
//! [0, 100] and an unparsed answer scores 0. Input: `ground truth \0 prediction` (without a
//! NUL, the text is both).

use dh_benchmark::pyjson::{self, PyValue};
use dh_benchmark::{parse, score_answer, ScoreOptions, TaskId};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(s) = std::str::from_utf8(data) else { return };
    let (gt, pred) = s.split_once('\u{0}').unwrap_or((s, s));
    let _ = parse::first_number(pred);
    let _ = parse::all_numbers(pred);
    let _ = parse::normalize_text(pred);
    let _ = parse::yes_no(pred);
    let _ = parse::choice_letter(pred);
    let _ = parse::strip_choice_prefix(pred);
    let _ = parse::bbox_of_str(pred);
    let gt = pyjson::loads(gt).unwrap_or(PyValue::Str(gt.to_string()));
    let _ = parse::number_of(&gt);
    let _ = parse::choice_letter_of(&gt);
    let _ = parse::bbox_of(&gt);
    let _ = parse::label_sequence(&gt);
    let _ = gt.py_str();
    let _ = gt.dumps();
    for strict in [false, true] {
        let opts = ScoreOptions { strict_order: strict, ..ScoreOptions::default() };
        for task in TaskId::ALL {
            if let Some(r) = score_answer(task.scorer(), &gt, pred, &opts) {
                assert!((0.0..=100.0).contains(&r.score), "{task}: {}", r.score);
                assert!(r.parsed || r.score == 0.0, "{task}: unparsed but {}", r.score);
            }
        }
    }
});
