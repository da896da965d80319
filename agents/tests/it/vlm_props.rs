//! Property tests: the reply parser never panics and agrees with a direct reading of the
//! protocol on replies built from the canonical format.

use dh_agents::vlm::{parse_reply, ParseFailure};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn never_panics_on_any_text(s in any::<String>()) {
        let _ = parse_reply(&s);
    }

    #[test]
    fn never_panics_on_label_soup(s in "(steer|target_speed_mps|target_speed|[:= \t\n.+\\-0-9eE٣１𝟘])*") {
        if let Ok(d) = parse_reply(&s) {
            prop_assert!(!d.steer.is_nan() && !d.target_speed_mps.is_nan());
        }
    }

    #[test]
    fn canonical_replies_round_trip(
        steer in -1.0f64..1.0,
        target in 0.0f64..30.0,
        noise in "[a-z ,.!]{0,40}",
        sep in prop::sample::select(vec![":", "=", " : ", ":\n"]),
    ) {
        // Python prints floats with repr(); Rust's Display is also shortest round-trip.
        let reply = format!("{noise}\nSTEER{sep}{steer}\nTarget_Speed_MPS{sep}{target}\n{noise}");
        match parse_reply(&reply) {
            Ok(d) => {
                prop_assert_eq!(d.steer, steer);
                prop_assert_eq!(d.target_speed_mps, target);
            }
            Err(e) => prop_assert!(false, "{reply:?} failed: {e}"),
        }
    }

    #[test]
    fn missing_target_is_reported(steer in -5.0f64..5.0, junk in "[a-z ]{0,30}") {
        prop_assume!(!junk.contains("target_speed"));
        let r = parse_reply(&format!("steer: {steer} {junk}"));
        prop_assert_eq!(r, Err(ParseFailure::MissingTargetSpeed));
    }
}
