//! Per-tick score accumulator: travel, off-road time, route progress, events and termination
//! (PROTOCOL.md §2.4–2.5).
//!
//! Order inside one [`ScoreTracker::update`] (documented because results depend on it):
//! 1. tick count += 1; time = ticks × dt (counted, never summed as floats);
//! 2. travel += |position − previous position| (the first tick measures from the start);
//! 3. off-road bookkeeping: off-road ticks and the continuous off-road run;
//! 4. progress: if on-road and |lateral| ≤ 6 m, progress = min(projection, best + 20),
//!    best = max(best, progress);
//! 5. destination: within 8 m (≤) of it → best = L (so the same tick's checks see it);
//! 6. slow-tick run (speed·3.6 < 1 km/h), counted from the first tick;
//! 7. red-light / stop-sign infractions become (non-terminating) events;
//! 8. termination, first match wins: external stop (system error, manual interrupt) →
//!    collision (pedestrian, then vehicle, then static, over all of this tick's contacts) →
//!    off-road run ≥ 30 ticks (1.5 s) → destination reached → slow run > 100 ticks →
//!    time ≥ 2·T_ref. The terminating event (all but destination_reached) is recorded.
//!
//! After termination further updates change nothing and return the same termination.
//! A non-finite position or speed terminates the run with `system_error`.

use super::event::{Contact, Event, EventKind, ExternalStop, Termination, TerminationReason, TickInput};
use super::params::ScoreParams;
use super::record::{
    CarlaDialect, Dialects, Location, RunInfo, SceneMeta, SceneScore, Status, PROTOCOL_VERSION,
};
use crate::geom::{Polyline, Vec2};
use crate::view::ContactClass;
use serde_json::{Map, Value};

#[derive(Debug, Clone)]
pub struct ScoreTracker {
    params: ScoreParams,
    route: Polyline,
    route_length: f64,
    destination: Vec2,
    reference_duration_s: f64,
    reference_from_scenario: bool,
    offroad_timeout_ticks: u64,

    ticks: u64,
    position: Vec2,
    travel_m: f64,
    offroad_travel_m: f64,
    offroad_ticks: u64,
    offroad_run: u64,
    slow_run: u64,
    best_m: f64,
    events: Vec<Event>,
    termination: Option<Termination>,
}

impl ScoreTracker {
    /// `route`: the reference polyline (its length is L); `start`: ego centre at t = 0;
    /// `reference_duration_s`: the scenario's T_ref for the ego (`None` → L / 5.56 m/s).
    pub fn new(
        route: Polyline,
        start: Vec2,
        destination: Vec2,
        reference_duration_s: Option<f64>,
        params: ScoreParams,
    ) -> crate::Result<Self> {
        params.validate()?;
        let route_length = route.length();
        if route.len() < 2 || !(route_length.is_finite() && route_length > 0.0) {
            return Err(crate::Error::config(
                "route",
                format!("{} points, length {route_length}", route.len()),
                "the scoring route needs at least two distinct finite points",
            ));
        }
        if !start.is_finite() {
            return Err(crate::Error::config("start", format!("{start:?}"), "must be finite"));
        }
        if !destination.is_finite() {
            return Err(crate::Error::config("destination", format!("{destination:?}"), "must be finite"));
        }
        let (reference_duration_s, reference_from_scenario) = match reference_duration_s {
            Some(t) if t.is_finite() && t > 0.0 => (t, true),
            Some(t) => {
                return Err(crate::Error::config(
                    "reference_duration_s",
                    t,
                    "must be a finite number > 0 (or absent for the L / 5.56 m/s fallback)",
                ))
            }
            None => (route_length / params.fallback_reference_speed_mps, false),
        };
        Ok(Self {
            offroad_timeout_ticks: params.offroad_timeout_ticks(),
            params,
            route,
            route_length,
            destination,
            reference_duration_s,
            reference_from_scenario,
            ticks: 0,
            position: start,
            travel_m: 0.0,
            offroad_travel_m: 0.0,
            offroad_ticks: 0,
            offroad_run: 0,
            slow_run: 0,
            best_m: 0.0,
            events: Vec::new(),
            termination: None,
        })
    }

    pub fn params(&self) -> &ScoreParams {
        &self.params
    }
    pub fn ticks(&self) -> u64 {
        self.ticks
    }
    /// Sim time after the last update, seconds.
    pub fn time_s(&self) -> f64 {
        self.ticks as f64 * self.params.dt_s
    }
    pub fn route_length_m(&self) -> f64 {
        self.route_length
    }
    /// Best progress so far (L once the destination was reached).
    pub fn best_progress_m(&self) -> f64 {
        self.best_m
    }
    pub fn travel_m(&self) -> f64 {
        self.travel_m
    }
    pub fn offroad_time_s(&self) -> f64 {
        self.offroad_ticks as f64 * self.params.dt_s
    }
    /// T_ref in use (the scenario's, else the fallback).
    pub fn reference_duration_s(&self) -> f64 {
        self.reference_duration_s
    }
    pub fn events(&self) -> &[Event] {
        &self.events
    }
    pub fn termination(&self) -> Option<Termination> {
        self.termination
    }

    /// S_route so far: 100 once terminated by `destination_reached`, else clip(100·best/L).
    pub fn route_score(&self) -> f64 {
        if self.termination.is_some_and(|t| t.reason == TerminationReason::DestinationReached) {
            100.0
        } else {
            (100.0 * self.best_m / self.route_length).clamp(0.0, 100.0)
        }
    }

    /// Accounts one tick (see the module doc for the order) and returns the termination, if
    /// the run ends at this tick or ended before.
    pub fn update(&mut self, tick: &TickInput<'_>) -> Option<Termination> {
        if self.termination.is_some() {
            return self.termination;
        }
        self.ticks += 1;
        let time_s = self.time_s();
        let p = &self.params;

        if !tick.position.is_finite() || !tick.speed_mps.is_finite() {
            let mut d = Map::new();
            d.insert("message".into(), Value::from("non-finite ego position or speed"));
            return Some(self.terminate(TerminationReason::SystemError, time_s, d));
        }

        let step = tick.position.dist(self.position);
        self.travel_m += step;
        self.position = tick.position;

        if tick.on_road {
            self.offroad_run = 0;
        } else {
            self.offroad_travel_m += step;
            self.offroad_ticks += 1;
            self.offroad_run += 1;
        }

        if tick.on_road {
            if let Some(proj) = self.route.project(tick.position) {
                if proj.distance <= p.progress_lateral_m {
                    let progress = proj.s.min(self.best_m + p.progress_step_cap_m);
                    self.best_m = self.best_m.max(progress);
                }
            }
        }

        let to_destination = tick.position.dist(self.destination);
        let at_destination = to_destination <= p.destination_radius_m;
        if at_destination {
            self.best_m = self.route_length;
        }

        if tick.speed_mps * 3.6 < p.blocked_speed_kmh {
            self.slow_run += 1;
        } else {
            self.slow_run = 0;
        }

        for (flag, kind) in
            [(tick.red_light, EventKind::RedLightViolation), (tick.stop_sign, EventKind::StopSignViolation)]
        {
            if flag {
                let details = self.location_details();
                self.events.push(Event {
                    kind,
                    time_s,
                    details,
                    penalty_multiplier: kind.penalty(&p.penalties),
                });
            }
        }

        let mut details = Map::new();
        let reason = if let Some(stop) = tick.stop {
            match stop {
                ExternalStop::SystemError => TerminationReason::SystemError,
                ExternalStop::ManualInterrupt => TerminationReason::ManualInterrupt,
            }
        } else if let Some(class) = most_severe(tick.contacts) {
            // The first contact of the most severe class is the collision; all are listed.
            if let Some(c) = tick.contacts.iter().find(|c| c.class == class) {
                details.insert("other_actor_id".into(), Value::from(c.actor_id));
            }
            details.insert("other_class".into(), serde_json::to_value(class).unwrap_or(Value::Null));
            let all: Vec<Value> = tick.contacts.iter().map(contact_value).collect();
            details.insert("contacts".into(), Value::Array(all));
            TerminationReason::collision(class)
        } else if self.offroad_run >= self.offroad_timeout_ticks {
            details.insert("offroad_continuous_time".into(), Value::from(self.offroad_run as f64 * p.dt_s));
            TerminationReason::OffroadTimeout
        } else if at_destination {
            TerminationReason::DestinationReached
        } else if self.slow_run > p.blocked_ticks {
            details.insert("blocked_ticks".into(), Value::from(self.slow_run));
            TerminationReason::BlockedTimeout
        } else if time_s >= p.scenario_timeout_factor * self.reference_duration_s {
            details.insert(
                "time_limit".into(),
                Value::from(p.scenario_timeout_factor * self.reference_duration_s),
            );
            TerminationReason::ScenarioTimeout
        } else {
            return None;
        };
        Some(self.terminate(reason, time_s, details))
    }

    fn location_details(&self) -> Map<String, Value> {
        let mut d = Map::new();
        d.insert("x".into(), Value::from(self.position.x));
        d.insert("y".into(), Value::from(self.position.y));
        d
    }

    fn terminate(
        &mut self,
        reason: TerminationReason,
        time_s: f64,
        extra: Map<String, Value>,
    ) -> Termination {
        if let Some(kind) = EventKind::for_termination(reason) {
            let mut details = if self.position.is_finite() { self.location_details() } else { Map::new() };
            details.extend(extra);
            let penalty_multiplier = kind.penalty(&self.params.penalties);
            self.events.push(Event { kind, time_s, details, penalty_multiplier });
        }
        let t = Termination { reason, tick: self.ticks, time_s };
        self.termination = Some(t);
        t
    }

    /// Ends the run from outside between ticks (e.g. the user stops it); no-op once ended.
    pub fn stop(&mut self, stop: ExternalStop) -> Termination {
        if let Some(t) = self.termination {
            return t;
        }
        let reason = match stop {
            ExternalStop::SystemError => TerminationReason::SystemError,
            ExternalStop::ManualInterrupt => TerminationReason::ManualInterrupt,
        };
        self.terminate(reason, self.time_s(), Map::new())
    }

    /// The score record of the run so far. Without a termination the reason is `incomplete`.
    pub fn finish(&self, info: &RunInfo) -> SceneScore {
        let p = &self.params;
        let l = self.route_length;
        let reason = self.termination.map_or(TerminationReason::Incomplete, |t| t.reason);
        let reached = reason == TerminationReason::DestinationReached;
        let duration = self.time_s();

        let score_route = self.route_score();
        let penalty_product: f64 = self.events.iter().map(|e| e.penalty_multiplier).product();
        let offroad_time = self.offroad_time_s();
        let offroad_ratio = if duration > 0.0 { offroad_time / duration } else { 0.0 };
        let score_safety = (penalty_product * (1.0 - offroad_ratio)).clamp(0.0, 1.0);
        // No travel or no time: nothing was wasted, so the ratio counts as 1.
        let distance_efficiency =
            if self.travel_m > 0.0 { (p.distance_grace * l / self.travel_m).min(1.0) } else { 1.0 };
        let time_efficiency =
            if duration > 0.0 { (p.time_grace * self.reference_duration_s / duration).min(1.0) } else { 1.0 };
        let score_efficiency = p.distance_weight * distance_efficiency + p.time_weight * time_efficiency;
        let score_penalty = score_safety * score_efficiency;
        let score_composed = score_route * score_safety * score_efficiency;
        let status = if !reached {
            Status::Failed
        } else if score_composed >= 100.0 - 1e-9 {
            Status::Perfect
        } else {
            Status::Completed
        };

        SceneScore {
            scene_id: info.scene_id.clone(),
            status,
            termination_reason: reason,
            score_route,
            score_safety,
            score_efficiency,
            score_penalty,
            score_composed,
            events: self.events.clone(),
            meta: SceneMeta {
                route_length: l,
                completed_distance: self.best_m,
                travel_distance: self.travel_m,
                offroad_time,
                offroad_ratio,
                sim_duration: duration,
                wall_duration: info.wall_duration_s,
                reference_duration: self.reference_duration_s,
                reference_duration_source: if self.reference_from_scenario { "scenario" } else { "fallback" }
                    .to_owned(),
                distance_efficiency,
                time_efficiency,
                destination_radius: p.destination_radius_m,
                last_location: Location { x: self.position.x, y: self.position.y },
                penalty_product,
            },
            protocol_version: PROTOCOL_VERSION.to_owned(),
            ticks: self.ticks,
            decisions: info.decisions,
            parse_failures: info.parse_failures,
            dialects: Dialects { carla: self.carla_dialect(score_route) },
        }
    }

    fn carla_dialect(&self, route_completion: f64) -> CarlaDialect {
        let c = &self.params.carla;
        let count = |k: EventKind| self.events.iter().filter(|e| e.kind == k).count() as u32;
        let n = [
            (count(EventKind::CollisionPedestrian), c.collision_pedestrian),
            (count(EventKind::CollisionVehicle), c.collision_vehicle),
            (count(EventKind::CollisionStatic), c.collision_static),
            (count(EventKind::RedLightViolation), c.red_light),
            (count(EventKind::StopSignViolation), c.stop_sign),
            (count(EventKind::ScenarioTimeout), c.scenario_timeout),
        ];
        let infraction_penalty: f64 = n.iter().map(|&(k, m)| m.powi(k as i32)).product();
        let offroad_fraction =
            if self.travel_m > 0.0 { (self.offroad_travel_m / self.travel_m).clamp(0.0, 1.0) } else { 0.0 };
        CarlaDialect {
            driving_score: route_completion * infraction_penalty * (1.0 - offroad_fraction),
            route_completion,
            infraction_penalty,
            offroad_fraction,
            collisions_pedestrian: n[0].0,
            collisions_vehicle: n[1].0,
            collisions_static: n[2].0,
            red_light_infractions: n[3].0,
            stop_sign_infractions: n[4].0,
            scenario_timeouts: n[5].0,
        }
    }
}

fn most_severe(contacts: &[Contact]) -> Option<ContactClass> {
    [ContactClass::Pedestrian, ContactClass::Vehicle, ContactClass::Static]
        .into_iter()
        .find(|class| contacts.iter().any(|c| c.class == *class))
}

fn contact_value(c: &Contact) -> Value {
    serde_json::to_value(c).unwrap_or(Value::Null)
}
