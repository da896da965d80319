//! Where the SUMO installation (`SUMO_HOME`) is: the one lookup of the workspace, in the order
//! docs/traffic.md documents ("Where SUMO is found"):
//!
//! 1. the folder of the `sumo` package (the pinned `eclipse-sumo` wheel) of the Python in use:
//!    the running interpreter when called through `_core` ([`SumoHome::locate_with`]), else
//!    `$PYO3_PYTHON`, else `python3` ([`SumoHome::locate`]);
//! 2. the `SUMO_HOME` environment variable, when set and non-empty, taken as is;
//! 3. none.
//!
//! `env/build.rs` includes the same steps (`locate.rs`) to find SUMO's headers.

use std::path::PathBuf;

include!("locate.rs");

/// An `eclipse-sumo` installation (its `SUMO_HOME`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SumoHome(pub PathBuf);

impl SumoHome {
    /// The `sumo` package of `$PYO3_PYTHON` or `python3` (asked once per process, a
    /// subprocess), else `$SUMO_HOME`; `None` when neither exists.
    pub fn locate() -> Option<SumoHome> {
        static PACKAGE: std::sync::OnceLock<Option<PathBuf>> = std::sync::OnceLock::new();
        Self::locate_with(|| PACKAGE.get_or_init(|| sumo_home_from_python(&sumo_home_python())).clone())
    }

    /// `package()`, else `$SUMO_HOME`: `package` finds the folder of the `sumo` package (the
    /// binding asks its own interpreter instead of starting one).
    pub fn locate_with(package: impl FnOnce() -> Option<PathBuf>) -> Option<SumoHome> {
        locate_sumo_home_with(package).map(SumoHome)
    }

    /// The `sumo` binary.
    pub fn binary(&self) -> PathBuf {
        self.0.join("bin").join("sumo")
    }
}
