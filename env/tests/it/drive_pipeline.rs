//! Route tracker → navigation command → prompt, on routes with known geometry.

use dh_env::drive::*;
use dh_env::geom::{Polyline, Pose, Vec2};
use std::f64::consts::FRAC_PI_2;

#[test]
fn right_turn_ahead() {
    // East for 20 m, then south (a right turn for an ego heading east).
    let tr = RouteTracker::new(Polyline::new(vec![
        Vec2::new(0.0, 0.0),
        Vec2::new(20.0, 0.0),
        Vec2::new(20.0, -100.0),
    ]));
    let ctx = decision_context(&tr, &Pose::new(Vec2::new(0.0, 0.0), 0.0), 4.96);
    // Far point (60 m) = (20, −40) → forward 20, right 40: heading 63.4° → command 2.
    assert_eq!(ctx.command, Command::TurnRight);
    assert_eq!(ctx.command as u8, 2);
    let prefix = "The ego vehicle is driving at the speed of 5.0 m/s, and it wants to turns right at the intersection. Remaining route distance to destination is approximately 120.0 meters. The local future route in ego coordinates is given as (forward_m, right_m): [(5.0, 0.0), (10.0, 0.0), (15.0, 0.0), (20.0, 0.0), (20.0, 10.0), (20.0, 20.0), (20.0, 30.0), (20.0, 40.0)]. ";
    assert_eq!(ctx.prompt, format!("{prefix}{ACTION_QUESTION}"));
}

#[test]
fn left_turn_straight_and_lane_change() {
    // Heading north (yaw π/2): forward = +y, right = +x.
    let north = Pose::new(Vec2::new(0.0, 0.0), FRAC_PI_2);
    let left = RouteTracker::new(Polyline::new(vec![
        Vec2::new(0.0, 0.0),
        Vec2::new(0.0, 15.0),
        Vec2::new(-100.0, 15.0),
    ]));
    assert_eq!(decision_context(&left, &north, 3.0).command, Command::TurnLeft);
    let straight = RouteTracker::new(Polyline::new(vec![Vec2::new(0.3, -5.0), Vec2::new(0.3, 200.0)]));
    assert_eq!(decision_context(&straight, &north, 3.0).command, Command::Straight);
    // Shift of 3 m to the left within the first 10 m, then straight: near.right = −3 → 5.
    let shift = RouteTracker::new(Polyline::new(vec![
        Vec2::new(0.0, 0.0),
        Vec2::new(-3.0, 8.0),
        Vec2::new(-3.0, 200.0),
    ]));
    assert_eq!(decision_context(&shift, &north, 3.0).command, Command::ChangeLaneLeft);
}

#[test]
fn at_the_destination() {
    let tr = RouteTracker::new(Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(50.0, 0.0)]));
    let ctx = decision_context(&tr, &Pose::new(Vec2::new(50.0, 0.0), 0.0), 0.0);
    // Every sample is the end point at forward 0: none kept → follow the road.
    assert_eq!(ctx.command, Command::FollowLane);
    assert!(ctx.prompt.contains("approximately 0.0 meters"));
    assert!(ctx.prompt.contains(
        "[(0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0), (0.0, 0.0)]"
    ));
    // No route at all: no distance sentence and an empty list.
    let ctx = decision_context(&RouteTracker::default(), &Pose::default(), 1.0);
    assert!(!ctx.prompt.contains("Remaining route distance"));
    assert!(ctx.prompt.contains("(forward_m, right_m): []. Your primary objective"));
}

#[test]
fn bridge_over_a_decision_sequence() {
    // Launch from rest, hold on a failure, then brake.
    let mut b = ActuationBridge::new();
    let c1 = b.apply(Some(Decision { steer: 0.5, target_speed_mps: 8.0 }), 0.0);
    // e = 8 → 0.25 + 1.76 = 2.01 → cap 0.85; steer 0 + 0.12.
    assert_eq!(c1, Control { throttle: 0.85, brake: 0.0, steer: 0.12 });
    assert_eq!(b.apply(None, 3.0), c1);
    let c3 = b.apply(Some(Decision { steer: 0.5, target_speed_mps: 2.0 }), 3.0);
    // e = −1 → brake 0.30; steer 0.12 + 0.12.
    assert_eq!(c3.throttle, 0.0);
    assert!((c3.brake - 0.3).abs() < 1e-12 && (c3.steer - 0.24).abs() < 1e-12);
    assert_eq!((b.decisions(), b.parse_failures()), (3, 1));
}
