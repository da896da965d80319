//! Every constant of the scene score (docs/protocol.md#r4-termination, #r4-scene-score);
//! `Default` is the protocol.

use serde::{Deserialize, Serialize};

/// Multiplier each terminating event applies to the safety term.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Penalties {
    pub collision_pedestrian: f64,
    pub collision_vehicle: f64,
    pub collision_static: f64,
    pub scenario_timeout: f64,
    pub blocked_timeout: f64,
    pub offroad_timeout: f64,
    pub manual_interrupt: f64,
    pub system_error: f64,
}

impl Default for Penalties {
    fn default() -> Self {
        Self {
            collision_pedestrian: 0.0,
            collision_vehicle: 0.2,
            collision_static: 0.3,
            scenario_timeout: 0.7,
            blocked_timeout: 0.7,
            offroad_timeout: 0.0,
            manual_interrupt: 0.0,
            system_error: 0.0,
        }
    }
}

/// Infraction multipliers of the secondary CARLA-leaderboard-style dialect.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CarlaPenalties {
    pub collision_pedestrian: f64,
    pub collision_vehicle: f64,
    pub collision_static: f64,
    pub red_light: f64,
    pub stop_sign: f64,
    pub scenario_timeout: f64,
}

impl Default for CarlaPenalties {
    fn default() -> Self {
        Self {
            collision_pedestrian: 0.50,
            collision_vehicle: 0.60,
            collision_static: 0.65,
            red_light: 0.70,
            stop_sign: 0.80,
            scenario_timeout: 0.70,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScoreParams {
    /// Simulation step; time is `ticks × dt_s` (ticks are counted, never summed as floats).
    pub dt_s: f64,
    /// Continuous off-road time that ends the run, measured from the first off-road sample.
    pub offroad_timeout_s: f64,
    /// 2-D distance to the destination at which it counts as reached (≤).
    pub destination_radius_m: f64,
    /// "Slow" means speed·3.6 < this.
    pub blocked_speed_kmh: f64,
    /// The run is blocked when slow for more than this many consecutive ticks.
    pub blocked_ticks: u64,
    /// Scenario timeout at sim time ≥ factor × the scenario duration.
    pub scenario_timeout_factor: f64,
    /// Progress counts only while |lateral offset| from the route ≤ this.
    pub progress_lateral_m: f64,
    /// Progress may grow by at most this much per tick.
    pub progress_step_cap_m: f64,
    pub penalties: Penalties,
    /// η_dist = min(1, distance_grace·L/travel).
    pub distance_grace: f64,
    /// η_time = min(1, time_grace·T_ref/duration).
    pub time_grace: f64,
    pub distance_weight: f64,
    pub time_weight: f64,
    /// T_ref = L / this when the scenario gives no reference duration.
    pub fallback_reference_speed_mps: f64,
    pub carla: CarlaPenalties,
}

impl Default for ScoreParams {
    fn default() -> Self {
        Self {
            dt_s: crate::DT_S,
            offroad_timeout_s: 1.5,
            destination_radius_m: 8.0,
            blocked_speed_kmh: 1.0,
            blocked_ticks: 100,
            scenario_timeout_factor: 2.0,
            progress_lateral_m: 6.0,
            progress_step_cap_m: 20.0,
            penalties: Penalties::default(),
            distance_grace: 1.10,
            time_grace: 1.50,
            distance_weight: 0.7,
            time_weight: 0.3,
            fallback_reference_speed_mps: 5.56,
            carla: CarlaPenalties::default(),
        }
    }
}

impl ScoreParams {
    /// Consecutive off-road ticks that make the timeout. The original measures the time from
    /// the first off-road sample (`t − t_first ≥ 1.5 s`), so it ends on the sample n + 1 where n
    /// is the smallest count with n·dt ≥ timeout: the 31st off-road tick at the protocol values.
    /// A tiny tolerance absorbs 1.5/0.05 = 29.999…
    pub fn offroad_timeout_ticks(&self) -> u64 {
        let n = (self.offroad_timeout_s / self.dt_s - 1e-9).ceil();
        if n.is_finite() && n >= 0.0 {
            n as u64 + 1
        } else {
            1
        }
    }

    /// Checks every value is finite and in range; names the first bad field.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |field: &str, v: f64, msg: &str| Err(crate::Error::config(field, v, msg));
        let positive = [
            ("dt_s", self.dt_s),
            ("offroad_timeout_s", self.offroad_timeout_s),
            ("destination_radius_m", self.destination_radius_m),
            ("blocked_speed_kmh", self.blocked_speed_kmh),
            ("scenario_timeout_factor", self.scenario_timeout_factor),
            ("progress_lateral_m", self.progress_lateral_m),
            ("progress_step_cap_m", self.progress_step_cap_m),
            ("fallback_reference_speed_mps", self.fallback_reference_speed_mps),
        ];
        for (f, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(f, v, "must be a finite number > 0");
            }
        }
        let non_negative = [
            ("distance_grace", self.distance_grace),
            ("time_grace", self.time_grace),
            ("distance_weight", self.distance_weight),
            ("time_weight", self.time_weight),
        ];
        for (f, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return bad(f, v, "must be a finite number ≥ 0");
            }
        }
        let p = &self.penalties;
        let c = &self.carla;
        let unit = [
            ("penalties.collision_pedestrian", p.collision_pedestrian),
            ("penalties.collision_vehicle", p.collision_vehicle),
            ("penalties.collision_static", p.collision_static),
            ("penalties.scenario_timeout", p.scenario_timeout),
            ("penalties.blocked_timeout", p.blocked_timeout),
            ("penalties.offroad_timeout", p.offroad_timeout),
            ("penalties.manual_interrupt", p.manual_interrupt),
            ("penalties.system_error", p.system_error),
            ("carla.collision_pedestrian", c.collision_pedestrian),
            ("carla.collision_vehicle", c.collision_vehicle),
            ("carla.collision_static", c.collision_static),
            ("carla.red_light", c.red_light),
            ("carla.stop_sign", c.stop_sign),
            ("carla.scenario_timeout", c.scenario_timeout),
        ];
        for (f, v) in unit {
            if !(0.0..=1.0).contains(&v) {
                return bad(f, v, "a penalty multiplier must lie in [0, 1]");
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_the_protocol() {
        let p = ScoreParams::default();
        assert_eq!(p.dt_s, 0.05);
        assert_eq!(p.offroad_timeout_s, 1.5);
        assert_eq!(p.offroad_timeout_ticks(), 31);
        assert_eq!(p.destination_radius_m, 8.0);
        assert_eq!(p.blocked_speed_kmh, 1.0);
        assert_eq!(p.blocked_ticks, 100);
        assert_eq!(p.scenario_timeout_factor, 2.0);
        assert_eq!(p.progress_lateral_m, 6.0);
        assert_eq!(p.progress_step_cap_m, 20.0);
        assert_eq!(
            p.penalties,
            Penalties {
                collision_pedestrian: 0.0,
                collision_vehicle: 0.2,
                collision_static: 0.3,
                scenario_timeout: 0.7,
                blocked_timeout: 0.7,
                offroad_timeout: 0.0,
                manual_interrupt: 0.0,
                system_error: 0.0,
            }
        );
        assert_eq!((p.distance_grace, p.time_grace), (1.10, 1.50));
        assert_eq!((p.distance_weight, p.time_weight), (0.7, 0.3));
        assert_eq!(p.fallback_reference_speed_mps, 5.56);
        assert_eq!(
            p.carla,
            CarlaPenalties {
                collision_pedestrian: 0.50,
                collision_vehicle: 0.60,
                collision_static: 0.65,
                red_light: 0.70,
                stop_sign: 0.80,
                scenario_timeout: 0.70,
            }
        );
        assert!(p.validate().is_ok());
    }

    #[test]
    fn validation_names_the_field() {
        let mut p = ScoreParams { dt_s: f64::NAN, ..ScoreParams::default() };
        assert!(p.validate().unwrap_err().to_string().contains("dt_s"));
        p.dt_s = 0.05;
        p.penalties.collision_vehicle = 1.5;
        assert!(p.validate().unwrap_err().to_string().contains("penalties.collision_vehicle"));
        let p: Result<ScoreParams, _> = serde_json::from_str(r#"{"dt":0.1}"#);
        assert!(p.is_err(), "unknown keys are rejected");
        let p: ScoreParams = serde_json::from_str(r#"{"offroad_timeout_s":1.0}"#).unwrap();
        assert_eq!(p.offroad_timeout_ticks(), 21);
        assert_eq!(p.blocked_ticks, 100);
    }
}
