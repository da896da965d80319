#![no_main]
//! The `waypoints` and `meta` levels' reply parsers (docs/vlm.md#action-levels) and the waypoint
//! tracker they feed: never panic, and any parsed plan becomes a finite control within the
//! actuator ranges, whatever the ego state.

use dh_env::drive::meta::speed_profile;
use dh_env::drive::{Plan, TrackerGains, WaypointTracker};
use dh_env::geom::{Pose, Vec2};
use dh_env::vehicle_params::VehicleParams;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let params = VehicleParams::default();
    let mut tracker = WaypointTracker::new(TrackerGains::default());
    let pose = Pose::new(Vec2::new(3.0, -2.0), 0.7);
    for parsed in [
        dh_agents::plan_reply::parse_waypoints_reply(text, 8),
        dh_agents::plan_reply::parse_meta_reply(text),
    ] {
        let points = match parsed {
            Ok(Plan::Waypoints(p)) => {
                assert!(!p.is_empty() && p.len() <= 8, "{p:?}");
                assert!(p.iter().all(|(x, y)| !x.is_nan() && !y.is_nan()), "{p:?}");
                p
            }
            // Meta plans become waypoints on a straight path here (no lane graph in the target).
            Ok(Plan::Meta(m)) => speed_profile(m.speed, 7.5, 8, 0.5).into_iter().map(|d| (d, 0.0)).collect(),
            Err(_) => continue,
        };
        tracker.set_plan(pose, &points, 0.5);
        for speed in [0.0, 7.5, 30.0] {
            let c = tracker.control(&pose, speed, &params);
            assert!((0.0..=1.0).contains(&c.throttle), "{c:?}");
            assert!((0.0..=1.0).contains(&c.brake), "{c:?}");
            assert!((-1.0..=1.0).contains(&c.steer), "{c:?}");
        }
    }
});
