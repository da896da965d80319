//! `lane_changes` of a route actor.

use super::{map_err, Ctx};
use crate::geom::{Polyline, Vec2};
use crate::map::{EdgeFunction, EdgeIdx, LaneIdx, VClass};
use crate::scenario::schema::LaneChangeSpec;
use crate::Result;

/// Default length of a lane change along the path, m.
pub const LANE_CHANGE_LENGTH_M: f64 = 20.0;

/// Applies `lane_changes` to a route actor's path `full` (over `lanes`, cut later to
/// [`s0`, `s1`]): from `s0 + at_s` the actor blends over `length_m` (cosine lateral profile)
/// from its lane onto `to_lane`, a neighbour lane of the same edge, and then follows the route's
/// remaining edges from `to_lane` along the lane graph (its connections; where `to_lane` does
/// not lead on, the router's own lane change is kept). Returns the new path and its end.
#[allow(clippy::too_many_arguments)]
pub(super) fn apply_lane_changes(
    ctx: &Ctx<'_>,
    field: &str,
    full: Polyline,
    lanes: &[LaneIdx],
    s0: f64,
    s1: f64,
    changes: &[LaneChangeSpec],
    vclass: VClass,
) -> Result<(Polyline, f64)> {
    let map = ctx.map;
    let mut cur = full;
    let mut s1 = s1;
    let mut lanes: Vec<LaneIdx> = lanes.to_vec();
    let mut done_s = s0;
    for (k, c) in changes.iter().enumerate() {
        let f = format!("{field}.lane_changes[{k}]");
        let at_s = ctx.nonneg(&format!("{f}.at_s"), c.at_s)?;
        let len = ctx.positive(&format!("{f}.length_m"), c.length_m.unwrap_or(LANE_CHANGE_LENGTH_M))?;
        let at = s0 + at_s;
        if at < done_s - 1e-6 {
            return Err(ctx.err(
                format!("{f}.at_s"),
                at_s,
                format!("starts before the previous lane change ends (at_s {:.1} m)", done_s - s0),
            ));
        }
        if at + len > s1 + 1e-6 {
            return Err(ctx.err(
                format!("{f}.at_s"),
                at_s,
                format!(
                    "the lane change (ending at {:.1} m) runs past the end of the path ({:.1} m)",
                    at_s + len,
                    s1 - s0
                ),
            ));
        }
        let p = cur.point_at(at);
        // The lane the actor is on at `at`: the nearest lane of a normal edge of the route,
        // with the point inside it (not beyond its ends, i.e. not in a junction).
        let from = lanes
            .iter()
            .copied()
            .filter(|&l| map.lane_function(l) == EdgeFunction::Normal)
            .filter_map(|l| {
                let sh = &map.lanes[l].shape;
                let pr = sh.project(p)?;
                (pr.s > 1e-6 && pr.s < sh.length() - 1e-6 && pr.distance <= 0.5 * map.lanes[l].width_m + 0.5)
                    .then_some((pr.distance, l))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|x| x.1)
            .ok_or_else(|| {
                ctx.err(
                    format!("{f}.at_s"),
                    at_s,
                    format!(
                        "the path is not on a lane of a normal edge there ({:.1}, {:.1}): inside a junction?",
                        p.x, p.y
                    ),
                )
            })?;
        let to = ctx.lane(&format!("{f}.to_lane"), &c.to_lane)?;
        let (lf, lt) = (&map.lanes[from], &map.lanes[to]);
        if lt.edge != lf.edge || lf.index.abs_diff(lt.index) != 1 {
            let neighbours: Vec<&str> = map.edges[lf.edge]
                .lanes
                .iter()
                .map(|&l| &map.lanes[l])
                .filter(|l| l.index.abs_diff(lf.index) == 1)
                .map(|l| l.id.as_str())
                .collect();
            return Err(ctx.err(
                format!("{f}.to_lane"),
                format!("\"{}\"", c.to_lane),
                format!(
                    "not a neighbour of lane `{}` the actor is on at at_s = {at_s} (neighbours: {})",
                    lf.id,
                    if neighbours.is_empty() { "none".to_string() } else { neighbours.join(", ") }
                ),
            ));
        }
        if !lt.allow.contains(vclass) {
            return Err(ctx.err(
                format!("{f}.to_lane"),
                format!("\"{}\"", c.to_lane),
                format!("lane does not allow vClass {}", vclass.sumo_name()),
            ));
        }
        // The route's normal edges from the current one on.
        let pos = lanes.iter().position(|&l| l == from).unwrap_or(0);
        let mut rem: Vec<EdgeIdx> = Vec::new();
        for &l in &lanes[pos..] {
            let e = map.lanes[l].edge;
            if map.edges[e].function == EdgeFunction::Normal && rem.last() != Some(&e) {
                rem.push(e);
            }
        }
        let next_lanes = map
            .route_lanes_for(&rem, Some(to), vclass)
            .map_err(|e| map_err(ctx, &format!("{f}.to_lane"), &format!("\"{}\"", c.to_lane), e))?;
        let next = map.lanes_polyline(&next_lanes);
        let n_a = next.project(p).map_or(0.0, |q| q.s);
        if n_a + len > next.length() {
            return Err(ctx.err(
                format!("{f}.length_m"),
                len,
                format!(
                    "the lane change does not fit on the rest of the route ({:.1} m left)",
                    next.length() - n_a
                ),
            ));
        }
        let end_pt = cur.point_at(s1);
        let mut pts: Vec<Vec2> = cur.slice(0.0, at).points().to_vec();
        let n = (len / 1.0).ceil().max(2.0) as usize;
        for i in 1..=n {
            let u = len * i as f64 / n as f64;
            let w = 0.5 - 0.5 * (std::f64::consts::PI * u / len).cos();
            pts.push(cur.point_at(at + u).lerp(next.point_at(n_a + u), w));
        }
        pts.extend_from_slice(&next.slice(n_a + len, next.length()).points()[1..]);
        let composite = Polyline::new(pts);
        let tail_left = next.length() - next.project(end_pt).map_or(next.length(), |q| q.s);
        s1 = (composite.length() - tail_left).clamp(at + len, composite.length());
        done_s = at + len;
        cur = composite;
        lanes = next_lanes;
    }
    Ok((cur, s1))
}
