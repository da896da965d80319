//! Events, termination reasons and the per-tick inputs they come from.

use crate::view::ContactClass;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

/// Why a run ended. Serialised in snake_case, as in the original `termination_reason`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TerminationReason {
    CollisionPedestrian,
    CollisionVehicle,
    CollisionStatic,
    OffroadTimeout,
    DestinationReached,
    BlockedTimeout,
    ScenarioTimeout,
    ManualInterrupt,
    SystemError,
    /// Ours: the record was written before any protocol termination (a truncated run).
    Incomplete,
}

impl TerminationReason {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::CollisionPedestrian => "collision_pedestrian",
            Self::CollisionVehicle => "collision_vehicle",
            Self::CollisionStatic => "collision_static",
            Self::OffroadTimeout => "offroad_timeout",
            Self::DestinationReached => "destination_reached",
            Self::BlockedTimeout => "blocked_timeout",
            Self::ScenarioTimeout => "scenario_timeout",
            Self::ManualInterrupt => "manual_interrupt",
            Self::SystemError => "system_error",
            Self::Incomplete => "incomplete",
        }
    }

    /// The collision reason for a contact class.
    pub fn collision(class: ContactClass) -> Self {
        match class {
            ContactClass::Pedestrian => Self::CollisionPedestrian,
            ContactClass::Vehicle => Self::CollisionVehicle,
            ContactClass::Static => Self::CollisionStatic,
        }
    }
}

/// Kinds of recorded events, named as the original's `scene_score.json` names them. The
/// terminating ones carry the protocol penalty (`destination_reached` carries none); the two
/// traffic-rule infractions are ours (multiplier 1 in the protocol score, used by the CARLA
/// dialect only).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EventKind {
    CollisionPedestrian,
    CollisionVehicle,
    CollisionStatic,
    /// The off-road timeout (the termination reason stays `offroad_timeout`).
    RouteDeviation,
    DestinationReached,
    BlockedTimeout,
    ScenarioTimeout,
    ManualInterrupt,
    SystemError,
    RedLightViolation,
    StopSignViolation,
}

impl EventKind {
    /// Event recorded when a run terminates for `reason` (none for an unfinished run).
    pub fn for_termination(reason: TerminationReason) -> Option<EventKind> {
        Some(match reason {
            TerminationReason::CollisionPedestrian => Self::CollisionPedestrian,
            TerminationReason::CollisionVehicle => Self::CollisionVehicle,
            TerminationReason::CollisionStatic => Self::CollisionStatic,
            TerminationReason::OffroadTimeout => Self::RouteDeviation,
            TerminationReason::DestinationReached => Self::DestinationReached,
            TerminationReason::BlockedTimeout => Self::BlockedTimeout,
            TerminationReason::ScenarioTimeout => Self::ScenarioTimeout,
            TerminationReason::ManualInterrupt => Self::ManualInterrupt,
            TerminationReason::SystemError => Self::SystemError,
            TerminationReason::Incomplete => return None,
        })
    }

    /// Protocol safety multiplier of this event; `None` for `destination_reached`, which the
    /// original records without one.
    pub fn penalty(self, p: &super::params::Penalties) -> Option<f64> {
        Some(match self {
            Self::CollisionPedestrian => p.collision_pedestrian,
            Self::CollisionVehicle => p.collision_vehicle,
            Self::CollisionStatic => p.collision_static,
            Self::RouteDeviation => p.offroad_timeout,
            Self::BlockedTimeout => p.blocked_timeout,
            Self::ScenarioTimeout => p.scenario_timeout,
            Self::ManualInterrupt => p.manual_interrupt,
            Self::SystemError => p.system_error,
            Self::RedLightViolation | Self::StopSignViolation => 1.0,
            Self::DestinationReached => return None,
        })
    }
}

/// One entry of `events[]`: `{"type", "time", <details…>, "penalty_multiplier"?}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    #[serde(rename = "type")]
    pub kind: EventKind,
    /// Sim time of the tick the event happened in, seconds (rounded to 3 decimals in records,
    /// as the original writes it).
    #[serde(rename = "time")]
    pub time_s: f64,
    #[serde(flatten)]
    pub details: Map<String, Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub penalty_multiplier: Option<f64>,
}

/// A contact of the ego during one tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Contact {
    pub actor_id: u32,
    pub class: ContactClass,
}

/// A run stopped from outside the protocol's own conditions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ExternalStop {
    ManualInterrupt,
    SystemError,
}

/// How and when a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Termination {
    pub reason: TerminationReason,
    /// Tick index (1-based) of the terminating tick.
    pub tick: u64,
    pub time_s: f64,
}

/// What the world reports about the ego after one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TickInput<'a> {
    /// Ego centre, world frame, metres.
    pub position: crate::geom::Vec2,
    pub speed_mps: f64,
    /// Ego centre inside some drivable lane.
    pub on_road: bool,
    /// Every actor touching the ego during this tick.
    pub contacts: &'a [Contact],
    /// The ego ran a red light / a stop sign during this tick (if the world detects it).
    pub red_light: bool,
    pub stop_sign: bool,
    /// Set when the run is being stopped from outside (user, crash of a component).
    pub stop: Option<ExternalStop>,
}

impl<'a> TickInput<'a> {
    /// A plain tick: no contacts, infractions or stop request.
    pub fn new(position: crate::geom::Vec2, speed_mps: f64, on_road: bool) -> Self {
        Self { position, speed_mps, on_road, contacts: &[], red_light: false, stop_sign: false, stop: None }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn event_serialises_like_the_original() {
        let mut details = Map::new();
        details.insert("other_actor_id".into(), Value::from(7));
        let e =
            Event { kind: EventKind::CollisionVehicle, time_s: 3.5, details, penalty_multiplier: Some(0.2) };
        let s = serde_json::to_string(&e).unwrap();
        assert_eq!(
            s,
            r#"{"type":"collision_vehicle","time":3.5,"other_actor_id":7,"penalty_multiplier":0.2}"#
        );
        let back: Event = serde_json::from_str(&s).unwrap();
        assert_eq!(back, e);
    }

    #[test]
    fn names_and_penalties() {
        let p = super::super::params::Penalties::default();
        // (reason, event type of the original, its multiplier)
        let all = [
            (TerminationReason::CollisionPedestrian, Some("collision_pedestrian"), Some(0.0)),
            (TerminationReason::CollisionVehicle, Some("collision_vehicle"), Some(0.2)),
            (TerminationReason::CollisionStatic, Some("collision_static"), Some(0.3)),
            (TerminationReason::OffroadTimeout, Some("route_deviation"), Some(0.0)),
            (TerminationReason::DestinationReached, Some("destination_reached"), None),
            (TerminationReason::BlockedTimeout, Some("blocked_timeout"), Some(0.7)),
            (TerminationReason::ScenarioTimeout, Some("scenario_timeout"), Some(0.7)),
            (TerminationReason::ManualInterrupt, Some("manual_interrupt"), Some(0.0)),
            (TerminationReason::SystemError, Some("system_error"), Some(0.0)),
            (TerminationReason::Incomplete, None, None),
        ];
        for (r, name, pen) in all {
            assert_eq!(serde_json::to_value(r).unwrap(), Value::from(r.as_str()));
            let kind = EventKind::for_termination(r);
            assert_eq!(kind.and_then(|k| k.penalty(&p)), pen);
            assert_eq!(kind.map(|k| serde_json::to_value(k).unwrap()), name.map(Value::from));
        }
        assert_eq!(EventKind::RedLightViolation.penalty(&p), Some(1.0));
        let d = Event {
            kind: EventKind::DestinationReached,
            time_s: 9.2,
            details: Map::new(),
            penalty_multiplier: None,
        };
        assert_eq!(serde_json::to_string(&d).unwrap(), r#"{"type":"destination_reached","time":9.2}"#);
    }
}
