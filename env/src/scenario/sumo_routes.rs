//! The SUMO route file of a resolved scenario's traffic and the scenario actors SUMO mirrors.
//! Both read the resolved ego/actors, so they sit above `resolve` (which itself resolves the
//! `[traffic]` table through `traffic`): keeping them in `traffic` made `traffic` ↔ `resolve` a
//! cycle.

use super::model::{ActorMotion, ResolvedActor, ResolvedEgo};
use super::traffic::{
    actor_vclass, FlowRate, LaneChoice, MirrorSpec, SpeedChoice, TrafficDemand, SUMO_EGO_ROUTE,
};
use crate::map::{EdgeIdx, Network};
use crate::view::ActorKind;
use std::fmt::Write as _;

impl TrafficDemand {
    /// The SUMO route file of one episode (times shifted so SUMO time 0 = episode −warmup_s):
    /// every vehicle type of the type file, the ego's and the mirrored actors' types, the ego
    /// route, explicit vehicles, random trips and flows sorted by departure.
    pub fn sumo_routes_xml(
        &self,
        map: &Network,
        seed: u64,
        ego: &ResolvedEgo,
        mirrors: &[MirrorSpec],
    ) -> String {
        let mut s = String::with_capacity(4096);
        s.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<routes>\n");
        for t in &self.vtypes {
            s.push_str("    <vType");
            for (k, v) in &t.attrs {
                let _ = write!(s, " {k}=\"{}\"", xml_escape(v));
            }
            s.push_str("/>\n");
        }
        let p = &ego.params;
        let _ = writeln!(
            s,
            "    <vType id=\"dh_ego\" vClass=\"passenger\" length=\"{}\" width=\"{}\" height=\"{}\" minGap=\"0\"/>",
            p.length_m, p.width_m, p.height_m
        );
        for m in mirrors {
            let _ = writeln!(
                s,
                "    <vType id=\"dh_actor_{}\" vClass=\"{}\" length=\"{}\" width=\"{}\" height=\"{}\" minGap=\"0\"/>",
                m.id,
                if m.kind.is_static() { "passenger" } else { actor_vclass(m.kind).sumo_name() },
                m.length_m,
                m.width_m,
                m.height_m
            );
        }
        let _ =
            writeln!(s, "    <route id=\"{SUMO_EGO_ROUTE}\" edges=\"{}\"/>", edge_ids(map, &ego.route_edges));
        let mut entries: Vec<(f64, String)> = Vec::new();
        let shift = self.warmup_s;
        let fmt_lane = |l: &LaneChoice| match l {
            LaneChoice::Index(i) => i.to_string(),
            LaneChoice::Named(n) => n.clone(),
        };
        let fmt_speed = |v: &SpeedChoice| match v {
            SpeedChoice::Value(x) => format!("{x}"),
            SpeedChoice::Named(n) => n.clone(),
        };
        let trips = self.random_trips(map, seed, ego.start.pos, 20.0);
        for v in self.vehicles.iter().chain(&trips) {
            let depart = v.depart_s + shift;
            let mut pos = v.depart_pos_m.map(|p| format!(" departPos=\"{p:.3}\"")).unwrap_or_default();
            if let Some(f) = v.speed_factor {
                let _ = write!(pos, " speedFactor=\"{f}\"");
            }
            entries.push((
                depart,
                format!(
                    "    <vehicle id=\"{}\" type=\"{}\" depart=\"{depart:.2}\" departLane=\"{}\" departSpeed=\"{}\"{pos}>\n        <route edges=\"{}\"/>\n    </vehicle>\n",
                    xml_escape(&v.id),
                    xml_escape(&self.vtypes[v.vtype].id),
                    fmt_lane(&v.depart_lane),
                    fmt_speed(&v.depart_speed),
                    edge_ids(map, &v.edges)
                ),
            ));
        }
        for f in &self.flows {
            let (b, e) = (f.begin_s + shift, f.end_s + shift);
            let rate = match f.rate {
                FlowRate::PerHour(v) => format!("vehsPerHour=\"{v}\""),
                FlowRate::Probability(p) => format!("probability=\"{p}\""),
            };
            // SUMO takes `end` or `number`, not both: a capped flow gets the departures that
            // fall before `end` as its `number` (as the `idm` model counts them).
            let end_or_number = match (f.number, f.rate) {
                (Some(n), FlowRate::PerHour(v)) => {
                    let before_end = ((f.end_s - f.begin_s) * v / 3600.0 - 1e-9).ceil().max(1.0) as u32;
                    format!("number=\"{}\"", n.min(before_end))
                }
                _ => format!("end=\"{e:.2}\""),
            };
            let mut pos = f.depart_pos_m.map(|p| format!(" departPos=\"{p:.3}\"")).unwrap_or_default();
            if let Some(sf) = f.speed_factor {
                let _ = write!(pos, " speedFactor=\"{sf}\"");
            }
            entries.push((
                b,
                format!(
                    "    <flow id=\"{}\" type=\"{}\" begin=\"{b:.2}\" {end_or_number} {rate} departLane=\"{}\" departSpeed=\"{}\"{pos}>\n        <route edges=\"{}\"/>\n    </flow>\n",
                    xml_escape(&f.id),
                    xml_escape(&self.vtypes[f.vtype].id),
                    fmt_lane(&f.depart_lane),
                    fmt_speed(&f.depart_speed),
                    edge_ids(map, &f.edges)
                ),
            ));
        }
        entries.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (_, e) in entries {
            s.push_str(&e);
        }
        s.push_str("</routes>\n");
        s
    }
}

fn edge_ids(map: &Network, edges: &[EdgeIdx]) -> String {
    edges.iter().map(|&e| xml_escape(&map.edges[e].id)).collect::<Vec<_>>().join(" ")
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;").replace('>', "&gt;")
}

/// The scenario actors SUMO should see: everything but pedestrians (SUMO vehicles treat them
/// as parked or moving vehicles on the lane they stand on).
pub fn mirror_specs(actors: &[ResolvedActor]) -> Vec<MirrorSpec> {
    actors
        .iter()
        .enumerate()
        .filter(|(_, a)| a.kind != ActorKind::Pedestrian)
        .filter(|(_, a)| !matches!(a.motion, ActorMotion::External { .. }))
        .map(|(i, a)| MirrorSpec {
            id: i as u32 + 1,
            kind: a.kind,
            length_m: a.length_m,
            width_m: a.width_m,
            height_m: a.height_m,
        })
        .collect()
}
