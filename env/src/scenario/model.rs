//! The resolved scenario: what a scenario file means in world coordinates ([`ResolvedScenario`]),
//! built by [`super::resolve`] and run by the world; the world never re-reads the file.

use crate::geom::{Polyline, Pose, Vec2};
use crate::map::{EdgeIdx, LaneIdx, Network};
use crate::vehicle_params::VehicleParams;
use crate::view::{ActorKind, SignView};
use std::path::PathBuf;
use std::sync::Arc;

/// Protocol fallback speed for the reference duration when a scenario gives none (docs/protocol.md#r4-scene-score).
pub const DEFAULT_REFERENCE_SPEED_MPS: f64 = 5.56;
/// Default body colours: actor `i` (file order, obstacles after actors) and native traffic
/// vehicle `key` get `PALETTE[i % 8]`, the renderer's named actor colours
/// ([`crate::render::palette::cycle_colour`]), so every default actor renders as a colour with
/// one clear name (docs/rendering.md#colour-names).
pub const PALETTE: [[u8; 3]; 8] = {
    let mut out = [[0u8; 3]; 8];
    let mut i = 0;
    while i < out.len() {
        out[i] = crate::render::palette::cycle_colour(i);
        i += 1;
    }
    out
};
/// Ego body colour unless the scenario sets one.
pub const EGO_COLOR: [u8; 3] = [30, 110, 230];

#[derive(Debug, Clone)]
pub struct ResolvedEgo {
    /// Vehicle centre and heading at t = 0.
    pub start: Pose,
    pub speed_mps: f64,
    pub params: VehicleParams,
    pub color: [u8; 3],
    pub start_lane: LaneIdx,
    /// Normal edges of the route, start edge first.
    pub route_edges: Vec<EdgeIdx>,
    /// Route centreline clipped between the projections of start and destination (L of docs/protocol.md#r4-scene-score).
    pub route: Polyline,
    pub destination: Vec2,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Trigger {
    /// Starts when sim time ≥ this.
    Time(f64),
    /// Starts when the ego centre is within `radius_m` of `point`.
    EgoWithin { radius_m: f64, point: Vec2 },
    /// Starts when the ego is expected to reach `point` within `eta_s`: its distance along its
    /// route to `route_s` (the point's projection) ÷ max(ego speed, [`crate::world::scripted::ETA_MIN_SPEED_MPS`]) ≤
    /// `eta_s`, while the point is still ahead.
    EgoEta { eta_s: f64, point: Vec2, route_s: f64 },
    /// Starts `delay_s` after `event` of the scenario actor with index `actor` (id = index + 1).
    After { actor: usize, event: ChainEvent, delay_s: f64 },
}

/// A time-to-conflict point must lie this close to the ego route, m.
pub const ETA_MAX_OFFSET_M: f64 = 30.0;

/// The event of another actor a chained trigger follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChainEvent {
    Start,
    Brake,
    End,
}

/// The program a traffic light runs in the episode (a `[[lights]]` override resolved against
/// the map): at episode time t it is at cycle position (t − `offset_s`) mod cycle, SUMO's
/// meaning of `offset`.
#[derive(Debug, Clone, PartialEq)]
pub struct LightProgram {
    pub tl_id: String,
    pub offset_s: f64,
    pub phases: Vec<crate::map::TlPhase>,
    /// Whether `phases` replace the map's program (SUMO must be given the new logic).
    pub replaced: bool,
}

impl LightProgram {
    /// (phase index, seconds left in it) at episode time `t`.
    pub fn phase_at(&self, t: f64) -> Option<(usize, f64)> {
        let cycle: f64 = self.phases.iter().map(|p| p.duration_s.max(0.0)).sum();
        if self.phases.is_empty() || !cycle.is_finite() || cycle <= 0.0 {
            return None;
        }
        let pos = (t - self.offset_s).rem_euclid(cycle);
        let mut end = 0.0;
        for (i, p) in self.phases.iter().enumerate() {
            end += p.duration_s.max(0.0);
            if pos < end {
                return Some((i, end - pos));
            }
        }
        Some((self.phases.len() - 1, 0.0))
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BrakeWhen {
    /// Arc length along the actor's path.
    AtS(f64),
    /// Seconds after the actor's trigger fired.
    AfterS(f64),
    /// The ego centre within `radius_m` of `point` (None: of the actor's centre, as it moves).
    EgoWithin { radius_m: f64, point: Option<Vec2> },
    /// The ego's bumper gap behind the actor along the ego route ≤ `gap_m`.
    EgoGap { gap_m: f64 },
    /// The ego's time gap (bumper gap ÷ ego speed) ≤ `gap_s`.
    EgoTimeGap { gap_s: f64 },
    /// The ego's time to collision (bumper gap ÷ closing speed, closing only) ≤ `ttc_s`.
    EgoTtc { ttc_s: f64 },
    /// The ego expected at `point` (route arc length `route_s`) within `eta_s`.
    EgoEta { eta_s: f64, point: Vec2, route_s: f64 },
    /// The actor's `pace` gap has stayed settled for `held_s`.
    GapHeld { held_s: f64 },
    /// `delay_s` after `event` of actor `actor` (index).
    After { actor: usize, event: ChainEvent, delay_s: f64 },
}

/// Ego-relative pacing (see [`crate::scenario::schema::PaceSpec`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pace {
    pub mode: PaceMode,
    pub min_speed_mps: f64,
    pub max_speed_mps: f64,
    /// Arc length along the path where pacing ends (∞ = never).
    pub until_s: f64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PaceMode {
    /// Hold a bumper gap of `gap_m` + `gap_s` × ego speed ahead of the ego along its route.
    Gap { gap_m: f64, gap_s: f64 },
    /// Reach arc length `actor_s` of the path (the point `point`, at `route_s` along the ego
    /// route) `offset_s` after the ego's expected arrival there.
    Meet { point: Vec2, route_s: f64, actor_s: f64, offset_s: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrakeEvent {
    pub when: BrakeWhen,
    pub decel_mps2: f64,
    pub to_speed_mps: f64,
    /// Resume the leg speed this long after reaching `to_speed_mps` (None = never).
    pub hold_s: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AtEnd {
    Stop,
    Remove,
}

#[derive(Debug, Clone)]
pub struct ScriptedPath {
    /// World-frame path; the actor's centre moves along it.
    pub path: Polyline,
    /// (arc length at which the leg ends, speed on the leg), increasing arc lengths; the last
    /// leg ends at the path length.
    pub legs: Vec<(f64, f64)>,
    pub initial_speed_mps: f64,
    /// Limit on speed changes between legs (∞ = instant).
    pub accel_mps2: f64,
    pub trigger: Trigger,
    pub brake: Option<BrakeEvent>,
    /// Ego-relative speed control while moving (None: the leg speeds).
    pub pace: Option<Pace>,
    pub at_end: AtEnd,
}

impl ScriptedPath {
    /// Speed of the leg containing arc length `s`.
    pub fn leg_speed(&self, s: f64) -> f64 {
        let i = self.legs.partition_point(|&(end, _)| end <= s).min(self.legs.len().saturating_sub(1));
        self.legs.get(i).map_or(0.0, |l| l.1)
    }
}

// One per actor, resolved once per scenario: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum ActorMotion {
    /// Never moves (obstacles).
    Static {
        pose: Pose,
    },
    Scripted(ScriptedPath),
    /// Pose set by the caller each tick; `pose` is where it stands until then.
    External {
        pose: Pose,
    },
}

#[derive(Debug, Clone)]
pub struct ResolvedActor {
    /// From the file, or `actors[i]` / `obstacles[i]`.
    pub name: String,
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub color: [u8; 3],
    /// Emergency beacons (rendering only).
    pub emergency: bool,
    pub motion: ActorMotion,
}

/// A scenario with everything in world coordinates; the world never re-reads the file.
#[derive(Debug, Clone)]
pub struct ResolvedScenario {
    pub file: PathBuf,
    pub id: String,
    pub name: String,
    pub category: String,
    pub description: String,
    /// The map file actually read (after `sumo:` resolution).
    pub map_path: PathBuf,
    /// The `map` value as written in the scenario file.
    pub map_spec: String,
    pub map: Arc<Network>,
    pub seed: u64,
    /// As written; see [`ResolvedScenario::reference_duration_s`] for the effective value.
    pub reference_duration_given_s: Option<f64>,
    /// As written; see [`ResolvedScenario::scenario_duration_s`] for the effective value.
    pub duration_given_s: Option<f64>,
    pub ego: ResolvedEgo,
    /// Scripted/external actors in file order, then obstacles in file order.
    pub actors: Vec<ResolvedActor>,
    pub signs: Vec<SignView>,
    /// Background-traffic demand (`[traffic]`; mode `none` when absent).
    pub traffic: crate::scenario::traffic::TrafficDemand,
    /// Traffic-light overrides (`[[lights]]`), one per overridden light, in file order.
    pub lights: Vec<LightProgram>,
    /// Bounds of the per-seed jitter ([`ResolvedScenario::varied`]).
    pub variation: crate::scenario::variation_spec::Variation,
    /// Light and weather (`[conditions]`; [`ResolvedScenario::varied`] may draw others).
    pub conditions: crate::conditions::Conditions,
    /// `[variation] conditions`: what a seed other than 0 draws its conditions from (empty:
    /// every seed keeps `conditions`).
    pub condition_choices: Vec<crate::conditions::Conditions>,
}

impl ResolvedScenario {
    /// Route length L, metres.
    pub fn route_length_m(&self) -> f64 {
        self.ego.route.length()
    }
    /// T_ref of docs/protocol.md#r4-scene-score: the scenario's value, else L / 5.56 m/s.
    pub fn reference_duration_s(&self) -> f64 {
        self.reference_duration_given_s.unwrap_or(self.route_length_m() / DEFAULT_REFERENCE_SPEED_MPS)
    }

    /// The scenario duration of docs/protocol.md#r4-termination (the scenario timeout is 2 × it): the file's `duration_s`,
    /// else — like the original's "longest estimated duration over all actors, ego included" —
    /// the largest of T_ref and every scripted actor's estimated finish time (start trigger +
    /// travel time of its legs + any brake hold). An ego-distance trigger is estimated to fire
    /// when the ego, progressing at L / T_ref, comes within the trigger radius of its point.
    pub fn scenario_duration_s(&self) -> f64 {
        if let Some(d) = self.duration_given_s {
            return d;
        }
        let t_ref = self.reference_duration_s();
        let starts = self.estimated_start_times_s();
        self.actors
            .iter()
            .zip(&starts)
            .filter_map(|(a, &start)| match &a.motion {
                ActorMotion::Scripted(p) => Some(start + travel_s(p, p.path.length()) + hold_s(p)),
                _ => None,
            })
            .filter(|d| d.is_finite())
            .fold(t_ref, f64::max)
    }

    /// Estimated trigger time of every actor (non-scripted: 0), the ego progressing along its
    /// route at L / T_ref: `time_s` as given; `ego_within_m` when the ego enters the radius;
    /// `ego_eta_s` when the ego is `eta_s` from the point at that pace (s_point / v − eta);
    /// chained triggers at the other actor's estimated event (start; start + time to its
    /// brake; start + travel + hold for the end) + `delay_s`.
    pub fn estimated_start_times_s(&self) -> Vec<f64> {
        let ego_speed = self.route_length_m() / self.reference_duration_s();
        let mut memo: Vec<Option<f64>> = vec![None; self.actors.len()];
        (0..self.actors.len()).map(|i| self.estimate_start(i, ego_speed, &mut memo, 0)).collect()
    }

    fn estimate_start(&self, i: usize, ego_speed: f64, memo: &mut Vec<Option<f64>>, depth: usize) -> f64 {
        if let Some(t) = memo[i] {
            return t;
        }
        let ActorMotion::Scripted(p) = &self.actors[i].motion else { return 0.0 };
        let t = match p.trigger {
            Trigger::Time(t) => t,
            Trigger::EgoWithin { radius_m, point } => match self.ego.route.project(point) {
                Some(proj) if ego_speed > 0.0 => (proj.s - radius_m).max(0.0) / ego_speed,
                _ => 0.0,
            },
            Trigger::EgoEta { eta_s, route_s, .. } => {
                if ego_speed > 0.0 {
                    (route_s / ego_speed - eta_s).max(0.0)
                } else {
                    0.0
                }
            }
            // Cycles are rejected at load; the depth guard keeps a hand-built one finite.
            Trigger::After { actor, event, delay_s } if depth < self.actors.len() => {
                let t0 = self.estimate_start(actor, ego_speed, memo, depth + 1);
                let ev = match (&self.actors[actor].motion, event) {
                    (ActorMotion::Scripted(q), ChainEvent::Brake) => match q.brake.map(|b| b.when) {
                        Some(BrakeWhen::AfterS(dt)) => dt,
                        Some(BrakeWhen::AtS(s)) => travel_s(q, s),
                        Some(BrakeWhen::GapHeld { held_s }) => held_s,
                        // Ego-relative and chained brakes: estimated at the trigger.
                        _ => 0.0,
                    },
                    (ActorMotion::Scripted(q), ChainEvent::End) => travel_s(q, q.path.length()) + hold_s(q),
                    _ => 0.0,
                };
                t0 + ev + delay_s
            }
            Trigger::After { .. } => 0.0,
        };
        memo[i] = Some(t);
        t
    }
}

/// Travel time of a scripted path from its start to arc length `upto` at the leg speeds.
fn travel_s(p: &ScriptedPath, upto: f64) -> f64 {
    let mut travel = 0.0;
    let mut from = 0.0;
    for &(end, speed) in &p.legs {
        let end = end.min(upto);
        if speed > 0.0 && end > from {
            travel += (end - from) / speed;
        }
        from = from.max(end);
    }
    travel
}

fn hold_s(p: &ScriptedPath) -> f64 {
    p.brake.and_then(|b| b.hold_s).unwrap_or(0.0)
}

#[cfg(test)]
mod tests {
    use super::PALETTE;
    use crate::render::palette::{name_of, PALETTE as NAMED};

    /// Every default actor colour is one of the renderer's named colours, and the eight differ
    /// by name (neighbours in file order are told apart by their colour word).
    #[test]
    fn default_actor_colours_are_named_palette_colours() {
        let mut names = Vec::new();
        for rgb in PALETTE {
            let entry = NAMED.iter().find(|c| c.rgb == rgb);
            assert!(entry.is_some(), "{rgb:?} is no palette entry");
            assert_eq!(name_of(rgb), entry.unwrap().name);
            names.push(name_of(rgb));
        }
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), PALETTE.len(), "{names:?}");
    }
}
