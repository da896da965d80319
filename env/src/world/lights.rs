//! Fixed-time traffic lights: each light runs its first (default) `tlLogic` program from t = 0,
//! or the scenario's `[[lights]]` override of it ([`LightState::with_programs`]).
//!
//! Cycle position at time t is (t − offset) mod cycle, so with offset = 10 the first phase
//! starts at t = 10 s (SUMO's meaning of `offset`). Actuated programs run their phases at the
//! nominal `duration` (no detectors).
//!
//! One signal head per (light, incoming lane). Its colour is the most permissive colour over the
//! lane's controlled links (green > yellow > red > off): a lane whose right turn has green while
//! straight is red shows green; use [`LightState::link_color`] for the exact colour of one link.

use crate::map::Network;
pub use crate::map::{signal_heads, SignalHead};
use crate::scenario::LightProgram;
use crate::view::{LightColor, TrafficLightView};
use smallvec::SmallVec;

fn rank(c: LightColor) -> u8 {
    match c {
        LightColor::Green => 3,
        LightColor::Yellow => 2,
        LightColor::Red => 1,
        LightColor::Off => 0,
    }
}

/// One light's program, flattened for fast phase lookup.
#[derive(Debug, Clone)]
struct Program {
    offset_s: f64,
    cycle_s: f64,
    /// Cumulative phase end times within the cycle.
    ends: Vec<f64>,
    states: Vec<Vec<LightColor>>,
    phase: usize,
    /// State set from outside (a traffic model running the programs, e.g. SUMO).
    external: Option<Vec<LightColor>>,
}

impl Program {
    fn phase_at(&self, t: f64) -> usize {
        if self.states.len() <= 1 || self.cycle_s.is_nan() || self.cycle_s <= 0.0 {
            return 0;
        }
        let pos = (t - self.offset_s).rem_euclid(self.cycle_s);
        self.ends.partition_point(|&e| e <= pos).min(self.states.len() - 1)
    }
    fn color(&self, link: usize) -> LightColor {
        if let Some(e) = &self.external {
            return e.get(link).copied().unwrap_or(LightColor::Off);
        }
        self.states.get(self.phase).and_then(|s| s.get(link)).copied().unwrap_or(LightColor::Off)
    }
}

/// Running state of every light in the map.
#[derive(Debug, Clone)]
pub struct LightState {
    tl_ids: Vec<String>,
    programs: Vec<Program>,
    /// (program index, link indices) of each view.
    heads: Vec<(usize, SmallVec<[usize; 4]>)>,
    views: Vec<TrafficLightView>,
}

impl LightState {
    pub fn new(map: &Network) -> LightState {
        Self::with_programs(map, &[])
    }

    /// Like [`LightState::new`], with the scenario's `[[lights]]` overrides replacing those
    /// lights' programs and offsets.
    pub fn with_programs(map: &Network, overrides: &[LightProgram]) -> LightState {
        let heads_spec = signal_heads(map);
        let mut tl_ids: Vec<String> = Vec::new();
        let mut programs = Vec::new();
        for id in map.tl_ids() {
            tl_ids.push(id.to_string());
            let (offset_s, phases) = match overrides.iter().find(|o| o.tl_id == id) {
                Some(o) => (o.offset_s, o.phases.as_slice()),
                None => match map.tl_logic(id) {
                    Some(l) => (l.offset_s, l.phases.as_slice()),
                    None => (0.0, &[][..]),
                },
            };
            let mut ends = Vec::with_capacity(phases.len());
            let mut acc = 0.0;
            for p in phases {
                acc += p.duration_s.max(0.0);
                ends.push(acc);
            }
            let states =
                phases.iter().map(|p| p.state.chars().map(LightColor::from_sumo).collect()).collect();
            programs.push(Program {
                offset_s,
                cycle_s: acc,
                ends,
                states,
                phase: usize::MAX,
                external: None,
            });
        }
        let mut heads = Vec::with_capacity(heads_spec.len());
        let mut views = Vec::with_capacity(heads_spec.len());
        for h in heads_spec {
            let pi = tl_ids.iter().position(|t| *t == h.tl_id).unwrap_or(0);
            let lane = &map.lanes[h.lane];
            views.push(TrafficLightView {
                tl_id: h.tl_id.clone(),
                lane_id: lane.id.clone(),
                stop_line: map.stop_line(h.lane),
                lane_width_m: lane.width_m,
                color: LightColor::Off,
            });
            heads.push((pi, h.link_indices));
        }
        let mut s = LightState { tl_ids, programs, heads, views };
        s.update(0.0);
        s
    }

    /// Sets every light to its phase at time `t`; recolours heads only on phase changes.
    pub fn update(&mut self, t: f64) {
        let mut changed = false;
        for p in &mut self.programs {
            let ph = p.phase_at(t);
            if ph != p.phase {
                p.phase = ph;
                changed = true;
            }
        }
        if !changed {
            return;
        }
        for (view, (pi, links)) in self.views.iter_mut().zip(&self.heads) {
            let p = &self.programs[*pi];
            view.color =
                links.iter().map(|&l| p.color(l)).max_by_key(|&c| rank(c)).unwrap_or(LightColor::Off);
        }
    }

    /// Sets light `tl_id` to a SUMO state string (one character per link index), overriding its
    /// program from now on; returns false if the light is unknown.
    pub fn set_external(&mut self, tl_id: &str, state: &str) -> bool {
        let Some(pi) = self.tl_ids.iter().position(|t| t == tl_id) else { return false };
        let cols: Vec<LightColor> = state.chars().map(LightColor::from_sumo).collect();
        let p = &mut self.programs[pi];
        if p.external.as_ref() == Some(&cols) {
            return true;
        }
        p.external = Some(cols);
        for (view, (hp, links)) in self.views.iter_mut().zip(&self.heads) {
            if *hp == pi {
                let p = &self.programs[pi];
                view.color =
                    links.iter().map(|&l| p.color(l)).max_by_key(|&c| rank(c)).unwrap_or(LightColor::Off);
            }
        }
        true
    }

    pub fn views(&self) -> &[TrafficLightView] {
        &self.views
    }

    /// Current colour of link `link_index` of light `tl_id` (None if the light is unknown).
    pub fn link_color(&self, tl_id: &str, link_index: usize) -> Option<LightColor> {
        let i = self.tl_ids.iter().position(|t| t == tl_id)?;
        Some(self.programs[i].color(link_index))
    }

    /// Current phase index of light `tl_id`.
    pub fn phase(&self, tl_id: &str) -> Option<usize> {
        let i = self.tl_ids.iter().position(|t| t == tl_id)?;
        Some(self.programs[i].phase)
    }
}
