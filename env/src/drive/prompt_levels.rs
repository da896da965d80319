//! Prompts of the `waypoints` and `meta` action levels (docs/vlm.md#action-levels). They are this
//! project's extension of the protocol, not the paper's: the paper's prompt ([`super::prompt`])
//! stays the default and untouched. Each keeps the paper's condition prefix and the first part of
//! its action question word for word, and replaces only the output instructions.

use super::command::Command;
use super::meta::{PathAction, SpeedAction};
use super::prompt::{condition_prefix, format_1f};

/// The paper's objective, constraints and driving policy (its action question up to the steer
/// sentence), shared by every level's question.
pub const OBJECTIVE: &str = "Your primary objective is to reach the destination in the minimum time while remaining safe and legal. Hard constraints: do not collide with vehicles, pedestrians, or static obstacles; do not leave the drivable route; obey traffic lights, stop signs, and right-of-way rules. Driving policy: do not idle, crawl, or wait without a concrete safety or rule-based reason; if the route ahead is clear, actively increase speed toward the highest safe speed; slow down only when required by route geometry, traffic rules, obstacles, or collision risk. When making the decision, consider the ego speed, the future route geometry, drivable space, nearby vehicles, pedestrians, traffic lights, traffic signs, and any immediate collision or off-road risk. Never idle without a concrete safety or rule-based reason. ";

/// The waypoint level's question for `n` points `dt_s` apart. Points are asked in the prompt's
/// own (forward_m, right_m) convention; the parser turns them into the action's (x forward,
/// y left).
pub fn waypoint_question(n: usize, dt_s: f64) -> String {
    format!(
        "{OBJECTIVE}Plan the ego vehicle's own future positions: give exactly {n} points in ego coordinates (forward_m, right_m), the first {dt} s from now and each next one {dt} s after the previous, so that their spacing sets the speed (points closer together mean slower; repeating the current position (0.0, 0.0) means stop). A negative right_m indicates left. Follow the future route and begin turning before curves. Output only the final plan without explanation in the exact format:\nwaypoints: [(<forward_m>, <right_m>), ... {n} points]",
        dt = format_1f(dt_s),
    )
}

/// The meta level's question.
pub fn meta_question() -> String {
    let paths: Vec<&str> = PathAction::ALL.iter().map(|a| a.name()).collect();
    let speeds: Vec<&str> = SpeedAction::ALL.iter().map(|a| a.name()).collect();
    format!(
        "{OBJECTIVE}Choose one path action and one speed action. Path actions: FOLLOW_LANE keeps the current lane; CHANGE_LANE_LEFT and CHANGE_LANE_RIGHT move to the neighbouring lane; GO_STRAIGHT, TURN_LEFT and TURN_RIGHT choose the direction at the next intersection. Speed actions: KEEP holds the current speed; ACCELERATE raises it by {acc} m/s; DECELERATE lowers it by {dec} m/s; STOP brakes to a standstill. Output only the final action decision without explanation in the exact format:\npath_action: <one of {}>\nspeed_action: <one of {}>",
        paths.join(", "),
        speeds.join(", "),
        acc = format_1f(super::meta::ACCEL_STEP_MPS),
        dec = format_1f(super::meta::DECEL_STEP_MPS),
    )
}

/// The full user text of one waypoint-level decision.
pub fn waypoint_prompt(
    speed_mps: f64,
    command: Command,
    distance_to_go_m: Option<f64>,
    points: &[(f64, f64)],
    n: usize,
    dt_s: f64,
) -> String {
    let mut s = condition_prefix(speed_mps, command, distance_to_go_m, points);
    s.push_str(&waypoint_question(n, dt_s));
    s
}

/// The full user text of one meta-level decision.
pub fn meta_prompt(
    speed_mps: f64,
    command: Command,
    distance_to_go_m: Option<f64>,
    points: &[(f64, f64)],
) -> String {
    let mut s = condition_prefix(speed_mps, command, distance_to_go_m, points);
    s.push_str(&meta_question());
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::prompt::ACTION_QUESTION;

    #[test]
    fn objective_is_the_papers_words() {
        // Every sentence of the shared objective is in the paper's question (the steering
        // sentences, which speak of a steer value, are left out).
        for clause in OBJECTIVE.split(['.', ';']).map(str::trim).filter(|s| !s.is_empty()) {
            assert!(ACTION_QUESTION.contains(clause), "{clause}");
        }
    }

    #[test]
    fn level_prompts_literal_tail() {
        let w = waypoint_prompt(3.0, Command::FollowLane, Some(10.0), &[(5.0, 0.0)], 8, 0.5);
        assert!(w.starts_with("The ego vehicle is driving at the speed of 3.0 m/s"));
        assert!(w.ends_with("Output only the final plan without explanation in the exact format:\nwaypoints: [(<forward_m>, <right_m>), ... 8 points]"));
        assert!(w.contains("the first 0.5 s from now"));
        let m = meta_prompt(3.0, Command::TurnLeft, None, &[]);
        assert!(m.ends_with("path_action: <one of FOLLOW_LANE, CHANGE_LANE_LEFT, CHANGE_LANE_RIGHT, GO_STRAIGHT, TURN_LEFT, TURN_RIGHT>\nspeed_action: <one of KEEP, ACCELERATE, DECELERATE, STOP>"));
        assert!(m.contains("ACCELERATE raises it by 2.0 m/s"));
    }
}
