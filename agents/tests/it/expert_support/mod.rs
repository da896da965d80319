//! A stand-in closed loop for the expert tests: the protocol's actuation bridge and the ego's
//! kinematic bicycle (centre reference) with the documented constants, on synthetic routes.
#![allow(dead_code)]

use dh_agents::expert::{Expert, ExpertAction, ExpertInput, ExpertParams};
use dh_env::geom::{Polyline, Pose, Vec2};
use dh_env::view::{ActorKind, ActorView, LightColor, TrafficLightView};

/// Ego front bumper offset from its centre (4.6 m long).
pub const EGO_HALF_LENGTH: f64 = 2.3;

pub const DT: f64 = 0.05;
pub const WHEELBASE: f64 = 2.9;
pub const L_R: f64 = 1.45;
pub const MAX_DELTA_DEG: f64 = 35.0;

pub fn actor(
    id: u32,
    kind: ActorKind,
    pos: Vec2,
    yaw: f64,
    speed: f64,
    length: f64,
    width: f64,
) -> ActorView {
    ActorView {
        id,
        kind,
        pose: Pose::new(pos, yaw),
        speed_mps: speed,
        length_m: length,
        width_m: width,
        height_m: 1.5,
        color: [200, 200, 200],
        braking: false,
        blinkers: 0,
        beacon: false,
    }
}

pub fn ego_at(pos: Vec2, yaw: f64, speed: f64) -> ActorView {
    actor(0, ActorKind::Car, pos, yaw, speed, 4.6, 1.9)
}

pub fn light(pos: Vec2, yaw: f64, color: LightColor) -> TrafficLightView {
    TrafficLightView {
        tl_id: "J".into(),
        lane_id: "in_0".into(),
        stop_line: Pose::new(pos, yaw),
        lane_width_m: 3.2,
        color,
    }
}

/// Route builder: straight pieces and circular arcs (positive angle = left turn).
pub struct RouteBuilder {
    pts: Vec<Vec2>,
    yaw: f64,
}

impl RouteBuilder {
    pub fn new(start: Vec2, yaw: f64) -> Self {
        Self { pts: vec![start], yaw }
    }
    fn last(&self) -> Vec2 {
        *self.pts.last().unwrap()
    }
    pub fn straight(mut self, len: f64) -> Self {
        let n = (len / 5.0).ceil().max(1.0) as usize;
        let p0 = self.last();
        for i in 1..=n {
            self.pts.push(p0 + Vec2::from_angle(self.yaw) * (len * i as f64 / n as f64));
        }
        self
    }
    pub fn arc(mut self, radius: f64, angle_deg: f64) -> Self {
        let ang = angle_deg.to_radians();
        let left = ang > 0.0;
        let c = self.last() + Vec2::from_angle(self.yaw).perp() * if left { radius } else { -radius };
        let n = ((radius * ang.abs()) / 1.0).ceil().max(2.0) as usize;
        let a0 = (self.last() - c).angle();
        for i in 1..=n {
            let a = a0 + ang * i as f64 / n as f64;
            self.pts.push(c + Vec2::from_angle(a) * radius);
        }
        self.yaw += ang;
        self
    }
    pub fn build(self) -> Polyline {
        Polyline::new(self.pts)
    }
}

/// A scripted actor: position as a function of time (moves along a direction at a speed
/// profile) — enough for pedestrians, lead vehicles and parked obstacles.
pub struct Scripted {
    pub view: ActorView,
    /// Speed over time.
    pub speed: Box<dyn Fn(f64) -> f64>,
}

pub struct Outcome {
    pub time_s: f64,
    pub reached: bool,
    pub collided: bool,
    pub max_lateral_m: f64,
    pub travel_m: f64,
    pub route_len_m: f64,
    pub min_clearance_m: f64,
    pub max_rest_s: f64,
    pub actions: Vec<ExpertAction>,
    /// (time, ego pose) after every tick.
    pub trajectory: Vec<(f64, Pose)>,
}

pub struct Sim {
    pub route: Polyline,
    pub actors: Vec<Scripted>,
    pub lights: Box<dyn Fn(f64) -> Vec<TrafficLightView>>,
    pub start_speed: f64,
    pub time_limit_s: f64,
    /// Bridge computes throttle/brake every tick (true) or once per decision (false).
    pub per_tick_bridge: bool,
    pub drivable: Option<Box<dyn Fn(Vec2, f64) -> bool>>,
    pub speed_limit: Option<f64>,
    /// (actor index, ego x): that actor stands still until the ego centre reaches x; its speed
    /// function then gets the time since that moment.
    pub triggers: Vec<(usize, f64)>,
}

impl Sim {
    pub fn new(route: Polyline) -> Self {
        Self {
            route,
            actors: Vec::new(),
            lights: Box::new(|_| Vec::new()),
            start_speed: 0.0,
            time_limit_s: 120.0,
            per_tick_bridge: true,
            drivable: None,
            speed_limit: None,
            triggers: Vec::new(),
        }
    }

    fn bridge(target: f64, v: f64) -> (f64, f64) {
        let e = target - v;
        if target <= 0.2 {
            (0.0, (0.35 + 0.25 * v).min(0.85))
        } else if e >= 0.0 {
            let mut th = 0.25 + 0.22 * e;
            if target >= 0.8 && v < 0.8 {
                th = th.max(0.45);
            }
            (th.clamp(0.0, 0.85), 0.0)
        } else {
            (0.0, (0.30 * (v - target)).clamp(0.0, 0.85))
        }
    }

    /// Runs until the ego is within 8 m of the route end, collides, or times out.
    pub fn run(&self, params: ExpertParams) -> Outcome {
        let mut expert = Expert::new(params).expect("valid params");
        let route = &self.route;
        let p0 = route.point_at(0.0);
        let mut pose = Pose::new(p0, route.heading_at(0.0));
        let mut v = self.start_speed;
        let mut steer = 0.0f64;
        let mut target = 0.0f64;
        let mut controls = (0.0, 0.0);
        let dest = route.point_at(route.length());
        let mut out = Outcome {
            time_s: 0.0,
            reached: false,
            collided: false,
            max_lateral_m: 0.0,
            travel_m: 0.0,
            route_len_m: route.length(),
            min_clearance_m: f64::INFINITY,
            max_rest_s: 0.0,
            actions: Vec::new(),
            trajectory: Vec::new(),
        };
        let mut actors: Vec<ActorView> = self.actors.iter().map(|a| a.view).collect();
        let mut rest = 0.0;
        let mut fired: Vec<Option<f64>> = vec![None; self.actors.len()];
        let mut tick: u64 = 0;
        while (tick as f64) * DT < self.time_limit_s {
            let t = tick as f64 * DT;
            for (i, (a, s)) in actors.iter_mut().zip(&self.actors).enumerate() {
                a.speed_mps = match self.triggers.iter().find(|(k, _)| *k == i) {
                    None => (s.speed)(t),
                    Some(_) => match fired[i] {
                        Some(t0) => (s.speed)(t - t0),
                        None => 0.0,
                    },
                };
            }
            for &(k, x) in &self.triggers {
                if fired[k].is_none() && pose.pos.x >= x {
                    fired[k] = Some(t);
                }
            }
            let ego = ego_at(pose.pos, pose.yaw, v);
            if tick % 5 == 0 {
                let lights = (self.lights)(t);
                let drivable = self.drivable.as_deref();
                let input = ExpertInput {
                    ego: &ego,
                    route,
                    actors: &actors,
                    lights: &lights,
                    speed_limit_mps: self.speed_limit,
                    drivable,
                    follow_lane: None,
                };
                let act = expert.act(&input);
                assert!(act.steer.is_finite() && act.target_speed_mps.is_finite());
                out.actions.push(act);
                steer = act.steer.clamp(-1.0, 1.0).clamp(steer - 0.12, steer + 0.12);
                target = act.target_speed_mps.clamp(0.0, 30.0);
                controls = Self::bridge(target, v);
            }
            if self.per_tick_bridge {
                controls = Self::bridge(target, v);
            }
            let (th, br) = controls;
            // Vehicle model.
            let acc = 4.0 * th * (1.0 - v / 40.0).max(0.0) - 9.0 * br - 0.15 - 0.0005 * v * v;
            let delta = -steer * MAX_DELTA_DEG.to_radians();
            let beta = (L_R / WHEELBASE * delta.tan()).atan();
            let before = pose.pos;
            pose.pos += Vec2::from_angle(pose.yaw + beta) * (v * DT);
            pose.yaw += v / L_R * beta.sin() * DT;
            v = (v + acc * DT).max(0.0);
            out.travel_m += pose.pos.dist(before);
            for a in actors.iter_mut() {
                a.pose.pos += Vec2::from_angle(a.pose.yaw) * (a.speed_mps * DT);
            }
            tick += 1;
            out.time_s = tick as f64 * DT;
            out.trajectory.push((out.time_s, pose));
            let pr = route.project(pose.pos).unwrap();
            out.max_lateral_m = out.max_lateral_m.max(pr.distance);
            let ego_now = ego_at(pose.pos, pose.yaw, v);
            for a in &actors {
                let c = clearance(&ego_now, a);
                out.min_clearance_m = out.min_clearance_m.min(c);
                if c <= 0.0 {
                    out.collided = true;
                }
            }
            if v < 1.0 / 3.6 {
                rest += DT;
                out.max_rest_s = out.max_rest_s.max(rest);
            } else {
                rest = 0.0;
            }
            if out.collided {
                break;
            }
            if pose.pos.dist(dest) < 8.0 {
                out.reached = true;
                break;
            }
        }
        out
    }
}

/// Separation of two footprints (separating-axis gap; ≤ 0 when they overlap).
pub fn clearance(a: &ActorView, b: &ActorView) -> f64 {
    let (ca, cb) = (a.footprint().corners(), b.footprint().corners());
    let mut gap = f64::NEG_INFINITY;
    for axis in [
        Vec2::from_angle(a.pose.yaw),
        Vec2::from_angle(a.pose.yaw).perp(),
        Vec2::from_angle(b.pose.yaw),
        Vec2::from_angle(b.pose.yaw).perp(),
    ] {
        let (mut a0, mut a1, mut b0, mut b1) =
            (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for c in ca {
            a0 = a0.min(c.dot(axis));
            a1 = a1.max(c.dot(axis));
        }
        for c in cb {
            b0 = b0.min(c.dot(axis));
            b1 = b1.max(c.dot(axis));
        }
        gap = gap.max((b0 - a1).max(a0 - b1));
    }
    gap
}

/// S_eff of the protocol with T_ref = L / 5.56 m/s (no scenario reference).
pub fn efficiency(o: &Outcome) -> f64 {
    let t_ref = o.route_len_m / 5.56;
    0.7 * (1.10 * o.route_len_m / o.travel_m.max(1e-9)).min(1.0) + 0.3 * (1.5 * t_ref / o.time_s).min(1.0)
}
