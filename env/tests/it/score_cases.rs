//! Hand-computed scoring cases (docs/protocol.md#r4-termination, #r4-scene-score). Every expected
//! number is derived in
//! the comment next to it.

use dh_env::geom::{Polyline, Vec2};
use dh_env::score::record::round_to;
use dh_env::score::*;
use dh_env::view::ContactClass;

const EPS: f64 = 1e-9;

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= EPS * (1.0 + b.abs())
}

macro_rules! assert_close {
    ($a:expr, $b:expr) => {{
        let (a, b) = ($a, $b);
        assert!(close(a, b), "{} = {a}, expected {b}", stringify!($a));
    }};
}

/// Straight 100 m route along +x; destination at its end; start at the origin.
fn tracker(reference: Option<f64>) -> ScoreTracker {
    let route = Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(100.0, 0.0)]);
    ScoreTracker::new(route, Vec2::ZERO, Vec2::new(100.0, 0.0), reference, ScoreParams::default()).unwrap()
}

fn on(x: f64, y: f64, v: f64) -> TickInput<'static> {
    TickInput::new(Vec2::new(x, y), v, true)
}

fn off(x: f64, y: f64, v: f64) -> TickInput<'static> {
    TickInput::new(Vec2::new(x, y), v, false)
}

/// Python's round(x, 6), as the original rounds every score.
fn r6(x: f64) -> f64 {
    round_to(x, 6)
}

fn info() -> RunInfo {
    RunInfo { scene_id: "case".into(), wall_duration_s: 1.25, decisions: 7, parse_failures: 2 }
}

/// Drives along the route at 10 m/s (0.5 m per tick) for `n` ticks; returns the last result.
fn cruise(t: &mut ScoreTracker, n: u64) -> Option<Termination> {
    let mut last = None;
    for _ in 0..n {
        let x = (t.ticks() + 1) as f64 * 0.5;
        last = t.update(&on(x, 0.0, 10.0));
    }
    last
}

#[test]
fn destination_reached_at_exactly_8_m_is_perfect() {
    let mut t = tracker(Some(20.0));
    // x = 0.5·k; |(91.5,0)−(100,0)| = 8.5 at k = 183: not yet; 8.0 at k = 184: reached (≤ 8).
    assert_eq!(cruise(&mut t, 183), None);
    let end = cruise(&mut t, 1).unwrap();
    assert_eq!(end.reason, TerminationReason::DestinationReached);
    assert_eq!(end.tick, 184);
    assert_close!(end.time_s, 9.2);
    let s = t.finish(&info());
    assert_eq!(s.status, Status::Perfect);
    assert_eq!(s.score_route, 100.0);
    assert_eq!(s.meta.completed_distance_m, 100.0); // best = L inside the radius
    assert_eq!(s.meta.travel_distance_m, 92.0);
    // η_dist = min(1, 1.1·100/92) = 1; η_time = min(1, 1.5·20/9.2) = 1.
    assert_eq!((s.meta.distance_efficiency, s.meta.time_efficiency), (1.0, 1.0));
    assert_eq!(
        (s.score_safety, s.score_efficiency, s.score_penalty, s.score_composed),
        (1.0, 1.0, 1.0, 100.0)
    );
    // The original records the arrival as an event without a multiplier.
    assert_eq!(s.events.len(), 1);
    assert_eq!(s.events[0].kind, EventKind::DestinationReached);
    assert_eq!(s.events[0].penalty_multiplier, None);
    assert_eq!(s.events[0].time_s, 9.2);
    assert_eq!(s.events[0].details["destination_radius"], 8.0);
    assert_eq!((s.ticks, s.decisions, s.parse_failures), (184, 7, 2));
    assert_eq!(s.meta.last_location, Location { x: 92.0, y: 0.0, z: 0.0 });
    assert_eq!(s.meta.last_route_distance_m, Some(0.0));
    // Updates after the end change nothing.
    assert_eq!(t.update(&on(50.0, 0.0, 0.0)), Some(end));
    assert_eq!(t.finish(&info()), s);
}

#[test]
fn destination_radius_is_two_dimensional() {
    // (94, 5.29): 6² + 5.29² = 63.9841 < 64 → inside. Progress is not needed for it.
    let mut t = tracker(Some(20.0));
    let end = t.update(&off(94.0, 5.29, 10.0)).unwrap();
    assert_eq!(end.reason, TerminationReason::DestinationReached);
    assert_eq!(t.best_progress_m(), 100.0);
    // (94, 5.3): 36 + 28.09 = 64.09 > 64 → outside.
    let mut t = tracker(Some(20.0));
    assert_eq!(t.update(&on(94.0, 5.3, 10.0)), None);
    // On-road, |lateral| 5.3 ≤ 6: progress = min(94, 0 + 20) = 20.
    assert_eq!(t.best_progress_m(), 20.0);
}

#[test]
fn progress_step_cap_of_20_m() {
    let mut t = tracker(Some(100.0));
    // Teleport to x = 50 and stay (speed 5 m/s so it is not blocked):
    // progress 20, then min(50, 40) = 40, then min(50, 60) = 50, and it never exceeds 50.
    for want in [20.0, 40.0, 50.0, 50.0] {
        assert_eq!(t.update(&on(50.0, 0.0, 5.0)), None);
        assert_eq!(t.best_progress_m(), want);
    }
    // Going back does not lower best.
    t.update(&on(10.0, 0.0, 5.0));
    assert_eq!(t.best_progress_m(), 50.0);
    let s = t.finish(&info());
    assert_eq!(s.termination_reason, TerminationReason::Incomplete);
    assert_eq!(s.status, Status::Failed);
    assert_eq!(s.score_route, 50.0);
    assert_eq!(t.route_score(), 50.0);
}

#[test]
fn progress_lateral_rule_of_6_m_and_on_road_only() {
    let mut t = tracker(Some(100.0));
    t.update(&on(10.0, 6.0, 5.0)); // |lateral| = 6 ≤ 6: counts
    assert_eq!(t.best_progress_m(), 10.0);
    t.update(&on(20.0, -6.01, 5.0)); // 6.01 > 6: ignored
    assert_eq!(t.best_progress_m(), 10.0);
    t.update(&off(20.0, 0.0, 5.0)); // on the route line but off-road: ignored
    assert_eq!(t.best_progress_m(), 10.0);
    t.update(&on(25.0, 0.0, 5.0)); // min(25, 10 + 20) = 25
    assert_eq!(t.best_progress_m(), 25.0);
    // Past the route end the distance to the polyline is the distance to its end point.
    let mut t = tracker(Some(100.0));
    for _ in 0..5 {
        t.update(&on(80.0, 0.0, 5.0));
    }
    assert_eq!(t.best_progress_m(), 80.0);
    let route = Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(100.0, 0.0)]);
    let mut t =
        ScoreTracker::new(route, Vec2::ZERO, Vec2::new(0.0, 50.0), Some(100.0), ScoreParams::default())
            .unwrap();
    for _ in 0..6 {
        t.update(&on(106.5, 0.0, 5.0)); // 6.5 m beyond the end: not within 6 m
    }
    assert_eq!(t.best_progress_m(), 0.0);
}

#[test]
fn offroad_timeout_fires_on_the_31st_off_road_tick() {
    let mut t = tracker(Some(100.0));
    // 10 ticks on the road; the first off-road sample is tick 11 (t = 0.55 s).
    assert_eq!(cruise(&mut t, 10), None);
    for k in 11..=40 {
        assert_eq!(t.update(&off(5.0, 3.0, 2.0)), None, "tick {k}");
    }
    // The original ends when t − t_first_offroad ≥ 1.5 s: tick 41 (2.05 s), the 31st.
    let end = t.update(&off(5.0, 3.0, 2.0)).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::OffroadTimeout, 41));
    assert_close!(end.time_s, 2.05);
    let s = t.finish(&info());
    // travel: 5 m along + √(0² + 3²) = 3 m sideways at tick 11 → 8 m.
    assert_close!(s.meta.travel_distance_m, 8.0);
    // Intervals opened by off-road samples 11..40 = 30 × 0.05 = 1.5 s = the run's duration.
    assert_eq!(s.meta.offroad_time_s, 1.5);
    assert_eq!(s.meta.offroad_ratio, r6(1.5 / 2.05));
    assert_eq!(s.meta.lane_keep_penalty, r6(1.0 - 1.5 / 2.05));
    assert_eq!(s.score_safety, 0.0); // penalty 0 × (1 − ratio)
    assert_eq!(s.score_composed, 0.0);
    assert_eq!(s.score_route, 5.0);
    assert_eq!(s.events.len(), 1);
    // The original's event type; the termination reason stays offroad_timeout.
    assert_eq!(s.events[0].kind, EventKind::RouteDeviation);
    assert_eq!(s.termination_reason, TerminationReason::OffroadTimeout);
    assert_eq!(s.events[0].penalty_multiplier, Some(0.0));
    assert_eq!(s.events[0].details["offroad_duration"], 1.5);
    assert_eq!(s.events[0].time_s, 2.05);
}

#[test]
fn offroad_run_resets_when_back_on_the_road() {
    let mut t = tracker(Some(100.0));
    // 30 off-road ticks do not end the run (the 31st would).
    for _ in 0..30 {
        assert_eq!(t.update(&off(0.0, 3.0, 2.0)), None);
    }
    assert_eq!(t.update(&on(0.0, 3.0, 2.0)), None);
    for _ in 0..30 {
        assert_eq!(t.update(&off(0.0, 3.0, 2.0)), None);
    }
    let s = t.finish(&info());
    // An interval counts when its opening sample was off-road: samples 1..30 and 32..60
    // (sample 61's interval has not happened) → 59 × 0.05 = 2.95 s of 3.05 s.
    assert_close!(s.meta.offroad_time_s, 2.95);
    assert_eq!(s.score_safety, r6(1.0 - 2.95 / 3.05));
    assert!(s.events.is_empty());
}

#[test]
fn blocked_timeout_after_more_than_100_slow_ticks_from_t0() {
    let mut t = tracker(Some(20.0));
    // 0.27 m/s = 0.972 km/h < 1: slow from the first tick.
    for k in 1..=100 {
        assert_eq!(t.update(&on(0.0, 0.0, 0.27)), None, "tick {k}");
    }
    let end = t.update(&on(0.0, 0.0, 0.27)).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::BlockedTimeout, 101));
    assert_close!(end.time_s, 5.05);
    let s = t.finish(&info());
    assert_eq!(s.events[0].kind, EventKind::BlockedTimeout);
    assert_eq!(s.events[0].penalty_multiplier, Some(0.7));
    assert_eq!(s.events[0].details["blocked_steps"], 101);
    assert_eq!(s.events[0].details["speed_kmh"], 0.972);
    assert_eq!(s.events[0].details["speed_threshold_kmh"], 1.0);
    assert_eq!(s.events[0].time_s, 5.05);
    // route 0; safety 0.7; travel 0 → η_dist = 1; η_time = min(1, 30/5.05) = 1.
    assert_eq!((s.score_route, s.score_safety, s.score_efficiency), (0.0, 0.7, 1.0));
    assert_eq!(s.score_composed, 0.0);
    assert_close!(s.score_penalty, 0.7);

    // 0.28 m/s = 1.008 km/h is not slow; a moving spell resets the run.
    let mut t = tracker(Some(20.0));
    for _ in 0..100 {
        t.update(&on(0.0, 0.0, 0.27));
    }
    assert_eq!(t.update(&on(0.0, 0.0, 0.28)), None);
    for _ in 0..100 {
        assert_eq!(t.update(&on(0.0, 0.0, 0.0)), None);
    }
    assert_eq!(t.update(&on(0.0, 0.0, 0.0)).unwrap().tick, 202);
}

#[test]
fn blocked_after_driving_20_m() {
    let mut t = tracker(Some(20.0));
    cruise(&mut t, 40); // x = 20 at t = 2.0
    for _ in 0..100 {
        assert_eq!(t.update(&on(20.0, 0.0, 0.0)), None);
    }
    let end = t.update(&on(20.0, 0.0, 0.0)).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::BlockedTimeout, 141));
    let s = t.finish(&info());
    // route 20; safety 0.7; η_dist = min(1, 110/20) = 1; η_time = min(1, 30/7.05) = 1.
    assert_eq!(s.score_composed, 14.0);
    assert_eq!(s.status, Status::Failed);
}

#[test]
fn scenario_timeout_and_time_efficiency_branch() {
    let mut t = tracker(Some(1.0));
    // 2·T_ref = 2.0 s = tick 40.
    assert_eq!(cruise(&mut t, 39), None);
    let end = cruise(&mut t, 1).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::ScenarioTimeout, 40));
    let s = t.finish(&info());
    // route 20; safety 0.7; η_dist = 1; η_time = 1.5·1/2 = 0.75; eff = 0.7 + 0.3·0.75 = 0.925.
    assert_eq!(s.score_route, 20.0);
    assert_eq!(s.score_safety, 0.7);
    assert_eq!(s.meta.time_efficiency, 0.75);
    assert_eq!(s.score_efficiency, 0.925);
    assert_eq!(s.score_penalty, 0.6475);
    assert_eq!(s.score_composed, 12.95); // 20 × 0.6475
    assert_eq!(s.meta.reference_duration_s, 1.0);
    assert_eq!(s.meta.reference_duration_source, "scenario");
    assert_eq!(s.events[0].penalty_multiplier, Some(0.7));
    assert_eq!(s.events[0].details["max_sim_time"], 2.0);
}

#[test]
fn reference_duration_fallback_is_route_length_over_5_56() {
    let mut t = tracker(None);
    let t_ref = 100.0 / 5.56; // 17.985611510791365 s; timeout at 35.971… s → tick 720 (36.0 s)
    assert_eq!(t.reference_duration_s(), t_ref);
    let mut end = None;
    for k in 1..=720u64 {
        let r = t.update(&on(k as f64 * 0.05, 0.0, 1.0));
        if k < 720 {
            assert_eq!(r, None, "tick {k}");
        }
        end = r;
    }
    let end = end.unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::ScenarioTimeout, 720));
    let s = t.finish(&info());
    assert_eq!(s.meta.reference_duration_source, "fallback");
    assert_eq!(s.score_route, 36.0);
    let eta_time = 1.5 * t_ref / 36.0; // 0.7494004796…
    assert_eq!(s.meta.time_efficiency, r6(eta_time));
    let eff = r6(0.7 + 0.3 * eta_time);
    assert_eq!(s.score_efficiency, eff);
    // Composed from the rounded terms, as the original does.
    assert_eq!(s.score_penalty, r6(0.7 * eff));
    assert_eq!(s.score_composed, r6(36.0 * r6(0.7 * eff)));
}

#[test]
fn distance_efficiency_branch_and_completed_status() {
    let mut t = tracker(Some(4.0));
    // 60 ticks zig-zagging 1 m sideways at the start (on road, 20 m/s), then 1 m/tick along x.
    for k in 1..=60u64 {
        assert_eq!(t.update(&on(0.0, (k % 2) as f64, 20.0)), None);
    }
    let mut end = None;
    for k in 1..=92u64 {
        end = t.update(&on(k as f64, 0.0, 20.0));
    }
    let end = end.unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::DestinationReached, 152));
    let s = t.finish(&info());
    // travel 60 + 92 = 152; η_dist = 110/152; duration 7.6 s; η_time = 6/7.6.
    assert_eq!(s.meta.travel_distance_m, 152.0);
    assert_eq!(s.meta.distance_efficiency, r6(110.0 / 152.0));
    assert_eq!(s.meta.time_efficiency, r6(6.0 / 7.6));
    let eff = r6(0.7 * (100.0 * 1.1) / 152.0 + 0.3 * (4.0 * 1.5) / 7.6); // 0.743421
    assert_eq!(s.score_efficiency, eff);
    assert_eq!(s.score_composed, r6(100.0 * eff));
    assert_eq!(s.status, Status::Completed);
    assert_eq!(s.score_safety, 1.0);
}

fn contacts_tick(contacts: &[Contact]) -> TickInput<'_> {
    TickInput { contacts, ..TickInput::new(Vec2::new(5.0, 0.0), 10.0, true) }
}

#[test]
fn every_collision_class() {
    for (class, reason, penalty) in [
        (ContactClass::Pedestrian, TerminationReason::CollisionPedestrian, 0.0),
        (ContactClass::Vehicle, TerminationReason::CollisionVehicle, 0.2),
        (ContactClass::Static, TerminationReason::CollisionStatic, 0.3),
    ] {
        let mut t = tracker(Some(20.0));
        cruise(&mut t, 9); // x = 4.5
        let c = [Contact { actor_id: 42, class }];
        let end = t.update(&contacts_tick(&c)).unwrap();
        assert_eq!((end.reason, end.tick), (reason, 10));
        let s = t.finish(&info());
        assert_eq!(s.events.len(), 1);
        let e = &s.events[0];
        assert_eq!(e.penalty_multiplier, Some(penalty));
        assert_eq!(e.details["other_actor_id"], 42);
        // A CARLA type id whose prefix the original's classifier maps back to the class.
        let other = e.details["other_actor"].as_str().unwrap();
        let prefix = ["walker.", "vehicle.", "static."][class as usize];
        assert!(other.starts_with(prefix), "{other}");
        assert_eq!(e.details["intensity"], 15000.0); // 1500 kg × 10 m/s
        assert_eq!(e.time_s, 0.5);
        // route 5; safety = penalty; η = 1 → composed = 5·penalty (0, 1.0, 1.5).
        assert_eq!(s.score_route, 5.0);
        assert_close!(s.score_composed, 5.0 * penalty);
        let carla = &s.dialects.carla;
        let m = [0.5, 0.6, 0.65][class as usize];
        assert_close!(carla.driving_score, 5.0 * m);
    }
}

#[test]
fn termination_order_within_one_tick() {
    // Several contacts: pedestrian beats vehicle beats static, whatever the list order.
    let mut t = tracker(Some(20.0));
    let c = [
        Contact { actor_id: 1, class: ContactClass::Static },
        Contact { actor_id: 2, class: ContactClass::Vehicle },
        Contact { actor_id: 3, class: ContactClass::Pedestrian },
    ];
    assert_eq!(t.update(&contacts_tick(&c)).unwrap().reason, TerminationReason::CollisionPedestrian);
    assert_eq!(t.events()[0].details["other_actor_id"], 3);
    assert_eq!(t.events()[0].details["contacts"].as_array().unwrap().len(), 3);
    let mut t = tracker(Some(20.0));
    assert_eq!(t.update(&contacts_tick(&c[..2])).unwrap().reason, TerminationReason::CollisionVehicle);

    // Collision inside the destination radius: the collision wins; best = L (route 100) but
    // the run failed.
    let mut t = tracker(Some(20.0));
    let c = [Contact { actor_id: 9, class: ContactClass::Vehicle }];
    let tick = TickInput { contacts: &c, ..on(95.0, 0.0, 10.0) };
    assert_eq!(t.update(&tick).unwrap().reason, TerminationReason::CollisionVehicle);
    let s = t.finish(&info());
    assert_eq!((s.status, s.score_route), (Status::Failed, 100.0));
    // travel 95 → η_dist = 1; duration 0.05 → η_time = 1 → composed = 100 · 0.2.
    assert_close!(s.score_composed, 20.0);

    // Off-road timeout beats destination: 30 off-road ticks, then the 31st inside the radius.
    let mut t = tracker(Some(20.0));
    for _ in 0..30 {
        assert_eq!(t.update(&off(80.0, 10.0, 5.0)), None);
    }
    assert_eq!(t.update(&off(95.0, 1.0, 5.0)).unwrap().reason, TerminationReason::OffroadTimeout);
    assert_eq!(t.best_progress_m(), 100.0);

    // Destination beats blocked and scenario timeout: T_ref = 2.525 s puts the time limit
    // (5.05 s) on tick 101, the same tick the 101st slow tick makes the run blocked.
    let mut t = tracker(Some(2.525));
    for _ in 0..100 {
        assert_eq!(t.update(&on(50.0, 0.0, 0.0)), None);
    }
    assert_eq!(t.update(&on(99.0, 0.0, 0.0)).unwrap().reason, TerminationReason::DestinationReached);
    // Blocked beats scenario timeout on the same tick.
    let mut t = tracker(Some(2.525));
    for _ in 0..100 {
        assert_eq!(t.update(&on(50.0, 0.0, 0.0)), None);
    }
    let end = t.update(&on(50.0, 0.0, 0.0)).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::BlockedTimeout, 101));
    // One tick less slow: the scenario timeout fires on its own at tick 101.
    let mut t = tracker(Some(2.525));
    t.update(&on(50.0, 0.0, 5.0));
    for _ in 0..99 {
        assert_eq!(t.update(&on(50.0, 0.0, 0.0)), None);
    }
    let end = t.update(&on(50.0, 0.0, 0.0)).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::ScenarioTimeout, 101));
    // An external stop beats everything.
    let mut t = tracker(Some(20.0));
    let c = [Contact { actor_id: 1, class: ContactClass::Pedestrian }];
    let tick = TickInput { contacts: &c, stop: Some(ExternalStop::SystemError), ..on(99.0, 0.0, 1.0) };
    assert_eq!(t.update(&tick).unwrap().reason, TerminationReason::SystemError);
}

#[test]
fn manual_interrupt_and_system_error() {
    let mut t = tracker(Some(20.0));
    cruise(&mut t, 20); // x = 10
    let end = t.stop(ExternalStop::ManualInterrupt);
    assert_eq!((end.reason, end.tick), (TerminationReason::ManualInterrupt, 20));
    let s = t.finish(&info());
    assert_eq!((s.score_route, s.score_safety, s.score_composed), (10.0, 0.0, 0.0));
    assert_eq!(s.events[0].kind, EventKind::ManualInterrupt);
    // A second stop changes nothing.
    assert_eq!(t.stop(ExternalStop::SystemError), end);

    let mut t = tracker(Some(20.0));
    cruise(&mut t, 4);
    let end = t.update(&on(f64::NAN, 0.0, 3.0)).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::SystemError, 5));
    let s = t.finish(&info());
    assert_eq!(s.meta.travel_distance_m, 2.0); // the NaN sample is not accumulated
    assert_eq!(s.events[0].penalty_multiplier, Some(0.0));
    assert!(s.events[0].details["error"].is_string());
}

#[test]
fn traffic_rule_infractions_only_count_in_the_carla_dialect() {
    let mut t = tracker(Some(20.0));
    cruise(&mut t, 99);
    let tick = TickInput { red_light: true, ..on(50.0, 0.0, 10.0) };
    assert_eq!(t.update(&tick), None);
    let tick = TickInput { stop_sign: true, ..on(50.5, 0.0, 10.0) };
    assert_eq!(t.update(&tick), None);
    // Leave the road for 10 ticks of 0.5 m (5 m of 101 m travel), then come back and finish.
    for k in 1..=10u64 {
        t.update(&off(50.5 + k as f64 * 0.5, 0.0, 10.0));
    }
    let mut end = None;
    let mut k = 0u64;
    while end.is_none() {
        k += 1;
        end = t.update(&on(55.5 + k as f64 * 0.5, 0.0, 10.0));
    }
    let s = t.finish(&info());
    assert_eq!(s.termination_reason, TerminationReason::DestinationReached);
    assert_eq!(s.events.len(), 3); // red light, stop sign, destination reached
    assert_eq!(s.meta.penalty_product, 1.0);
    // Protocol: route 100, safety = 1 − 10/184 (off-road intervals / ticks).
    assert_eq!(s.ticks, 184);
    assert_eq!(s.score_safety, r6(1.0 - 0.5 / 9.2));
    assert_eq!(s.status, Status::Completed);
    // CARLA: 100 × 0.7 × 0.8 × (1 − 5/92).
    let c = &s.dialects.carla;
    assert_eq!((c.red_light_infractions, c.stop_sign_infractions), (1, 1));
    assert_close!(c.offroad_fraction, 5.0 / 92.0);
    assert_close!(c.infraction_penalty, 0.56);
    assert_close!(c.driving_score, 100.0 * 0.56 * (1.0 - 5.0 / 92.0));
}

#[test]
fn invalid_setup_is_a_named_error() {
    let route = Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(100.0, 0.0)]);
    let p = ScoreParams::default();
    let err = |r: dh_env::Result<ScoreTracker>| r.unwrap_err().to_string();
    let e = err(ScoreTracker::new(Polyline::new(vec![Vec2::ZERO]), Vec2::ZERO, Vec2::ZERO, None, p.clone()));
    assert!(e.contains("route"), "{e}");
    let e = err(ScoreTracker::new(route.clone(), Vec2::ZERO, Vec2::ZERO, Some(0.0), p.clone()));
    assert!(e.contains("reference_duration_s"), "{e}");
    let e = err(ScoreTracker::new(route.clone(), Vec2::ZERO, Vec2::new(f64::NAN, 0.0), None, p.clone()));
    assert!(e.contains("destination"), "{e}");
    let bad = ScoreParams { blocked_speed_kmh: -1.0, ..p };
    let e = err(ScoreTracker::new(route, Vec2::ZERO, Vec2::ZERO, None, bad));
    assert!(e.contains("blocked_speed_kmh"), "{e}");
}

#[test]
fn record_has_the_original_fields() {
    let mut t = tracker(Some(20.0));
    cruise(&mut t, 9);
    let c = [Contact { actor_id: 4, class: ContactClass::Static }];
    t.update(&contacts_tick(&c));
    let v = serde_json::to_value(t.finish(&info())).unwrap();
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
    let mut want = vec![
        "scene_id",
        "status",
        "termination_reason",
        "score_route",
        "score_safety",
        "score_efficiency",
        "score_penalty",
        "score_composed",
        "events",
        "meta",
        "protocol_version",
        "ticks",
        "decisions",
        "parse_failures",
        "dialects",
    ];
    let mut keys_sorted = keys.clone();
    keys_sorted.sort_unstable();
    want.sort_unstable();
    assert_eq!(keys_sorted, want);
    assert_eq!(v["status"], "Failed");
    assert_eq!(v["termination_reason"], "collision_static");
    let e = &v["events"][0];
    assert_eq!(e["type"], "collision_static");
    assert_eq!(e["penalty_multiplier"], 0.3);
    assert_eq!(e["time"], 0.5);
    for key in ["other_actor", "intensity"] {
        assert!(e.get(key).is_some(), "event key {key}");
    }
    let mut meta: Vec<&str> = v["meta"].as_object().unwrap().keys().map(|k| k.as_str()).collect();
    meta.sort_unstable();
    // The original's meta keys, then ours.
    let mut want_meta = vec![
        "route_source",
        "route_length_m",
        "completed_distance_m",
        "travel_distance_m",
        "offroad_time_s",
        "offroad_ratio",
        "lane_keep_penalty",
        "duration_game",
        "duration_system",
        "reference_duration_s",
        "distance_efficiency",
        "time_efficiency",
        "destination_radius",
        "last_route_distance_m",
        "last_location",
        "reference_duration_source",
        "scenario_duration_s",
        "max_sim_time_s",
        "penalty_product",
    ];
    want_meta.sort_unstable();
    assert_eq!(meta, want_meta);
    assert_eq!(v["meta"]["destination_radius"], 8.0);
    assert_eq!(v["meta"]["duration_system"], 1.25);
    assert_eq!(v["meta"]["route_source"], "route_edges");
    assert_eq!(v["meta"]["last_location"], serde_json::json!({"x": 5.0, "y": 0.0, "z": 0.0}));
    let back: SceneScore = serde_json::from_value(v).unwrap();
    assert_eq!(back, t.finish(&info()));
}

#[test]
fn scenario_timeout_uses_the_scenario_duration_not_t_ref() {
    // T_ref = 1 s feeds the efficiency term; the scenario lasts 3 s, so the limit is 6 s
    // (tick 120), not 2 × T_ref = 2 s.
    let mut t = tracker(Some(1.0)).with_scenario_duration(Some(3.0)).unwrap();
    for k in 1..120u64 {
        assert_eq!(t.update(&on(k as f64 * 0.05, 0.0, 1.0)), None, "tick {k}");
    }
    let end = t.update(&on(6.0, 0.0, 1.0)).unwrap();
    assert_eq!((end.reason, end.tick), (TerminationReason::ScenarioTimeout, 120));
    let s = t.finish(&info());
    assert_eq!(s.events[0].details["max_sim_time"], 6.0);
    assert_eq!((s.meta.scenario_duration_s, s.meta.max_sim_time_s), (3.0, 6.0));
    assert_eq!(s.meta.reference_duration_s, 1.0);
    assert_eq!(s.meta.time_efficiency, r6(1.5 / 6.0));
    let bad = tracker(Some(1.0)).with_scenario_duration(Some(f64::NAN));
    assert!(bad.unwrap_err().to_string().contains("scenario_duration_s"));
}

#[test]
fn status_follows_the_original_thresholds() {
    // Safety 1 and efficiency ≥ 0.999999 after rounding → Perfect; a hair lower → Completed.
    let route = Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(100.0, 0.0)]);
    let p = ScoreParams::default();
    let run = |travel_extra: f64| {
        let mut t =
            ScoreTracker::new(route.clone(), Vec2::ZERO, Vec2::new(100.0, 0.0), Some(100.0), p.clone())
                .unwrap();
        // A sideways hop adds travel; then straight on to the destination.
        t.update(&on(0.0, travel_extra, 10.0));
        let mut k = 0;
        while t.termination().is_none() {
            k += 1;
            t.update(&on(k as f64, 0.0, 10.0));
        }
        t.finish(&info())
    };
    // Travel h + √(1 + h²) + 91 must exceed 110 for the distance term to drop below 1.
    assert_eq!(run(1.0).status, Status::Perfect);
    let s = run(10.0); // travel ≈ 111.05 → η_dist ≈ 0.9905
    assert_eq!(s.status, Status::Completed);
    assert!(s.score_efficiency < 0.999999);
}
