//! The exact text sent to the VLM at each decision (docs/protocol.md#r4-prompt), original quirks kept.

use super::command::Command;
use std::fmt::Write as _;

/// The fixed action question, appended directly after the condition prefix. The missing space
/// in "right.When" and the real newlines before the output format are the original's.
pub const ACTION_QUESTION: &str = "Your primary objective is to reach the destination in the minimum time while remaining safe and legal. Hard constraints: do not collide with vehicles, pedestrians, or static obstacles; do not leave the drivable route; obey traffic lights, stop signs, and right-of-way rules. Driving policy: do not idle, crawl, or wait without a concrete safety or rule-based reason; if the route ahead is clear, actively increase speed toward the highest safe speed; use steering proactively to follow the future path and begin steering before turns instead of defaulting to zero steering; slow down only when required by route geometry, traffic rules, obstacles, or collision risk. For the steer value, a negative value indicates left, while a positive value indicates right.When making the decision, consider the ego speed, the future route geometry, drivable space, nearby vehicles, pedestrians, traffic lights, traffic signs, and any immediate collision or off-road risk. Never idle without a concrete safety or rule-based reason. Use steering proactively to track the future path instead of defaulting to straight driving. Output only the final action decision without explanation in the exact format:\nsteer: <float in [-1.0, 1.0]>\ntarget_speed_mps: <float in [0.0, 30.0]>";

/// Python's `f"{v:.1f}"`. Rust's `{:.1}` already rounds the exact binary value half-to-even
/// and prints negative zero as `-0.0`, as Python does; only NaN is spelled differently.
pub fn format_1f(v: f64) -> String {
    if v.is_nan() {
        "nan".to_owned()
    } else {
        format!("{v:.1}")
    }
}

/// The dynamic condition prefix; it ends with a space. No distance sentence when the
/// distance is unknown; `[]` when there are no points.
pub fn condition_prefix(
    speed_mps: f64,
    command: Command,
    distance_to_go_m: Option<f64>,
    points: &[(f64, f64)],
) -> String {
    let mut s = String::with_capacity(512);
    // Writing into a String cannot fail.
    let _ = write!(
        s,
        "The ego vehicle is driving at the speed of {} m/s, and it wants to {}. ",
        format_1f(speed_mps),
        command.text()
    );
    if let Some(d) = distance_to_go_m {
        let _ =
            write!(s, "Remaining route distance to destination is approximately {} meters. ", format_1f(d));
    }
    s.push_str("The local future route in ego coordinates is given as (forward_m, right_m): [");
    for (i, &(f, r)) in points.iter().enumerate() {
        if i > 0 {
            s.push_str(", ");
        }
        let _ = write!(s, "({}, {})", format_1f(f), format_1f(r));
    }
    s.push_str("]. ");
    s
}

/// Prefix + [`ACTION_QUESTION`]: the full user text of one decision.
pub fn decision_prompt(
    speed_mps: f64,
    command: Command,
    distance_to_go_m: Option<f64>,
    points: &[(f64, f64)],
) -> String {
    let mut s = condition_prefix(speed_mps, command, distance_to_go_m, points);
    s.push_str(ACTION_QUESTION);
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn action_question_is_pinned() {
        let expected = concat!(
            "Your primary objective is to reach the destination in the minimum time while remaining safe and legal. ",
            "Hard constraints: do not collide with vehicles, pedestrians, or static obstacles; do not leave the drivable route; ",
            "obey traffic lights, stop signs, and right-of-way rules. ",
            "Driving policy: do not idle, crawl, or wait without a concrete safety or rule-based reason; ",
            "if the route ahead is clear, actively increase speed toward the highest safe speed; ",
            "use steering proactively to follow the future path and begin steering before turns instead of defaulting to zero steering; ",
            "slow down only when required by route geometry, traffic rules, obstacles, or collision risk. ",
            "For the steer value, a negative value indicates left, while a positive value indicates right.",
            "When making the decision, consider the ego speed, the future route geometry, drivable space, nearby vehicles, ",
            "pedestrians, traffic lights, traffic signs, and any immediate collision or off-road risk. ",
            "Never idle without a concrete safety or rule-based reason. ",
            "Use steering proactively to track the future path instead of defaulting to straight driving. ",
            "Output only the final action decision without explanation in the exact format:",
            "\n",
            "steer: <float in [-1.0, 1.0]>",
            "\n",
            "target_speed_mps: <float in [0.0, 30.0]>"
        );
        assert_eq!(ACTION_QUESTION, expected);
        assert!(ACTION_QUESTION.contains("right.When"));
        assert_eq!(ACTION_QUESTION.matches('\n').count(), 2);
        assert!(!ACTION_QUESTION.contains('\\'));
    }

    #[test]
    fn full_prompt_literal() {
        let pts = [(5.0, 0.04), (10.0, -0.04), (15.25, 0.35), (20.0, 2.675)];
        let got = decision_prompt(3.25, Command::TurnRight, Some(123.45), &pts);
        let expected = "The ego vehicle is driving at the speed of 3.2 m/s, and it wants to turns right at the intersection. Remaining route distance to destination is approximately 123.5 meters. The local future route in ego coordinates is given as (forward_m, right_m): [(5.0, 0.0), (10.0, -0.0), (15.2, 0.3), (20.0, 2.7)]. Your primary objective is to reach the destination in the minimum time while remaining safe and legal. Hard constraints: do not collide with vehicles, pedestrians, or static obstacles; do not leave the drivable route; obey traffic lights, stop signs, and right-of-way rules. Driving policy: do not idle, crawl, or wait without a concrete safety or rule-based reason; if the route ahead is clear, actively increase speed toward the highest safe speed; use steering proactively to follow the future path and begin steering before turns instead of defaulting to zero steering; slow down only when required by route geometry, traffic rules, obstacles, or collision risk. For the steer value, a negative value indicates left, while a positive value indicates right.When making the decision, consider the ego speed, the future route geometry, drivable space, nearby vehicles, pedestrians, traffic lights, traffic signs, and any immediate collision or off-road risk. Never idle without a concrete safety or rule-based reason. Use steering proactively to track the future path instead of defaulting to straight driving. Output only the final action decision without explanation in the exact format:
steer: <float in [-1.0, 1.0]>
target_speed_mps: <float in [0.0, 30.0]>";
        assert_eq!(got, expected);
    }

    #[test]
    fn prefix_without_distance_and_points() {
        assert_eq!(
            condition_prefix(0.0, Command::FollowLane, None, &[]),
            "The ego vehicle is driving at the speed of 0.0 m/s, and it wants to follow the road. The local future route in ego coordinates is given as (forward_m, right_m): []. "
        );
        assert_eq!(
            condition_prefix(12.0, Command::ChangeLaneLeft, Some(0.0), &[(1.0, -2.0)]),
            "The ego vehicle is driving at the speed of 12.0 m/s, and it wants to do a lane change to the left. Remaining route distance to destination is approximately 0.0 meters. The local future route in ego coordinates is given as (forward_m, right_m): [(1.0, -2.0)]. "
        );
    }

    #[test]
    fn one_decimal_matches_python() {
        // Expected values produced by CPython's f"{v:.1f}".
        let cases: [(f64, &str); 16] = [
            (0.25, "0.2"),
            (0.35, "0.3"),
            (2.675, "2.7"),
            (-0.04, "-0.0"),
            (-0.0, "-0.0"),
            (0.05, "0.1"),
            (0.15, "0.1"),
            (-0.05, "-0.1"),
            (0.45, "0.5"),
            (1.25, "1.2"),
            (-1.25, "-1.2"),
            (12345.65, "12345.6"),
            (1e20, "100000000000000000000.0"),
            (f64::NAN, "nan"),
            (f64::INFINITY, "inf"),
            (f64::NEG_INFINITY, "-inf"),
        ];
        for (v, want) in cases {
            assert_eq!(format_1f(v), want, "{v:?}");
        }
    }
}
