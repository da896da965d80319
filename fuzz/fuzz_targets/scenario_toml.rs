#![no_main]
//! Scenario TOML: parse, then (when it parses) resolve against one of the project's maps and
//! summarise it, as `drivehierarchy scenario validate` does. Must never panic; a resolved
//! scenario must be self-consistent.
//!
//! The `map` value is not used as a path (a fuzzer-chosen path could name any file on the
//! machine); it picks one of the committed maps by name, so real scenarios resolve as they do
//! in the suite and mutated ones exercise resolution against a real network.

use dh_env::scenario::{parse, LoadOptions, MapCache, Summary};
use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::{Arc, LazyLock};

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
    match dh_env::scenario::resolve::resolve(file, &spec, &OPTS) {
        Ok(s) => {
            let summary = Summary::of(&s);
            let _ = summary.to_string();
            assert!(summary.reference_duration_s.is_finite() && summary.reference_duration_s > 0.0);
            let _ = s.scenario_duration_s();
            let _ = s.estimated_start_times_s();
        }
        Err(e) => {
            let _ = parse::locate(e, file, text).to_string();
        }
    }
});
