#![no_main]
//! VLM reply parser (docs/protocol.md#r4-actuation) and the actuation bridge it feeds: never panics, and any
//! parsed decision becomes a finite control within the actuator ranges.

use dh_env::drive::bridge::ActuationBridge;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let parsed = dh_agents::vlm::parse_for_env(text);
    if let Ok(d) = parsed {
        assert!(!d.steer.is_nan() && !d.target_speed_mps.is_nan(), "{d:?}");
    }
    let mut bridge = ActuationBridge::new();
    for speed in [0.0, 7.5, 30.0] {
        let c = bridge.apply(parsed.ok(), speed);
        assert!((0.0..=1.0).contains(&c.throttle), "{c:?}");
        assert!((0.0..=1.0).contains(&c.brake), "{c:?}");
        assert!((-1.0..=1.0).contains(&c.steer), "{c:?}");
    }
});
