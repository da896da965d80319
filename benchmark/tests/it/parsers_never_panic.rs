//! Property tests: parsers and scorers never panic and stay in range on arbitrary text.

use dh_benchmark::parse;
use dh_benchmark::pyjson::{self, PyValue};
use dh_benchmark::{score_answer, ScoreOptions, TaskId};
use proptest::prelude::*;

fn reply() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<String>(),
        "[ \\[\\]{}\"',:0-9A-Za-z.eE+-]{0,40}",
        "(yes|no|OPTION|ANSWER|choice|[A-D]|[0-9]{1,3}|\\.|,|\\[|\\]|\"| |\n|٣|Ⓐ|ſ|İ|NaN|Infinity){0,12}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn parsers_never_panic(s in reply()) {
        let _ = parse::first_number(&s);
        let _ = parse::all_numbers(&s);
        let _ = parse::normalize_text(&s);
        let _ = parse::yes_no(&s);
        let _ = parse::choice_letter(&s);
        let _ = parse::strip_choice_prefix(&s);
        let _ = parse::bbox_of_str(&s);
        let _ = parse::label_sequence(&PyValue::Str(s.clone()));
        if let Some(v) = pyjson::loads(&s) {
            let _ = v.py_str();
            let _ = v.dumps();
        }
    }

    #[test]
    fn scores_stay_in_range(s in reply(), gt in reply(), strict in any::<bool>()) {
        let opts = ScoreOptions { strict_order: strict, ..ScoreOptions::default() };
        for task in TaskId::ALL {
            let gt_value = pyjson::loads(&gt).unwrap_or(PyValue::Str(gt.clone()));
            if let Some(r) = score_answer(task.scorer(), &gt_value, &s, &opts) {
                prop_assert!((0.0..=100.0).contains(&r.score), "{task}: {}", r.score);
                if !r.parsed {
                    prop_assert_eq!(r.score, 0.0);
                }
            }
        }
    }

    #[test]
    fn normalised_text_is_in_the_allowed_alphabet(s in any::<String>()) {
        let n = parse::normalize_text(&s);
        prop_assert!(n.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == ' '));
        prop_assert!(!n.starts_with(' ') && !n.ends_with(' '));
    }
}
