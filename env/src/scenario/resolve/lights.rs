//! `[[lights]]` → the programs the overridden lights run.

use super::Ctx;
use crate::scenario::model::LightProgram;
use crate::scenario::schema::LightOverrideSpec;
use crate::Result;

/// `[[lights]]` → the programs the overridden lights run (see [`LightProgram`]).
pub(super) fn resolve_lights(ctx: &Ctx<'_>, specs: &[LightOverrideSpec]) -> Result<Vec<LightProgram>> {
    let map = ctx.map;
    let mut out: Vec<LightProgram> = Vec::with_capacity(specs.len());
    for (i, l) in specs.iter().enumerate() {
        let f = format!("lights[{i}]");
        let tl_id = l.tls.as_str();
        let known = map.tl_ids();
        if !known.contains(&tl_id) {
            return Err(ctx.err(
                format!("{f}.tls"),
                format!("\"{tl_id}\""),
                format!("no traffic light of that id in the map (lights: {})", known.join(", ")),
            ));
        }
        if out.iter().any(|o| o.tl_id == tl_id) {
            return Err(ctx.err(format!("{f}.tls"), format!("\"{tl_id}\""), "overridden twice"));
        }
        let logic = map.tl_logic(tl_id);
        // Link count: the state length of the map's program, else the highest link index + 1.
        let links = logic
            .and_then(|lg| lg.phases.first())
            .map(|p| p.state.chars().count())
            .unwrap_or_else(|| map.tl_links(tl_id).iter().map(|k| k.link_index + 1).max().unwrap_or(0));
        let (phases, base_offset, replaced) = match &l.phases {
            Some(ps) => {
                if ps.is_empty() {
                    return Err(ctx.err(format!("{f}.phases"), "[]", "needs at least one phase"));
                }
                let mut phases = Vec::with_capacity(ps.len());
                for (k, p) in ps.iter().enumerate() {
                    let pf = format!("{f}.phases[{k}]");
                    let n = p.state.chars().count();
                    if n != links {
                        return Err(ctx.err(
                            format!("{pf}.state"),
                            format!("\"{}\"", p.state),
                            format!("has {n} characters; light `{tl_id}` controls {links} links (one character per link index)"),
                        ));
                    }
                    if let Some(c) = p.state.chars().find(|c| !"rygGsuoO".contains(*c)) {
                        return Err(ctx.err(
                            format!("{pf}.state"),
                            format!("\"{}\"", p.state),
                            format!("unknown signal character `{c}` (use SUMO's r y g G s u o O)"),
                        ));
                    }
                    let duration_s = ctx.positive(&format!("{pf}.duration_s"), p.duration_s)?;
                    phases.push(crate::map::TlPhase { duration_s, state: p.state.clone() });
                }
                (phases, 0.0, true)
            }
            None => match logic {
                Some(lg) if !lg.phases.is_empty() && lg.cycle_s() > 0.0 => {
                    (lg.phases.clone(), lg.offset_s, false)
                }
                _ => {
                    return Err(ctx.err(
                        format!("{f}.tls"),
                        format!("\"{tl_id}\""),
                        "the map has no timed program for this light; give `phases`",
                    ))
                }
            },
        };
        let offset_s = match (l.offset_s, l.start_phase, l.phase_elapsed_s) {
            (Some(_), Some(k), _) => {
                return Err(ctx.err(
                    &f,
                    format!("start_phase = {k}"),
                    "give `offset_s` or `start_phase`, not both",
                ))
            }
            (_, None, Some(e)) => {
                return Err(ctx.err(
                    format!("{f}.phase_elapsed_s"),
                    e,
                    "`phase_elapsed_s` goes with `start_phase`",
                ))
            }
            (Some(o), None, None) => base_offset + ctx.finite(&format!("{f}.offset_s"), o)?,
            (None, Some(k), e) => {
                if k >= phases.len() {
                    return Err(ctx.err(
                        format!("{f}.start_phase"),
                        k,
                        format!("light `{tl_id}` has {} phases (0-based index)", phases.len()),
                    ));
                }
                let e = ctx.nonneg(&format!("{f}.phase_elapsed_s"), e.unwrap_or(0.0))?;
                if e >= phases[k].duration_s {
                    return Err(ctx.err(
                        format!("{f}.phase_elapsed_s"),
                        e,
                        format!("must be below the phase's duration {} s", phases[k].duration_s),
                    ));
                }
                let before: f64 = phases[..k].iter().map(|p| p.duration_s).sum();
                -(before + e)
            }
            (None, None, None) if replaced => 0.0,
            (None, None, None) => {
                return Err(ctx.err(
                    &f,
                    format!("tls = \"{tl_id}\""),
                    "give one of `offset_s`, `start_phase` or `phases`",
                ))
            }
        };
        out.push(LightProgram { tl_id: tl_id.to_string(), offset_s, phases, replaced });
    }
    Ok(out)
}
