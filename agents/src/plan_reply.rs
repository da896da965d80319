//! Reply parsers of the `waypoints` and `meta` action levels (docs/vlm.md#action-levels; this
//! project's extension of the protocol, beside the paper's [`crate::vlm`] parser). Both read the
//! lower-cased reply like the paper's parser, never fail on any text, and say which field was
//! missing when there is no plan; the env then holds the last plan and counts the failure.

use crate::vlm::{python_float, NUM_PATTERN};
use dh_env::drive::bridge::DecisionFailure;
use dh_env::drive::{MetaAction, PathAction, Plan, SpeedAction};
use regex::Regex;
use std::sync::LazyLock;

/// Python's `\s` (as in [`crate::vlm`]).
const PY_SPACE: &str = r"[\s\x1C-\x1F]";

static WAYPOINTS_LABEL: LazyLock<Regex> = LazyLock::new(|| re(&format!(r"waypoints{PY_SPACE}*[:=]")));
/// One point: `(a, b)` or `[a, b]` (any Python whitespace around the numbers).
static POINT: LazyLock<Regex> = LazyLock::new(|| {
    let n = NUM_PATTERN;
    re(&format!(r"[(\[]{PY_SPACE}*({n}){PY_SPACE}*,{PY_SPACE}*({n}){PY_SPACE}*[)\]]"))
});
static PATH_LABEL: LazyLock<Regex> = LazyLock::new(|| re(&format!(r"path_action{PY_SPACE}*[:=]{PY_SPACE}*")));
static SPEED_LABEL: LazyLock<Regex> =
    LazyLock::new(|| re(&format!(r"speed_action{PY_SPACE}*[:=]{PY_SPACE}*")));

fn re(p: &str) -> Regex {
    #[allow(clippy::expect_used)]
    Regex::new(p).expect("static pattern")
}

/// Most points read from one reply (more are ignored).
pub const MAX_REPLY_POINTS: usize = 64;

/// Parses a waypoint reply: the `(forward_m, right_m)` points after the first `waypoints:` (or,
/// without that label, anywhere in the reply), at most `max_points`, turned into the action's
/// (x forward, y left). Numbers too long for f64 become ±inf, which the tracker clips.
pub fn parse_waypoints_reply(text: &str, max_points: usize) -> Result<Plan, DecisionFailure> {
    let lower = text.to_lowercase();
    let start = WAYPOINTS_LABEL.find(&lower).map_or(0, |m| m.end());
    let max_points = max_points.clamp(1, MAX_REPLY_POINTS);
    let mut pts = Vec::new();
    for c in POINT.captures_iter(&lower[start..]) {
        let (Some(f), Some(r)) = (c.get(1), c.get(2)) else { continue };
        let (Some(f), Some(r)) = (python_float(f.as_str()), python_float(r.as_str())) else { continue };
        pts.push((f, -r));
        if pts.len() >= max_points {
            break;
        }
    }
    if pts.is_empty() {
        Err(DecisionFailure::MissingWaypoints)
    } else {
        Ok(Plan::Waypoints(pts))
    }
}

/// The name of `all` that the text at `at` starts with (spaces or hyphens may stand for `_`,
/// quotes and backticks around it are skipped), or without a label the first one named anywhere.
fn find_name<T: Copy>(lower: &str, label: &Regex, all: &[(T, &'static str)]) -> Option<T> {
    let norm = |s: &str| s.replace(['-', ' '], "_");
    if let Some(m) = label.find(lower) {
        let rest = lower[m.end()..].trim_start_matches(['"', '\'', '`', '*', '<']);
        let head: String = rest.chars().take(24).collect();
        let head = norm(&head);
        return all.iter().find(|(_, n)| head.starts_with(&n.to_ascii_lowercase())).map(|(a, _)| *a);
    }
    let text = norm(lower);
    all.iter()
        .filter_map(|(a, n)| text.find(&n.to_ascii_lowercase()).map(|i| (i, *a)))
        .min_by_key(|(i, _)| *i)
        .map(|(_, a)| a)
}

/// Parses a meta reply: `path_action: <name>` and `speed_action: <name>` (case-insensitive; the
/// first name after each label, else the first name of each kind anywhere in the reply).
pub fn parse_meta_reply(text: &str) -> Result<Plan, DecisionFailure> {
    let lower = text.to_lowercase();
    let paths: Vec<(PathAction, &str)> = PathAction::ALL.iter().map(|a| (*a, a.name())).collect();
    let speeds: Vec<(SpeedAction, &str)> = SpeedAction::ALL.iter().map(|a| (*a, a.name())).collect();
    let path = find_name(&lower, &PATH_LABEL, &paths);
    let speed = find_name(&lower, &SPEED_LABEL, &speeds);
    match (path, speed) {
        (Some(path), Some(speed)) => Ok(Plan::Meta(MetaAction { path, speed })),
        (None, Some(_)) => Err(DecisionFailure::MissingPathAction),
        (Some(_), None) => Err(DecisionFailure::MissingSpeedAction),
        (None, None) => Err(DecisionFailure::MissingMetaAction),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta(path: PathAction, speed: SpeedAction) -> Result<Plan, DecisionFailure> {
        Ok(Plan::Meta(MetaAction { path, speed }))
    }

    #[test]
    fn waypoints_canonical_and_loose() {
        let r = parse_waypoints_reply("waypoints: [(2.0, 0.0), (4.5, -0.5), (7, 1)]", 8);
        assert_eq!(r, Ok(Plan::Waypoints(vec![(2.0, -0.0), (4.5, 0.5), (7.0, -1.0)])));
        // JSON-ish lists, no label, extra points dropped.
        let r = parse_waypoints_reply("[[1, 2], [3, 4], [5, 6]]", 2);
        assert_eq!(r, Ok(Plan::Waypoints(vec![(1.0, -2.0), (3.0, -4.0)])));
        // The label wins over points before it.
        let r = parse_waypoints_reply("route (9, 9)\nWAYPOINTS = [(1,0)]", 8);
        assert_eq!(r, Ok(Plan::Waypoints(vec![(1.0, -0.0)])));
        // Unicode digits as Python's float() reads them; huge numbers become infinite.
        assert_eq!(parse_waypoints_reply("waypoints: [(１, ٠)]", 8), Ok(Plan::Waypoints(vec![(1.0, -0.0)])));
        let big = "9".repeat(400);
        let Ok(Plan::Waypoints(p)) = parse_waypoints_reply(&format!("({big}, -{big})"), 8) else { panic!() };
        assert_eq!(p, vec![(f64::INFINITY, f64::INFINITY)]);
    }

    #[test]
    fn waypoints_failures() {
        for bad in ["", "waypoints: []", "steer: 0.1 target_speed_mps: 3", "(nan, 1)", "(1 2)"] {
            assert_eq!(parse_waypoints_reply(bad, 8), Err(DecisionFailure::MissingWaypoints), "{bad}");
        }
    }

    #[test]
    fn meta_replies() {
        use PathAction::*;
        use SpeedAction::*;
        assert_eq!(parse_meta_reply("path_action: FOLLOW_LANE\nspeed_action: KEEP"), meta(FollowLane, Keep));
        assert_eq!(
            parse_meta_reply("Path_Action = \"turn left\", speed_action: 'stop'"),
            meta(TurnLeft, Stop)
        );
        assert_eq!(
            parse_meta_reply("I will CHANGE_LANE_RIGHT and DECELERATE."),
            meta(ChangeLaneRight, Decelerate)
        );
        assert_eq!(parse_meta_reply("speed_action: accelerate"), Err(DecisionFailure::MissingPathAction));
        assert_eq!(parse_meta_reply("path_action: go_straight"), Err(DecisionFailure::MissingSpeedAction));
        assert_eq!(
            parse_meta_reply("path_action: fly speed_action: warp"),
            Err(DecisionFailure::MissingMetaAction)
        );
        assert_eq!(parse_meta_reply(""), Err(DecisionFailure::MissingMetaAction));
    }
}
