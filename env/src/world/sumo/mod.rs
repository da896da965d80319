//! SUMO co-simulation: the one orchestration of every SUMO transport (docs/traffic.md).
//!
//! [`SumoCoSim`] is the world's [`TrafficModel`] in SUMO mode. It owns the whole exchange: the
//! command line, the warm-up with the ego standing at its start, the replacement light programs
//! and the light sync at t = 0, the ego's and the mirrored scenario actors' placement each tick
//! (and what happens when SUMO cannot place one), departure tracking with keys counted from 0,
//! the type cache, and the conversion to the world's [`TrafficFrame`]. A [`SumoTransport`] only
//! carries the calls: libsumo in this process or TraCI to a `sumo` subprocess (the C++ shim,
//! [`shim`]), or the `libsumo` Python module (the binding crate's fallback). Same scenario, seed
//! and ego motion ⇒ the same traffic on every transport.
//!
//! The process-facing side is a [`SumoSession`] (shared with the binding's handle through
//! [`SharedSession`]): the transport, SUMO's start and stop, the episode's temporary files and
//! the rule that one in-process SUMO (libsumo's global state) runs at a time.

pub mod shim;
pub mod transport;

pub use shim::{Flavour, ShimTransport, SumoHome};
pub use transport::{Placed, SumoTransport, TypeInfo, VehicleState};

use crate::geom::{Pose, Vec2};
use crate::map::{Network, VClass};
use crate::scenario::traffic::{kind_of_vclass, mirror_specs, MirrorSpec, TrafficDemand};
use crate::scenario::{LightProgram, ResolvedEgo, ResolvedScenario, PALETTE};
use crate::view::ActorKind;
use crate::world::{TrafficAgent, TrafficFrame, TrafficInput, TrafficModel};
use crate::{Error, Result};
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

/// SUMO's step, s (the world's tick).
pub const STEP_LENGTH_S: f64 = crate::DT_S;
pub const EGO_ID: &str = crate::scenario::traffic::SUMO_EGO_ID;
pub const EGO_ROUTE: &str = crate::scenario::traffic::SUMO_EGO_ROUTE;
/// The ego counts as on its route within this distance of the route line (the route's edges
/// span a few lanes either side), m.
const EGO_ON_ROUTE_M: f64 = 5.0;
/// What a second in-process SUMO gets.
pub const ONE_PER_PROCESS: &str = "libsumo runs one simulation per process and another SUMO env in this \
     process is running; close it first, use sumo_backend=\"auto\" or \"traci\" (SUMO as a subprocess), or \
     vectorise SUMO envs over processes (gymnasium.vector.AsyncVectorEnv)";

/// One in-process SUMO (libsumo, shim or Python module) runs at a time.
static IN_PROCESS_BUSY: AtomicBool = AtomicBool::new(false);
static TMP_SEQ: AtomicU64 = AtomicU64::new(0);

/// Whether an in-process SUMO simulation (libsumo) runs in this process.
pub fn in_process_busy() -> bool {
    IN_PROCESS_BUSY.load(Ordering::SeqCst)
}

/// A traffic vehicle's attributes that do not change (read once, when it departs).
#[derive(Debug, Clone, Copy)]
pub struct Static {
    pub key: u64,
    pub kind: ActorKind,
    pub length_m: f64,
    pub width_m: f64,
    pub height_m: f64,
    pub color: [u8; 3],
    /// SUMO vClass `emergency`: its beacons flash in the pictures.
    pub emergency: bool,
}

impl Static {
    /// From SUMO's type attributes; SUMO's default colour (yellow) gets a palette colour.
    pub fn new(key: u64, t: &TypeInfo) -> Static {
        let kind = kind_of_vclass(VClass::from_sumo(&t.vclass).unwrap_or(VClass::Passenger));
        let c = t.color;
        let color = if c != [255, 255, 0, 255] {
            [c[0].clamp(0, 255) as u8, c[1].clamp(0, 255) as u8, c[2].clamp(0, 255) as u8]
        } else {
            PALETTE[key as usize % PALETTE.len()]
        };
        let emergency = t.vclass == "emergency";
        Static { key, kind, length_m: t.length_m, width_m: t.width_m, height_m: t.height_m, color, emergency }
    }

    /// The world's agent from SUMO's front-bumper position and SUMO angle (degrees, clockwise
    /// from north).
    pub fn agent(&self, v: &VehicleState) -> TrafficAgent {
        let yaw = (90.0 - v.angle).to_radians();
        let fwd = Vec2::new(yaw.cos(), yaw.sin());
        let centre = Vec2::new(v.x, v.y) - fwd * (0.5 * self.length_m);
        TrafficAgent {
            key: self.key,
            kind: self.kind,
            length_m: self.length_m,
            width_m: self.width_m,
            height_m: self.height_m,
            color: self.color,
            emergency: self.emergency,
            pose: Pose::new(centre, crate::geom::wrap_angle(yaw)),
            speed_mps: v.speed.max(0.0),
            signals: v.signals.max(0) as u32,
        }
    }
}

/// One ego/actor placement for SUMO: (id, front x, front y, SUMO angle, speed, moveToXY
/// keepRoute); id 0 is the ego, others are scenario actor ids.
pub type Mover = (u32, f64, f64, f64, f64, u8);

/// The process side of a co-simulation: the transport, SUMO's lifecycle and temporary files.
#[derive(Debug)]
pub struct SumoSession {
    transport: Box<dyn SumoTransport>,
    sumo_binary: PathBuf,
    extra_args: Vec<String>,
    running: bool,
    claimed: bool,
    tmp: Option<PathBuf>,
    /// SUMO steps since the start (warm-up included).
    pub steps: u64,
}

/// A shared handle on a session (the world's model and the binding's handle).
pub type SharedSession = Arc<Mutex<SumoSession>>;

fn lock(s: &SharedSession) -> MutexGuard<'_, SumoSession> {
    s.lock().unwrap_or_else(|p| p.into_inner())
}

impl SumoSession {
    pub fn new(
        transport: Box<dyn SumoTransport>,
        sumo_binary: PathBuf,
        extra_args: Vec<String>,
    ) -> SumoSession {
        SumoSession {
            transport,
            sumo_binary,
            extra_args,
            running: false,
            claimed: false,
            tmp: None,
            steps: 0,
        }
    }

    pub fn shared(self) -> SharedSession {
        Arc::new(Mutex::new(self))
    }

    /// The transport's kind ("libsumo", "libsumo-python", "traci").
    pub fn transport_kind(&self) -> &'static str {
        self.transport.kind()
    }

    pub fn running(&self) -> bool {
        self.running
    }

    /// SUMO's time, s (0 when not running).
    pub fn sumo_time_s(&mut self) -> f64 {
        if self.running {
            self.transport.time_s().unwrap_or(0.0)
        } else {
            0.0
        }
    }

    /// Stops SUMO (idempotent); the next start starts a fresh simulation.
    pub fn close(&mut self) {
        if self.running {
            self.running = false;
            self.transport.close();
        }
        if self.claimed {
            self.claimed = false;
            IN_PROCESS_BUSY.store(false, Ordering::SeqCst);
        }
        if let Some(tmp) = self.tmp.take() {
            let _ = std::fs::remove_dir_all(tmp);
        }
    }

    /// Starts SUMO on `net` with the episode's routes and seed.
    fn start(&mut self, net: &Path, routes_xml: &str, seed: u64) -> Result<()> {
        self.close();
        if self.transport.in_process() {
            if IN_PROCESS_BUSY.swap(true, Ordering::SeqCst) {
                return Err(Error::Simulation(ONE_PER_PROCESS.into()));
            }
            self.claimed = true;
        }
        let tmp = std::env::temp_dir().join(format!(
            "dh_sumo_{}_{}",
            std::process::id(),
            TMP_SEQ.fetch_add(1, Ordering::SeqCst)
        ));
        self.tmp = Some(tmp.clone());
        let routes = tmp.join("traffic.rou.xml");
        if let Err(e) = std::fs::create_dir_all(&tmp).and_then(|()| std::fs::write(&routes, routes_xml)) {
            self.close();
            return Err(Error::Simulation(format!("SUMO co-simulation: {}: {e}", tmp.display())));
        }
        let errlog = tmp.join("sumo_errors.log");
        let path = |p: &Path| p.to_string_lossy().into_owned();
        let mut cmd: Vec<String> = vec![path(&self.sumo_binary)];
        for (k, v) in [
            ("--net-file", path(net)),
            ("--route-files", path(&routes)),
            ("--step-length", STEP_LENGTH_S.to_string()),
            ("--seed", (seed % (1 << 31)).to_string()),
            ("--begin", "0".into()),
            ("--collision.action", "none".into()),
            ("--no-step-log", "true".into()),
            ("--no-warnings", "true".into()),
            ("--error-log", path(&errlog)),
        ] {
            cmd.push(k.into());
            cmd.push(v);
        }
        cmd.extend(self.extra_args.iter().cloned());
        if let Err(exc) = self.transport.start(&cmd) {
            let said = std::fs::read_to_string(&errlog).unwrap_or_default();
            let said = said.trim();
            self.close();
            let mut msg = format!("SUMO failed to start on {}: {exc}", net.display());
            if !said.is_empty() {
                msg.push_str("\nSUMO said:\n");
                msg.push_str(said);
            }
            return Err(Error::Simulation(msg));
        }
        self.running = true;
        self.steps = 0;
        Ok(())
    }
}

impl Drop for SumoSession {
    fn drop(&mut self) {
        self.close();
    }
}

/// The world's SUMO-mode traffic: the scenario's side (net, demand, ego route, mirrored actors,
/// light programs) and the episode's state, over a shared [`SumoSession`].
#[derive(Debug)]
pub struct SumoCoSim {
    session: SharedSession,
    net: PathBuf,
    map: Arc<Network>,
    demand: TrafficDemand,
    ego: ResolvedEgo,
    mirrors: Vec<MirrorSpec>,
    /// The scenario's `[[lights]]` overrides.
    programs: Vec<LightProgram>,
    movers: Vec<Mover>,
    /// Scenario actor ids with a SUMO double.
    in_sumo: BTreeSet<u32>,
    /// Ego (0) / actor ids out of SUMO because SUMO could not place them.
    out: BTreeSet<u32>,
    vehicles: HashMap<u64, Static>,
    types: HashMap<String, TypeInfo>,
    next_key: u64,
    light_ids: Vec<String>,
    lights: Vec<String>,
    new_lights: Vec<String>,
    departed: Vec<String>,
    raw: Vec<VehicleState>,
}

impl SumoCoSim {
    pub fn new(session: SharedSession, scenario: &ResolvedScenario) -> SumoCoSim {
        SumoCoSim {
            session,
            net: scenario.map_path.clone(),
            map: scenario.map.clone(),
            demand: scenario.traffic.clone(),
            ego: scenario.ego.clone(),
            mirrors: mirror_specs(&scenario.actors),
            programs: scenario.lights.clone(),
            movers: Vec::new(),
            in_sumo: BTreeSet::new(),
            out: BTreeSet::new(),
            vehicles: HashMap::new(),
            types: HashMap::new(),
            next_key: 0,
            light_ids: Vec::new(),
            lights: Vec::new(),
            new_lights: Vec::new(),
            departed: Vec::new(),
            raw: Vec::new(),
        }
    }

    /// The SUMO route file of an episode.
    pub fn routes_xml(&self, seed: u64, variation_seed: u64) -> String {
        self.demand.varied(variation_seed).sumo_routes_xml(&self.map, seed, &self.ego, &self.mirrors)
    }

    /// For each light, the phase and its remaining time that its program (the map's, or the
    /// scenario's `[[lights]]` override) has at episode t = 0: SUMO runs `warmup_s` before
    /// t = 0, so its lights are set to this at the end of the warm-up and then show what the
    /// world's own light model would.
    pub fn light_sync(&self) -> Vec<(String, usize, f64)> {
        let mut out = Vec::new();
        for tl in self.map.tl_ids() {
            let program = match self.programs.iter().find(|p| p.tl_id == tl) {
                Some(p) => p.clone(),
                None => {
                    let Some(logic) = self.map.tl_logic(tl) else { continue };
                    LightProgram {
                        tl_id: tl.to_string(),
                        offset_s: logic.offset_s,
                        phases: logic.phases.clone(),
                        replaced: false,
                    }
                }
            };
            if let Some((i, left)) = program.phase_at(0.0) {
                out.push((tl.to_string(), i, left));
            }
        }
        out
    }

    /// Replacement programs for SUMO: (light, [(state, s)]).
    pub fn replaced_programs(&self) -> Vec<(String, Vec<(String, f64)>)> {
        self.programs
            .iter()
            .filter(|p| p.replaced)
            .map(|p| (p.tl_id.clone(), p.phases.iter().map(|ph| (ph.state.clone(), ph.duration_s)).collect()))
            .collect()
    }

    /// Movers for SUMO. The ego near its route is mapped onto the route's edges only
    /// (keepRoute=1, several times cheaper than SUMO's search of the whole net); elsewhere, and
    /// for the scenario's actors, onto any lane, or off the network (keepRoute=2).
    fn fill_movers(&mut self, input: &TrafficInput<'_>) {
        self.movers.clear();
        let sumo = |id: u32, pose: Pose, length: f64, speed: f64, keep: u8| {
            let front = pose.pos + pose.forward() * (0.5 * length);
            (id, front.x, front.y, 90.0 - pose.yaw.to_degrees(), speed, keep)
        };
        let e = input.ego;
        let on_route = self.ego.route.project(e.pose.pos).is_some_and(|p| p.distance <= EGO_ON_ROUTE_M);
        self.movers.push(sumo(0, e.pose, e.length_m, e.speed_mps, if on_route { 1 } else { 2 }));
        for a in input.actors {
            if self.mirrors.binary_search_by_key(&a.id, |m| m.id).is_ok() {
                self.movers.push(sumo(a.id, a.pose, a.length_m, a.speed_mps, 2));
            }
        }
    }

    /// Places the ego and the mirrored actors. A body SUMO cannot place (off its network, too
    /// far from a lane its class may use) leaves SUMO and is added back, at its new place, as
    /// soon as SUMO can place it again: no agent behaviour stops the episode.
    fn move_all(&mut self, t: &mut dyn SumoTransport) -> Result<()> {
        if self.movers.len().saturating_sub(1) != self.in_sumo.len() {
            // A scenario actor left the world: its SUMO double leaves too.
            let present: BTreeSet<u32> = self.movers.iter().map(|m| m.0).collect();
            let gone: Vec<u32> = self.in_sumo.difference(&present).copied().collect();
            for ident in gone {
                if !self.out.remove(&ident) {
                    t.remove(&mirror_id(ident))?;
                }
                self.in_sumo.remove(&ident);
            }
        }
        for &(ident, x, y, angle, _speed, keep) in &self.movers {
            let vid = if ident == 0 { EGO_ID.to_string() } else { mirror_id(ident) };
            let vtype = vid.as_str(); // the ego's type is "dh_ego", an actor's its own id
            if ident != 0 && !self.in_sumo.contains(&ident) {
                t.add(&vid, EGO_ROUTE, vtype)?;
                self.in_sumo.insert(ident);
            }
            if self.out.contains(&ident) {
                // Out of SUMO since it could not be placed: try again at its new place.
                if t.add(&vid, EGO_ROUTE, vtype).is_err() {
                    continue;
                }
                self.out.remove(&ident);
            }
            // keepRoute=1 maps onto SUMO's copy of the ego's route, which an earlier keepRoute=2
            // placement replaced by the edges it was placed on: then it is placed anywhere.
            let placed = match t.move_to_xy(&vid, x, y, angle, keep)? {
                Placed::Unmappable if keep == 1 => t.move_to_xy(&vid, x, y, angle, 2)?,
                p => p,
            };
            if placed == Placed::Unmappable {
                // SUMO may already have dropped it.
                let _ = t.remove(&vid);
                self.out.insert(ident);
            }
        }
        Ok(())
    }

    /// Moves the bodies, steps SUMO once and tracks the departures.
    fn step(&mut self, s: &mut SumoSession) -> Result<()> {
        if !s.running {
            return Err(Error::Simulation(
                "SUMO is not running (the traffic was closed); call reset()".into(),
            ));
        }
        let t = s.transport.as_mut();
        self.move_all(t)?;
        t.step(&mut self.departed)?;
        s.steps += 1;
        for vid in &self.departed {
            // Our own bodies (ego, mirrors) are "dh_*".
            if vid.starts_with("dh_") {
                continue;
            }
            let vtype = t.vehicle_type(vid)?;
            if !self.types.contains_key(&vtype) {
                let info = t.type_info(&vtype)?;
                self.types.insert(vtype.clone(), info);
            }
            let key = self.next_key;
            self.next_key += 1;
            self.vehicles.insert(key, Static::new(key, &self.types[&vtype]));
            t.track(vid, key)?;
        }
        Ok(())
    }

    /// The vehicles and the changed light states after a step.
    fn read(&mut self, t: &mut dyn SumoTransport, out: &mut TrafficFrame) -> Result<()> {
        t.read(&mut self.raw)?;
        for v in &self.raw {
            if let Some(st) = self.vehicles.get(&v.key) {
                out.agents.push(st.agent(v));
            }
        }
        t.light_states(&mut self.new_lights)?;
        self.lights.resize(self.light_ids.len(), String::new());
        for ((tl, old), new) in self.light_ids.iter().zip(self.lights.iter_mut()).zip(&self.new_lights) {
            if old != new {
                out.lights.push((tl.clone(), new.clone()));
                old.clone_from(new);
            }
        }
        Ok(())
    }
}

fn mirror_id(ident: u32) -> String {
    format!("dh_actor_{ident}")
}

impl TrafficModel for SumoCoSim {
    fn start(&mut self, input: &TrafficInput<'_>, seed: u64, out: &mut TrafficFrame) -> Result<()> {
        self.vehicles.clear();
        self.types.clear();
        self.next_key = 0;
        self.in_sumo.clear();
        self.out.clear();
        self.lights.clear();
        let routes = self.routes_xml(seed, input.variation_seed);
        self.fill_movers(input);
        let session = self.session.clone();
        let mut s = lock(&session);
        s.start(&self.net, &routes, seed)?;
        let t = s.transport.as_mut();
        self.light_ids = t.light_ids()?;
        for (tl, phases) in self.replaced_programs() {
            if !self.light_ids.contains(&tl) {
                return Err(Error::Simulation(format!("light override: SUMO has no traffic light {tl:?}")));
            }
            t.set_program(&tl, &phases)?;
        }
        t.add(EGO_ID, EGO_ROUTE, EGO_ID)?;
        // Ties to even (as Python's round, which the first implementation used).
        let warmup = (self.demand.warmup_s / STEP_LENGTH_S).round_ties_even() as u64;
        for _ in 0..warmup {
            self.step(&mut s)?;
        }
        // Also without a warm-up: `[[lights]]` overrides start where the world's model does.
        let t = s.transport.as_mut();
        for (tl, phase, remaining) in self.light_sync() {
            if self.light_ids.contains(&tl) {
                t.set_phase(&tl, phase, remaining)?;
            }
        }
        self.read(t, out)
    }

    fn tick(&mut self, input: &TrafficInput<'_>, out: &mut TrafficFrame) -> Result<()> {
        self.fill_movers(input);
        let session = self.session.clone();
        let mut s = lock(&session);
        self.step(&mut s)?;
        self.read(s.transport.as_mut(), out)
    }

    fn drives_lights(&self) -> bool {
        true
    }

    fn name(&self) -> &str {
        "sumo"
    }
}
