//! Ego vehicle parameters: read by the scenario schema (`[ego.vehicle]`) and by the world's
//! dynamics ([`crate::world::vehicle`]), so they live below both (no `scenario` ↔ `world` cycle).

use crate::{Error, Result};
use serde::{Deserialize, Serialize};

/// Ego vehicle parameters. Units are in the names; angles in degrees where noted.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct VehicleParams {
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub length_m: f64,
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub width_m: f64,
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub height_m: f64,
    /// Front-to-rear axle distance L.
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub wheelbase_m: f64,
    /// Rear axle to the reference point (vehicle centre), l_r.
    #[schemars(range(min = 0))]
    pub rear_axle_to_center_m: f64,
    /// Road-wheel angle at |steer| = 1.
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub max_steer_deg: f64,
    /// Full-throttle acceleration at standstill, m/s² (fades linearly to 0 at `max_speed_mps`).
    #[schemars(range(min = 0))]
    pub max_accel_mps2: f64,
    /// Full-brake deceleration, m/s².
    #[schemars(range(min = 0))]
    pub max_brake_mps2: f64,
    /// Constant rolling deceleration while moving, m/s².
    #[schemars(range(min = 0))]
    pub rolling_decel_mps2: f64,
    /// Aerodynamic drag coefficient: decel = drag · v², 1/m.
    #[schemars(range(min = 0))]
    pub drag_per_m: f64,
    /// Speed cap; speeds are clamped to [0, max] (no reverse).
    #[schemars(extend("exclusiveMinimum" = 0))]
    pub max_speed_mps: f64,
}

impl Default for VehicleParams {
    fn default() -> Self {
        Self {
            length_m: 4.9,
            width_m: 2.0,
            height_m: 1.5,
            wheelbase_m: 2.9,
            rear_axle_to_center_m: 1.45,
            max_steer_deg: 35.0,
            max_accel_mps2: 4.0,
            max_brake_mps2: 9.0,
            rolling_decel_mps2: 0.15,
            drag_per_m: 0.0005,
            max_speed_mps: 40.0,
        }
    }
}

impl VehicleParams {
    /// Rejects non-finite or non-positive geometry (named by field).
    pub fn validate(&self) -> Result<()> {
        let checks = [
            ("length_m", self.length_m),
            ("width_m", self.width_m),
            ("height_m", self.height_m),
            ("wheelbase_m", self.wheelbase_m),
            ("max_steer_deg", self.max_steer_deg),
            ("max_speed_mps", self.max_speed_mps),
        ];
        for (name, v) in checks {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::config(format!("vehicle.{name}"), v, "must be a finite number > 0"));
            }
        }
        let nonneg = [
            ("rear_axle_to_center_m", self.rear_axle_to_center_m),
            ("max_accel_mps2", self.max_accel_mps2),
            ("max_brake_mps2", self.max_brake_mps2),
            ("rolling_decel_mps2", self.rolling_decel_mps2),
            ("drag_per_m", self.drag_per_m),
        ];
        for (name, v) in nonneg {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::config(format!("vehicle.{name}"), v, "must be a finite number ≥ 0"));
            }
        }
        if self.rear_axle_to_center_m > self.wheelbase_m {
            return Err(Error::config(
                "vehicle.rear_axle_to_center_m",
                self.rear_axle_to_center_m,
                "must not exceed wheelbase_m",
            ));
        }
        Ok(())
    }
}
