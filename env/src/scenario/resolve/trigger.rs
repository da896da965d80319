//! Start triggers, brake events and chains between actors.

use super::{Ctx, TriggerCtx};
use crate::geom::Vec2;
use crate::scenario::model::{
    ActorMotion, BrakeEvent, BrakeWhen, ChainEvent, ResolvedActor, Trigger, ETA_MAX_OFFSET_M,
};
use crate::scenario::schema::{BrakeSpec, ChainEventSpec, OfSpec, TriggerSpec};
use crate::{Error, Result};
use std::path::Path;

/// Where a trigger's `of` point is read: the table (`start` or `brake`), the key it goes with,
/// whether `"actor_self"` is accepted there, and whether `of` is required. The resolver below
/// applies these rules; the editor reads this table (`_core.constants()["of_rules"]`), and a test
/// checks the two agree.
pub struct OfRule {
    pub table: &'static str,
    pub key: &'static str,
    pub actor_self: bool,
    pub required: bool,
}

pub const OF_RULES: &[OfRule] = &[
    OfRule { table: "start", key: "ego_within_m", actor_self: true, required: false },
    OfRule { table: "start", key: "ego_eta_s", actor_self: true, required: false },
    OfRule { table: "brake", key: "ego_within_m", actor_self: true, required: false },
    OfRule { table: "brake", key: "ego_eta_s", actor_self: false, required: true },
];

pub(super) fn resolve_of(ctx: &Ctx<'_>, field: &str, of: Option<&OfSpec>, self_pos: Vec2) -> Result<Vec2> {
    Ok(match of {
        None => self_pos,
        Some(OfSpec::Name(n)) if n == "actor_self" => self_pos,
        Some(OfSpec::Name(n)) => {
            return Err(ctx.err(format!("{field}.of"), n, "the only name allowed is \"actor_self\""))
        }
        Some(OfSpec::Point([x, y])) => {
            Vec2::new(ctx.finite(&format!("{field}.of[0]"), *x)?, ctx.finite(&format!("{field}.of[1]"), *y)?)
        }
        Some(OfSpec::Place(p)) => ctx.place(&format!("{field}.of"), p)?.0.pos,
    })
}

pub(super) fn resolve_trigger(
    ctx: &Ctx<'_>,
    tc: &TriggerCtx<'_>,
    field: &str,
    t: Option<&TriggerSpec>,
    self_pos: Vec2,
) -> Result<Trigger> {
    let Some(t) = t else { return Ok(Trigger::Time(0.0)) };
    ctx.exactly_one(
        field,
        &[
            ("time_s", t.time_s.is_some()),
            ("ego_within_m", t.ego_within_m.is_some()),
            ("ego_eta_s", t.ego_eta_s.is_some()),
            ("after", t.after.is_some()),
        ],
    )?;
    let of_ok = t.ego_within_m.is_some() || t.ego_eta_s.is_some();
    if let (Some(of), false) = (&t.of, of_ok) {
        return Err(ctx.err(
            format!("{field}.of"),
            format!("{of:?}"),
            "`of` goes with `ego_within_m` or `ego_eta_s`",
        ));
    }
    if t.after.is_none() {
        if let Some(d) = t.delay_s {
            return Err(ctx.err(format!("{field}.delay_s"), d, "`delay_s` goes with `after`"));
        }
        if let Some(e) = t.event {
            return Err(ctx.err(format!("{field}.event"), format!("{e:?}"), "`event` goes with `after`"));
        }
    }
    if let Some(ts) = t.time_s {
        return Ok(Trigger::Time(ctx.nonneg(&format!("{field}.time_s"), ts)?));
    }
    if let Some(r) = t.ego_within_m {
        let radius_m = ctx.positive(&format!("{field}.ego_within_m"), r)?;
        let point = resolve_of(ctx, field, t.of.as_ref(), self_pos)?;
        return Ok(Trigger::EgoWithin { radius_m, point });
    }
    if let Some(eta) = t.ego_eta_s {
        let eta_s = ctx.positive(&format!("{field}.ego_eta_s"), eta)?;
        let point = resolve_of(ctx, field, t.of.as_ref(), self_pos)?;
        let route_s = ego_route_s_of(ctx, tc, &format!("{field}.of"), point)?;
        return Ok(Trigger::EgoEta { eta_s, point, route_s });
    }
    let actor = actor_by_name(ctx, tc, &format!("{field}.after"), t.after.as_deref().unwrap_or_default())?;
    let delay_s = ctx.nonneg(&format!("{field}.delay_s"), t.delay_s.unwrap_or(0.0))?;
    Ok(Trigger::After { actor, event: chain_event(t.event), delay_s })
}

pub(super) fn chain_event(e: Option<ChainEventSpec>) -> ChainEvent {
    match e.unwrap_or_default() {
        ChainEventSpec::Start => ChainEvent::Start,
        ChainEventSpec::Brake => ChainEvent::Brake,
        ChainEventSpec::End => ChainEvent::End,
    }
}

/// The arc length along the ego route of a point's projection; the foot of the perpendicular
/// must fall strictly inside the route (not clamped to its start or destination) and near it.
pub(super) fn ego_route_s_of(ctx: &Ctx<'_>, tc: &TriggerCtx<'_>, field: &str, point: Vec2) -> Result<f64> {
    let route = tc.ego_route;
    let proj = route.project(point).ok_or_else(|| ctx.err(field, "?", "empty ego route"))?;
    if proj.s <= 1e-6 || proj.s >= route.length() - 1e-6 || proj.distance > ETA_MAX_OFFSET_M {
        return Err(ctx.err(
            field,
            format!("({:.2}, {:.2})", point.x, point.y),
            format!(
                "does not project onto the ego route: nearest route point at s = {:.1} m of {:.1} m, {:.1} m away (the point must lie beside the route, within {ETA_MAX_OFFSET_M} m, between the ego start and destination)",
                proj.s,
                route.length(),
                proj.distance
            ),
        ));
    }
    Ok(proj.s)
}

/// Index of the scenario actor called `name` (its `name`, or `actors[i]`).
pub(super) fn actor_by_name(ctx: &Ctx<'_>, tc: &TriggerCtx<'_>, field: &str, name: &str) -> Result<usize> {
    let hits: Vec<usize> = tc.names.iter().enumerate().filter(|(_, n)| *n == name).map(|(i, _)| i).collect();
    match hits.as_slice() {
        [i] => Ok(*i),
        [] => Err(ctx.err(
            field,
            format!("\"{name}\""),
            format!("no actor of that name (actors: {})", tc.names.join(", ")),
        )),
        _ => Err(ctx.err(
            field,
            format!("\"{name}\""),
            "several actors have that name; give them unique `name`s",
        )),
    }
}

/// `brake` → when and how the actor brakes.
pub(super) fn resolve_brake(
    ctx: &Ctx<'_>,
    tc: &TriggerCtx<'_>,
    bf: &str,
    b: &BrakeSpec,
    has_pace: bool,
) -> Result<BrakeEvent> {
    ctx.exactly_one(
        bf,
        &[
            ("at_s", b.at_s.is_some()),
            ("after_s", b.after_s.is_some()),
            ("ego_within_m", b.ego_within_m.is_some()),
            ("ego_gap_m", b.ego_gap_m.is_some()),
            ("ego_gap_s", b.ego_gap_s.is_some()),
            ("ego_ttc_s", b.ego_ttc_s.is_some()),
            ("ego_eta_s", b.ego_eta_s.is_some()),
            ("gap_held_s", b.gap_held_s.is_some()),
            ("after", b.after.is_some()),
        ],
    )?;
    if let (Some(of), false) = (&b.of, b.ego_within_m.is_some() || b.ego_eta_s.is_some()) {
        return Err(ctx.err(
            format!("{bf}.of"),
            format!("{of:?}"),
            "`of` goes with `ego_within_m` or `ego_eta_s`",
        ));
    }
    if b.after.is_none() {
        if let Some(d) = b.delay_s {
            return Err(ctx.err(format!("{bf}.delay_s"), d, "`delay_s` goes with `after`"));
        }
        if let Some(e) = b.event {
            return Err(ctx.err(format!("{bf}.event"), format!("{e:?}"), "`event` goes with `after`"));
        }
    }
    let when = if let Some(v) = b.at_s {
        BrakeWhen::AtS(ctx.nonneg(&format!("{bf}.at_s"), v)?)
    } else if let Some(v) = b.after_s {
        BrakeWhen::AfterS(ctx.nonneg(&format!("{bf}.after_s"), v)?)
    } else if let Some(v) = b.ego_within_m {
        let radius_m = ctx.positive(&format!("{bf}.ego_within_m"), v)?;
        let point = match &b.of {
            None => None,
            Some(OfSpec::Name(n)) if n == "actor_self" => None,
            Some(of) => Some(resolve_of(ctx, bf, Some(of), Vec2::ZERO)?),
        };
        BrakeWhen::EgoWithin { radius_m, point }
    } else if let Some(v) = b.ego_gap_m {
        BrakeWhen::EgoGap { gap_m: ctx.finite(&format!("{bf}.ego_gap_m"), v)? }
    } else if let Some(v) = b.ego_gap_s {
        BrakeWhen::EgoTimeGap { gap_s: ctx.positive(&format!("{bf}.ego_gap_s"), v)? }
    } else if let Some(v) = b.ego_ttc_s {
        BrakeWhen::EgoTtc { ttc_s: ctx.positive(&format!("{bf}.ego_ttc_s"), v)? }
    } else if let Some(v) = b.ego_eta_s {
        let eta_s = ctx.positive(&format!("{bf}.ego_eta_s"), v)?;
        let point = match &b.of {
            None | Some(OfSpec::Name(_)) => {
                return Err(ctx.err(
                    format!("{bf}.of"),
                    b.of.as_ref().map_or("<missing>".to_string(), |o| format!("{o:?}")),
                    "`ego_eta_s` on a brake needs `of` = a point `[x, y]` or a place",
                ))
            }
            Some(of) => resolve_of(ctx, bf, Some(of), Vec2::ZERO)?,
        };
        let route_s = ego_route_s_of(ctx, tc, &format!("{bf}.of"), point)?;
        BrakeWhen::EgoEta { eta_s, point, route_s }
    } else if let Some(v) = b.gap_held_s {
        if !has_pace {
            return Err(ctx.err(format!("{bf}.gap_held_s"), v, "`gap_held_s` needs a `pace` with a gap"));
        }
        BrakeWhen::GapHeld { held_s: ctx.nonneg(&format!("{bf}.gap_held_s"), v)? }
    } else {
        let actor = actor_by_name(ctx, tc, &format!("{bf}.after"), b.after.as_deref().unwrap_or_default())?;
        let delay_s = ctx.nonneg(&format!("{bf}.delay_s"), b.delay_s.unwrap_or(0.0))?;
        BrakeWhen::After { actor, event: chain_event(b.event), delay_s }
    };
    let hold_s = match b.hold_s {
        Some(h) => Some(ctx.nonneg(&format!("{bf}.hold_s"), h)?),
        None => None,
    };
    Ok(BrakeEvent {
        when,
        decel_mps2: ctx.positive(&format!("{bf}.decel_mps2"), b.decel_mps2)?,
        to_speed_mps: ctx.nonneg(&format!("{bf}.to_speed_mps"), b.to_speed_mps)?,
        hold_s,
    })
}

/// Chained triggers must point at scripted actors (brake: one with a brake event) and must
/// not form a cycle.
pub(super) fn check_chains(file: &Path, actors: &[ResolvedActor]) -> Result<()> {
    let target = |i: usize| match &actors[i].motion {
        ActorMotion::Scripted(p) => match p.trigger {
            Trigger::After { actor, event, .. } => Some((actor, event)),
            _ => None,
        },
        _ => None,
    };
    for i in 0..actors.len() {
        let Some((j, event)) = target(i) else { continue };
        let field = format!("actors[{i}].start.after");
        let value = format!("\"{}\"", actors[j].name);
        match &actors[j].motion {
            ActorMotion::Scripted(q) => {
                if event == ChainEvent::Brake && q.brake.is_none() {
                    return Err(Error::scenario(
                        file,
                        field,
                        value,
                        "event = \"brake\" but that actor has no `brake`",
                    ));
                }
            }
            _ => {
                return Err(Error::scenario(
                    file,
                    field,
                    value,
                    "that actor is not scripted (it has no trigger or events)",
                ))
            }
        }
        let mut chain = vec![i];
        let mut k = j;
        for _ in 0..actors.len() {
            if k == i {
                let names: Vec<&str> = chain.iter().map(|&x| actors[x].name.as_str()).collect();
                return Err(Error::scenario(
                    file,
                    field,
                    value,
                    format!("chained triggers form a cycle: {} → {}", names.join(" → "), actors[i].name),
                ));
            }
            chain.push(k);
            match target(k) {
                Some((n, _)) => k = n,
                None => break,
            }
        }
    }
    Ok(())
}
