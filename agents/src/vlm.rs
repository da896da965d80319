//! VLM reply parser (docs/protocol.md#r4-actuation): text → (steer, target speed) decision.
//!
//! Mirrors the original Python (`re.search` on `reply.lower()`, then `float()`), including
//! Python's notion of `\s` (which also matches U+001C–U+001F) and `\d` (any Unicode decimal
//! digit, which Python's `float()` accepts).

use dh_env::drive::bridge::{Decision, DecisionFailure};
use regex::Regex;
use std::sync::LazyLock;

/// The number pattern of the protocol.
pub const NUM_PATTERN: &str = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)";

/// Python's `\s` for `str` patterns: Unicode White_Space plus the four ASCII separators.
const PY_SPACE: &str = r"[\s\x1C-\x1F]";

static STEER_RE: LazyLock<Regex> = LazyLock::new(|| labelled("steer"));
static TARGET_RE: LazyLock<Regex> = LazyLock::new(|| labelled("target_speed_mps"));
static TARGET_FALLBACK_RE: LazyLock<Regex> = LazyLock::new(|| labelled("target_speed"));
static DECIMAL_DIGIT_RE: LazyLock<Regex> = LazyLock::new(|| {
    #[allow(clippy::expect_used)]
    Regex::new(r"^\d$").expect("static pattern")
});

fn labelled(label: &str) -> Regex {
    let pattern = format!(r"{label}{PY_SPACE}*[:=]{PY_SPACE}*({NUM_PATTERN})");
    #[allow(clippy::expect_used)]
    Regex::new(&pattern).expect("static pattern")
}

/// Which field of the reply could not be found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, thiserror::Error)]
pub enum ParseFailure {
    #[error("reply has no `steer: <number>`")]
    MissingSteer,
    #[error("reply has no `target_speed_mps: <number>` (nor `target_speed: <number>`)")]
    MissingTargetSpeed,
    #[error("reply has neither `steer: <number>` nor `target_speed_mps: <number>`")]
    MissingBoth,
}

impl From<ParseFailure> for DecisionFailure {
    fn from(f: ParseFailure) -> Self {
        match f {
            ParseFailure::MissingSteer => DecisionFailure::MissingSteer,
            ParseFailure::MissingTargetSpeed => DecisionFailure::MissingTargetSpeed,
            ParseFailure::MissingBoth => DecisionFailure::MissingBoth,
        }
    }
}

/// Parses a reply into what the env applies: the decision, or why there is none.
pub fn parse_for_env(text: &str) -> Result<Decision, DecisionFailure> {
    parse_reply(text).map_err(DecisionFailure::from)
}

/// Parses a reply. The first `steer` and the first `target_speed_mps` (else `target_speed`)
/// followed by `:` or `=` and a number win; anything else in the text is ignored.
/// Numbers too long for f64 become ±inf, which the bridge clips.
pub fn parse_reply(text: &str) -> Result<Decision, ParseFailure> {
    let lower = text.to_lowercase();
    let steer = first_number(&STEER_RE, &lower);
    let target = first_number(&TARGET_RE, &lower).or_else(|| first_number(&TARGET_FALLBACK_RE, &lower));
    match (steer, target) {
        (Some(steer), Some(target_speed_mps)) => Ok(Decision { steer, target_speed_mps }),
        (None, Some(_)) => Err(ParseFailure::MissingSteer),
        (Some(_), None) => Err(ParseFailure::MissingTargetSpeed),
        (None, None) => Err(ParseFailure::MissingBoth),
    }
}

fn first_number(re: &Regex, text: &str) -> Option<f64> {
    let m = re.captures(text)?.get(1)?;
    python_float(m.as_str())
}

/// `float()` of a string already matched by [`NUM_PATTERN`]: non-ASCII decimal digits are
/// mapped to their ASCII value first, as Python does.
pub(crate) fn python_float(s: &str) -> Option<f64> {
    if s.is_ascii() {
        return s.parse().ok();
    }
    let ascii: String = s.chars().map(|c| if c.is_ascii() { c } else { ascii_digit(c) }).collect();
    ascii.parse().ok()
}

/// Value of a Unicode decimal digit. Unicode assigns Nd characters only in contiguous runs of
/// ten, ascending from zero, so the value is the distance from the run start modulo 10.
fn ascii_digit(c: char) -> char {
    let is_digit = |c: char| {
        let mut buf = [0u8; 4];
        DECIMAL_DIGIT_RE.is_match(c.encode_utf8(&mut buf))
    };
    let mut run = 0u32;
    let mut code = c as u32;
    while let Some(prev) = code.checked_sub(1).and_then(char::from_u32) {
        if !is_digit(prev) {
            break;
        }
        run += 1;
        code -= 1;
    }
    // `run % 10` < 10, so this is always an ASCII digit.
    char::from_digit(run % 10, 10).unwrap_or('0')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ok(s: f64, t: f64) -> Result<Decision, ParseFailure> {
        Ok(Decision { steer: s, target_speed_mps: t })
    }

    #[test]
    fn canonical_reply() {
        assert_eq!(parse_reply("steer: -0.25\ntarget_speed_mps: 8.5"), ok(-0.25, 8.5));
        assert_eq!(parse_reply("STEER = +.5 , Target_Speed_MPS=12."), ok(0.5, 12.0));
        assert_eq!(parse_reply("steer:0\ntarget_speed:3"), ok(0.0, 3.0));
    }

    #[test]
    fn first_match_wins_and_mps_label_preferred() {
        let r = "target_speed: 1\nsteer: 0.1 steer: 0.9\ntarget_speed_mps: 7 target_speed_mps: 9";
        assert_eq!(parse_reply(r), ok(0.1, 7.0));
    }

    #[test]
    fn missing_fields_are_named() {
        assert_eq!(parse_reply("target_speed_mps: 3"), Err(ParseFailure::MissingSteer));
        assert_eq!(parse_reply("steer: 0.3"), Err(ParseFailure::MissingTargetSpeed));
        assert_eq!(parse_reply("I would slow down."), Err(ParseFailure::MissingBoth));
        assert_eq!(parse_reply(""), Err(ParseFailure::MissingBoth));
        // Labels must be followed by `:`/`=`; "steering:" is not "steer:".
        assert_eq!(parse_reply("steering: 0.3 target_speed_mps: 2"), Err(ParseFailure::MissingSteer));
        // No exponent, no comma decimals: "1e3" reads 1, "0,5" reads 0.
        assert_eq!(parse_reply("steer: 1e3 target_speed_mps: 0,5"), ok(1.0, 0.0));
        // A sign alone is not a number.
        assert_eq!(parse_reply("steer: - target_speed_mps: 4"), Err(ParseFailure::MissingSteer));
    }

    #[test]
    fn python_whitespace_and_digits() {
        // U+001F is whitespace for Python's re; U+00A0 too.
        assert_eq!(parse_reply("steer\u{1f}:\u{a0}0.5 target_speed_mps:\t2"), ok(0.5, 2.0));
        // Arabic-Indic and fullwidth digits: Python's float() reads them.
        assert_eq!(parse_reply("steer: ٠.٣ target_speed_mps: １２"), ok(0.3, 12.0));
        // Mathematical double-struck digits sit right after the bold ones (one 50-char run).
        assert_eq!(parse_reply("steer: 𝟘 target_speed_mps: 𝟡𝟟"), ok(0.0, 97.0));
    }

    #[test]
    fn huge_numbers_become_infinite() {
        let big = "9".repeat(400);
        let r = parse_reply(&format!("steer: {big} target_speed_mps: -{big}")).unwrap();
        assert_eq!((r.steer, r.target_speed_mps), (f64::INFINITY, f64::NEG_INFINITY));
    }
}
