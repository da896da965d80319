//! The R4 world and its tick pipeline (fixed [`DT_S`] = 0.05 s):
//!
//! 1. check and clamp the ego [`Control`];
//! 2. advance the ego (kinematic bicycle, [`vehicle`]);
//! 3. advance time;
//! 4. traffic lights ([`lights`]);
//! 5. scenario actors (triggers, scripted paths, brake events; [`scripted`]) in id order, except
//!    that an actor with a chained trigger steps after the actor it follows;
//! 6. collisions (rapier2d, [`collision`]);
//! 7. off-road test at the ego centre.
//!
//! One [`World::tick`] returns all of it as a [`TickReport`].
//!
//! Ids: the ego is id 0; scenario `actors` get 1..=n in file order, then `obstacles` in file
//! order, then actors spawned at run time ([`World::spawn_external`]). [`World::actors`]
//! excludes the ego and removed actors and is sorted by id.
//!
//! Deterministic: no hash-map iteration, fixed order, no randomness (the seed is kept for
//! behaviours that will need it).

pub mod collision;
pub mod idm;
pub mod lane_change;
pub mod lights;
pub mod scripted;
pub mod sumo;
pub mod traffic;
pub mod vehicle;

pub use lights::{signal_heads, LightState, SignalHead};
pub use traffic::{TrafficAgent, TrafficFrame, TrafficInput, TrafficModel};
pub use vehicle::{longitudinal_accel, sanitize_control, step_bicycle, EgoState, VehicleParams};

use crate::geom::{Pose, Vec2};
use crate::map::Network;
use crate::scenario::{
    ActorMotion, BrakeWhen, ChainEvent, PaceMode, ResolvedScenario, ScriptedPath, Trigger, ETA_MAX_OFFSET_M,
};
use crate::view::{ActorKind, ActorView, ContactClass, LightColor, SignView, TrafficLightView};
use crate::{Error, Result, DT_S};
use collision::CollisionWorld;
use rapier2d::prelude::ColliderHandle;
use scripted::{
    path_pose, smoothing_m, step_scripted, EgoRelative, Phase, ETA_MIN_SPEED_MPS, PACE_GAIN_PER_S,
    PACE_SETTLED_M,
};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;
pub use vehicle::Control;

/// Id of the ego in views and contacts.
pub const EGO_ID: u32 = 0;

/// An actor added at run time whose pose the caller drives ([`World::set_external_pose`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExternalSpawn {
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub color: [u8; 3],
    pub pose: Pose,
    pub speed_mps: f64,
}

/// Everything about one tick.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TickReport {
    /// Number of ticks done, this one included (1 after the first tick).
    pub tick: u64,
    /// Sim time at the end of the tick = tick · DT_S.
    pub time_s: f64,
    pub ego: ActorView,
    /// Ego state with acceleration, steering angle and yaw rate of this tick.
    pub ego_state: EgoState,
    /// Actors overlapping the ego at the end of the tick, by id, with the protocol's class.
    pub contacts: Vec<(u32, ContactClass)>,
    /// Ego centre on a drivable lane or junction.
    pub on_road: bool,
    /// Actors whose start trigger fired during this tick.
    pub triggered: Vec<u32>,
    /// The ego centre crossed the stop line of a red signal head during this tick (heading
    /// within 60° of the lane, laterally within the lane width).
    pub ran_red_light: bool,
}

#[derive(Debug, Clone)]
enum Motion {
    Static,
    Scripted(Box<ScriptedPath>),
    External,
    /// Moved by the traffic model (key of the model's vehicle).
    Traffic(u64),
}

#[derive(Debug, Clone)]
struct ActorRt {
    view: ActorView,
    motion: Motion,
    collider: ColliderHandle,
    s: f64,
    phase: Phase,
    triggered_at_s: f64,
    brake_pending: bool,
    /// When its brake event began / it reached its path end (∞ = not yet), for chained triggers.
    brake_at_s: f64,
    end_at_s: f64,
    /// Since when its `pace` gap has been settled (∞ = not settled), for `gap_held_s` brakes.
    gap_settled_since_s: f64,
    /// Removed from the world (end of path with `at_end = remove`, or despawned).
    removed: bool,
    /// Traffic vehicles: the last frame that listed it, and its signal bits.
    traffic_frame: u64,
    signals: u32,
}

/// The simulated world of one episode.
#[derive(Debug)]
pub struct World {
    map: Arc<Network>,
    params: VehicleParams,
    seed: u64,
    /// Seed of the scenario variation the episode plays (the traffic demand's jitter).
    variation_seed: u64,
    ego: EgoState,
    ego_view: ActorView,
    actors: Vec<ActorRt>,
    views: Vec<ActorView>,
    lights: LightState,
    signs: Vec<SignView>,
    tick: u64,
    collision: CollisionWorld,
    contact_ids: Vec<u32>,
    /// Number of scenario actors (ids 1..=n); traffic and runtime actors come after.
    scenario_actors: u32,
    traffic: Option<Box<dyn TrafficModel>>,
    traffic_buf: TrafficFrame,
    /// Traffic key → actor id of the vehicles present.
    traffic_ids: BTreeMap<u64, u32>,
    traffic_frames: u64,
    /// Traffic vehicles' lane jumps shown as continuous moves.
    lane_change: lane_change::LaneChangeSmoother,
    /// Scenario actors in stepping order: chained actors after the actor they follow (so a
    /// chain fires in the tick of its event), otherwise by id.
    step_order: Vec<usize>,
    /// The ego route and the ego's progress along it (time-to-conflict triggers).
    ego_route: crate::geom::Polyline,
    ego_route_s: f64,
    track_route: bool,
}

impl World {
    /// Builds the world at t = 0 from a resolved scenario.
    pub fn new(scenario: &ResolvedScenario, seed: u64) -> Result<World> {
        let params = scenario.ego.params;
        params.validate()?;
        let ego = EgoState::new(scenario.ego.start, scenario.ego.speed_mps);
        let ego_view = ActorView {
            id: EGO_ID,
            kind: ActorKind::Car,
            pose: ego.pose,
            speed_mps: ego.speed_mps,
            length_m: params.length_m,
            width_m: params.width_m,
            height_m: params.height_m,
            color: scenario.ego.color,
            braking: false,
            blinkers: 0,
            beacon: false,
        };
        let mut collision = CollisionWorld::new(ego.pose.pos, ego.pose, params.length_m, params.width_m);
        let mut actors = Vec::with_capacity(scenario.actors.len());
        for (i, a) in scenario.actors.iter().enumerate() {
            let id = u32::try_from(i + 1).map_err(|_| Error::Simulation("too many actors".into()))?;
            let (pose, motion) = match &a.motion {
                ActorMotion::Static { pose } => (*pose, Motion::Static),
                ActorMotion::External { pose } => (*pose, Motion::External),
                ActorMotion::Scripted(p) => {
                    (path_pose(&p.path, 0.0, smoothing_m(a.length_m)), Motion::Scripted(Box::new(p.clone())))
                }
            };
            let view = ActorView {
                id,
                kind: a.kind,
                pose,
                speed_mps: 0.0,
                length_m: a.length_m,
                width_m: a.width_m,
                height_m: a.height_m,
                color: a.color,
                braking: false,
                blinkers: 0,
                beacon: a.emergency,
            };
            let brake_pending = matches!(&motion, Motion::Scripted(p) if p.brake.is_some());
            let collider = collision.add_actor(id, pose, a.length_m, a.width_m);
            actors.push(ActorRt {
                view,
                motion,
                collider,
                s: 0.0,
                phase: Phase::Waiting,
                triggered_at_s: 0.0,
                brake_pending,
                brake_at_s: f64::INFINITY,
                end_at_s: f64::INFINITY,
                gap_settled_since_s: f64::INFINITY,
                removed: false,
                traffic_frame: 0,
                signals: 0,
            });
        }
        let scenario_actors = actors.len() as u32;
        // Chain depth (cycles are rejected at load; the bound keeps a hand-built one finite).
        let depth = |mut i: usize| {
            let mut d = 0usize;
            while let ActorMotion::Scripted(p) = &scenario.actors[i].motion {
                match p.trigger {
                    Trigger::After { actor, .. } if d < scenario.actors.len() => {
                        i = actor;
                        d += 1;
                    }
                    _ => break,
                }
            }
            d
        };
        let mut step_order: Vec<usize> = (0..actors.len()).collect();
        step_order.sort_by_key(|&i| (depth(i), i));
        // The ego's route progress is needed by time-to-conflict triggers, pacing and brakes on
        // the ego's gap or ETA.
        let track_route = scenario.actors.iter().any(|a| match &a.motion {
            ActorMotion::Scripted(p) => {
                matches!(p.trigger, Trigger::EgoEta { .. })
                    || p.pace.is_some()
                    || p.brake.is_some_and(|b| {
                        matches!(
                            b.when,
                            BrakeWhen::EgoGap { .. }
                                | BrakeWhen::EgoTimeGap { .. }
                                | BrakeWhen::EgoTtc { .. }
                                | BrakeWhen::EgoEta { .. }
                        )
                    })
            }
            _ => false,
        });
        let mut w = World {
            map: scenario.map.clone(),
            params,
            seed,
            variation_seed: seed,
            ego,
            ego_view,
            views: Vec::with_capacity(actors.len()),
            actors,
            lights: LightState::with_programs(&scenario.map, &scenario.lights),
            signs: scenario.signs.clone(),
            tick: 0,
            collision,
            contact_ids: Vec::with_capacity(8),
            scenario_actors,
            traffic: None,
            traffic_buf: TrafficFrame::default(),
            traffic_ids: BTreeMap::new(),
            traffic_frames: 0,
            lane_change: lane_change::LaneChangeSmoother::default(),
            step_order,
            ego_route: scenario.ego.route.clone(),
            ego_route_s: 0.0,
            track_route,
        };
        w.track_ego_route();
        w.rebuild_views();
        Ok(w)
    }

    fn rebuild_views(&mut self) {
        self.views.clear();
        self.views.extend(self.actors.iter().filter(|a| !a.removed).map(|a| a.view));
    }

    /// Advances the world by one tick under `control` (NaN/∞ → error; values clamped to range).
    pub fn tick(&mut self, control: &Control) -> Result<TickReport> {
        let c = sanitize_control(control)?;
        // 2. Ego.
        let prev_speed = self.ego.speed_mps;
        let prev_pos = self.ego.pose.pos;
        self.ego = step_bicycle(&self.params, &self.ego, &c, DT_S);
        self.ego_view.pose = self.ego.pose;
        self.ego_view.speed_mps = self.ego.speed_mps;
        self.ego_view.braking = c.brake > 0.0 && prev_speed > 0.0;
        // 3. Time.
        self.tick += 1;
        let t = self.time_s();
        // 4. Lights (unless the traffic model drives them, below).
        if !self.traffic.as_ref().is_some_and(|m| m.drives_lights()) {
            self.lights.update(t);
        }
        // 5. Actors.
        let mut triggered = Vec::new();
        let ego_pos = self.ego.pose.pos;
        self.track_ego_route();
        let mut any_removed = false;
        for k in 0..self.step_order.len() {
            let i = self.step_order[k];
            if self.actors[i].removed {
                continue;
            }
            let Motion::Scripted(p) = &self.actors[i].motion else { continue };
            let fire = self.actors[i].phase == Phase::Waiting && self.trigger_fires(&p.trigger, t);
            let rel = self.ego_relative(i, t);
            let a = &mut self.actors[i];
            a.gap_settled_since_s = match rel.gap_settled {
                Some(true) => a.gap_settled_since_s.min(t),
                _ => f64::INFINITY,
            };
            let Motion::Scripted(p) = &a.motion else { continue };
            let before = a.view.pose;
            let removed = step_scripted(
                a.view.id,
                &mut a.view,
                &mut a.s,
                &mut a.phase,
                &mut a.triggered_at_s,
                &mut a.brake_pending,
                p,
                t,
                fire,
                rel,
                &mut triggered,
            );
            if a.brake_at_s.is_infinite() && matches!(a.phase, Phase::Braking | Phase::Holding { .. }) {
                a.brake_at_s = t;
            }
            if a.end_at_s.is_infinite() && (removed || a.phase == Phase::Done) {
                a.end_at_s = t;
            }
            if removed {
                a.removed = true;
                any_removed = true;
                self.collision.set_enabled(a.collider, false);
            } else if a.view.pose != before {
                self.collision.set_pose(a.collider, a.view.pose);
            }
        }
        triggered.sort_unstable();
        if any_removed {
            self.rebuild_views();
        } else {
            for (view, a) in self.views.iter_mut().zip(self.actors.iter().filter(|a| !a.removed)) {
                *view = a.view;
            }
        }
        // 5b. Background traffic (sees this tick's ego and actors), then red-light running.
        self.step_traffic(None)?;
        let ran_red_light = crossed_red_stop_line(self.lights.views(), prev_pos, self.ego.pose);
        // 6. Collisions.
        self.collision.set_ego_pose(self.ego.pose);
        self.contact_ids.clear();
        self.collision.ego_contacts(&mut self.contact_ids);
        let contacts = self
            .contact_ids
            .iter()
            .filter_map(|&id| self.actor_index(id).map(|i| (id, self.actors[i].view.kind.contact_class())))
            .collect();
        // 7. Off-road.
        let on_road = self.map.drivable().is_drivable(ego_pos);
        Ok(TickReport {
            tick: self.tick,
            time_s: t,
            ego: self.ego_view,
            ego_state: self.ego,
            contacts,
            on_road,
            triggered,
            ran_red_light,
        })
    }

    /// Updates the ego's progress along its route (searched near the last value, so a route
    /// passing near itself is not confused).
    fn track_ego_route(&mut self) {
        if !self.track_route {
            return;
        }
        let p = self.ego.pose.pos;
        let s0 = self.ego_route_s;
        if let Some(pr) = self.ego_route.project_within(p, s0 - 5.0, s0 + 30.0) {
            // Off the window (e.g. after a teleport in a test): take the global projection.
            let pr = if pr.distance > 10.0 { self.ego_route.project(p).unwrap_or(pr) } else { pr };
            self.ego_route_s = pr.s;
        }
    }

    /// The ego's arc length along its route (tracked while a time-to-conflict trigger exists).
    pub fn ego_route_s(&self) -> f64 {
        self.ego_route_s
    }

    /// Arc length along the ego route of a point beside it near the ego (None: farther than
    /// [`ETA_MAX_OFFSET_M`] from the route); before the route start / past its end the
    /// distance along the first / last direction (negative before the start).
    fn along_ego_route(&self, pos: Vec2) -> Option<f64> {
        let r = &self.ego_route;
        let s0 = self.ego_route_s;
        let pr = r.project_within(pos, s0 - 100.0, s0 + 400.0)?;
        let len = r.length();
        let s = if pr.s <= 1e-6 {
            (pos - r.point_at(0.0)).dot(Vec2::from_angle(r.heading_at(0.0)))
        } else if pr.s >= len - 1e-6 {
            len + (pos - r.point_at(len)).dot(Vec2::from_angle(r.heading_at(len)))
        } else {
            pr.s
        };
        (pr.distance <= ETA_MAX_OFFSET_M).then_some(s)
    }

    /// The ego-relative inputs of scripted actor `i` at time `t`: its pace speed and whether an
    /// ego-relative or chained brake is due.
    fn ego_relative(&self, i: usize, t: f64) -> EgoRelative {
        let a = &self.actors[i];
        let Motion::Scripted(p) = &a.motion else { return EgoRelative::default() };
        let needs_gap = p.pace.is_some_and(|q| matches!(q.mode, PaceMode::Gap { .. }))
            || p.brake.is_some_and(|b| {
                matches!(
                    b.when,
                    BrakeWhen::EgoGap { .. } | BrakeWhen::EgoTimeGap { .. } | BrakeWhen::EgoTtc { .. }
                )
            });
        if a.phase == Phase::Waiting && p.brake.is_none() || a.phase == Phase::Done {
            return EgoRelative::default();
        }
        let v_ego = self.ego.speed_mps;
        // Bumper gap from the ego's front to the actor's rear along the ego route.
        let gap = if needs_gap {
            self.along_ego_route(a.view.pose.pos)
                .map(|s| s - self.ego_route_s - 0.5 * (self.params.length_m + a.view.length_m))
        } else {
            None
        };
        let mut out = EgoRelative::default();
        let pacing = a.phase == Phase::Moving && (a.brake_pending || p.brake.is_none());
        if let Some(q) = p.pace.filter(|q| pacing && a.s < q.until_s) {
            let target = match q.mode {
                PaceMode::Gap { gap_m, gap_s } => gap.map(|g| {
                    let want = gap_m + gap_s * v_ego;
                    out.gap_settled = Some((g - want).abs() <= PACE_SETTLED_M.max(0.15 * want.abs()));
                    v_ego - PACE_GAIN_PER_S * (g - want)
                }),
                PaceMode::Meet { route_s, actor_s, offset_s, .. } => {
                    // The ego's ETA to the point (negative once past it: seconds since).
                    let left = actor_s - a.s;
                    let ego_left = route_s - self.ego_route_s;
                    if left <= 0.0 {
                        None
                    } else {
                        let t_arrive = ego_left / v_ego.max(ETA_MIN_SPEED_MPS) + offset_s;
                        Some(if t_arrive <= 0.05 { f64::INFINITY } else { left / t_arrive })
                    }
                }
            };
            out.pace_mps = target.map(|v| v.clamp(q.min_speed_mps, q.max_speed_mps));
        }
        if let Some(b) = p.brake.filter(|_| a.brake_pending && a.phase == Phase::Moving) {
            let pos = a.view.pose.pos;
            out.brake_due = match b.when {
                BrakeWhen::AtS(_) | BrakeWhen::AfterS(_) => false,
                BrakeWhen::EgoWithin { radius_m, point } => {
                    self.ego.pose.pos.dist_sq(point.unwrap_or(pos)) <= radius_m * radius_m
                }
                BrakeWhen::EgoGap { gap_m } => gap.is_some_and(|g| g <= gap_m),
                BrakeWhen::EgoTimeGap { gap_s } => gap.is_some_and(|g| g <= gap_s * v_ego),
                BrakeWhen::EgoTtc { ttc_s } => {
                    let closing = v_ego - a.view.speed_mps;
                    gap.is_some_and(|g| closing > 1e-3 && g <= ttc_s * closing)
                }
                BrakeWhen::EgoEta { eta_s, route_s, .. } => {
                    let d = route_s - self.ego_route_s;
                    d > 0.0 && d / v_ego.max(ETA_MIN_SPEED_MPS) <= eta_s
                }
                BrakeWhen::GapHeld { held_s } => t - a.gap_settled_since_s >= held_s - 1e-9,
                BrakeWhen::After { actor, event, delay_s } => self.event_passed(actor, event, delay_s, t),
            };
        }
        out
    }

    /// Whether `delay_s` has passed since `event` of scenario actor `actor` at time `t`.
    fn event_passed(&self, actor: usize, event: ChainEvent, delay_s: f64, t: f64) -> bool {
        let Some(o) = self.actors.get(actor) else { return false };
        let at = match event {
            ChainEvent::Start if o.phase != Phase::Waiting => o.triggered_at_s,
            ChainEvent::Start => f64::INFINITY,
            ChainEvent::Brake => o.brake_at_s,
            ChainEvent::End => o.end_at_s,
        };
        t >= at + delay_s - 1e-9
    }

    /// Whether a waiting actor's start trigger fires at time `t`.
    fn trigger_fires(&self, trigger: &Trigger, t: f64) -> bool {
        match *trigger {
            Trigger::Time(t0) => t >= t0 - 1e-9,
            Trigger::EgoWithin { radius_m, point } => self.ego.pose.pos.dist_sq(point) <= radius_m * radius_m,
            Trigger::EgoEta { eta_s, route_s, .. } => {
                let d = route_s - self.ego_route_s;
                d > 0.0 && d / self.ego.speed_mps.max(ETA_MIN_SPEED_MPS) <= eta_s
            }
            Trigger::After { actor, event, delay_s } => self.event_passed(actor, event, delay_s, t),
        }
    }

    fn actor_index(&self, id: u32) -> Option<usize> {
        let i = (id as usize).checked_sub(1)?;
        (i < self.actors.len()).then_some(i)
    }

    /// Sets the pose and speed of an `external` actor (SUMO co-simulation hook).
    pub fn set_external_pose(&mut self, id: u32, pose: Pose, speed_mps: f64) -> Result<()> {
        let i = self.actor_index(id).ok_or_else(|| Error::config("actor_id", id, "no such actor"))?;
        if !matches!(self.actors[i].motion, Motion::External) || self.actors[i].removed {
            return Err(Error::config("actor_id", id, "not an active external actor"));
        }
        if !(pose.pos.is_finite() && pose.yaw.is_finite()) {
            return Err(Error::config("pose", format!("{pose:?}"), "must be finite"));
        }
        if !(speed_mps.is_finite() && speed_mps >= 0.0) {
            return Err(Error::config("speed_mps", speed_mps, "must be a finite number ≥ 0"));
        }
        let a = &mut self.actors[i];
        a.view.braking = speed_mps < a.view.speed_mps - 1e-3;
        a.view.pose = pose;
        a.view.speed_mps = speed_mps;
        let (h, view) = (a.collider, a.view);
        self.collision.set_pose(h, pose);
        if let Some(v) = self.views.iter_mut().find(|v| v.id == id) {
            *v = view;
        }
        Ok(())
    }

    /// Adds an external actor at run time (e.g. a SUMO background vehicle); returns its id.
    pub fn spawn_external(&mut self, spawn: &ExternalSpawn) -> Result<u32> {
        let ExternalSpawn { kind, length_m, width_m, height_m, color, pose, speed_mps } = *spawn;
        for (n, v) in [("length_m", length_m), ("width_m", width_m), ("height_m", height_m)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::config(n, v, "must be a finite number > 0"));
            }
        }
        if !(pose.pos.is_finite() && pose.yaw.is_finite() && speed_mps.is_finite() && speed_mps >= 0.0) {
            return Err(Error::config(
                "pose",
                format!("{pose:?} at {speed_mps} m/s"),
                "must be finite, speed ≥ 0",
            ));
        }
        let id =
            u32::try_from(self.actors.len() + 1).map_err(|_| Error::Simulation("too many actors".into()))?;
        let view = ActorView {
            id,
            kind,
            pose,
            speed_mps,
            length_m,
            width_m,
            height_m,
            color,
            braking: false,
            blinkers: 0,
            beacon: false,
        };
        self.push_driven_actor(view, Motion::External, 0, 0);
        self.views.push(view);
        Ok(id)
    }

    /// Adds an actor whose pose is driven from outside its script (an external actor or a
    /// traffic vehicle): moving from now on, with a collider at its pose.
    fn push_driven_actor(&mut self, view: ActorView, motion: Motion, traffic_frame: u64, signals: u32) {
        let collider = self.collision.add_actor(view.id, view.pose, view.length_m, view.width_m);
        self.actors.push(ActorRt {
            view,
            motion,
            collider,
            s: 0.0,
            phase: Phase::Moving,
            triggered_at_s: self.time_s(),
            brake_pending: false,
            brake_at_s: f64::INFINITY,
            end_at_s: f64::INFINITY,
            gap_settled_since_s: f64::INFINITY,
            removed: false,
            traffic_frame,
            signals,
        });
    }

    /// Plugs a traffic model in and starts it (the vehicles present at t = 0 appear now).
    /// On error the model stays attached (take it back with [`World::detach_traffic`]).
    pub fn attach_traffic(&mut self, model: Box<dyn TrafficModel>) -> Result<()> {
        self.traffic = Some(model);
        self.step_traffic(Some(self.seed))
    }

    /// Unplugs the traffic model (its vehicles stay where they are).
    pub fn detach_traffic(&mut self) -> Option<Box<dyn TrafficModel>> {
        self.traffic.take()
    }

    /// Name of the attached traffic model, if any.
    pub fn traffic_name(&self) -> Option<&str> {
        self.traffic.as_deref().map(|m| m.name())
    }

    /// Runs the model for this tick (`start` = `Some(seed)`: its start) and applies its frame.
    fn step_traffic(&mut self, start: Option<u64>) -> Result<()> {
        let Some(mut model) = self.traffic.take() else { return Ok(()) };
        let n = self.views.partition_point(|v| v.id <= self.scenario_actors);
        let input = TrafficInput {
            tick: self.tick,
            time_s: self.time_s(),
            ego: &self.ego_view,
            actors: &self.views[..n],
            map: &self.map,
            lights: self.lights.views(),
            variation_seed: self.variation_seed,
        };
        self.traffic_buf.clear();
        let res = match start {
            Some(seed) => model.start(&input, seed, &mut self.traffic_buf),
            None => model.tick(&input, &mut self.traffic_buf),
        };
        self.traffic = Some(model);
        res?;
        self.apply_traffic()
    }

    /// Applies the traffic frame in `traffic_buf`: updates, spawns and removes traffic actors
    /// and sets changed light states.
    fn apply_traffic(&mut self) -> Result<()> {
        let frame = std::mem::take(&mut self.traffic_buf);
        self.traffic_frames += 1;
        let gen = self.traffic_frames;
        let mut changed = false;
        for a in &frame.agents {
            if !(a.pose.pos.is_finite() && a.pose.yaw.is_finite() && a.speed_mps.is_finite()) {
                return Err(Error::Simulation(format!(
                    "traffic vehicle {} has a non-finite pose {a:?}",
                    a.key
                )));
            }
            let pose = self.lane_change.smooth(a.key, a.pose, a.speed_mps);
            match self.traffic_ids.get(&a.key) {
                Some(&id) => {
                    let rt = &mut self.actors[id as usize - 1];
                    rt.view.pose = pose;
                    rt.view.speed_mps = a.speed_mps;
                    rt.view.braking = a.signals & traffic::SIGNAL_BRAKELIGHT != 0;
                    rt.view.blinkers = traffic::blinkers(a.signals);
                    rt.signals = a.signals;
                    rt.traffic_frame = gen;
                    let h = rt.collider;
                    self.collision.set_pose(h, pose);
                }
                None => {
                    let id = u32::try_from(self.actors.len() + 1)
                        .map_err(|_| Error::Simulation("too many actors".into()))?;
                    if !(a.length_m > 0.0
                        && a.width_m > 0.0
                        && a.length_m.is_finite()
                        && a.width_m.is_finite())
                    {
                        return Err(Error::Simulation(format!(
                            "traffic vehicle {} has a bad size {a:?}",
                            a.key
                        )));
                    }
                    let view = ActorView {
                        id,
                        kind: a.kind,
                        pose: a.pose,
                        speed_mps: a.speed_mps.max(0.0),
                        length_m: a.length_m,
                        width_m: a.width_m,
                        height_m: a.height_m,
                        color: a.color,
                        braking: a.signals & traffic::SIGNAL_BRAKELIGHT != 0,
                        blinkers: traffic::blinkers(a.signals),
                        beacon: a.emergency,
                    };
                    self.push_driven_actor(view, Motion::Traffic(a.key), gen, a.signals);
                    self.traffic_ids.insert(a.key, id);
                    changed = true;
                }
            }
        }
        if self.traffic_ids.len() > frame.agents.len() || changed {
            let actors = &mut self.actors;
            let collision = &mut self.collision;
            self.traffic_ids.retain(|_, id| {
                let rt = &mut actors[*id as usize - 1];
                if rt.traffic_frame == gen {
                    return true;
                }
                rt.removed = true;
                collision.set_enabled(rt.collider, false);
                changed = true;
                false
            });
            let ids = &self.traffic_ids;
            self.lane_change.retain(|k| ids.contains_key(&k));
        }
        for (tl, state) in &frame.lights {
            self.lights.set_external(tl, state);
        }
        if changed {
            self.rebuild_views();
        } else {
            for (view, a) in self.views.iter_mut().zip(self.actors.iter().filter(|a| !a.removed)) {
                *view = a.view;
            }
        }
        self.traffic_buf = frame;
        Ok(())
    }

    /// Signal bits of a traffic vehicle (0 for other actors; see [`traffic::SIGNAL_BRAKELIGHT`]).
    pub fn actor_signals(&self, id: u32) -> u32 {
        self.actor_index(id).map_or(0, |i| self.actors[i].signals)
    }

    /// How actor `id` moves: `"static"` (obstacles), `"scripted"`, `"external"` or `"traffic"`
    /// (None for an unknown id). Open-loop generation tells parked from stopped vehicles by it.
    pub fn actor_motion(&self, id: u32) -> Option<&'static str> {
        Some(match self.actors.get(self.actor_index(id)?)?.motion {
            Motion::Static => "static",
            Motion::Scripted(_) => "scripted",
            Motion::External => "external",
            Motion::Traffic(_) => "traffic",
        })
    }

    /// Whether actor `id` is a background-traffic vehicle.
    pub fn is_traffic_actor(&self, id: u32) -> bool {
        self.traffic_key(id).is_some()
    }

    /// The traffic model's key of actor `id` (None unless it is a traffic vehicle).
    pub fn traffic_key(&self, id: u32) -> Option<u64> {
        match self.actors.get(self.actor_index(id)?)?.motion {
            Motion::Traffic(key) => Some(key),
            _ => None,
        }
    }

    /// Removes an actor (its collider too); ids are never reused.
    pub fn remove_actor(&mut self, id: u32) -> Result<()> {
        let i = self.actor_index(id).ok_or_else(|| Error::config("actor_id", id, "no such actor"))?;
        if !self.actors[i].removed {
            self.actors[i].removed = true;
            self.collision.set_enabled(self.actors[i].collider, false);
            self.rebuild_views();
        }
        Ok(())
    }

    /// Active actors (ego excluded), sorted by id.
    pub fn actors(&self) -> &[ActorView] {
        &self.views
    }
    pub fn ego(&self) -> &ActorView {
        &self.ego_view
    }
    pub fn ego_state(&self) -> &EgoState {
        &self.ego
    }
    pub fn vehicle_params(&self) -> &VehicleParams {
        &self.params
    }
    /// Signal heads, one per (light, controlled incoming lane), sorted by light id then lane.
    pub fn lights(&self) -> &[TrafficLightView] {
        self.lights.views()
    }
    /// Exact colour of one controlled link (`tl_id`, SUMO link index).
    pub fn link_color(&self, tl_id: &str, link_index: usize) -> Option<LightColor> {
        self.lights.link_color(tl_id, link_index)
    }
    /// Colour governing the connection `from_lane` → `to_lane` (None if not signalised).
    pub fn connection_color(&self, from_lane: usize, to_lane: usize) -> Option<LightColor> {
        self.map.connections_from_lane(from_lane).iter().map(|&ci| &self.map.connections[ci]).find_map(|c| {
            if c.to_lane != to_lane {
                return None;
            }
            self.lights.link_color(c.tl.as_deref()?, c.link_index?)
        })
    }
    pub fn signs(&self) -> &[SignView] {
        &self.signs
    }
    pub fn map(&self) -> &Arc<Network> {
        &self.map
    }
    pub fn time_s(&self) -> f64 {
        self.tick as f64 * DT_S
    }
    pub fn tick_count(&self) -> u64 {
        self.tick
    }
    pub fn seed(&self) -> u64 {
        self.seed
    }
    /// Sets the variation seed the traffic demand is played with (default: the world seed);
    /// call before attaching traffic.
    pub fn set_variation_seed(&mut self, v: u64) {
        self.variation_seed = v;
    }
    pub fn variation_seed(&self) -> u64 {
        self.variation_seed
    }
}

/// Whether the segment `from` → `to.pos` crosses the stop line of a red head in its direction.
fn crossed_red_stop_line(heads: &[TrafficLightView], from: Vec2, to: Pose) -> bool {
    heads.iter().any(|h| {
        if h.color != LightColor::Red || to.pos.dist_sq(h.stop_line.pos) > 100.0 {
            return false;
        }
        let f = h.stop_line.forward();
        let (da, db) = ((from - h.stop_line.pos).dot(f), (to.pos - h.stop_line.pos).dot(f));
        let lateral = (to.pos - h.stop_line.pos).dot(f.perp());
        da < 0.0
            && db >= 0.0
            && lateral.abs() <= 0.5 * h.lane_width_m
            && (to.yaw - h.stop_line.yaw).cos() > 0.5
    })
}
