//! Ego-relative hazards (issue 21): pacing (a lead holding a gap ahead of the ego, a crossing
//! actor timed to meet the ego at a conflict point), brakes triggered by the ego's gap, time to
//! collision, distance, ETA or another actor's event, cut-ins paced beside the ego, brake lamps
//! of a standing vehicle. The point of each: a hazard-blind ego meets the hazard at any speed.

use crate::common;

use common::{cruise, Town01Scenarios};
use dh_env::drive::Control;
use dh_env::scenario::ResolvedScenario;
use dh_env::world::World;

const FILES: Town01Scenarios = Town01Scenarios { id: "hazards", category: "07_sudden_brake" };

fn load(tag: &str, speed: f64, body: &str) -> ResolvedScenario {
    FILES.load(tag, speed, body)
}

fn load_err(tag: &str, body: &str) -> String {
    let (p, e) = FILES.load_err(tag, body);
    assert!(e.starts_with(&format!("{}:", p.display())), "error names the file: {e}");
    e
}

/// Cruises blind at `v` for at most `secs`; returns the time of the first contact with `id`.
fn blind_contact(w: &mut World, id: u32, v: f64, secs: f64) -> Option<f64> {
    for _ in 0..(secs / 0.05) as usize {
        let c = cruise(w, v);
        let r = w.tick(&c).unwrap();
        if r.contacts.iter().any(|c| c.0 == id) {
            return Some(r.time_s);
        }
    }
    None
}

fn actor(w: &World, id: u32) -> dh_env::view::ActorView {
    *w.actors().iter().find(|a| a.id == id).expect("actor present")
}

/// Bumper gap from the ego's front to actor `id`'s rear (both eastbound on y ≈ −4.8).
fn gap(w: &World, id: u32) -> f64 {
    let a = actor(w, id);
    a.pose.pos.x - w.ego().pose.pos.x - 0.5 * (w.ego().length_m + a.length_m)
}

const GAP_LEAD: &str = r#"
[[actors]]
name = "lead"
kind = "car"
route = { lanes = ["C2T_1", "T2E_0"], start_s = 60.0 }
speed_mps = 8.0
pace = { gap_s = 1.5, gap_m = 2.0, min_speed_mps = 2.0, max_speed_mps = 14.0 }
brake = { gap_held_s = 4.0, decel_mps2 = 7.0, hold_s = 4.0 }
"#;

#[test]
fn gap_lead_holds_its_gap_and_brakes_in_front_of_a_blind_ego_at_any_speed() {
    for v in [3.5, 5.0, 8.0, 11.0] {
        let s = load(&format!("gap_{v}"), v, GAP_LEAD);
        let mut w = World::new(&s, 0).unwrap();
        // Settles on 2 m + 1.5 s · v and holds it until it brakes.
        let want = 2.0 + 1.5 * v;
        let mut settled_at = None;
        let mut braked = false;
        let mut prev_speed = 8.0;
        for k in 0..(40.0 / 0.05) as usize {
            let c = cruise(&w, v);
            w.tick(&c).unwrap();
            let a = actor(&w, 1);
            // The hard brake: 7 m/s² = 0.35 m/s a tick (pacing changes speed at ≤ 3 m/s²).
            if prev_speed - a.speed_mps > 0.3 {
                braked = true;
                break;
            }
            prev_speed = a.speed_mps;
            let g = gap(&w, 1);
            if settled_at.is_none() && (g - want).abs() < 1.0_f64.max(0.15 * want) {
                settled_at = Some(k);
            }
            if settled_at.is_some_and(|s| k > s + 20) {
                assert!((g - want).abs() < 1.5_f64.max(0.2 * want), "v = {v}: gap {g:.2} vs {want:.2}");
                assert!((a.speed_mps - v).abs() < 1.0, "v = {v}: lead at {:.2} m/s", a.speed_mps);
            }
        }
        assert!(settled_at.is_some() && braked, "v = {v}: settled {settled_at:?}, braked {braked}");
        // A blind ego rear-ends it, whatever its pace.
        let s = load(&format!("gap_hit_{v}"), v, GAP_LEAD);
        let mut w = World::new(&s, 0).unwrap();
        assert!(blind_contact(&mut w, 1, v, 60.0).is_some(), "v = {v}: no contact");
    }
}

#[test]
fn pacing_respects_its_speed_bounds() {
    // A standing ego: the lead slows to min_speed_mps (2) and no further, so it drives away.
    let s = load("gap_stand", 0.0, GAP_LEAD);
    let mut w = World::new(&s, 0).unwrap();
    for _ in 0..200 {
        w.tick(&Control { throttle: 0.0, brake: 1.0, steer: 0.0 }).unwrap();
    }
    assert!((actor(&w, 1).speed_mps - 2.0).abs() < 1e-9, "{:?}", actor(&w, 1));
    // A fast ego: the lead is capped at max_speed_mps (14).
    let s = load("gap_fast", 20.0, GAP_LEAD);
    let mut w = World::new(&s, 0).unwrap();
    let mut top: f64 = 0.0;
    for _ in 0..200 {
        let c = cruise(&w, 20.0);
        w.tick(&c).unwrap();
        top = top.max(actor(&w, 1).speed_mps);
    }
    assert!((top - 14.0).abs() < 1e-9, "top speed {top}");
}

/// A lead at 6 m/s 50 m ahead with `brake` (no pacing): when does it brake?
fn lead_with_brake(brake: &str) -> String {
    format!(
        "\n[[actors]]\nname = \"lead\"\nkind = \"car\"\nroute = {{ lanes = [\"C2T_1\", \"T2E_0\"], start_s = 75.0 }}\nspeed_mps = 6.0\nbrake = {brake}\n"
    )
}

/// Cruises at `v` until actor 1 starts braking; returns (time, bumper gap, ego x).
fn until_brake(s: &ResolvedScenario, v: f64) -> Option<(f64, f64, f64)> {
    let mut w = World::new(s, 0).unwrap();
    for _ in 0..1200 {
        let c = cruise(&w, v);
        let r = w.tick(&c).unwrap();
        if actor(&w, 1).speed_mps < 5.9 && r.time_s > 2.5 {
            return Some((r.time_s, gap(&w, 1), w.ego().pose.pos.x));
        }
    }
    None
}

#[test]
fn brakes_fire_on_the_egos_gap_time_gap_ttc_distance_and_eta() {
    // Bumper gap ≤ 10 m.
    let s = load("b_gap", 10.0, &lead_with_brake("{ ego_gap_m = 10.0, decel_mps2 = 6.0 }"));
    let (_, g, _) = until_brake(&s, 10.0).expect("fires");
    assert!(g <= 10.35 && g > 9.5, "gap at the brake {g}");
    // Time gap ≤ 2 s at 10 m/s: 20 m.
    let s = load("b_tgap", 10.0, &lead_with_brake("{ ego_gap_s = 2.0, decel_mps2 = 6.0 }"));
    let (_, g, _) = until_brake(&s, 10.0).expect("fires");
    assert!(g <= 20.35 && g > 19.5, "gap at the brake {g}");
    // TTC ≤ 4 s closing at 4 m/s: 16 m.
    let s = load("b_ttc", 10.0, &lead_with_brake("{ ego_ttc_s = 4.0, decel_mps2 = 6.0 }"));
    let (_, g, _) = until_brake(&s, 10.0).expect("fires");
    assert!(g <= 16.35 && g > 15.5, "gap at the brake {g}");
    // Ego centre within 25 m of the actor's centre (default `of`: the actor itself).
    let s = load("b_within", 10.0, &lead_with_brake("{ ego_within_m = 25.0, decel_mps2 = 6.0 }"));
    let (_, g, _) = until_brake(&s, 10.0).expect("fires");
    assert!((g + 4.7 - 25.0).abs() < 0.6, "centre distance at the brake {}", g + 4.7);
    // The ego expected at x = 200 within 3 s: at any ego speed it is 3 s · v before it.
    for v in [4.0, 10.0] {
        let s = load(
            &format!("b_eta_{v}"),
            v,
            &lead_with_brake("{ ego_eta_s = 3.0, of = [200.0, -4.8], decel_mps2 = 6.0 }"),
        );
        let (_, _, x) = until_brake(&s, v).expect("fires");
        assert!((x - (200.0 - 3.0 * v)).abs() < 0.1 * v + 0.3, "v = {v}: ego at x = {x}");
    }
    // Chained: 1 s after another actor's start (a walker released by time at 5 s).
    let body = format!(
        "{}\n[[actors]]\nname = \"walker\"\nkind = \"pedestrian\"\nwaypoints = [{{ x = 300.0, y = -12.0 }}, {{ x = 300.0, y = -10.0 }}]\nstart = {{ time_s = 5.0 }}\n",
        lead_with_brake("{ after = \"walker\", delay_s = 1.0, decel_mps2 = 6.0 }")
    );
    let s = load("b_chain", 10.0, &body);
    let (t, _, _) = until_brake(&s, 10.0).expect("fires");
    assert!((t - 6.05).abs() < 0.06, "braked at {t}");
}

/// A car crossing the ego's lane northwards at x = 200, paced to meet the ego there.
const MEET: &str = r#"
[[actors]]
name = "crosser"
kind = "car"
speed_mps = 8.0
waypoints = [{ x = 200.0, y = -60.0 }, { x = 200.0, y = 40.0 }]
pace = { meet = [200.0, -4.8], min_speed_mps = 0.0, max_speed_mps = 12.0 }
"#;

#[test]
fn meet_pacing_brings_a_crossing_car_to_the_conflict_point_with_the_ego() {
    for v in [3.0, 5.0, 8.0, 12.0] {
        let s = load(&format!("meet_{v}"), v, MEET);
        let mut w = World::new(&s, 0).unwrap();
        let t = blind_contact(&mut w, 1, v, 90.0);
        assert!(t.is_some(), "v = {v}: the blind ego never met the crossing car");
    }
    // A standing ego (ETA = distance ÷ 0.5 m/s): the car creeps towards the conflict point and
    // stays out of the ego's lane.
    let s = load("meet_stand", 0.0, MEET);
    let mut w = World::new(&s, 0).unwrap();
    for _ in 0..600 {
        w.tick(&Control { throttle: 0.0, brake: 1.0, steer: 0.0 }).unwrap();
    }
    let a = actor(&w, 1);
    assert!(a.pose.pos.y < -8.0 && a.pose.pos.y > -59.0, "car at {:?}", a.pose.pos);
    // offset_s = 3: it arrives 3 s after the ego would, so a steady ego passes first.
    let s =
        load("meet_late", 6.0, &MEET.replace("max_speed_mps = 12.0", "max_speed_mps = 12.0, offset_s = 3.0"));
    let mut w = World::new(&s, 0).unwrap();
    assert!(blind_contact(&mut w, 1, 6.0, 60.0).is_none());
}

/// A car in the left lane paced 3 m ahead of the ego's front (rear overlap) cuts in at s = 80.
const CUT_IN: &str = r#"
[[actors]]
name = "cutter"
kind = "car"
route = { lanes = ["C2T_2", "T2E_1"], start_s = 40.0 }
speed_mps = 10.0
pace = { gap_m = 3.0, min_speed_mps = 2.0, max_speed_mps = 16.0, until_s = 80.0 }
lane_changes = [{ at_s = 80.0, to_lane = "C2T_1", length_m = 20.0 }]
brake = { at_s = 100.0, decel_mps2 = 7.0, hold_s = 3.0 }
"#;

#[test]
fn cut_in_paced_beside_the_ego_lands_close_ahead_at_any_speed() {
    for v in [4.0, 6.0, 10.0] {
        let s = load(&format!("cut_{v}"), v, CUT_IN);
        let mut w = World::new(&s, 0).unwrap();
        let mut at_cut = None;
        for _ in 0..1600 {
            let c = cruise(&w, v);
            w.tick(&c).unwrap();
            let a = actor(&w, 1);
            // Crossing into the ego lane (y < −3.2): the relative position of the cut.
            if at_cut.is_none() && a.pose.pos.y < -3.2 {
                at_cut = Some(gap(&w, 1));
                break;
            }
        }
        let g = at_cut.expect("cuts in");
        assert!(g > 0.0 && g < 8.0, "v = {v}: bumper gap when the cutter enters the lane {g:.2}");
        let s = load(&format!("cut_hit_{v}"), v, CUT_IN);
        let mut w = World::new(&s, 0).unwrap();
        assert!(blind_contact(&mut w, 1, v, 60.0).is_some(), "v = {v}: no contact");
    }
}

#[test]
fn brake_lamps_stay_lit_while_a_braked_vehicle_stands() {
    let s = load("lamps", 0.0, &lead_with_brake("{ after_s = 2.0, decel_mps2 = 6.0, hold_s = 3.0 }"));
    let mut w = World::new(&s, 0).unwrap();
    let mut seen = Vec::new();
    for _ in 0..200 {
        w.tick(&Control { throttle: 0.0, brake: 1.0, steer: 0.0 }).unwrap();
        let a = actor(&w, 1);
        seen.push((w.time_s(), a.speed_mps, a.braking));
    }
    // Braking from 2 s, standing from 3 s to 6 s: lit throughout; dark once it drives off.
    for &(t, v, lit) in &seen {
        if t > 2.1 && t < 6.0 {
            assert!(lit, "t = {t:.2}, v = {v:.2}: lamps dark");
        }
        if t > 6.2 {
            assert!(!lit && v > 0.0, "t = {t:.2}, v = {v:.2}: lamps lit while driving off");
        }
    }
    assert!(seen.iter().any(|&(t, v, _)| t > 3.5 && t < 5.5 && v == 0.0), "stands");
}

#[test]
fn hazard_scenarios_are_deterministic() {
    let body =
        format!("{GAP_LEAD}{}", MEET.replace("[200.0, -4.8]", "[250.0, -4.8]").replace("200.0", "250.0"));
    let run = || {
        let s = load("det", 6.0, &body);
        let mut w = World::new(&s, 0).unwrap();
        let mut out = Vec::new();
        for _ in 0..800 {
            let c = cruise(&w, 6.0);
            w.tick(&c).unwrap();
            out.extend(
                w.actors().iter().map(|a| (a.pose.pos.x.to_bits(), a.pose.pos.y.to_bits(), a.braking)),
            );
        }
        out
    };
    assert_eq!(run(), run());
}

#[test]
fn pace_and_brake_errors_name_field_and_value() {
    let lead = |extra: &str| {
        format!(
            "\n[[actors]]\nkind = \"car\"\nroute = {{ lanes = [\"C2T_1\", \"T2E_0\"], start_s = 60.0 }}\n{extra}\n"
        )
    };
    let cases: &[(&str, &str, &str)] = &[
        ("pace = { min_speed_mps = 2.0 }", "actors[0].pace", "give a gap"),
        ("pace = { gap_s = 1.0, meet = [200.0, -4.8] }", "actors[0].pace", "not both"),
        ("pace = { gap_s = -1.0 }", "actors[0].pace.gap_s", "≥ 0"),
        ("pace = { gap_s = 1.0, offset_s = 1.0 }", "actors[0].pace.offset_s", "goes with `meet`"),
        (
            "pace = { gap_s = 1.0, min_speed_mps = 9.0, max_speed_mps = 5.0 }",
            "actors[0].pace.max_speed_mps",
            "below min_speed_mps",
        ),
        ("pace = { meet = [200.0, 30.0] }", "actors[0].pace.meet", "does not project onto the ego route"),
        ("pace = { meet = [200.0, -1.6] }", "actors[0].pace.meet", "not on the actor's path"),
        ("brake = { decel_mps2 = 5.0 }", "actors[0].brake", "give exactly one of"),
        ("brake = { at_s = 5.0, ego_gap_m = 3.0, decel_mps2 = 5.0 }", "actors[0].brake", "at_s + ego_gap_m"),
        ("brake = { ego_eta_s = 2.0, decel_mps2 = 5.0 }", "actors[0].brake.of", "needs `of`"),
        ("brake = { ego_gap_s = 0.0, decel_mps2 = 5.0 }", "actors[0].brake.ego_gap_s", "> 0"),
        ("brake = { ego_ttc_s = 2.0, of = [1.0, 2.0], decel_mps2 = 5.0 }", "actors[0].brake.of", "goes with"),
        ("brake = { gap_held_s = 2.0, decel_mps2 = 5.0 }", "actors[0].brake.gap_held_s", "needs a `pace`"),
        ("brake = { after = \"ghost\", decel_mps2 = 5.0 }", "actors[0].brake.after", "no actor of that name"),
        (
            "brake = { ego_gap_m = 5.0, delay_s = 1.0, decel_mps2 = 5.0 }",
            "actors[0].brake.delay_s",
            "goes with `after`",
        ),
    ];
    for (i, (extra, field, msg)) in cases.iter().enumerate() {
        let e = load_err(&format!("err_{i}"), &lead(extra));
        assert!(e.contains(&format!("field `{field}`")) && e.contains(msg), "{extra}: {e}");
        // Line and column of the field in the file.
        let loc = e.split(": field").next().unwrap();
        assert!(loc.rsplit(':').take(2).all(|n| n.parse::<usize>().is_ok()), "{e}");
    }
    // A gap needs the actor near the ego route.
    let far = "\n[[actors]]\nkind = \"car\"\nroute = { lanes = [\"T2E_0\"], start_s = 60.0 }\npace = { gap_s = 1.0 }\n";
    let e = load_err("err_far", far);
    assert!(e.contains("actors[0].pace") && e.contains("measured along the ego route"), "{e}");
}

/// Ego and actor states over `ticks` ticks of blind cruising at 6 m/s.
fn trace(s: &ResolvedScenario, ticks: usize) -> Vec<(u64, u64, u64)> {
    let mut w = World::new(s, 0).unwrap();
    let mut out = Vec::new();
    for _ in 0..ticks {
        let c = cruise(&w, 6.0);
        let r = w.tick(&c).unwrap();
        for a in std::iter::once(&r.ego).chain(w.actors()) {
            out.push((a.pose.pos.x.to_bits(), a.pose.pos.y.to_bits(), a.speed_mps.to_bits()));
        }
    }
    out
}

#[test]
fn seeds_vary_the_scenario_within_its_bounds_and_seed_zero_is_as_written() {
    let body = format!(
        "{GAP_LEAD}{CUT_IN}\n[[obstacles]]\nkind = \"cone\"\nat = {{ lane = \"C2T_2\", s = 300.0 }}\n"
    );
    let s = load("var", 6.0, &body);
    let base = trace(&s, 300);
    assert_eq!(trace(&s.varied(0), 300), base, "seed 0 is the scenario as written");
    assert_eq!(trace(&s.varied(5), 300), trace(&s.varied(5), 300), "a seed is reproducible");
    let mut distinct = std::collections::BTreeSet::new();
    for seed in 1..=8u64 {
        let v = s.varied(seed);
        let t = trace(&v, 300);
        assert_ne!(t, base, "seed {seed} plays the canonical episode");
        distinct.insert(t);
        // Within the default bounds: ego ≤ 2 m further along its route, speed ± 10 %.
        let d = v.ego.start.pos.dist(s.ego.start.pos);
        assert!(d <= 2.0 + 1e-9 && (v.ego.speed_mps / 6.0 - 1.0).abs() <= 0.1 + 1e-9, "seed {seed}");
        for (a, b) in v.actors.iter().zip(&s.actors) {
            match (&a.motion, &b.motion) {
                (dh_env::scenario::ActorMotion::Scripted(p), dh_env::scenario::ActorMotion::Scripted(q)) => {
                    let d = p.path.point_at(0.0).dist(q.path.point_at(0.0));
                    assert!(d <= 2.0 + 1e-6, "seed {seed}: {} start moved {d}", a.name);
                    let f = p.legs[0].1 / q.legs[0].1;
                    assert!((f - 1.0).abs() <= 0.08 + 1e-9, "seed {seed}: speed × {f}");
                }
                (
                    dh_env::scenario::ActorMotion::Static { pose: p },
                    dh_env::scenario::ActorMotion::Static { pose: q },
                ) => assert!(p.pos.dist(q.pos) <= 0.5 + 1e-9),
                _ => unreachable!(),
            }
        }
    }
    assert_eq!(distinct.len(), 8, "eight seeds, eight episodes");
    // Declared bounds of zero switch the jitter off.
    let off = "\n[variation]\nego_start_m = 0.0\nego_speed = 0.0\nactor_start_m = 0.0\nactor_speed = 0.0\ntrigger = 0.0\nobstacle_m = 0.0\n";
    let s = load("var_off", 6.0, &format!("{body}{off}"));
    assert_eq!(trace(&s.varied(3), 300), trace(&s, 300));
}

#[test]
fn variation_errors_name_the_key() {
    for (text, field) in [
        ("[variation]\nego_speed = 0.7\n", "variation.ego_speed"),
        ("[variation]\nactor_start_m = -1.0\n", "variation.actor_start_m"),
        ("[variation]\nspeed = 0.1\n", "variation.speed"),
    ] {
        let e = load_err(&format!("var_err_{field}"), &format!("\n{text}"));
        assert!(e.contains(&format!("field `{field}`")), "{e}");
    }
}

#[test]
fn traffic_departures_vary_by_seed_only_off_seed_zero() {
    let body = "\n[traffic]\nmode = \"idm\"\n\n[[traffic.vehicles]]\nroute = [\"C2T\"]\ndepart_s = 2.0\nspeed_factor = 0.9\n\n[[traffic.flows]]\nfrom = \"C2T\"\nto = \"C2T\"\nvehs_per_hour = 600\n";
    let s = load("var_traffic", 6.0, body);
    let d0 = s.traffic.varied(0);
    assert_eq!(d0, s.traffic);
    let d1 = s.traffic.varied(1);
    assert_ne!(d1.vehicles[0].depart_s, 2.0);
    assert!((d1.vehicles[0].depart_s - 2.0).abs() <= 1.5);
    assert!((d1.vehicles[0].speed_factor.unwrap() / 0.9 - 1.0).abs() <= 0.05 + 1e-12);
    assert!(
        d1.flows[0].begin_s > s.traffic.flows[0].begin_s,
        "a flow from the warm-up start only departs later"
    );
    assert_eq!(d1, s.traffic.varied(1));
    let m = s.map.clone();
    assert_ne!(
        s.traffic.varied(0).sumo_routes_xml(&m, 0, &s.ego, &[]),
        s.traffic.varied(1).sumo_routes_xml(&m, 0, &s.ego, &[])
    );
}
