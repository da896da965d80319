//! `[[actors]]`, `[[obstacles]]` and `[[signs]]` → resolved actors and signs (paths, sizes,
//! colours, pacing).

use super::lane_change::apply_lane_changes;
use super::trigger::{ego_route_s_of, resolve_brake, resolve_of, resolve_trigger};
use super::{lane_chain, map_err, offset_polyline, route_label, size, Ctx, TriggerCtx};
use crate::geom::{Polyline, Pose, Vec2};
use crate::scenario::model::{
    ActorMotion, AtEnd, Pace, PaceMode, ResolvedActor, ScriptedPath, ETA_MAX_OFFSET_M, PALETTE,
};
use crate::scenario::schema::{
    ActorSpec, AtEndSpec, BehaviorSpec, ObstacleSpec, OfSpec, PaceSpec, PlaceSpec, SignSpec,
};
use crate::scenario::tables::vclass_of;
use crate::view::{ActorKind, SignView};
use crate::Result;

/// Default cruise speed of a scripted actor, m/s.
pub fn default_speed_mps(kind: ActorKind) -> f64 {
    match kind {
        ActorKind::Pedestrian => 1.2,
        ActorKind::Cyclist => 4.0,
        _ => 8.0,
    }
}

pub(super) fn default_color(kind: ActorKind, i: usize) -> [u8; 3] {
    match kind {
        ActorKind::Cone => [255, 120, 0],
        ActorKind::Barrier => [230, 60, 40],
        _ => PALETTE[i % PALETTE.len()],
    }
}

/// `pace` → ego-relative speed control of a scripted actor on `path` cruising at `speed`.
pub(super) fn resolve_pace(
    ctx: &Ctx<'_>,
    tc: &TriggerCtx<'_>,
    pf: &str,
    p: &PaceSpec,
    path: &Polyline,
    speed: f64,
) -> Result<Pace> {
    let gap = p.gap_s.is_some() || p.gap_m.is_some();
    let mode = match (gap, &p.meet) {
        (true, None) => {
            if let Some(o) = p.offset_s {
                return Err(ctx.err(format!("{pf}.offset_s"), o, "`offset_s` goes with `meet`"));
            }
            let gap_s = ctx.nonneg(&format!("{pf}.gap_s"), p.gap_s.unwrap_or(0.0))?;
            let gap_m = ctx.finite(&format!("{pf}.gap_m"), p.gap_m.unwrap_or(0.0))?;
            // The actor must start beside the ego route to measure a gap along it.
            let start = path.point_at(0.0);
            let d = tc.ego_route.project(start).map_or(f64::INFINITY, |q| q.distance);
            if d > ETA_MAX_OFFSET_M {
                return Err(ctx.err(
                    pf,
                    format!("gap_s = {gap_s}, gap_m = {gap_m}"),
                    format!("a gap is measured along the ego route, but the actor starts {d:.1} m from it (at most {ETA_MAX_OFFSET_M} m)"),
                ));
            }
            PaceMode::Gap { gap_m, gap_s }
        }
        (false, Some(of)) => {
            if let Some(OfSpec::Name(n)) = Some(of) {
                return Err(ctx.err(format!("{pf}.meet"), n, "give a point `[x, y]` or a place"));
            }
            let point = resolve_of(ctx, &format!("{pf}.meet"), Some(of), Vec2::ZERO)?;
            let route_s = ego_route_s_of(ctx, tc, &format!("{pf}.meet"), point)?;
            let q = path.project(point).ok_or_else(|| ctx.err(format!("{pf}.meet"), "?", "empty path"))?;
            if q.distance > 3.0 || q.s >= path.length() - 1e-6 {
                return Err(ctx.err(
                    format!("{pf}.meet"),
                    format!("({:.2}, {:.2})", point.x, point.y),
                    format!("not on the actor's path: nearest path point {:.1} m away at s = {:.1} m of {:.1} m (at most 3 m, before the path end)", q.distance, q.s, path.length()),
                ));
            }
            let offset_s = ctx.finite(&format!("{pf}.offset_s"), p.offset_s.unwrap_or(0.0))?;
            PaceMode::Meet { point, route_s, actor_s: q.s, offset_s }
        }
        (true, Some(_)) => {
            return Err(ctx.err(pf, "gap + meet", "give a gap (`gap_s`, `gap_m`) or `meet`, not both"))
        }
        (false, None) => {
            return Err(ctx.err(pf, "{}", "give a gap (`gap_s` and/or `gap_m`) or a conflict point `meet`"))
        }
    };
    let min_speed_mps = ctx.nonneg(&format!("{pf}.min_speed_mps"), p.min_speed_mps.unwrap_or(0.0))?;
    let max_speed_mps =
        ctx.positive(&format!("{pf}.max_speed_mps"), p.max_speed_mps.unwrap_or(1.5 * speed))?;
    if max_speed_mps < min_speed_mps {
        return Err(ctx.err(
            format!("{pf}.max_speed_mps"),
            max_speed_mps,
            format!("below min_speed_mps ({min_speed_mps})"),
        ));
    }
    let until_s = match p.until_s {
        Some(u) => ctx.nonneg(&format!("{pf}.until_s"), u)?,
        None => f64::INFINITY,
    };
    Ok(Pace { mode, min_speed_mps, max_speed_mps, until_s })
}

pub(super) fn resolve_actor(
    ctx: &Ctx<'_>,
    tc: &TriggerCtx<'_>,
    i: usize,
    a: &ActorSpec,
) -> Result<ResolvedActor> {
    let map = ctx.map;
    let field = format!("actors[{i}]");
    let (length_m, width_m, height_m) = size(ctx, &field, a.kind, a.length_m, a.width_m, a.height_m)?;
    let color = a.color.unwrap_or(default_color(a.kind, i));
    let name = a.name.clone().unwrap_or_else(|| field.clone());
    let emergency = emergency(ctx, &field, a.kind, a.emergency)?;
    let base = |motion| ResolvedActor {
        name: name.clone(),
        kind: a.kind,
        length_m,
        width_m,
        height_m,
        color,
        emergency,
        motion,
    };
    if a.behavior == BehaviorSpec::External {
        if a.waypoints.is_some() || a.route.is_some() {
            return Err(ctx.err(
                format!("{field}.behavior"),
                "external",
                "an external actor takes `at`, not `waypoints`/`route`",
            ));
        }
        let at =
            a.at.as_ref()
                .ok_or_else(|| ctx.err(format!("{field}.at"), "<missing>", "an external actor needs `at`"))?;
        return Ok(base(ActorMotion::External { pose: ctx.place(&format!("{field}.at"), at)?.0 }));
    }
    if a.at.is_some() {
        return Err(ctx.err(
            format!("{field}.at"),
            "{..}",
            "scripted actors start at their path start; use [[obstacles]] for parked objects",
        ));
    }
    let speed =
        ctx.nonneg(&format!("{field}.speed_mps"), a.speed_mps.unwrap_or(default_speed_mps(a.kind)))?;
    let (path, legs) = match (&a.waypoints, &a.route) {
        (Some(wps), None) => {
            let f = format!("{field}.waypoints");
            if !a.lane_changes.is_empty() {
                return Err(ctx.err(
                    format!("{field}.lane_changes"),
                    a.lane_changes.len(),
                    "lane changes need a `route` actor (its path follows lanes)",
                ));
            }
            if wps.is_empty() {
                return Err(ctx.err(&f, "[]", "empty waypoint list (needs at least 2 points)"));
            }
            if wps.len() < 2 {
                return Err(ctx.err(&f, wps.len(), "needs at least 2 waypoints"));
            }
            let mut pts = Vec::with_capacity(wps.len());
            let mut legs = Vec::with_capacity(wps.len() - 1);
            let mut acc = 0.0;
            for (k, w) in wps.iter().enumerate() {
                let wf = format!("{f}[{k}]");
                let place = PlaceSpec {
                    lane: w.lane.clone(),
                    s: w.s,
                    offset_m: w.offset_m,
                    x: w.x,
                    y: w.y,
                    yaw_deg: None,
                };
                let p = ctx.place(&wf, &place)?.0.pos;
                let v = match w.speed_mps {
                    Some(v) => ctx.nonneg(&format!("{wf}.speed_mps"), v)?,
                    None => speed,
                };
                if let Some(&prev) = pts.last() {
                    acc += p.dist(prev);
                    legs.push((acc, v));
                }
                pts.push(p);
            }
            if acc <= 1e-6 {
                return Err(ctx.err(&f, wps.len(), "waypoints do not span any distance"));
            }
            (Polyline::new(pts), legs)
        }
        (None, Some(r)) => {
            let f = format!("{field}.route");
            let vclass = vclass_of(a.kind);
            let lanes = match (&r.edges, &r.lanes) {
                (Some(ids), None) => {
                    let edges = ctx.edge_chain(&format!("{f}.edges"), ids, vclass)?;
                    let start_lane = match &r.start_lane {
                        Some(l) => {
                            let lane = ctx.lane(&format!("{f}.start_lane"), l)?;
                            if map.lanes[lane].edge != edges[0] {
                                return Err(ctx.err(
                                    format!("{f}.start_lane"),
                                    l,
                                    "not a lane of the first route edge",
                                ));
                            }
                            Some(lane)
                        }
                        None => None,
                    };
                    map.route_lanes_for(&edges, start_lane, vclass)
                        .map_err(|e| map_err(ctx, &format!("{f}.edges"), &route_label(map, &edges), e))?
                }
                (None, Some(ids)) => {
                    if let Some(l) = &r.start_lane {
                        return Err(ctx.err(
                            format!("{f}.start_lane"),
                            l,
                            "`start_lane` goes with `edges`; the lane list starts at its first lane",
                        ));
                    }
                    lane_chain(ctx, &format!("{f}.lanes"), ids)?
                }
                _ => return Err(ctx.err(&f, "{..}", "give exactly one of `edges` or `lanes`")),
            };
            let full = map.lanes_polyline(&lanes);
            let len = full.length();
            let s0 = ctx.nonneg(&format!("{f}.start_s"), r.start_s.unwrap_or(0.0))?;
            let s1 = ctx.nonneg(&format!("{f}.end_s"), r.end_s.unwrap_or(len))?.min(len);
            if s1 <= s0 + 1e-6 {
                return Err(ctx.err(
                    format!("{f}.start_s"),
                    s0,
                    format!("start_s must be below end_s ({s1:.2}) and the route length ({len:.2} m)"),
                ));
            }
            let (full, s1) = apply_lane_changes(ctx, &field, full, &lanes, s0, s1, &a.lane_changes, vclass)?;
            let off = ctx.finite(&format!("{f}.offset_m"), r.offset_m.unwrap_or(0.0))?;
            let path = offset_polyline(&full.slice(s0, s1), off);
            let l = path.length();
            (path, vec![(l, speed)])
        }
        (Some(_), Some(_)) => return Err(ctx.err(&field, "{..}", "give `waypoints` or `route`, not both")),
        (None, None) => {
            return Err(ctx.err(
                format!("{field}.waypoints"),
                "<missing>",
                "a scripted actor needs `waypoints` or `route` (use [[obstacles]] for parked objects)",
            ))
        }
    };
    let initial_speed_mps = match a.initial_speed_mps {
        Some(v) => ctx.nonneg(&format!("{field}.initial_speed_mps"), v)?,
        None => legs.first().map_or(0.0, |l| l.1),
    };
    let accel_mps2 = match a.accel_mps2 {
        Some(v) => ctx.positive(&format!("{field}.accel_mps2"), v)?,
        None if a.kind == ActorKind::Pedestrian => f64::INFINITY,
        None => 3.0,
    };
    let trigger = resolve_trigger(ctx, tc, &format!("{field}.start"), a.start.as_ref(), path.point_at(0.0))?;
    let pace = match &a.pace {
        Some(p) => Some(resolve_pace(ctx, tc, &format!("{field}.pace"), p, &path, speed)?),
        None => None,
    };
    let has_gap = matches!(pace, Some(Pace { mode: PaceMode::Gap { .. }, .. }));
    let brake = match &a.brake {
        None => None,
        Some(b) => Some(resolve_brake(ctx, tc, &format!("{field}.brake"), b, has_gap)?),
    };
    let at_end = match a.at_end {
        AtEndSpec::Stop => AtEnd::Stop,
        AtEndSpec::Remove => AtEnd::Remove,
    };
    Ok(base(ActorMotion::Scripted(ScriptedPath {
        path,
        legs,
        initial_speed_mps,
        accel_mps2,
        trigger,
        brake,
        pace,
        at_end,
    })))
}

/// `emergency = true` is a roof light bar, so only vehicles with a roof take it.
fn emergency(ctx: &Ctx<'_>, field: &str, kind: ActorKind, emergency: bool) -> Result<bool> {
    if emergency && !matches!(kind, ActorKind::Car | ActorKind::Bus | ActorKind::Truck) {
        let kind = serde_json::to_value(kind).ok().and_then(|v| v.as_str().map(str::to_owned));
        return Err(ctx.err(
            format!("{field}.emergency"),
            "true",
            format!(
                "only a car, bus or truck can be an emergency vehicle, not a {}",
                kind.unwrap_or_default()
            ),
        ));
    }
    Ok(emergency)
}

pub(super) fn resolve_obstacle(
    ctx: &Ctx<'_>,
    i: usize,
    palette_index: usize,
    o: &ObstacleSpec,
) -> Result<ResolvedActor> {
    let field = format!("obstacles[{i}]");
    let (length_m, width_m, height_m) = size(ctx, &field, o.kind, o.length_m, o.width_m, o.height_m)?;
    let (pose, _) = ctx.place(&format!("{field}.at"), &o.at)?;
    let emergency = emergency(ctx, &field, o.kind, o.emergency)?;
    Ok(ResolvedActor {
        name: o.name.clone().unwrap_or(field),
        kind: o.kind,
        length_m,
        width_m,
        height_m,
        color: o.color.unwrap_or(default_color(o.kind, palette_index)),
        emergency,
        motion: ActorMotion::Static { pose },
    })
}

pub(super) fn resolve_sign(ctx: &Ctx<'_>, i: usize, s: &SignSpec) -> Result<SignView> {
    let field = format!("signs[{i}].at");
    let pose = match &s.at.lane {
        Some(lane_id) => {
            let lane = ctx.lane(&format!("{field}.lane"), lane_id)?;
            let default_off = -(0.5 * ctx.map.lanes[lane].width_m + 1.0);
            let spec = PlaceSpec { offset_m: Some(s.at.offset_m.unwrap_or(default_off)), ..s.at.clone() };
            let (pose, _) = ctx.place(&field, &spec)?;
            // Faces oncoming traffic unless a yaw is given.
            if s.at.yaw_deg.is_some() {
                pose
            } else {
                Pose::new(pose.pos, crate::geom::wrap_angle(pose.yaw + std::f64::consts::PI))
            }
        }
        None => ctx.place(&field, &s.at)?.0,
    };
    Ok(SignView { kind: s.kind, pose })
}
