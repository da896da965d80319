//! Per-tick score accumulator: travel, off-road time, route progress, events and termination
//! (docs/protocol.md#r4-termination, #r4-scene-score).
//!
//! It follows the original's `SceneScoreTracker` and runner loop, sample by sample. The state
//! at t = 0 is sample 0 (given at construction); each tick adds one sample. Order inside one
//! [`ScoreTracker::update`] (documented because results depend on it):
//! 1. tick count += 1; time = ticks × dt (counted, never summed as floats);
//! 2. travel += |position − previous position| (the first tick measures from the start);
//!    off-road time += dt when the *previous* sample was off-road (the original accounts each
//!    interval by the state at its start);
//! 3. the continuous off-road run (consecutive off-road samples);
//! 4. progress: if on-road, the distance to the route is remembered (`last_route_distance_m`)
//!    and, if ≤ 6 m, progress = min(projection, best + 20), best = max(best, progress);
//! 5. destination: within 8 m (≤) of it → best = L (so the same tick's checks see it);
//! 6. slow-tick run (speed·3.6 < 1 km/h), counted from the first tick;
//! 7. red-light / stop-sign infractions become (non-terminating) events;
//! 8. termination, first match wins: external stop (system error, manual interrupt) →
//!    collision (pedestrian, then vehicle, then static, over all of this tick's contacts) →
//!    off-road for ≥ 1.5 s since the first off-road sample (the 31st consecutive off-road
//!    tick; off-road time becomes max(off-road time, that duration)) → destination reached →
//!    slow run > 100 ticks → time ≥ 2 × the scenario duration. The terminating event is
//!    recorded with the original's type and keys.
//!
//! After termination further updates change nothing and return the same termination.
//! A non-finite position or speed terminates the run with `system_error`.

use super::event::{Contact, Event, EventKind, ExternalStop, Termination, TerminationReason, TickInput};
use super::params::ScoreParams;
use super::record::{
    round_to, CarlaDialect, Dialects, Location, RunInfo, SceneMeta, SceneScore, Status, PROTOCOL_VERSION,
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
    scenario_duration_s: f64,
    offroad_timeout_ticks: u64,

    ticks: u64,
    position: Vec2,
    last_on_road: bool,
    travel_m: f64,
    offroad_travel_m: f64,
    /// Intervals that started off-road (the original's off-road time, in ticks).
    offroad_intervals: u64,
    /// Set by the off-road timeout: max(accumulated, continuous off-road duration).
    offroad_time_override: Option<f64>,
    offroad_run: u64,
    slow_run: u64,
    best_m: f64,
    last_route_distance: Option<f64>,
    events: Vec<Event>,
    termination: Option<Termination>,
}

/// Nominal ego mass for the collision `intensity` (N·s). Our world is kinematic and has no
/// impulses; the record carries the ego's momentum at contact in the original's field.
pub const NOMINAL_EGO_MASS_KG: f64 = 1500.0;

impl ScoreTracker {
    /// `route`: the reference polyline (its length is L); `start`: ego centre at t = 0;
    /// `reference_duration_s`: the scenario's T_ref for the ego (`None` → L / 5.56 m/s). The
    /// scenario duration defaults to T_ref and the start to on-road; see
    /// [`with_scenario_duration`](Self::with_scenario_duration) and
    /// [`with_start_on_road`](Self::with_start_on_road).
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
        let mut t = Self {
            offroad_timeout_ticks: params.offroad_timeout_ticks(),
            params,
            route,
            route_length,
            destination,
            reference_duration_s,
            reference_from_scenario,
            scenario_duration_s: reference_duration_s,
            ticks: 0,
            position: start,
            last_on_road: true,
            travel_m: 0.0,
            offroad_travel_m: 0.0,
            offroad_intervals: 0,
            offroad_time_override: None,
            offroad_run: 0,
            slow_run: 0,
            best_m: 0.0,
            last_route_distance: None,
            events: Vec::new(),
            termination: None,
        };
        t.track_progress(start);
        Ok(t)
    }

    /// Sets the scenario duration (the scenario timeout is `factor ×` it); `None` keeps T_ref.
    pub fn with_scenario_duration(mut self, scenario_duration_s: Option<f64>) -> crate::Result<Self> {
        match scenario_duration_s {
            Some(d) if d.is_finite() && d > 0.0 => self.scenario_duration_s = d,
            Some(d) => {
                return Err(crate::Error::config(
                    "scenario_duration_s",
                    d,
                    "must be a finite number > 0 (or absent for the reference duration)",
                ))
            }
            None => {}
        }
        Ok(self)
    }

    /// Whether sample 0 (the start) is on the road: it decides whether the first interval
    /// counts as off-road time and whether the start's projection counts as progress.
    pub fn with_start_on_road(mut self, on_road: bool) -> Self {
        self.last_on_road = on_road;
        self.best_m = 0.0;
        self.last_route_distance = None;
        if on_road {
            self.track_progress(self.position);
        }
        self
    }

    fn track_progress(&mut self, position: Vec2) {
        if let Some(proj) = self.route.project(position) {
            self.last_route_distance = Some(proj.distance);
            if proj.distance <= self.params.progress_lateral_m {
                let progress = proj.s.min(self.best_m + self.params.progress_step_cap_m);
                self.best_m = self.best_m.max(progress);
            }
        }
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
    /// Off-road time as the original accounts it.
    pub fn offroad_time_s(&self) -> f64 {
        let accumulated = self.offroad_intervals as f64 * self.params.dt_s;
        self.offroad_time_override.map_or(accumulated, |d| accumulated.max(d))
    }
    /// The scenario duration (the timeout is `scenario_timeout_factor ×` it).
    pub fn scenario_duration_s(&self) -> f64 {
        self.scenario_duration_s
    }
    /// Sim time at which the scenario timeout fires.
    pub fn max_sim_time_s(&self) -> f64 {
        self.params.scenario_timeout_factor * self.scenario_duration_s
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

        if !tick.position.is_finite() || !tick.speed_mps.is_finite() {
            let mut d = Map::new();
            d.insert("error".into(), Value::from("non-finite ego position or speed"));
            return Some(self.terminate(TerminationReason::SystemError, time_s, d));
        }

        let step = tick.position.dist(self.position);
        self.travel_m += step;
        self.position = tick.position;
        if !self.last_on_road {
            self.offroad_intervals += 1;
            self.offroad_travel_m += step;
        }
        self.last_on_road = tick.on_road;

        if tick.on_road {
            self.offroad_run = 0;
            self.track_progress(tick.position);
        } else {
            self.offroad_run += 1;
        }

        let p = &self.params;
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
                ExternalStop::SystemError => {
                    details.insert("error".into(), Value::from("stopped by the runner (system error)"));
                    TerminationReason::SystemError
                }
                ExternalStop::ManualInterrupt => TerminationReason::ManualInterrupt,
            }
        } else if let Some(class) = most_severe(tick.contacts) {
            // The first contact of the most severe class is the collision; all are listed.
            let first = tick.contacts.iter().find(|c| c.class == class);
            let id = first.map_or(0, |c| c.actor_id);
            details.insert("other_actor".into(), Value::from(carla_type_id(class, id)));
            details
                .insert("intensity".into(), Value::from(round_to(NOMINAL_EGO_MASS_KG * tick.speed_mps, 3)));
            details.insert("other_actor_id".into(), Value::from(id));
            details.insert("other_class".into(), serde_json::to_value(class).unwrap_or(Value::Null));
            let all: Vec<Value> = tick.contacts.iter().map(contact_value).collect();
            details.insert("contacts".into(), Value::Array(all));
            TerminationReason::collision(class)
        } else if self.offroad_run >= self.offroad_timeout_ticks {
            // Time since the first off-road sample.
            let duration = (self.offroad_run - 1) as f64 * p.dt_s;
            self.offroad_time_override = Some(duration);
            details.insert("offroad_duration".into(), Value::from(round_to(duration, 3)));
            TerminationReason::OffroadTimeout
        } else if at_destination {
            details.insert("destination_radius".into(), Value::from(round_to(p.destination_radius_m, 3)));
            TerminationReason::DestinationReached
        } else if self.slow_run > p.blocked_ticks {
            details.insert("blocked_steps".into(), Value::from(self.slow_run));
            details.insert("speed_kmh".into(), Value::from(round_to(tick.speed_mps * 3.6, 3)));
            details.insert("speed_threshold_kmh".into(), Value::from(round_to(p.blocked_speed_kmh, 3)));
            TerminationReason::BlockedTimeout
        } else if time_s >= self.max_sim_time_s() {
            details.insert("max_sim_time".into(), Value::from(round_to(self.max_sim_time_s(), 3)));
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
        details: Map<String, Value>,
    ) -> Termination {
        if let Some(kind) = EventKind::for_termination(reason) {
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
        let mut details = Map::new();
        let reason = match stop {
            ExternalStop::SystemError => {
                details.insert("error".into(), Value::from("stopped by the runner (system error)"));
                TerminationReason::SystemError
            }
            ExternalStop::ManualInterrupt => TerminationReason::ManualInterrupt,
        };
        self.terminate(reason, self.time_s(), details)
    }

    /// The score record of the run so far, computed and rounded exactly as the original's
    /// `SceneScoreTracker.finalize`. Without a termination the reason is `incomplete`.
    pub fn finish(&self, info: &RunInfo) -> SceneScore {
        const TOL: f64 = 1e-6;
        let p = &self.params;
        let l = self.route_length;
        let reason = self.termination.map_or(TerminationReason::Incomplete, |t| t.reason);
        let duration = self.time_s();

        let route = round_to(self.route_score(), 6);
        let penalty_product: f64 = self.events.iter().filter_map(|e| e.penalty_multiplier).product();
        let offroad_time = self.offroad_time_s();
        let (offroad_ratio, lane_keep) = if duration > TOL {
            let r = (offroad_time / duration).clamp(0.0, 1.0);
            (r, 1.0 - r)
        } else {
            (0.0, 1.0)
        };
        let safety = round_to((penalty_product * lane_keep).clamp(0.0, 1.0), 6);
        let distance_reference = l * p.distance_grace;
        let distance_efficiency =
            if self.travel_m <= distance_reference + TOL { 1.0 } else { distance_reference / self.travel_m }
                .clamp(0.0, 1.0);
        let duration_reference = self.reference_duration_s * p.time_grace;
        let time_efficiency =
            if self.reference_duration_s <= TOL || duration <= TOL || duration <= duration_reference + TOL {
                1.0
            } else {
                duration_reference / duration
            }
            .clamp(0.0, 1.0);
        let efficiency = round_to(
            (p.distance_weight * distance_efficiency + p.time_weight * time_efficiency).clamp(0.0, 1.0),
            6,
        );
        let penalty = round_to((safety * efficiency).max(0.0), 6);
        let composed = round_to((route * penalty).max(0.0), 6);
        let success = route >= 100.0 && reason == TerminationReason::DestinationReached;
        let status = if !success {
            Status::Failed
        } else if safety >= 0.999999 && efficiency >= 0.999999 {
            Status::Perfect
        } else {
            Status::Completed
        };
        let events =
            self.events.iter().map(|e| Event { time_s: round_to(e.time_s, 3), ..e.clone() }).collect();

        SceneScore {
            scene_id: info.scene_id.clone(),
            status,
            termination_reason: reason,
            score_route: route,
            score_safety: safety,
            score_efficiency: efficiency,
            score_penalty: penalty,
            score_composed: composed,
            events,
            meta: SceneMeta {
                route_source: "route_edges".to_owned(),
                route_length_m: round_to(l, 3),
                completed_distance_m: round_to(self.best_m, 3),
                travel_distance_m: round_to(self.travel_m, 3),
                offroad_time_s: round_to(offroad_time, 3),
                offroad_ratio: round_to(offroad_ratio, 6),
                lane_keep_penalty: round_to(lane_keep, 6),
                duration_game: round_to(duration, 3),
                duration_system: round_to(info.wall_duration_s, 3),
                reference_duration_s: round_to(self.reference_duration_s, 3),
                distance_efficiency: round_to(distance_efficiency, 6),
                time_efficiency: round_to(time_efficiency, 6),
                destination_radius: round_to(p.destination_radius_m, 3),
                last_route_distance_m: self.last_route_distance.map(|d| round_to(d, 3)),
                last_location: Location {
                    x: round_to(self.position.x, 3),
                    y: round_to(self.position.y, 3),
                    z: 0.0,
                },
                reference_duration_source: if self.reference_from_scenario { "scenario" } else { "fallback" }
                    .to_owned(),
                scenario_duration_s: self.scenario_duration_s,
                max_sim_time_s: self.max_sim_time_s(),
                penalty_product,
            },
            protocol_version: PROTOCOL_VERSION.to_owned(),
            ticks: self.ticks,
            decisions: info.decisions,
            parse_failures: info.parse_failures,
            dialects: Dialects { carla: self.carla_dialect(self.route_score()) },
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

/// A CARLA-style type id whose prefix the original's collision classifier reads
/// (`walker.` → pedestrian, `vehicle.` → vehicle, anything else → static).
fn carla_type_id(class: ContactClass, actor_id: u32) -> String {
    match class {
        ContactClass::Pedestrian => format!("walker.pedestrian.actor_{actor_id}"),
        ContactClass::Vehicle => format!("vehicle.actor_{actor_id}"),
        ContactClass::Static => format!("static.prop.actor_{actor_id}"),
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
