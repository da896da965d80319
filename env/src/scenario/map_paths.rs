//! A scenario's `map` value → a network file (relative path, `sumo:` under `SUMO_HOME`,
//! `builtin:` shipped maps), and the cache of loaded networks.

use crate::map::Network;
use crate::sumo_home::SumoHome;
use crate::{Error, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Map-path prefix resolved against `SUMO_HOME`.
pub const SUMO_PREFIX: &str = "sumo:";
/// `map = "builtin:town01"`: a map shipped with the package, from a scenario anywhere.
pub const BUILTIN_PREFIX: &str = "builtin:";

/// Where `sumo:` maps live and an optional cache of loaded networks.
#[derive(Debug, Clone, Default)]
pub struct LoadOptions {
    /// `SUMO_HOME` for `sumo:` map paths; when `None`, [`SumoHome::locate`] finds it.
    pub sumo_home: Option<PathBuf>,
    pub cache: Option<Arc<MapCache>>,
}

/// Loaded networks by canonical path, so episodes on one map parse it once.
#[derive(Debug, Default)]
pub struct MapCache {
    maps: Mutex<BTreeMap<PathBuf, Arc<Network>>>,
}

impl MapCache {
    pub fn new() -> Self {
        Self::default()
    }
    pub fn get_or_load(&self, path: &Path) -> Result<Arc<Network>> {
        let key = path.canonicalize().unwrap_or_else(|_| path.to_path_buf());
        if let Some(n) = self.maps.lock().ok().and_then(|m| m.get(&key).cloned()) {
            return Ok(n);
        }
        let net = Arc::new(Network::from_file(path)?);
        if let Ok(mut m) = self.maps.lock() {
            m.insert(key, net.clone());
        }
        Ok(net)
    }
}

/// `builtin:NAME` maps: the folder holding the shipped maps (`NAME/NAME.net.xml`), registered
/// once per process (the Python package registers the maps it ships when imported).
static BUILTIN_MAPS: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Registers the folder of the shipped maps for `builtin:NAME`; a second call is ignored
/// (returns `false`) so every scenario of a process resolves against the same maps.
pub fn set_builtin_maps_dir(dir: PathBuf) -> bool {
    BUILTIN_MAPS.set(dir).is_ok()
}

fn resolve_builtin_map(file: &Path, map: &str, name: &str) -> Result<PathBuf> {
    let dir = BUILTIN_MAPS.get().ok_or_else(|| {
        Error::scenario(file, "map", map, "`builtin:` names the drivehierarchy package's shipped maps, and none are registered in this process (import drivehierarchy)")
    })?;
    let plain = !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    let path = dir.join(name).join(format!("{name}.net.xml"));
    if plain && path.is_file() {
        return Ok(path);
    }
    let mut shipped: Vec<String> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok()?.file_name().into_string().ok())
                .filter(|n| dir.join(n).join(format!("{n}.net.xml")).is_file())
                .collect()
        })
        .unwrap_or_default();
    shipped.sort();
    Err(Error::scenario(
        file,
        "map",
        map,
        format!("no shipped map of this name (shipped: {})", shipped.join(", ")),
    ))
}

/// Resolves the `map` value of a scenario file to a path.
pub fn resolve_map_path(file: &Path, map: &str, sumo_home: Option<&Path>) -> Result<PathBuf> {
    if let Some(name) = map.strip_prefix(BUILTIN_PREFIX) {
        return resolve_builtin_map(file, map, name);
    }
    if let Some(rest) = map.strip_prefix(SUMO_PREFIX) {
        let home = match sumo_home {
            Some(h) => h.to_path_buf(),
            None => SumoHome::locate().map(|h| h.0).ok_or_else(|| {
                Error::scenario(file, "map", map, "a `sumo:` map needs SUMO_HOME (set the SUMO_HOME environment variable, pass sumo_home, or `pip install eclipse-sumo`)")
            })?,
        };
        let p = home.join(rest.trim_start_matches('/'));
        if !p.is_file() {
            return Err(Error::scenario(
                file,
                "map",
                map,
                format!("map file not found under SUMO_HOME ({})", p.display()),
            ));
        }
        return Ok(p);
    }
    let base = file.parent().unwrap_or(Path::new("."));
    let p = base.join(map);
    if map.is_empty() || !p.is_file() {
        return Err(Error::scenario(
            file,
            "map",
            map,
            format!(
                "map file not found (looked for {}, relative to the scenario file){}",
                p.display(),
                builtin_hint(map)
            ),
        ));
    }
    Ok(p)
}

/// For a missing relative map named like a shipped one (`../../maps/town01/town01.net.xml` in a
/// copied suite folder): the `builtin:` name that finds it from anywhere.
fn builtin_hint(map: &str) -> String {
    let Some(dir) = BUILTIN_MAPS.get() else { return String::new() };
    let name = Path::new(map).file_name().and_then(|n| n.to_str()).and_then(|n| n.strip_suffix(".net.xml"));
    match name {
        Some(n) if !n.is_empty() && dir.join(n).join(format!("{n}.net.xml")).is_file() => {
            format!("; `{n}` is a shipped map: write map = \"{BUILTIN_PREFIX}{n}\" to use it from any folder")
        }
        _ => String::new(),
    }
}
