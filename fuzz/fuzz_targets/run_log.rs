#![no_main]
//! Episode run log (JSONL) reader and the re-scorer behind `r4 rescore`: never panics; a
//! re-scored run's scores stay in range and survive a write/read round trip.

use dh_env::score::RunLog;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(log) = RunLog::from_jsonl(text, "fuzz.jsonl") else { return };
    let Ok(score) = log.rescore() else { return };
    for (s, max) in [
        (score.score_route, 100.0),
        (score.score_safety, 1.0),
        (score.score_efficiency, 1.0),
        (score.score_penalty, 1.0),
        (score.score_composed, 100.0),
    ] {
        assert!((0.0..=max).contains(&s), "{score:?}");
    }
    let back = RunLog::from_jsonl(&log.to_jsonl(), "round trip");
    if let Ok(back) = back {
        let again = back.rescore().expect("a re-read log re-scores");
        assert_eq!(format!("{again:?}"), format!("{score:?}"));
    }
});
