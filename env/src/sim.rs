//! One R4 episode: world + route tracker + actuation bridge + score tracker + renderers, stepped
//! one decision at a time. This is what the Python env wraps (one coarse call per decision).
//!
//! Decision timing, as the original runner does it: `reset` plays `warmup_ticks` (4) ticks with
//! zero control and returns the state after them; the policy is asked then (the original's
//! "tick 5") and after every `decision_interval_ticks` (5) ticks; the control computed at a
//! decision is held until the next. `warmup_ticks = 0` asks at t = 0 instead.
//!
//! A decision is an action array, or a raw VLM reply parsed by the caller (`Action::Reply`):
//! a reply without a usable decision, or no reply at all, holds the previous control verbatim
//! and counts as a parse failure (docs/protocol.md#r4-actuation). Every decision is logged (`decision_log`).

use crate::drive::meta::MetaResolver;
use crate::drive::prompt_levels::{meta_prompt, waypoint_prompt};
use crate::drive::tracker::{DEFAULT_WAYPOINTS, DEFAULT_WAYPOINT_DT_S};
use crate::drive::{
    decision_prompt, navigation_command, ActuationBridge, Command, Control, Decision, DecisionFailure, Plan,
    RouteTracker, RouteView, TrackerGains, TrackingError, WaypointTracker,
};
use crate::geom::{wrap_angle, Pose, Vec2};
use crate::render::{Ambience, BevConfig, CameraConfig, FrameInput, Image, RenderMap};
use crate::scenario::{LoadOptions, ResolvedScenario, Scenario};
use crate::score::{
    Contact, RunFooter, RunHeader, RunInfo, RunLog, SceneScore, ScoreParams, ScoreTracker, TickInput,
    TrajectorySample,
};
use crate::view::{ActorView, LightColor, SignView, TrafficLightView};
use crate::world::{TrafficModel, World};
use crate::{Error, Result, DECISION_INTERVAL_TICKS};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock, Weak};
use std::time::Instant;

/// How actions are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionMode {
    /// `[steer, target_speed_mps]` through the protocol's actuation bridge (what a VLM sends).
    Decision,
    /// `[throttle, brake, steer]` applied as is (for RL).
    Raw,
    /// K ego-frame points (x forward, y left) at fixed time steps, driven by the waypoint
    /// tracker (docs/r4.md#action-levels; this project's extension of the protocol).
    Waypoints,
    /// A path action × a speed action, resolved on the lane graph into waypoints for the
    /// same tracker (docs/r4.md#action-levels; this project's extension of the protocol).
    Meta,
}

impl ActionMode {
    /// Whether the mode's decisions are plans driven by the waypoint tracker.
    pub fn is_plan(self) -> bool {
        matches!(self, ActionMode::Waypoints | ActionMode::Meta)
    }
}

/// Runtime settings of an episode (the Python `R4Config` minus the scenario).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    pub action_mode: ActionMode,
    pub decision_interval_ticks: u32,
    /// Ticks played with zero control before the first decision (the original: 4).
    #[serde(default = "default_warmup_ticks")]
    pub warmup_ticks: u32,
    /// Front camera of the observation; `None` = no image.
    pub front: Option<CameraConfig>,
    /// Bird's-eye view of the observation; `None` = no image.
    pub bev: Option<BevConfig>,
    /// Build the VLM prompt text for each observation.
    pub prompt: bool,
    /// Light and weather for every episode, overriding the scenario's `[conditions]` and its
    /// per-seed draw (a robustness control): a name such as `night`, `fog` or `dusk+rain`
    /// ([`crate::conditions::Conditions::parse`]). `None`: the scenario's.
    #[serde(default)]
    pub conditions: Option<String>,
    /// A fault of the observation's front camera (a robustness control); `None`: none.
    #[serde(default)]
    pub camera_fault: Option<crate::render::CameraFault>,
    /// Waypoint level: points per plan and seconds between them (also the meta level's plan).
    #[serde(default = "default_waypoints")]
    pub waypoints: u32,
    #[serde(default = "default_waypoint_dt_s")]
    pub waypoint_dt_s: f64,
}

fn default_waypoints() -> u32 {
    DEFAULT_WAYPOINTS as u32
}
fn default_waypoint_dt_s() -> f64 {
    DEFAULT_WAYPOINT_DT_S
}

/// Most points a waypoint plan may have.
pub const MAX_WAYPOINTS: u32 = 64;

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            action_mode: ActionMode::Decision,
            decision_interval_ticks: DECISION_INTERVAL_TICKS,
            warmup_ticks: WARMUP_TICKS,
            front: Some(CameraConfig::default()),
            bev: Some(BevConfig::default()),
            prompt: true,
            conditions: None,
            camera_fault: None,
            waypoints: default_waypoints(),
            waypoint_dt_s: default_waypoint_dt_s(),
        }
    }
}

/// The original runner applies zero control on ticks 1–4 and first asks the policy at tick 5.
pub const WARMUP_TICKS: u32 = 4;

fn default_warmup_ticks() -> u32 {
    WARMUP_TICKS
}

impl SimConfig {
    pub fn from_json(text: &str) -> Result<SimConfig> {
        let cfg: SimConfig = json_config("config", text)?;
        cfg.validate()?;
        Ok(cfg)
    }

    pub fn validate(&self) -> Result<()> {
        if self.decision_interval_ticks == 0 {
            return Err(Error::config("decision_interval_ticks", 0, "must be ≥ 1"));
        }
        if self.waypoints == 0 || self.waypoints > MAX_WAYPOINTS {
            return Err(Error::config(
                "waypoints",
                self.waypoints,
                format!("must be in 1..={MAX_WAYPOINTS}"),
            ));
        }
        if !(self.waypoint_dt_s.is_finite() && self.waypoint_dt_s > 0.0 && self.waypoint_dt_s <= 10.0) {
            return Err(Error::config("waypoint_dt_s", self.waypoint_dt_s, "must be in (0, 10] seconds"));
        }
        if let Some(c) = &self.front {
            c.validate()?;
        }
        if let Some(b) = &self.bev {
            b.validate()?;
        }
        self.conditions_override()?;
        Ok(())
    }
}

impl SimConfig {
    /// The parsed `conditions` override.
    pub fn conditions_override(&self) -> Result<Option<crate::conditions::Conditions>> {
        match &self.conditions {
            None => Ok(None),
            Some(n) => crate::conditions::Conditions::parse(n)
                .map(Some)
                .map_err(|e| Error::config("conditions", n, e)),
        }
    }
}

/// Parses a JSON setting, naming the offending field (`config.front.width`) on error.
pub fn json_config<T: serde::de::DeserializeOwned>(what: &str, text: &str) -> Result<T> {
    let de = &mut serde_json::Deserializer::from_str(text);
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let field = if path == "." || path.is_empty() { what.to_owned() } else { format!("{what}.{path}") };
        Error::config(field, text, e.into_inner().to_string())
    })
}

/// An action of either mode.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    Decision(Decision),
    Raw(Control),
    /// A VLM reply (decision mode): `raw` as received (`None`: no reply, e.g. a transport
    /// error) and what the reply parser made of it. A failure holds the previous control.
    Reply {
        raw: Option<String>,
        parsed: std::result::Result<Decision, DecisionFailure>,
    },
    /// A plan of the `waypoints` (x forward, y left points) or `meta` level.
    Plan(Plan),
    /// A VLM reply of the `waypoints` or `meta` level, parsed by the caller; a failure holds
    /// the last plan and counts as a parse failure.
    PlanReply {
        raw: Option<String>,
        parsed: std::result::Result<Plan, DecisionFailure>,
    },
}

/// One decision of an episode, as logged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DecisionRecord {
    /// 1-based decision count (the `n` of the original's `Q(frame n)`).
    pub decision: u64,
    /// Tick after which the decision was asked for (4, 9, 14, … with the default warm-up).
    pub tick: u64,
    /// The raw reply, for reply actions.
    pub raw: Option<String>,
    /// The decision applied (for array actions, the array; `None` for raw-control actions).
    pub parsed: Option<Decision>,
    pub failure: Option<DecisionFailure>,
    /// The control held until the next decision (plan levels: the tracker's first control).
    pub control: Control,
    /// Plan levels: the plan applied (`None` when the reply had none: the last plan was held).
    /// In a step's `info` only for replies: an array action's plan is the action itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plan: Option<Plan>,
    /// Plan levels: how well the tracker followed the plan over this decision's ticks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracking: Option<TrackingError>,
}

/// Names of the entries of [`Observation::state`], in order.
pub const STATE_FIELDS: &[&str] = &[
    "speed_mps",
    "steer",
    "throttle",
    "brake",
    "progress_m",
    "route_length_m",
    "distance_to_go_m",
    "command",
    "time_s",
    "on_road",
    "lateral_offset_m",
    "heading_error_rad",
    "route_p1_forward_m",
    "route_p1_right_m",
    "route_p2_forward_m",
    "route_p2_right_m",
    "route_p3_forward_m",
    "route_p3_right_m",
    "route_p4_forward_m",
    "route_p4_right_m",
    "route_p5_forward_m",
    "route_p5_right_m",
    "route_p6_forward_m",
    "route_p6_right_m",
    "route_p7_forward_m",
    "route_p7_right_m",
    "route_p8_forward_m",
    "route_p8_right_m",
    "actor1_present",
    "actor1_forward_m",
    "actor1_right_m",
    "actor1_speed_mps",
    "actor1_heading_rad",
    "actor2_present",
    "actor2_forward_m",
    "actor2_right_m",
    "actor2_speed_mps",
    "actor2_heading_rad",
    "actor3_present",
    "actor3_forward_m",
    "actor3_right_m",
    "actor3_speed_mps",
    "actor3_heading_rad",
    "actor4_present",
    "actor4_forward_m",
    "actor4_right_m",
    "actor4_speed_mps",
    "actor4_heading_rad",
    "actor5_present",
    "actor5_forward_m",
    "actor5_right_m",
    "actor5_speed_mps",
    "actor5_heading_rad",
    "actor6_present",
    "actor6_forward_m",
    "actor6_right_m",
    "actor6_speed_mps",
    "actor6_heading_rad",
    "light_ahead_distance_m",
    "light_ahead_stop",
];
const NEAREST_ACTORS: usize = 6;
/// Lights and actors farther than this along the route are "none" in the state vector.
const STATE_HORIZON_M: f64 = 100.0;
/// A signal head belongs to the route when its stop line lies this close to the route line.
const LIGHT_ON_ROUTE_M: f64 = 2.0;

/// What the agent sees after a reset or a step.
#[derive(Debug, Clone)]
pub struct Observation {
    pub front: Option<Image>,
    pub bev: Option<Image>,
    pub prompt: String,
    pub state: Vec<f32>,
}

/// Everything about one decision step.
#[derive(Debug, Clone)]
pub struct StepOutcome {
    pub observation: Observation,
    /// Gain in S_route / 100; the terminal step adds (S_R4 − S_route) / 100, so an episode's
    /// rewards sum to S_R4 / 100.
    pub reward: f64,
    pub terminated: bool,
    pub info: StepInfo,
}

/// The per-step `info` of the env.
#[derive(Debug, Clone, Serialize)]
pub struct StepInfo {
    pub tick: u64,
    pub time_s: f64,
    /// Sim time at which the scenario timeout ends the episode (2 × the scenario duration).
    pub time_limit_s: f64,
    /// `time_limit_s - time_s`, floored at 0: what an RL critic needs to bootstrap near the limit.
    pub time_left_s: f64,
    pub decision: u64,
    pub command: u8,
    /// Best progress along the route so far (what S_route counts), metres.
    pub best_progress_m: f64,
    pub route_length_m: f64,
    pub distance_to_go_m: f64,
    pub on_road: bool,
    pub speed_mps: f64,
    pub control: Control,
    /// Contacts during this step's ticks (actor id, class).
    pub contacts: Vec<Contact>,
    pub termination_reason: Option<String>,
    /// Running score terms (final once terminated).
    pub score_route: f64,
    pub score_composed: Option<f64>,
    /// Events recorded so far (collisions, timeouts, ...).
    pub events: Vec<crate::score::Event>,
    /// SHA-256 over the bits of every tick's ego state and contacts so far.
    pub trajectory_hash: String,
    /// The decision this step applied (`None` after `reset`).
    pub reply: Option<DecisionRecord>,
    /// Decisions whose reply had no usable decision so far.
    pub parse_failures: u64,
}

/// A running R4 episode.
#[derive(Debug)]
pub struct Sim {
    scenario: ResolvedScenario,
    config: SimConfig,
    params: ScoreParams,
    /// Built at load when observations carry images, else on the first render call (then kept:
    /// rebuilding it per call costs milliseconds on a city net).
    render_map: OnceLock<Arc<RenderMap>>,
    tracker: RouteTracker,
    /// (arc length on the route, index into the world's light views) of the route's signal heads.
    route_lights: Vec<(f64, usize)>,
    episode: Option<Episode>,
    /// Background-traffic model for the next episode (moves into its world at reset).
    traffic: Option<Box<dyn TrafficModel>>,
}

#[derive(Debug)]
struct Episode {
    world: World,
    bridge: ActuationBridge,
    /// Plan levels: the waypoint tracker and the replies without a usable plan.
    tracker: WaypointTracker,
    /// Meta level: the lane-graph resolution's memo for this episode's route.
    meta: MetaResolver,
    plan_failures: u64,
    score: ScoreTracker,
    seed: u64,
    /// The ego's start in this episode (varied by the seed).
    start: crate::geom::Vec2,
    samples: Vec<TrajectorySample>,
    hasher: Sha256,
    control: Control,
    decisions: u64,
    decision_log: Vec<DecisionRecord>,
    start_on_road: bool,
    on_road: bool,
    last_route_score: f64,
    started: Instant,
    terminated: bool,
    /// The terminal step has been returned to the caller (an episode can end during warm-up;
    /// the first `step` then reports it without ticking).
    terminal_reported: bool,
    /// Light and weather of this episode.
    conditions: crate::conditions::Conditions,
    /// The front image the camera-fault control last delivered (frozen and dropped frames
    /// repeat it); behind a lock because observing does not change the episode otherwise.
    fault_frame: std::sync::Mutex<Option<Image>>,
}

impl Episode {
    fn ambience(&self) -> Ambience {
        Ambience { conditions: self.conditions, seed: self.seed, tick: self.world.tick_count() }
    }
}

impl Sim {
    /// Loads a scenario file and prepares (but does not start) an episode.
    pub fn new(scenario_path: &Path, config: SimConfig, load: &LoadOptions) -> Result<Sim> {
        config.validate()?;
        let scenario = Scenario::load_with(scenario_path, load)?;
        Self::from_scenario(scenario, config)
    }

    pub fn from_scenario(scenario: ResolvedScenario, config: SimConfig) -> Result<Sim> {
        config.validate()?;
        let render_map = OnceLock::new();
        if config.front.is_some() || config.bev.is_some() {
            let _ = render_map.set(shared_render_map(&scenario.map));
        }
        let tracker = RouteTracker::new(scenario.ego.route.clone());
        Ok(Sim {
            scenario,
            config,
            params: ScoreParams::default(),
            render_map,
            tracker,
            route_lights: Vec::new(),
            episode: None,
            traffic: None,
        })
    }

    pub fn scenario(&self) -> &ResolvedScenario {
        &self.scenario
    }
    pub fn config(&self) -> &SimConfig {
        &self.config
    }
    /// The world of the running episode.
    pub fn world(&self) -> Result<&World> {
        self.episode.as_ref().map(|e| &e.world).ok_or_else(not_started)
    }
    pub fn route(&self) -> &crate::geom::Polyline {
        self.tracker.route()
    }
    /// The episode has ended (possibly during the warm-up, before the caller was told).
    pub fn is_terminated(&self) -> bool {
        self.episode.as_ref().is_some_and(|e| e.terminated)
    }

    /// Starts a new episode from t = 0 and plays the warm-up ticks with zero control.
    pub fn reset(&mut self, seed: u64) -> Result<(Observation, StepInfo)> {
        self.reset_varied(seed, seed)
    }

    /// [`Sim::reset`] with the world (SUMO, random trips) seeded by `seed` and the scenario
    /// varied by `variation` ([`ResolvedScenario::varied`]; 0 = as written).
    pub fn reset_varied(&mut self, seed: u64, variation: u64) -> Result<(Observation, StepInfo)> {
        let scenario = self.scenario.varied(variation);
        let conditions = self.config.conditions_override()?.unwrap_or(scenario.conditions);
        let mut world = World::new(&scenario, seed)?;
        world.set_variation_seed(variation);
        self.start_traffic(&mut world)?;
        let route = self.tracker.route().clone();
        let start = scenario.ego.start.pos;
        let on_road = self.scenario.map.drivable().is_drivable(start);
        let score = ScoreTracker::new(
            route.clone(),
            start,
            self.scenario.ego.destination,
            self.scenario.reference_duration_given_s,
            self.params.clone(),
        )?
        .with_scenario_duration(Some(self.scenario.scenario_duration_s()))?
        .with_start_on_road(on_road);
        self.route_lights = route_lights(&route, world.lights());
        self.episode = Some(Episode {
            world,
            bridge: ActuationBridge::new(),
            tracker: WaypointTracker::new(TrackerGains::default()),
            meta: MetaResolver::new(),
            plan_failures: 0,
            score,
            seed,
            start,
            samples: Vec::with_capacity(1024),
            hasher: Sha256::new(),
            control: Control::default(),
            decisions: 0,
            decision_log: Vec::new(),
            start_on_road: on_road,
            on_road,
            last_route_score: 0.0,
            started: Instant::now(),
            terminated: false,
            terminal_reported: false,
            conditions,
            fault_frame: std::sync::Mutex::new(None),
        });
        let warmup = self.config.warmup_ticks;
        if warmup > 0 {
            let ep = self.episode.as_mut().ok_or_else(not_started)?;
            run_ticks(ep, Control::default(), warmup)?;
        }
        let obs = self.observe()?;
        let info = self.info(Vec::new(), None)?;
        Ok((obs, info))
    }

    /// Applies one action and advances `decision_interval_ticks` ticks (fewer if the episode
    /// ends on the way). If the episode ended during the warm-up, the first call reports that
    /// end without ticking.
    pub fn step(&mut self, action: Action) -> Result<StepOutcome> {
        let mode = self.config.action_mode;
        let interval = self.config.decision_interval_ticks;
        let ep = self.episode.as_mut().ok_or_else(not_started)?;
        if ep.terminal_reported {
            return Err(Error::Simulation(
                "the episode has ended (terminated); call reset() before step()".into(),
            ));
        }
        let mut step_contacts = Vec::new();
        let mut reply = None;
        if !ep.terminated && mode.is_plan() {
            let (raw, plan, failure) = match (mode, action) {
                (ActionMode::Waypoints, Action::Plan(Plan::Waypoints(pts))) => {
                    let want = self.config.waypoints as usize;
                    if pts.len() != want {
                        return Err(Error::config(
                            "action",
                            format!("{} points", pts.len()),
                            format!("expected {want} waypoints (x forward, y left)"),
                        ));
                    }
                    for &(x, y) in &pts {
                        check_finite("action.x", x)?;
                        check_finite("action.y", y)?;
                    }
                    (None, Some(Plan::Waypoints(pts)), None)
                }
                (ActionMode::Meta, Action::Plan(Plan::Meta(m))) => (None, Some(Plan::Meta(m)), None),
                (ActionMode::Waypoints, Action::PlanReply { raw, parsed: Ok(Plan::Waypoints(p)) }) => {
                    (raw, Some(Plan::Waypoints(p)), None)
                }
                (ActionMode::Meta, Action::PlanReply { raw, parsed: Ok(Plan::Meta(m)) }) => {
                    (raw, Some(Plan::Meta(m)), None)
                }
                (_, Action::PlanReply { raw, parsed: Err(f) }) => (raw, None, Some(f)),
                (m, a) => {
                    return Err(Error::config(
                        "action",
                        format!("{a:?}"),
                        format!("the env's action mode is {m:?}"),
                    ))
                }
            };
            match &plan {
                Some(p) => {
                    let ego = *ep.world.ego();
                    let (n, dt) = (self.config.waypoints as usize, self.config.waypoint_dt_s);
                    let pts = match p {
                        Plan::Waypoints(pts) => pts.clone(),
                        Plan::Meta(m) => ep.meta.waypoints(
                            ep.world.map(),
                            self.tracker.route(),
                            &ego.pose,
                            ego.speed_mps,
                            *m,
                            n,
                            dt,
                        ),
                    };
                    ep.tracker.set_plan(ego.pose, &pts, dt);
                }
                None => ep.plan_failures += 1,
            }
            ep.decisions += 1;
            let decision = ep.decisions;
            let tick = ep.world.tick_count();
            let (contacts, first) = run_tracked_ticks(ep, interval)?;
            step_contacts = contacts;
            let record = DecisionRecord {
                decision,
                tick,
                raw,
                parsed: None,
                failure,
                control: first,
                plan,
                tracking: Some(ep.tracker.take_error()),
            };
            // The step's info leaves out a plan that arrived as an array: the caller holds it
            // (and `decision_log()` keeps it), and handing 8 points to Python every decision
            // cost more than tracking them. A reply's plan is news to the caller: it stays.
            let mut echo = record.clone();
            if echo.raw.is_none() {
                echo.plan = None;
            }
            ep.decision_log.push(record);
            reply = Some(echo);
        } else if !ep.terminated {
            let speed = ep.world.ego().speed_mps;
            let (control, raw, parsed, failure) = match (mode, action) {
                (ActionMode::Decision, Action::Decision(d)) => {
                    check_finite("action.steer", d.steer)?;
                    check_finite("action.target_speed_mps", d.target_speed_mps)?;
                    (ep.bridge.apply(Some(d), speed), None, Some(d), None)
                }
                (ActionMode::Decision, Action::Reply { raw, parsed }) => match parsed {
                    // The parser yields finite numbers or ±∞ (which the bridge clips), never NaN.
                    Ok(d) => (ep.bridge.apply(Some(d), speed), raw, Some(d), None),
                    Err(f) => (ep.bridge.apply(None, speed), raw, None, Some(f)),
                },
                (ActionMode::Raw, Action::Raw(c)) => {
                    check_finite("action.throttle", c.throttle)?;
                    check_finite("action.brake", c.brake)?;
                    check_finite("action.steer", c.steer)?;
                    let c = Control {
                        throttle: c.throttle.clamp(0.0, 1.0),
                        brake: c.brake.clamp(0.0, 1.0),
                        steer: c.steer.clamp(-1.0, 1.0),
                    };
                    (c, None, None, None)
                }
                (m, a) => {
                    return Err(Error::config(
                        "action",
                        format!("{a:?}"),
                        format!("the env's action mode is {m:?}"),
                    ))
                }
            };
            ep.control = control;
            ep.decisions += 1;
            let record = DecisionRecord {
                decision: ep.decisions,
                tick: ep.world.tick_count(),
                raw,
                parsed,
                failure,
                control,
                plan: None,
                tracking: None,
            };
            ep.decision_log.push(record.clone());
            reply = Some(record);
            step_contacts = run_ticks(ep, control, interval)?;
        }
        let route_score = self.route_score();
        let ep = self.episode.as_mut().ok_or_else(not_started)?;
        let previous = ep.last_route_score;
        ep.last_route_score = route_score;
        let terminated = ep.terminated;
        ep.terminal_reported = terminated;
        // The terminal step pays up to the (rounded) composed score, so the rewards sum to it.
        let reward = if terminated {
            (self.score_record()?.score_composed - previous) / 100.0
        } else {
            (route_score - previous) / 100.0
        };
        let observation = self.observe()?;
        let info = self.info(step_contacts, reply)?;
        Ok(StepOutcome { observation, reward, terminated, info })
    }

    /// Every decision of the running episode so far.
    pub fn decision_log(&self) -> Result<&[DecisionRecord]> {
        self.episode.as_ref().map(|e| e.decision_log.as_slice()).ok_or_else(not_started)
    }

    /// Sets the background-traffic model used from the next `reset` on (`None`: no traffic).
    pub fn set_traffic(&mut self, model: Option<Box<dyn TrafficModel>>) {
        if let Some(ep) = self.episode.as_mut() {
            ep.world.detach_traffic();
        }
        self.traffic = model;
    }

    /// Name of the traffic model in use ("sumo", "idm"), if any.
    pub fn traffic_name(&self) -> Option<&str> {
        match &self.traffic {
            Some(m) => Some(m.name()),
            None => self.episode.as_ref().and_then(|e| e.world.traffic_name()),
        }
    }

    /// Moves the traffic model (set, or kept from the previous episode) into `world` and starts
    /// it; on failure the model is kept for the next try.
    fn start_traffic(&mut self, world: &mut World) -> Result<()> {
        let model =
            self.traffic.take().or_else(|| self.episode.as_mut().and_then(|e| e.world.detach_traffic()));
        let Some(model) = model else { return Ok(()) };
        let res = world.attach_traffic(model);
        if res.is_err() {
            self.traffic = world.detach_traffic();
        }
        res
    }

    fn route_score(&self) -> f64 {
        self.episode.as_ref().map_or(0.0, |ep| ep.score.route_score())
    }

    /// The scene score record so far (final once terminated).
    pub fn score_record(&self) -> Result<SceneScore> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        Ok(ep.score.finish(&RunInfo {
            scene_id: self.scenario.id.clone(),
            wall_duration_s: ep.started.elapsed().as_secs_f64(),
            decisions: ep.decisions,
            parse_failures: ep.bridge.parse_failures() + ep.plan_failures,
        }))
    }

    /// The run log (header, one sample per tick, end) from which [`crate::score::rescore`]
    /// recomputes the score without simulating.
    pub fn run_log(&self) -> Result<RunLog> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let header = RunHeader::new(
            self.scenario.id.clone(),
            self.tracker.route(),
            ep.start,
            self.scenario.ego.destination,
            self.scenario.reference_duration_given_s,
            self.params.clone(),
        )
        .with_scenario(Some(self.scenario.scenario_duration_s()), ep.start_on_road);
        let footer = RunFooter {
            wall_duration_s: ep.started.elapsed().as_secs_f64(),
            decisions: ep.decisions,
            parse_failures: ep.bridge.parse_failures() + ep.plan_failures,
            stop: None,
        };
        Ok(RunLog { header, samples: ep.samples.clone(), footer })
    }

    /// [`Sim::run_log`] as JSONL text (the `episode_log.jsonl` file).
    pub fn episode_log(&self) -> Result<String> {
        Ok(self.run_log()?.to_jsonl())
    }

    /// Seed of the running episode.
    pub fn seed(&self) -> Result<u64> {
        self.episode.as_ref().map(|e| e.seed).ok_or_else(not_started)
    }

    pub fn trajectory_hash(&self) -> Result<String> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        Ok(hex(&ep.hasher.clone().finalize()))
    }

    /// The route view (progress, distance to go, 8 future points) at the current ego pose.
    pub fn route_view(&self) -> Result<RouteView> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        Ok(self.tracker.future_points(&ep.world.ego().pose))
    }

    /// Renders one camera of the current state into `out` (any config; not the observation's).
    pub fn render_camera(&self, cfg: &CameraConfig, out: &mut Image) -> Result<()> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let map = self.render_map_or_build();
        let route_pts = self.route_points_world(&ep.world.ego().pose);
        let frame = frame_input(ep, &route_pts);
        crate::render::render_camera(&map, &frame, cfg, out)
    }

    /// Renders a BEV of the current state into `out`.
    pub fn render_bev(&self, cfg: &BevConfig, out: &mut Image) -> Result<()> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let map = self.render_map_or_build();
        let route_pts = self.route_points_world(&ep.world.ego().pose);
        let frame = frame_input(ep, &route_pts);
        crate::render::render_bev(&map, &frame, cfg, out)
    }

    /// Every actor the camera sees (pixel box, centre, distance, visible fraction).
    pub fn project_actors(&self, cfg: &CameraConfig) -> Result<Vec<crate::render::ProjectedActor>> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let map = self.render_map_or_build();
        let route_pts = self.route_points_world(&ep.world.ego().pose);
        let frame = frame_input(ep, &route_pts);
        crate::render::project_actors(&map, &frame, cfg)
    }

    /// [`Sim::render_camera`] and [`Sim::project_actors`] from one raster pass.
    pub fn render_and_project(
        &self,
        cfg: &CameraConfig,
        out: &mut Image,
    ) -> Result<Vec<crate::render::ProjectedActor>> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let map = self.render_map_or_build();
        let route_pts = self.route_points_world(&ep.world.ego().pose);
        let frame = frame_input(ep, &route_pts);
        crate::render::render_and_project(&map, &frame, cfg, out)
    }

    /// What the renderers draw of the current state, kept to draw later: the scene at a time
    /// already played renders without replaying the world (and its SUMO) from reset.
    pub fn frame_snapshot(&self) -> Result<FrameSnapshot> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let world = &ep.world;
        Ok(FrameSnapshot {
            map: self.render_map_or_build(),
            ego: *world.ego(),
            actors: world.actors().to_vec(),
            lights: world.lights().to_vec(),
            signs: world.signs().to_vec(),
            route_points: self.route_points_world(&world.ego().pose),
            ambience: ep.ambience(),
        })
    }

    fn render_map_or_build(&self) -> Arc<RenderMap> {
        self.render_map.get_or_init(|| shared_render_map(&self.scenario.map)).clone()
    }

    /// The vertices of the local route slice in the world frame (drawn on the BEV).
    fn route_points_world(&self, ego: &Pose) -> Vec<Vec2> {
        self.tracker.local_slice(ego).points().to_vec()
    }

    fn observe(&self) -> Result<Observation> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let ego = *ep.world.ego();
        let view = self.tracker.future_points(&ego.pose);
        let command = navigation_command(&view.points);
        let prompt = if !self.config.prompt {
            String::new()
        } else {
            let (v, d, p) = (ego.speed_mps, view.distance_to_go_m, &view.points);
            match self.config.action_mode {
                ActionMode::Decision | ActionMode::Raw => decision_prompt(v, command, d, p),
                ActionMode::Waypoints => waypoint_prompt(
                    v,
                    command,
                    d,
                    p,
                    self.config.waypoints as usize,
                    self.config.waypoint_dt_s,
                ),
                ActionMode::Meta => meta_prompt(v, command, d, p),
            }
        };
        let state = self.state_vector(ep, &ego, &view, command);
        let (front, bev) = if self.config.front.is_some() || self.config.bev.is_some() {
            let map = self.render_map_or_build();
            let route_pts = self.route_points_world(&ego.pose);
            let frame = frame_input(ep, &route_pts);
            let front = match &self.config.front {
                Some(cfg) => {
                    let mut img = Image::new(cfg.width, cfg.height);
                    crate::render::render_camera(&map, &frame, cfg, &mut img)?;
                    if let Some(fault) = self.config.camera_fault {
                        let mut last = ep.fault_frame.lock().unwrap_or_else(|p| p.into_inner());
                        fault.apply(&mut img, &mut last, ep.seed, ep.decisions);
                    }
                    Some(img)
                }
                None => None,
            };
            let bev = match &self.config.bev {
                Some(cfg) => {
                    let mut img = Image::new(cfg.size_px, cfg.size_px);
                    crate::render::render_bev(&map, &frame, cfg, &mut img)?;
                    Some(img)
                }
                None => None,
            };
            (front, bev)
        } else {
            (None, None)
        };
        Ok(Observation { front, bev, prompt, state })
    }

    fn state_vector(&self, ep: &Episode, ego: &ActorView, view: &RouteView, command: Command) -> Vec<f32> {
        let route = self.tracker.route();
        let l = route.length();
        let mut s = Vec::with_capacity(STATE_FIELDS.len());
        let proj = route.project(ego.pose.pos);
        let (lateral, heading_err) = match proj {
            Some(p) => (-p.lateral, wrap_angle(ego.pose.yaw - route.heading_at(p.s))),
            None => (0.0, 0.0),
        };
        s.extend_from_slice(&[
            ego.speed_mps,
            ep.control.steer,
            ep.control.throttle,
            ep.control.brake,
            view.progress_m,
            l,
            view.distance_to_go_m.unwrap_or(0.0),
            f64::from(command as u8),
            ep.world.time_s(),
            if ep.on_road { 1.0 } else { 0.0 },
            lateral,
            heading_err,
        ]);
        for i in 0..8 {
            let (f, r) = view.points.get(i).copied().unwrap_or((0.0, 0.0));
            s.push(f);
            s.push(r);
        }
        // Nearest actors by distance (ties by id, so the order is deterministic).
        let mut near: Vec<(f64, &ActorView)> = ep
            .world
            .actors()
            .iter()
            .map(|a| (a.pose.pos.dist(ego.pose.pos), a))
            .filter(|(d, _)| *d <= STATE_HORIZON_M)
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.id.cmp(&b.1.id)));
        for i in 0..NEAREST_ACTORS {
            match near.get(i) {
                Some((_, a)) => {
                    let (f, r) = ego.pose.to_forward_right(a.pose.pos);
                    s.extend_from_slice(&[1.0, f, r, a.speed_mps, wrap_angle(a.pose.yaw - ego.pose.yaw)]);
                }
                None => s.extend_from_slice(&[0.0; 5]),
            }
        }
        let (dist, stop) = self.light_ahead(ep, view.progress_m);
        s.push(dist);
        s.push(stop);
        s.into_iter().map(|v| v as f32).collect()
    }

    /// Distance along the route to the next signal head on it, and 1 if it shows red/yellow.
    fn light_ahead(&self, ep: &Episode, progress_m: f64) -> (f64, f64) {
        let lights = ep.world.lights();
        for &(s, i) in &self.route_lights {
            let d = s - progress_m;
            if d < 0.0 {
                continue;
            }
            if d > STATE_HORIZON_M {
                break;
            }
            let stop = matches!(lights.get(i).map(|l| l.color), Some(LightColor::Red | LightColor::Yellow));
            return (d, if stop { 1.0 } else { 0.0 });
        }
        (STATE_HORIZON_M, 0.0)
    }

    fn info(&self, contacts: Vec<Contact>, reply: Option<DecisionRecord>) -> Result<StepInfo> {
        let ep = self.episode.as_ref().ok_or_else(not_started)?;
        let ego = ep.world.ego();
        let view = self.tracker.future_points(&ego.pose);
        let termination = ep.score.termination();
        let time_limit_s = ep.score.max_sim_time_s();
        Ok(StepInfo {
            tick: ep.world.tick_count(),
            time_s: ep.world.time_s(),
            time_limit_s,
            time_left_s: (time_limit_s - ep.world.time_s()).max(0.0),
            decision: ep.decisions,
            command: navigation_command(&view.points) as u8,
            best_progress_m: ep.score.best_progress_m(),
            route_length_m: ep.score.route_length_m(),
            distance_to_go_m: view.distance_to_go_m.unwrap_or(0.0),
            on_road: ep.on_road,
            speed_mps: ego.speed_mps,
            control: ep.control,
            contacts,
            termination_reason: termination.map(|t| t.reason.as_str().to_owned()),
            score_route: self.route_score(),
            score_composed: if ep.terminated { Some(self.score_record()?.score_composed) } else { None },
            events: ep.score.events().to_vec(),
            trajectory_hash: hex(&ep.hasher.clone().finalize()),
            reply,
            parse_failures: ep.bridge.parse_failures() + ep.plan_failures,
        })
    }
}

/// Advances up to `n` ticks under the waypoint tracker (a control per tick), like [`run_ticks`].
/// Returns the contacts and the first tick's control.
fn run_tracked_ticks(ep: &mut Episode, n: u32) -> Result<(Vec<Contact>, Control)> {
    let mut step_contacts = Vec::new();
    let params = *ep.world.vehicle_params();
    let mut first = None;
    for _ in 0..n {
        let ego = *ep.world.ego();
        let control = ep.tracker.control(&ego.pose, ego.speed_mps, &params);
        first.get_or_insert(control);
        ep.control = control;
        let (contacts, ended) = tick_once(ep, control)?;
        step_contacts.extend(contacts);
        if ended {
            break;
        }
    }
    Ok((step_contacts, first.unwrap_or_default()))
}

/// Advances `n` ticks with `control` held, feeding the score tracker and the log; stops at a
/// termination. Returns the contacts of these ticks.
fn run_ticks(ep: &mut Episode, control: Control, n: u32) -> Result<Vec<Contact>> {
    let mut step_contacts = Vec::new();
    for _ in 0..n {
        let (contacts, ended) = tick_once(ep, control)?;
        step_contacts.extend(contacts);
        if ended {
            break;
        }
    }
    Ok(step_contacts)
}

/// One tick with `control`: the score tracker, the hash and the log; `true` at a termination.
fn tick_once(ep: &mut Episode, control: Control) -> Result<(Vec<Contact>, bool)> {
    {
        let report = ep.world.tick(&control)?;
        let contacts: Vec<Contact> =
            report.contacts.iter().map(|&(actor_id, class)| Contact { actor_id, class }).collect();
        let tick_input = TickInput {
            position: report.ego.pose.pos,
            speed_mps: report.ego.speed_mps,
            on_road: report.on_road,
            contacts: &contacts,
            red_light: report.ran_red_light,
            stop_sign: false,
            stop: None,
        };
        let termination = ep.score.update(&tick_input);
        hash_tick(&mut ep.hasher, &report.ego, &contacts);
        ep.on_road = report.on_road;
        ep.samples.push(TrajectorySample {
            tick: report.tick,
            time_s: report.time_s,
            x: report.ego.pose.pos.x,
            y: report.ego.pose.pos.y,
            yaw: report.ego.pose.yaw,
            speed_mps: report.ego.speed_mps,
            on_road: report.on_road,
            contacts: contacts.clone(),
            red_light: report.ran_red_light,
            stop_sign: false,
            stop: None,
        });
        let ended = termination.is_some();
        if ended {
            ep.terminated = true;
        }
        Ok((contacts, ended))
    }
}

fn not_started() -> Error {
    Error::Simulation("no episode is running; call reset() before step()".into())
}

fn check_finite(field: &str, v: f64) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::config(field, v, "must be a finite number"))
    }
}

/// The render map of a network, built once per process while the network lives: every Sim on a
/// map shares it (a city's takes tens of milliseconds to build; an editor or a suite run makes
/// a Sim per buffer or scenario on the same few networks).
fn shared_render_map(net: &Arc<crate::map::Network>) -> Arc<RenderMap> {
    type Entry = (Weak<crate::map::Network>, Arc<RenderMap>);
    static MAPS: Mutex<Vec<Entry>> = Mutex::new(Vec::new());
    let mut maps = MAPS.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    maps.retain(|(w, _)| w.strong_count() > 0);
    if let Some((_, m)) = maps.iter().find(|(w, _)| w.upgrade().is_some_and(|n| Arc::ptr_eq(&n, net))) {
        return m.clone();
    }
    let m = Arc::new(RenderMap::build(net));
    maps.push((Arc::downgrade(net), m.clone()));
    m
}

/// The renderers' input at one moment, owned ([`Sim::frame_snapshot`]): a frame rendered from it
/// equals the one [`Sim::render_camera`] / [`Sim::render_bev`] gave at that moment.
#[derive(Debug, Clone)]
pub struct FrameSnapshot {
    map: Arc<RenderMap>,
    ego: ActorView,
    actors: Vec<ActorView>,
    lights: Vec<TrafficLightView>,
    signs: Vec<SignView>,
    route_points: Vec<Vec2>,
    ambience: Ambience,
}

impl FrameSnapshot {
    fn input(&self) -> FrameInput<'_> {
        FrameInput {
            ego: &self.ego,
            actors: &self.actors,
            lights: &self.lights,
            signs: &self.signs,
            route_points: &self.route_points,
            ambience: self.ambience,
        }
    }

    pub fn render_camera(&self, cfg: &CameraConfig, out: &mut Image) -> Result<()> {
        crate::render::render_camera(&self.map, &self.input(), cfg, out)
    }

    pub fn render_bev(&self, cfg: &BevConfig, out: &mut Image) -> Result<()> {
        crate::render::render_bev(&self.map, &self.input(), cfg, out)
    }
}

fn frame_input<'a>(ep: &'a Episode, route_points: &'a [Vec2]) -> FrameInput<'a> {
    let world = &ep.world;
    FrameInput {
        ego: world.ego(),
        actors: world.actors(),
        lights: world.lights(),
        signs: world.signs(),
        route_points,
        ambience: ep.ambience(),
    }
}

/// Signal heads whose stop line lies on the route, sorted by arc length.
fn route_lights(route: &crate::geom::Polyline, lights: &[TrafficLightView]) -> Vec<(f64, usize)> {
    let mut out: Vec<(f64, usize)> = lights
        .iter()
        .enumerate()
        .filter_map(|(i, l)| {
            let p = route.project(l.stop_line.pos)?;
            let aligned = wrap_angle(route.heading_at(p.s) - l.stop_line.yaw).abs() < 0.5;
            (p.distance <= LIGHT_ON_ROUTE_M && aligned).then_some((p.s, i))
        })
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    out
}

fn hash_tick(h: &mut Sha256, ego: &ActorView, contacts: &[Contact]) {
    for v in [ego.pose.pos.x, ego.pose.pos.y, ego.pose.yaw, ego.speed_mps] {
        h.update(v.to_bits().to_le_bytes());
    }
    for c in contacts {
        h.update(c.actor_id.to_le_bytes());
    }
}

fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write as _;
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        let _ = write!(s, "{b:02x}");
    }
    s
}
