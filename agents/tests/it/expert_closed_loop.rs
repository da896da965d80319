//! The expert driving synthetic routes in a stand-in closed loop (protocol bridge + the ego's
//! kinematic bicycle at 20 Hz, decisions at 4 Hz): it must finish without collision, stay in its
//! lane, never rest long enough to trip the blocked timeout, and keep S_eff high.

use crate::expert_support;

use std::f64::consts::FRAC_PI_2;

use dh_agents::expert::{ExpertParams, SpeedReason};
use dh_env::geom::{Polyline, Vec2};
use dh_env::view::{ActorKind, LightColor};
use expert_support::{actor, efficiency, light, Outcome, RouteBuilder, Scripted, Sim};

/// Half a 3.2 m lane: the ego centre never leaves its lane.
const LANE_HALF: f64 = 1.6;

fn report(name: &str, o: &Outcome) {
    println!(
        "{name}: t={:.1}s reached={} collided={} max_lat={:.2}m clearance={:.2}m rest={:.1}s eff={:.3}",
        o.time_s,
        o.reached,
        o.collided,
        o.max_lateral_m,
        o.min_clearance_m,
        o.max_rest_s,
        efficiency(o)
    );
}

fn check(name: &str, sim: &Sim, min_eff: f64) -> Outcome {
    check_within(name, sim, min_eff, LANE_HALF)
}

/// As [`check`], allowing the centre up to `max_lat` m from the route (detours).
fn check_within(name: &str, sim: &Sim, min_eff: f64, max_lat: f64) -> Outcome {
    let o = sim.run(ExpertParams::default());
    report(name, &o);
    assert!(o.reached && !o.collided, "{name}: not completed");
    assert!(o.max_lateral_m < max_lat, "{name}: {:.2} m off the route", o.max_lateral_m);
    assert!(o.max_rest_s < 5.0, "{name}: rested {:.1} s (blocked timeout)", o.max_rest_s);
    assert!(efficiency(&o) >= min_eff, "{name}: efficiency {:.3}", efficiency(&o));
    o
}

fn urban_route() -> Polyline {
    RouteBuilder::new(Vec2::ZERO, 0.0)
        .straight(60.0)
        .arc(10.0, 90.0)
        .straight(40.0)
        .arc(8.0, -90.0)
        .straight(30.0)
        .arc(15.0, -60.0)
        .arc(15.0, 60.0)
        .straight(50.0)
        .build()
}

#[test]
fn drives_curves_in_lane() {
    for per_tick in [true, false] {
        let sim = Sim { per_tick_bridge: per_tick, ..Sim::new(urban_route()) };
        check(&format!("urban per_tick={per_tick}"), &sim, 0.95);
    }
}

#[test]
fn drives_a_roundabout_like_loop() {
    let route = RouteBuilder::new(Vec2::ZERO, 0.0)
        .straight(40.0)
        .arc(12.0, 30.0)
        .arc(14.0, -240.0)
        .arc(12.0, 30.0)
        .straight(40.0)
        .build();
    check("roundabout", &Sim::new(route), 0.9);
}

#[test]
fn u_turn() {
    let route = RouteBuilder::new(Vec2::ZERO, 0.0).straight(30.0).arc(7.0, 180.0).straight(30.0).build();
    check("u-turn", &Sim::new(route), 0.9);
}

/// Furthest x of the ego front bumper up to time `t` (routes along +x).
fn front_x_until(o: &Outcome, t: f64) -> f64 {
    o.trajectory
        .iter()
        .filter(|(ti, _)| *ti <= t)
        .map(|(_, p)| p.pos.x + p.forward().x * expert_support::EGO_HALF_LENGTH)
        .fold(f64::NEG_INFINITY, f64::max)
}

fn straight(len: f64) -> Polyline {
    RouteBuilder::new(Vec2::ZERO, 0.0).straight(len).build()
}

#[test]
fn waits_for_a_crossing_pedestrian() {
    let mut sim = Sim::new(straight(200.0));
    // Starts 6 m right of the lane at x = 60 and crosses to the left at 1.2 m/s.
    sim.actors.push(Scripted {
        view: actor(1, ActorKind::Pedestrian, Vec2::new(60.0, -6.0), FRAC_PI_2, 1.2, 0.5, 0.5),
        speed: Box::new(|_| 1.2),
    });
    let o = check("pedestrian crossing", &sim, 0.85);
    assert!(o.min_clearance_m > 1.0, "passed {:.2} m from the pedestrian", o.min_clearance_m);
    assert!(o.actions.iter().any(|a| a.reason == SpeedReason::Obstacle { actor_id: 1 }));
}

#[test]
fn pedestrian_standing_in_the_lane_for_a_while() {
    let mut sim = Sim::new(straight(200.0));
    // Stands in the lane for 12 s, then walks off to the left.
    sim.actors.push(Scripted {
        view: actor(1, ActorKind::Pedestrian, Vec2::new(50.0, 0.0), FRAC_PI_2, 0.0, 0.5, 0.5),
        speed: Box::new(|t| if t < 12.0 { 0.0 } else { 1.2 }),
    });
    let o = check("pedestrian standing", &sim, 0.8);
    assert!(o.min_clearance_m > 0.7, "passed {:.2} m from the pedestrian", o.min_clearance_m);
}

#[test]
fn follows_a_lead_that_brakes_hard() {
    let mut sim = Sim::new(straight(400.0));
    sim.start_speed = 10.0;
    // Lead at 10 m/s, 25 m ahead; brakes at 6 m/s² at t = 8 s to a stop, waits 3 s, drives on.
    sim.actors.push(Scripted {
        view: actor(2, ActorKind::Car, Vec2::new(27.0, 0.0), 0.0, 10.0, 4.6, 1.9),
        speed: Box::new(|t| {
            if t < 8.0 {
                10.0
            } else if t < 8.0 + 10.0 / 6.0 {
                10.0 - 6.0 * (t - 8.0)
            } else if t < 12.67 {
                0.0
            } else {
                (1.5 * (t - 12.67)).min(9.0)
            }
        }),
    });
    let o = check("sudden braking", &sim, 0.85);
    assert!(o.min_clearance_m > 1.5, "came within {:.2} m of the lead", o.min_clearance_m);
    assert!(o.actions.iter().any(|a| a.reason == SpeedReason::Lead { actor_id: 2 }));
}

#[test]
fn stops_at_red_and_goes_on_green() {
    let mut sim = Sim::new(straight(200.0));
    let stop_line = Vec2::new(80.0, 0.0);
    // Red until t = 14 s (a long wait), then green.
    sim.lights = Box::new(move |t| {
        vec![light(stop_line, 0.0, if t < 14.0 { LightColor::Red } else { LightColor::Green })]
    });
    let o = check("red light", &sim, 0.85);
    assert!(o.actions.iter().any(|a| a.reason == SpeedReason::Light));
    let front_at_green = front_x_until(&o, 14.0);
    assert!(front_at_green < 80.0 && front_at_green > 74.0, "front at {front_at_green:.2} m when green");
}

#[test]
fn never_crosses_a_red_line() {
    // A red that never ends: the ego must stay behind the line (and, stalled, creep but not cross).
    let mut sim = Sim::new(straight(200.0));
    sim.time_limit_s = 60.0;
    sim.lights = Box::new(|_| vec![light(Vec2::new(60.0, 0.0), 0.0, LightColor::Red)]);
    let o = sim.run(ExpertParams::default());
    report("endless red", &o);
    assert!(!o.reached && !o.collided);
    let last = o.actions.last().unwrap();
    assert_eq!(last.reason, SpeedReason::Light);
    let front = front_x_until(&o, 60.0);
    assert!(front < 60.0 && front > 55.0, "front reached {front:.2} m (line at 60 m)");
    assert!(o.max_rest_s < 5.0, "stall guard failed: rested {:.1} s", o.max_rest_s);
}

#[test]
fn stops_for_a_static_obstacle_without_drivable_space() {
    let mut sim = Sim::new(straight(200.0));
    sim.time_limit_s = 40.0;
    sim.actors.push(Scripted {
        view: actor(4, ActorKind::Barrier, Vec2::new(70.0, 0.0), FRAC_PI_2, 0.0, 2.0, 0.6),
        speed: Box::new(|_| 0.0),
    });
    let o = sim.run(ExpertParams::default());
    report("blocked lane", &o);
    assert!(!o.collided && !o.reached);
    assert!(o.min_clearance_m > 1.0 && o.min_clearance_m < 6.0, "stopped {:.2} m before", o.min_clearance_m);
}

#[test]
fn passes_a_static_obstacle_through_the_free_adjacent_lane() {
    let mut sim = Sim::new(straight(220.0));
    // Two lanes: ours (y in [-1.6, 1.6]) and a free one to the left (y up to 4.8).
    sim.drivable = Some(Box::new(|p: Vec2, _h: f64| p.y > -1.6 && p.y < 4.8 && p.x > -10.0 && p.x < 260.0));
    sim.actors.push(Scripted {
        view: actor(4, ActorKind::StaticObject, Vec2::new(80.0, 0.0), 0.0, 0.0, 4.5, 2.0),
        speed: Box::new(|_| 0.0),
    });
    sim.actors.push(Scripted {
        view: actor(5, ActorKind::Cone, Vec2::new(74.0, 0.5), 0.0, 0.0, 0.4, 0.4),
        speed: Box::new(|_| 0.0),
    });
    let o = sim.run(ExpertParams::default());
    report("detour", &o);
    assert!(o.reached && !o.collided, "detour failed");
    assert!(o.min_clearance_m > 0.4, "clearance {:.2}", o.min_clearance_m);
    assert!(o.actions.iter().any(|a| a.path_offset_m > 2.0));
    assert!(efficiency(&o) > 0.9, "efficiency {:.3}", efficiency(&o));
}

/// Deterministic pseudo-random numbers in [0, 1) (64-bit LCG) so the sweep is reproducible.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn crossing_actors_sweep_never_collides() {
    // 40 crossings of a straight road by a pedestrian or a car with random side, position,
    // speed and distance to the road. Half walk / drive from t = 0 (visible throughout), half
    // stand still until the ego is a fair distance away (a scenario trigger: pedestrians 20 m,
    // cars 35 m) and then go. The actors never react to the ego.
    let mut rng = Lcg(7);
    let mut interacted = 0;
    for case in 0..40 {
        let mut sim = Sim::new(straight(240.0));
        sim.start_speed = 10.0 * rng.next();
        let is_car = case % 2 == 1;
        let side = if rng.next() < 0.5 { 1.0 } else { -1.0 };
        let x = 60.0 + 100.0 * rng.next();
        let (speed, dist, len, wid, kind, trigger_gap) = if is_car {
            (6.0 + 8.0 * rng.next(), 15.0 + 40.0 * rng.next(), 4.6, 1.9, ActorKind::Car, 35.0)
        } else {
            (0.8 + 1.4 * rng.next(), 3.0 + 4.0 * rng.next(), 0.5, 0.5, ActorKind::Pedestrian, 20.0)
        };
        let triggered = case % 4 >= 2;
        let yaw = if side > 0.0 { -FRAC_PI_2 } else { FRAC_PI_2 };
        sim.actors.push(Scripted {
            view: actor(1, kind, Vec2::new(x, side * dist), yaw, 0.0, len, wid),
            speed: Box::new(move |_| speed),
        });
        if triggered {
            sim.triggers.push((0, x - trigger_gap));
        }
        let o = sim.run(ExpertParams::default());
        let name = format!(
            "case {case}: {kind:?} x={x:.0} side={side} v={speed:.1} d={dist:.0} triggered={triggered}"
        );
        assert!(!o.collided, "{name}: collision");
        assert!(o.reached, "{name}: not reached in {:.0} s", o.time_s);
        assert!(o.max_rest_s < 5.0, "{name}: rested {:.1} s", o.max_rest_s);
        interacted += usize::from(o.actions.iter().any(|a| matches!(a.reason, SpeedReason::Obstacle { .. })));
    }
    // The sweep exercises the conflict logic, not just empty roads.
    assert!(interacted >= 10, "only {interacted} cases interacted");
}

#[test]
fn oncoming_traffic_in_the_next_lane_is_ignored() {
    let mut sim = Sim::new(straight(200.0));
    sim.start_speed = 10.0;
    for (i, x) in [60.0, 90.0, 140.0].into_iter().enumerate() {
        sim.actors.push(Scripted {
            view: actor(
                i as u32 + 1,
                ActorKind::Car,
                Vec2::new(x, 3.3),
                std::f64::consts::PI,
                10.0,
                4.6,
                1.9,
            ),
            speed: Box::new(|_| 10.0),
        });
    }
    let o = check("oncoming", &sim, 0.95);
    assert!(o.actions.iter().all(|a| !matches!(a.reason, SpeedReason::Obstacle { .. })));
}

/// Two lanes (ours and a free one to the left); everything else is off road.
fn two_lane_drivable() -> Box<dyn Fn(Vec2, f64) -> bool> {
    Box::new(|p: Vec2, _h: f64| p.y > -1.6 && p.y < 4.8 && p.x > -30.0 && p.x < 300.0)
}

#[test]
fn passes_a_parked_car_after_a_short_wait() {
    let mut sim = Sim::new(straight(220.0));
    sim.drivable = Some(two_lane_drivable());
    sim.actors.push(Scripted {
        view: actor(3, ActorKind::Car, Vec2::new(90.0, 0.0), 0.0, 0.0, 4.6, 1.9),
        speed: Box::new(|_| 0.0),
    });
    let o = check_within("parked car", &sim, 0.85, 3.3);
    assert!(o.min_clearance_m > 0.4, "clearance {:.2}", o.min_clearance_m);
    assert!(o.actions.iter().any(|a| a.path_offset_m > 2.0));
}

#[test]
fn waits_for_traffic_in_the_passing_lane() {
    // A barrier blocks our lane; a stream of cars in the left lane passes it first.
    let mut sim = Sim::new(straight(260.0));
    sim.drivable = Some(two_lane_drivable());
    sim.actors.push(Scripted {
        view: actor(1, ActorKind::Barrier, Vec2::new(80.0, 0.0), FRAC_PI_2, 0.0, 2.6, 0.6),
        speed: Box::new(|_| 0.0),
    });
    for (i, x) in [-10.0, -30.0, -50.0].into_iter().enumerate() {
        sim.actors.push(Scripted {
            view: actor(i as u32 + 2, ActorKind::Car, Vec2::new(x, 3.2), 0.0, 8.0, 4.6, 1.9),
            speed: Box::new(|_| 8.0),
        });
    }
    // The centre must stay inside the two-lane band (y < 4.8).
    let o = check_within("traffic in the passing lane", &sim, 0.8, 4.0);
    assert!(o.min_clearance_m > 0.4, "clearance {:.2}", o.min_clearance_m);
    assert!(o.actions.iter().any(|a| a.path_offset_m > 2.0));
}

#[test]
fn does_not_pass_a_car_queuing_at_a_light() {
    let mut sim = Sim::new(straight(220.0));
    sim.drivable = Some(two_lane_drivable());
    sim.time_limit_s = 40.0;
    // A car stands 8 m before a red stop line at x = 100 (red for the whole run).
    sim.actors.push(Scripted {
        view: actor(3, ActorKind::Car, Vec2::new(92.0, 0.0), 0.0, 0.0, 4.6, 1.9),
        speed: Box::new(|_| 0.0),
    });
    sim.lights = Box::new(|_| vec![light(Vec2::new(100.0, 0.0), 0.0, LightColor::Red)]);
    let o = sim.run(ExpertParams::default());
    report("queue", &o);
    assert!(!o.collided && !o.reached);
    assert!(o.actions.iter().all(|a| a.path_offset_m == 0.0), "overtook a queuing car");
}

#[test]
fn lead_braking_sweep_never_collides() {
    // 30 leads: speed 6–13 m/s, 15–35 m ahead of an ego at the same speed, braking at 4–8 m/s²
    // to a stop after 2–8 s, standing 2 s, then driving on.
    let mut rng = Lcg(11);
    for case in 0..30 {
        let mut sim = Sim::new(straight(400.0));
        let v0 = 6.0 + 7.0 * rng.next();
        let gap = 15.0 + 20.0 * rng.next();
        let decel = 4.0 + 4.0 * rng.next();
        let t_brake = 2.0 + 6.0 * rng.next();
        sim.start_speed = v0;
        let t_stop = t_brake + v0 / decel;
        sim.actors.push(Scripted {
            view: actor(2, ActorKind::Car, Vec2::new(gap + 4.6, 0.0), 0.0, v0, 4.6, 1.9),
            speed: Box::new(move |t| {
                if t < t_brake {
                    v0
                } else if t < t_stop {
                    v0 - decel * (t - t_brake)
                } else if t < t_stop + 2.0 {
                    0.0
                } else {
                    (2.0 * (t - t_stop - 2.0)).min(v0)
                }
            }),
        });
        let o = sim.run(ExpertParams::default());
        let name = format!("case {case}: v0={v0:.1} gap={gap:.0} decel={decel:.1} t_brake={t_brake:.1}");
        assert!(!o.collided && o.reached, "{name}: collided={} reached={}", o.collided, o.reached);
        assert!(o.min_clearance_m > 1.0, "{name}: came within {:.2} m", o.min_clearance_m);
    }
}
