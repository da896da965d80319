//! Helpers shared by the integration tests: scenario files (an ego eastbound on town01's
//! C2T_1 plus a test's own TOML body, written to a per-test-binary temp folder and loaded), and
//! the render tests' ego.

use dh_env::drive::Control;
use dh_env::geom::Pose;
use dh_env::scenario::{ResolvedScenario, Scenario};
use dh_env::view::{ActorKind, ActorView};
use dh_env::world::World;
use std::path::PathBuf;

pub fn town01() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps/town01/town01.net.xml")
}

/// Scenario files of one test binary: `id` and `category` head every file it writes.
pub struct Town01Scenarios {
    pub id: &'static str,
    pub category: &'static str,
}

impl Town01Scenarios {
    /// Ego eastbound on C2T_1 (y = −4.8) from x ≈ 30 to x ≈ 340 at `speed` m/s, plus `body`.
    pub fn text(&self, speed: f64, body: &str) -> String {
        format!(
            r#"version = 1
id = "{id}"
category = "{category}"
map = {map:?}

[ego]
start = {{ lane = "C2T_1", s = 20.0 }}
destination = {{ lane = "C2T_1", s = 330.0 }}
speed_mps = {speed}
{body}
"#,
            id = self.id,
            category = self.category,
            map = town01().display().to_string()
        )
    }

    pub fn write(&self, tag: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("dh_scenario_{}_{}", self.id, std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(format!("{tag}.toml"));
        std::fs::write(&p, text).unwrap();
        p
    }

    pub fn load(&self, tag: &str, speed: f64, body: &str) -> ResolvedScenario {
        let p = self.write(tag, &self.text(speed, body));
        Scenario::load(&p).unwrap_or_else(|e| panic!("{tag}: {e}"))
    }

    /// The file written and the error loading it gave (the load must fail).
    pub fn load_err(&self, tag: &str, body: &str) -> (PathBuf, String) {
        let p = self.write(tag, &self.text(8.0, body));
        let e = Scenario::load(&p).expect_err("must fail").to_string();
        (p, e)
    }
}

/// Holds the ego's speed (throttle/brake on the error), straight ahead: a hazard-blind driver.
pub fn cruise(w: &World, v: f64) -> Control {
    let e = v - w.ego().speed_mps;
    Control { throttle: (0.5 * e).clamp(0.0, 1.0), brake: (-0.5 * e).clamp(0.0, 1.0), steer: 0.0 }
}

/// The render tests' ego: a grey car of the default car size, at rest.
pub fn grey_ego(pose: Pose) -> ActorView {
    ActorView {
        length_m: 4.6,
        width_m: 1.9,
        height_m: 1.5,
        ..ActorView::at_rest(0, ActorKind::Car, pose, [200, 200, 200])
    }
}
