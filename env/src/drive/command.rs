//! Navigation command (docs/protocol.md#r4-prompt), derived from the future route points alone.

use serde::{Deserialize, Serialize};

/// The six navigation commands, numbered as in the original (`as u8` gives the number).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[repr(u8)]
pub enum Command {
    TurnLeft = 1,
    TurnRight = 2,
    Straight = 3,
    FollowLane = 4,
    ChangeLaneLeft = 5,
    ChangeLaneRight = 6,
}

/// Points with forward ≤ this are behind or beside the ego and ignored.
pub const MIN_FORWARD_M: f64 = 1.0;
/// |heading| of the far point at or beyond which the route turns.
pub const TURN_HEADING_DEG: f64 = 18.0;
/// |right| of the near point at or beyond which the route turns.
pub const TURN_NEAR_RIGHT_M: f64 = 4.0;
/// Straight-at-intersection band: |heading| ≤ 8° and |near.right| ≤ 1.5 m.
pub const STRAIGHT_HEADING_DEG: f64 = 8.0;
pub const STRAIGHT_NEAR_RIGHT_M: f64 = 1.5;
/// |near.right| at or beyond which (short of a turn) a lane change is asked for.
pub const LANE_CHANGE_NEAR_RIGHT_M: f64 = 2.0;

impl Command {
    /// The phrase inserted into the prompt. "turns right" is the original's wording, kept.
    pub const fn text(self) -> &'static str {
        match self {
            Command::TurnLeft => "turn left at the intersection",
            Command::TurnRight => "turns right at the intersection",
            Command::Straight => "drive straight at the intersection",
            Command::FollowLane => "follow the road",
            Command::ChangeLaneLeft => "do a lane change to the left",
            Command::ChangeLaneRight => "do a lane change to the right",
        }
    }

    /// The command with number `n` (1..=6).
    pub const fn from_u8(n: u8) -> Option<Command> {
        match n {
            1 => Some(Command::TurnLeft),
            2 => Some(Command::TurnRight),
            3 => Some(Command::Straight),
            4 => Some(Command::FollowLane),
            5 => Some(Command::ChangeLaneLeft),
            6 => Some(Command::ChangeLaneRight),
            _ => None,
        }
    }
}

/// Command from the ego-frame route points `(forward, right)`: keep points with forward > 1 m
/// (none → follow the road); near = the 2nd kept point (or the only one), far = the last;
/// heading = atan2(far.right, max(far.forward, 1e-3)) in degrees; then the rules in order:
/// heading ≤ −18° or near.right ≤ −4 → 1; heading ≥ 18° or near.right ≥ 4 → 2;
/// |heading| ≤ 8° and |near.right| ≤ 1.5 → 3; near.right ≤ −2 → 5; near.right ≥ 2 → 6; else 4.
pub fn navigation_command(points: &[(f64, f64)]) -> Command {
    let kept: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.0 > MIN_FORWARD_M).collect();
    let (Some(&near), Some(&far)) = (kept.get(1).or(kept.first()), kept.last()) else {
        return Command::FollowLane;
    };
    let heading = far.1.atan2(far.0.max(1e-3)).to_degrees();
    let near_right = near.1;
    if heading <= -TURN_HEADING_DEG || near_right <= -TURN_NEAR_RIGHT_M {
        Command::TurnLeft
    } else if heading >= TURN_HEADING_DEG || near_right >= TURN_NEAR_RIGHT_M {
        Command::TurnRight
    } else if heading.abs() <= STRAIGHT_HEADING_DEG && near_right.abs() <= STRAIGHT_NEAR_RIGHT_M {
        Command::Straight
    } else if near_right <= -LANE_CHANGE_NEAR_RIGHT_M {
        Command::ChangeLaneLeft
    } else if near_right >= LANE_CHANGE_NEAR_RIGHT_M {
        Command::ChangeLaneRight
    } else {
        Command::FollowLane
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_and_phrases() {
        let all = [
            (Command::TurnLeft, 1, "turn left at the intersection"),
            (Command::TurnRight, 2, "turns right at the intersection"),
            (Command::Straight, 3, "drive straight at the intersection"),
            (Command::FollowLane, 4, "follow the road"),
            (Command::ChangeLaneLeft, 5, "do a lane change to the left"),
            (Command::ChangeLaneRight, 6, "do a lane change to the right"),
        ];
        for (c, n, t) in all {
            assert_eq!(c as u8, n);
            assert_eq!(c.text(), t);
            assert_eq!(Command::from_u8(n), Some(c));
        }
        assert_eq!(Command::from_u8(0), None);
        assert_eq!(Command::from_u8(7), None);
    }

    #[test]
    fn pinned_thresholds() {
        assert_eq!(MIN_FORWARD_M, 1.0);
        assert_eq!(TURN_HEADING_DEG, 18.0);
        assert_eq!(TURN_NEAR_RIGHT_M, 4.0);
        assert_eq!(STRAIGHT_HEADING_DEG, 8.0);
        assert_eq!(STRAIGHT_NEAR_RIGHT_M, 1.5);
        assert_eq!(LANE_CHANGE_NEAR_RIGHT_M, 2.0);
    }

    /// far point at `deg` degrees, 40 m away; near point at right = `near_r`.
    fn pts(deg: f64, near_r: f64) -> Vec<(f64, f64)> {
        let (s, c) = deg.to_radians().sin_cos();
        vec![(0.5, 9.0), (5.0, 0.0), (10.0, near_r), (40.0 * c, 40.0 * s)]
    }

    #[test]
    fn rules_in_order() {
        use Command::*;
        assert_eq!(navigation_command(&[]), FollowLane);
        assert_eq!(navigation_command(&[(1.0, 0.0), (-3.0, 5.0)]), FollowLane); // forward ≤ 1
        assert_eq!(navigation_command(&pts(-18.0, 0.0)), TurnLeft);
        assert_eq!(navigation_command(&pts(-17.9, 0.0)), FollowLane);
        assert_eq!(navigation_command(&pts(17.9, 3.9)), ChangeLaneRight);
        assert_eq!(navigation_command(&pts(18.0, 0.0)), TurnRight);
        assert_eq!(navigation_command(&pts(0.0, -4.0)), TurnLeft);
        assert_eq!(navigation_command(&pts(0.0, 4.0)), TurnRight);
        // Left wins over right when both hold (checked first).
        assert_eq!(navigation_command(&pts(30.0, -4.0)), TurnLeft);
        assert_eq!(navigation_command(&pts(8.0, 1.5)), Straight);
        assert_eq!(navigation_command(&pts(-8.0, -1.5)), Straight);
        assert_eq!(navigation_command(&pts(8.5, 0.0)), FollowLane);
        assert_eq!(navigation_command(&pts(0.0, -2.0)), ChangeLaneLeft);
        assert_eq!(navigation_command(&pts(0.0, 2.0)), ChangeLaneRight);
        assert_eq!(navigation_command(&pts(0.0, 1.9)), FollowLane);
        assert_eq!(navigation_command(&pts(0.0, -3.99)), ChangeLaneLeft);
    }

    #[test]
    fn near_is_second_kept_or_only_point() {
        // The first raw point is dropped (forward ≤ 1); the 2nd kept point decides near.
        let p = [(0.9, -9.0), (5.0, -9.0), (10.0, 2.5), (20.0, 0.0)];
        // near = (10, 2.5) → lane change right; taking the 1st kept point would give TurnLeft.
        assert_eq!(navigation_command(&p), Command::ChangeLaneRight);
        // Only one kept point: it is both near and far.
        assert_eq!(navigation_command(&[(5.0, 2.5)]), Command::TurnRight); // heading 26.6°
        assert_eq!(navigation_command(&[(5.0, 0.2)]), Command::Straight);
        // Two kept points: near = far = the 2nd; atan2(-0.5, 1.0001) ≈ −26.6°.
        assert_eq!(navigation_command(&[(5.0, 0.0), (1.0001, -0.5)]), Command::TurnLeft);
    }
}
