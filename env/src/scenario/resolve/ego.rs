//! `[ego]` → [`ResolvedEgo`](crate::scenario::ResolvedEgo): start, destination and route.

use super::{map_err, route_label, Ctx, SNAP_DISTANCE_M};
use crate::map::VClass;
use crate::scenario::model::{ResolvedEgo, EGO_COLOR};
use crate::scenario::schema::EgoSpec;
use crate::{Error, Result};

/// The ego's SUMO class: its route and start lanes must allow it.
pub const EGO_VCLASS: VClass = VClass::Passenger;

pub(super) fn resolve_ego(ctx: &Ctx<'_>, spec: &EgoSpec) -> Result<ResolvedEgo> {
    let map = ctx.map;
    let params = spec.vehicle.unwrap_or_default();
    params.validate().map_err(|e| match e {
        Error::Config { field, value, message } => ctx.err(format!("ego.{field}"), value, message),
        other => other,
    })?;
    let speed = ctx.nonneg("ego.speed_mps", spec.speed_mps)?;
    if speed > params.max_speed_mps {
        return Err(ctx.err(
            "ego.speed_mps",
            speed,
            format!("above the vehicle's max speed {} m/s", params.max_speed_mps),
        ));
    }
    let chain = match &spec.route_edges {
        Some(ids) => Some(ctx.edge_chain("ego.route_edges", ids, EGO_VCLASS)?),
        None => None,
    };
    if spec.destination.is_none() && chain.is_none() {
        return Err(ctx.err("ego.destination", "<missing>", "give `destination` or `route_edges`"));
    }
    // Start.
    let (start, start_lane) = match (&spec.start, &chain) {
        (Some(p), _) => {
            let (mut pose, lane) = ctx.place("ego.start", p)?;
            let lane = ctx.snap_lane("ego.start", pose, lane)?;
            if p.lane.is_none() && p.yaw_deg.is_none() {
                let sh = &map.lanes[lane].shape;
                pose.yaw = sh.heading_at(sh.project(pose.pos).map_or(0.0, |q| q.s));
            }
            (pose, lane)
        }
        (None, Some(c)) => {
            let lane = ctx.first_lane("ego.route_edges[0]", c[0], EGO_VCLASS)?;
            let len = map.lanes[lane].shape.length();
            (map.lane_position(lane, (0.25 * len).min(5.0)), lane)
        }
        (None, None) => {
            return Err(ctx.err(
                "ego.start",
                "<missing>",
                "give `start` (or `route_edges` to start on its first edge)",
            ))
        }
    };
    let start_edge = map.lanes[start_lane].edge;
    // Destination.
    let (destination, dest_edge) = match (&spec.destination, &chain) {
        (Some(p), _) => {
            let (pose, lane) = ctx.place("ego.destination", p)?;
            let lane = ctx.snap_lane("ego.destination", pose, lane)?;
            (pose.pos, map.lanes[lane].edge)
        }
        (None, Some(c)) => {
            let last = *c.last().unwrap_or(&start_edge);
            let lane = ctx.first_lane("ego.route_edges", last, EGO_VCLASS)?;
            let len = map.lanes[lane].shape.length();
            (map.lane_position(lane, len - (0.25 * len).min(5.0)).pos, last)
        }
        (None, None) => {
            return Err(ctx.err("ego.destination", "<missing>", "give `destination` or `route_edges`"))
        }
    };
    // Route edges.
    let edges = match &chain {
        Some(c) => {
            let i0 = c.iter().position(|&e| e == start_edge).ok_or_else(|| {
                ctx.err(
                    "ego.start",
                    &map.edges[start_edge].id,
                    format!("start edge is not on route_edges ({})", route_label(map, c)),
                )
            })?;
            let i1 = c.iter().rposition(|&e| e == dest_edge).filter(|&i| i >= i0).ok_or_else(|| {
                ctx.err(
                    "ego.destination",
                    &map.edges[dest_edge].id,
                    format!(
                        "destination edge is not on route_edges after the start ({})",
                        route_label(map, c)
                    ),
                )
            })?;
            c[i0..=i1].to_vec()
        }
        None => map.edge_route(start_edge, dest_edge, EGO_VCLASS).ok_or_else(|| {
            ctx.err(
                "ego.destination",
                &map.edges[dest_edge].id,
                format!("no drivable route from edge `{}`", map.edges[start_edge].id),
            )
        })?,
    };
    let label = route_label(map, &edges);
    let full = map
        .route_polyline(&edges, Some(start_lane))
        .map_err(|e| map_err(ctx, "ego.route_edges", &label, e))?;
    let p0 = full.project(start.pos).ok_or_else(|| ctx.err("ego.route_edges", &label, "empty route"))?;
    let p1 = full.project(destination).ok_or_else(|| ctx.err("ego.route_edges", &label, "empty route"))?;
    if p1.distance > SNAP_DISTANCE_M + 4.0 {
        return Err(ctx.err(
            "ego.destination",
            format!("({:.2}, {:.2})", destination.x, destination.y),
            format!("{:.1} m away from the route {label}", p1.distance),
        ));
    }
    if p1.s <= p0.s + 1.0 {
        return Err(ctx.err(
            "ego.destination",
            format!("({:.2}, {:.2})", destination.x, destination.y),
            format!("lies behind (or at) the start along the route {label} (start s = {:.1} m, destination s = {:.1} m)", p0.s, p1.s),
        ));
    }
    let color = spec.color.unwrap_or(EGO_COLOR);
    Ok(ResolvedEgo {
        start,
        speed_mps: speed,
        params,
        color,
        start_lane,
        route_edges: edges,
        route: full.slice(p0.s, p1.s),
        destination,
    })
}
