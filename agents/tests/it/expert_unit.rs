//! Single-decision behaviour of the expert on synthetic inputs.

use crate::expert_support;

use std::f64::consts::FRAC_PI_2;

use dh_agents::expert::{Expert, ExpertInput, ExpertParams, SpeedReason};
use dh_env::geom::{Polyline, Vec2};
use dh_env::view::{ActorKind, ActorView, LightColor, TrafficLightView};
use expert_support::{actor, ego_at, light, RouteBuilder};

fn decide(
    route: &Polyline,
    ego: &ActorView,
    actors: &[ActorView],
    lights: &[TrafficLightView],
) -> dh_agents::expert::ExpertAction {
    let mut ex = Expert::new(ExpertParams::default()).unwrap();
    ex.act(&ExpertInput {
        ego,
        route,
        actors,
        lights,
        speed_limit_mps: None,
        drivable: None,
        follow_lane: None,
    })
}

fn straight() -> Polyline {
    RouteBuilder::new(Vec2::ZERO, 0.0).straight(300.0).build()
}

#[test]
fn straight_route_cruises_with_zero_steer() {
    let route = straight();
    let a = decide(&route, &ego_at(Vec2::new(10.0, 0.0), 0.0, 10.0), &[], &[]);
    assert!(a.steer.abs() < 1e-6, "steer {}", a.steer);
    assert_eq!(a.target_speed_mps, ExpertParams::default().cruise_speed_mps);
    assert_eq!(a.reason, SpeedReason::Cruise);
}

#[test]
fn speed_limit_caps_the_target() {
    let route = straight();
    let ego = ego_at(Vec2::new(10.0, 0.0), 0.0, 5.0);
    let mut ex = Expert::new(ExpertParams::default()).unwrap();
    let a = ex.act(&ExpertInput {
        ego: &ego,
        route: &route,
        actors: &[],
        lights: &[],
        speed_limit_mps: Some(8.33),
        drivable: None,
        follow_lane: None,
    });
    assert_eq!(a.target_speed_mps, 8.33);
    assert_eq!(a.reason, SpeedReason::SpeedLimit);
}

#[test]
fn left_curve_steers_left_and_right_curve_right() {
    let left = RouteBuilder::new(Vec2::ZERO, 0.0).straight(12.0).arc(12.0, 90.0).straight(50.0).build();
    let right = RouteBuilder::new(Vec2::ZERO, 0.0).straight(12.0).arc(12.0, -90.0).straight(50.0).build();
    let ego = ego_at(Vec2::new(12.5, 0.0), 0.0, 5.0);
    let l = decide(&left, &ego, &[], &[]);
    let r = decide(&right, &ego, &[], &[]);
    assert!(l.steer < -0.1, "left curve steer {}", l.steer);
    assert!(r.steer > 0.1, "right curve steer {}", r.steer);
    // A tight curve ahead at speed lowers the target below cruise.
    let fast = ego_at(Vec2::new(0.0, 0.0), 0.0, 12.0);
    let a = decide(&left, &fast, &[], &[]);
    assert!(a.target_speed_mps < 10.0 && a.reason == SpeedReason::Curve, "{a:?}");
}

#[test]
fn steer_respects_the_bridge_rate_limit() {
    // The ego is 3 m right of the route: pursuit wants a large left steer, but one decision may
    // change it by at most 0.12.
    let route = straight();
    let mut ex = Expert::new(ExpertParams::default()).unwrap();
    let ego = ego_at(Vec2::new(10.0, -3.0), 0.0, 5.0);
    let input = ExpertInput {
        ego: &ego,
        route: &route,
        actors: &[],
        lights: &[],
        speed_limit_mps: None,
        drivable: None,
        follow_lane: None,
    };
    let a1 = ex.act(&input);
    let a2 = ex.act(&input);
    assert!((a1.steer + 0.12).abs() < 1e-9, "first {}", a1.steer);
    assert!((a2.steer + 0.24).abs() < 1e-9, "second {}", a2.steer);
    ex.reset();
    assert!((ex.act(&input).steer + 0.12).abs() < 1e-9);
}

#[test]
fn pedestrian_on_route_stops_the_ego_before_it() {
    let route = straight();
    let ped = actor(7, ActorKind::Pedestrian, Vec2::new(30.0, 0.5), FRAC_PI_2, 0.0, 0.5, 0.5);
    let far = decide(&route, &ego_at(Vec2::new(0.0, 0.0), 0.0, 10.0), &[ped], &[]);
    assert_eq!(far.reason, SpeedReason::Obstacle { actor_id: 7 });
    assert!(far.target_speed_mps < ExpertParams::default().cruise_speed_mps);
    let near = decide(&route, &ego_at(Vec2::new(24.0, 0.0), 0.0, 1.0), &[ped], &[]);
    assert_eq!(near.target_speed_mps, 0.0, "{near:?}");
    // A pedestrian on the pavement walking along the road does not stop the ego.
    let side = actor(8, ActorKind::Pedestrian, Vec2::new(40.0, 4.5), 0.0, 1.2, 0.5, 0.5);
    let a = decide(&route, &ego_at(Vec2::new(0.0, 0.0), 0.0, 10.0), &[side], &[]);
    assert_eq!(a.reason, SpeedReason::Cruise);
}

#[test]
fn pedestrian_about_to_cross_is_predicted() {
    let route = straight();
    // 4 m right of the centreline walking left at 1.5 m/s: in the corridor within ~2 s.
    let ped = actor(3, ActorKind::Pedestrian, Vec2::new(25.0, -4.0), FRAC_PI_2, 1.5, 0.5, 0.5);
    let a = decide(&route, &ego_at(Vec2::new(0.0, 0.0), 0.0, 10.0), &[ped], &[]);
    assert_eq!(a.reason, SpeedReason::Obstacle { actor_id: 3 }, "{a:?}");
    // Walking away from the road: ignored.
    let away = actor(3, ActorKind::Pedestrian, Vec2::new(25.0, -4.0), -FRAC_PI_2, 1.5, 0.5, 0.5);
    let b = decide(&route, &ego_at(Vec2::new(0.0, 0.0), 0.0, 10.0), &[away], &[]);
    assert_eq!(b.reason, SpeedReason::Cruise);
}

#[test]
fn red_light_stops_and_green_goes() {
    let route = straight();
    let ego = ego_at(Vec2::new(0.0, 0.0), 0.0, 10.0);
    let red = decide(&route, &ego, &[], &[light(Vec2::new(30.0, 0.0), 0.0, LightColor::Red)]);
    assert_eq!(red.reason, SpeedReason::Light);
    assert!(red.target_speed_mps < ExpertParams::default().cruise_speed_mps);
    let at_line = decide(
        &route,
        &ego_at(Vec2::new(26.0, 0.0), 0.0, 0.5),
        &[],
        &[light(Vec2::new(30.0, 0.0), 0.0, LightColor::Red)],
    );
    assert_eq!(at_line.target_speed_mps, 0.0);
    let green = decide(&route, &ego, &[], &[light(Vec2::new(30.0, 0.0), 0.0, LightColor::Green)]);
    assert_eq!(green.reason, SpeedReason::Cruise);
    // A red head of the opposite direction (other side of the road, facing the other way).
    let opposite =
        decide(&route, &ego, &[], &[light(Vec2::new(30.0, 3.2), std::f64::consts::PI, LightColor::Red)]);
    assert_eq!(opposite.reason, SpeedReason::Cruise);
    // Yellow too close to stop comfortably: go through.
    let yellow_close = decide(
        &route,
        &ego_at(Vec2::new(22.0, 0.0), 0.0, 12.0),
        &[],
        &[light(Vec2::new(30.0, 0.0), 0.0, LightColor::Yellow)],
    );
    assert_ne!(yellow_close.reason, SpeedReason::Light);
    // Red appearing with the front 3 m from the line at 12 m/s: cannot stop before it, go on.
    let committed = decide(
        &route,
        &ego_at(Vec2::new(24.7, 0.0), 0.0, 12.0),
        &[],
        &[light(Vec2::new(30.0, 0.0), 0.0, LightColor::Red)],
    );
    assert_ne!(committed.reason, SpeedReason::Light);
    let yellow_far = decide(&route, &ego, &[], &[light(Vec2::new(30.0, 0.0), 0.0, LightColor::Yellow)]);
    assert_eq!(yellow_far.reason, SpeedReason::Light);
}

#[test]
fn lead_vehicle_is_followed_with_headway() {
    let route = straight();
    let ego = ego_at(Vec2::new(0.0, 0.0), 0.0, 10.0);
    let lead = actor(5, ActorKind::Car, Vec2::new(20.0, 0.2), 0.0, 6.0, 4.6, 1.9);
    let a = decide(&route, &ego, &[lead], &[]);
    assert_eq!(a.reason, SpeedReason::Lead { actor_id: 5 });
    assert!(a.target_speed_mps < 10.0 && a.target_speed_mps > 0.0, "{a:?}");
    // Far ahead and faster: no constraint.
    let far = actor(5, ActorKind::Car, Vec2::new(150.0, 0.0), 0.0, 14.0, 4.6, 1.9);
    assert_eq!(decide(&route, &ego, &[far], &[]).reason, SpeedReason::Cruise);
    // A car in the adjacent lane does not constrain.
    let adj = actor(6, ActorKind::Car, Vec2::new(15.0, 3.3), 0.0, 3.0, 4.6, 1.9);
    assert_eq!(decide(&route, &ego, &[adj], &[]).reason, SpeedReason::Cruise);
}

#[test]
fn degenerate_input_stops_without_panicking() {
    let empty = Polyline::new(vec![]);
    let a = decide(&empty, &ego_at(Vec2::ZERO, 0.0, 3.0), &[], &[]);
    assert_eq!((a.target_speed_mps, a.reason), (0.0, SpeedReason::NoRoute));
    let nan = ego_at(Vec2::new(f64::NAN, 0.0), 0.0, 3.0);
    assert_eq!(decide(&straight(), &nan, &[], &[]).reason, SpeedReason::NoRoute);
    // Non-finite sizes, actors and lights are tolerated.
    let mut odd = ego_at(Vec2::new(10.0, 0.0), 0.0, 5.0);
    odd.length_m = f64::NAN;
    let nan_actor = actor(9, ActorKind::Car, Vec2::new(f64::NAN, 0.0), 0.0, 1.0, 4.0, 2.0);
    let nan_light = light(Vec2::new(f64::INFINITY, 0.0), 0.0, LightColor::Red);
    let a = decide(&straight(), &odd, &[nan_actor], &[nan_light]);
    assert!(
        a.steer.is_finite() && a.target_speed_mps.is_finite() && a.reason == SpeedReason::Cruise,
        "{a:?}"
    );
    let bad = ExpertParams { cruise_speed_mps: f64::NAN, ..ExpertParams::default() };
    let err = Expert::new(bad).unwrap_err().to_string();
    assert!(err.contains("cruise_speed_mps"), "{err}");
}
