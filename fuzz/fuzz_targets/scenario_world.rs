#![no_main]
//! Scenario TOML through to a running world: parse, resolve against one of the project's maps
//! (as `scenario_toml` does), then build the world and play a few ticks. A scenario that
//! validates must never make the world panic.
//!
//! The `map` value is not used as a path (a fuzzer-chosen path could name any file on the
//! machine); it picks one of the committed maps by name, so real scenarios resolve as they do
//! in the suite and mutated ones exercise resolution against a real network.

use dh_env::scenario::{parse, LoadOptions, MapCache};
use dh_env::world::{Control, World};
use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::{Arc, LazyLock};

/// Ticks played per input (1 s of sim time: actors start moving, triggers fire).
const TICKS: usize = 20;

fn maps_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps")
}

static MAPS: LazyLock<[(&str, PathBuf); 3]> = LazyLock::new(|| {
    let d = maps_dir();
    [
        ("town02", d.join("town02/town02.net.xml")),
        ("bs3d", d.join("bs3d_arterial/bs3d_arterial.net.xml")),
        ("town01", d.join("town01/town01.net.xml")),
    ]
});

static OPTS: LazyLock<LoadOptions> = LazyLock::new(|| {
    let cache = Arc::new(MapCache::new());
    for (_, p) in MAPS.iter() {
        cache.get_or_load(p).expect("committed map loads");
    }
    LoadOptions { sumo_home: None, cache: Some(cache) }
});

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let file = Path::new("fuzz.toml");
    let Ok(mut spec) = parse::parse_scenario_str(file, text) else { return };
    let map = MAPS.iter().find(|(k, _)| spec.map.contains(k)).unwrap_or(&MAPS[2]);
    spec.map = map.1.to_string_lossy().into_owned();
    let Ok(s) = dh_env::scenario::resolve::resolve(file, &spec, &OPTS) else { return };
    let Ok(mut world) = World::new(&s, s.seed) else { return };
    let control = Control { throttle: 1.0, brake: 0.0, steer: 0.3 };
    for _ in 0..TICKS {
        if world.tick(&control).is_err() {
            break;
        }
    }
});
