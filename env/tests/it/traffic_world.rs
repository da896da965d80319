//! Background traffic: the world's batched traffic seam and the `[traffic]` demand (random trips,
//! the SUMO route file) on the project's town01 net.

use dh_env::drive::Control;
use dh_env::geom::{Pose, Vec2};
use dh_env::scenario::traffic::{mirror_specs, LaneChoice, TrafficMode};
use dh_env::scenario::Scenario;
use dh_env::view::{ActorKind, ContactClass, LightColor};
use dh_env::world::{TrafficAgent, TrafficFrame, TrafficInput, TrafficModel, World};
use dh_env::Result;
use std::path::PathBuf;

fn scenarios() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

/// One scripted frame: the vehicles present and the changed light states.
type ScriptFrame = (Vec<TrafficAgent>, Vec<(String, String)>);

/// A model replaying a fixed script of frames (tick → agents, lights), recording its inputs.
#[derive(Debug, Default)]
struct Script {
    frames: Vec<ScriptFrame>,
    seen_ego: Vec<Pose>,
    started_with: Option<u64>,
}

impl TrafficModel for Script {
    fn start(&mut self, input: &TrafficInput<'_>, seed: u64, out: &mut TrafficFrame) -> Result<()> {
        self.started_with = Some(seed);
        self.tick(input, out)
    }
    fn tick(&mut self, input: &TrafficInput<'_>, out: &mut TrafficFrame) -> Result<()> {
        self.seen_ego.push(input.ego.pose);
        if let Some((agents, lights)) = self.frames.get(input.tick as usize) {
            out.agents.extend_from_slice(agents);
            out.lights.extend(lights.iter().cloned());
        }
        Ok(())
    }
    fn drives_lights(&self) -> bool {
        true
    }
    fn name(&self) -> &str {
        "script"
    }
}

fn agent(key: u64, x: f64, y: f64, speed: f64, signals: u32) -> TrafficAgent {
    TrafficAgent {
        key,
        kind: ActorKind::Car,
        length_m: 4.5,
        width_m: 1.9,
        height_m: 1.5,
        color: [1, 2, 3],
        emergency: false,
        pose: Pose::new(Vec2::new(x, y), 0.0),
        speed_mps: speed,
        signals,
    }
}

#[test]
fn traffic_frames_spawn_move_remove_collide_and_drive_lights() {
    let s = Scenario::load(scenarios().join("bench/town01_sumo_traffic.toml")).unwrap();
    let mut w = World::new(&s, 42).unwrap();
    let base = s.actors.len() as u32;
    let ego = w.ego().pose.pos;
    let all_red = "r".repeat(20);
    let script = Script {
        frames: vec![
            // t = 0: two vehicles far ahead.
            (vec![agent(7, ego.x + 50.0, ego.y, 5.0, 0), agent(9, ego.x + 80.0, ego.y, 6.0, 0)], vec![]),
            // tick 1: key 7 brakes (brake light) and moves; key 9 leaves; key 11 appears on the ego.
            (
                vec![agent(7, ego.x + 51.0, ego.y, 4.0, 8), agent(11, ego.x + 1.0, ego.y, 0.0, 2)],
                vec![("C".into(), all_red.clone())],
            ),
        ],
        ..Script::default()
    };
    w.attach_traffic(Box::new(script)).unwrap();
    assert_eq!(w.traffic_name(), Some("script"));
    let ids: Vec<u32> = w.actors().iter().filter(|a| w.is_traffic_actor(a.id)).map(|a| a.id).collect();
    assert_eq!(ids, vec![base + 1, base + 2]);
    assert_eq!(w.traffic_key(base + 1), Some(7));
    let r = w.tick(&Control { throttle: 0.0, brake: 1.0, steer: 0.0 }).unwrap();
    let traffic: Vec<_> = w.actors().iter().filter(|a| w.is_traffic_actor(a.id)).copied().collect();
    assert_eq!(traffic.iter().map(|a| a.id).collect::<Vec<_>>(), vec![base + 1, base + 3]);
    assert!(traffic[0].braking && (traffic[0].pose.pos.x - (ego.x + 51.0)).abs() < 1e-12);
    assert_eq!(w.actor_signals(base + 3), 2);
    // The vehicle standing on the ego collides through the same path as every actor.
    assert_eq!(r.contacts, vec![(base + 3, ContactClass::Vehicle)]);
    // SUMO-style states drive the signal heads of light C.
    assert!(w.lights().iter().filter(|l| l.tl_id == "C").all(|l| l.color == LightColor::Red));
    // Tick 2: the model lists nobody, so every traffic vehicle leaves; ids are never reused.
    w.tick(&Control::default()).unwrap();
    assert!(w.actors().iter().all(|a| !w.is_traffic_actor(a.id)));
    assert!(w.tick(&Control::default()).unwrap().contacts.is_empty());
    let back = w.detach_traffic().unwrap();
    assert_eq!(back.name(), "script");
}

#[test]
fn bench_demand_resolves_with_seeded_connected_random_trips() {
    let s = Scenario::load(scenarios().join("bench/town01_sumo_traffic.toml")).unwrap();
    let t = &s.traffic;
    assert_eq!(t.mode, TrafficMode::Sumo);
    assert_eq!(t.flows.len(), 2);
    assert!(t.vtypes.iter().any(|v| v.id == "car") && t.vtypes.iter().any(|v| v.id == "bus"));
    let map = &s.map;
    let a = t.random_trips(map, 1, s.ego.start.pos, 20.0);
    let b = t.random_trips(map, 1, s.ego.start.pos, 20.0);
    let c = t.random_trips(map, 2, s.ego.start.pos, 20.0);
    assert_eq!(a, b);
    assert_ne!(a, c);
    assert!(a.len() >= 50, "{}", a.len());
    for v in &a {
        // Every route follows the lane graph for its class, departs on a lane that allows it,
        // away from the ego start.
        let class = t.vtypes[v.vtype].vclass;
        for pair in v.edges.windows(2) {
            assert!(map.edge_route(pair[0], pair[1], class).is_some_and(|r| r.len() == 2), "{:?}", v.edges);
        }
        let LaneChoice::Index(li) = v.depart_lane else { panic!("explicit lane") };
        let lane = &map.lanes[map.edges[v.edges[0]].lanes[li as usize]];
        assert!(lane.allow.contains(class));
        let p = lane.shape.point_at(v.depart_pos_m.unwrap());
        assert!(p.dist(s.ego.start.pos) >= 20.0);
    }
    let xml = t.sumo_routes_xml(map, 1, &s.ego, &mirror_specs(&s.actors));
    assert_eq!(xml, t.sumo_routes_xml(map, 1, &s.ego, &mirror_specs(&s.actors)));
    assert_eq!(xml.matches("<vehicle ").count(), a.len());
    assert!(xml.contains("<flow id=\"north_south\"") && xml.contains("<vType id=\"dh_ego\""));
}

#[test]
fn scenarios_without_a_traffic_table_have_no_demand() {
    let s = Scenario::load(scenarios().join("r4/07_sudden_brake/town01_07_lead_brakes.toml")).unwrap();
    assert_eq!(s.traffic.mode, TrafficMode::None);
    assert!(s.traffic.is_empty());
}

/// A town01 scenario in idm traffic mode: `ego` is the `[ego]` table body, `rest` is
/// appended (actors, traffic).
fn idm_town01(tag: &str, ego: &str, rest: &str) -> dh_env::scenario::ResolvedScenario {
    let map = scenarios().join("maps/town01/town01.net.xml");
    let text = format!(
        "version = 1\nid = \"{tag}\"\nname = \"t\"\ncategory = \"06_traffic_flow\"\ndescription = \"d\"\n\
         map = {:?}\nreference_duration_s = 50.0\n\n[ego]\n{ego}\n{rest}",
        map.display().to_string()
    );
    let dir = std::env::temp_dir().join(format!("dh_traffic_world_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(format!("{tag}.toml"));
    std::fs::write(&p, text).unwrap();
    Scenario::load(&p).unwrap_or_else(|e| panic!("{tag}: {e}"))
}

/// Runs `secs` with the ego holding `v` m/s straight on; returns every contact (time, id) and
/// the number of traffic vehicles seen.
fn run_idm(s: &dh_env::scenario::ResolvedScenario, v: f64, secs: f64) -> (Vec<(f64, u32)>, usize) {
    let mut w = World::new(s, 0).unwrap();
    w.attach_traffic(Box::new(dh_env::world::idm::IdmTraffic::new(s).unwrap())).unwrap();
    let mut contacts = Vec::new();
    let mut seen = std::collections::BTreeSet::new();
    for _ in 0..(secs / dh_env::DT_S).round() as usize {
        let e = v - w.ego().speed_mps;
        let c =
            Control { throttle: (0.5 * e).clamp(0.0, 1.0), brake: (-0.5 * e).clamp(0.0, 1.0), steer: 0.0 };
        let r = w.tick(&c).unwrap();
        contacts.extend(r.contacts.iter().map(|&(id, _)| (r.time_s, id)));
        seen.extend(w.actors().iter().filter(|a| w.is_traffic_actor(a.id)).map(|a| a.id));
    }
    (contacts, seen.len())
}

/// IDM insertion waits, as SUMO's does, until the departure spot is free: a flow in the
/// ego's own lane never places (or, after the warm-up, queues) a car into the ego or into a
/// scripted actor standing on its departure spot.
#[test]
fn idm_insertion_never_overlaps_the_ego_or_an_actor() {
    let flow =
        "[traffic]\nmode = \"idm\"\nwarmup_s = 3.0\n\n[[traffic.flows]]\nid = \"mine\"\nfrom = \"C2T\"\n\
                to = \"T2E\"\ndepart_lane = 1\nvehs_per_hour = 1800\nbegin_s = -3.0\n";
    // The ego 30 m into the lane, driving off at 8 m/s at t = 0 (it stands during the warm-up).
    let s = idm_town01(
        "own_lane",
        "start = { lane = \"C2T_1\", s = 30.0 }\nspeed_mps = 8.0\nroute_edges = [\"C2T\", \"T2E\"]",
        flow,
    );
    let (contacts, n) = run_idm(&s, 8.0, 20.0);
    assert!(contacts.is_empty(), "{contacts:?}");
    assert!(n >= 5, "the flow inserts once there is room: {n} vehicles");
    // The ego standing right on the departure spot: nothing departs until it has left.
    let s = idm_town01(
        "on_spot",
        "start = { lane = \"C2T_1\", s = 3.0 }\nroute_edges = [\"C2T\", \"T2E\"]",
        flow,
    );
    let (contacts, n) = run_idm(&s, 6.0, 20.0);
    assert!(contacts.is_empty(), "{contacts:?}");
    assert!(n >= 3, "{n}");
    // A scripted car parked on the departure spot (never triggered): the flow waits behind it
    // for ever, it never spawns into it.
    let parked = format!(
        "[[actors]]\nkind = \"car\"\nroute = {{ lanes = [\"C2T_1\"], start_s = 4.0 }}\nspeed_mps = 5.0\n\
         start = {{ time_s = 1000.0 }}\n{flow}"
    );
    let s = idm_town01(
        "actor_spot",
        "start = { lane = \"C2T_1\", s = 60.0 }\nroute_edges = [\"C2T\", \"T2E\"]",
        &parked,
    );
    let mut w = World::new(&s, 0).unwrap();
    w.attach_traffic(Box::new(dh_env::world::idm::IdmTraffic::new(&s).unwrap())).unwrap();
    for _ in 0..200 {
        w.tick(&Control::default()).unwrap();
        let actor = w.actors().iter().find(|a| !w.is_traffic_actor(a.id)).unwrap().footprint();
        for t in w.actors().iter().filter(|a| w.is_traffic_actor(a.id)) {
            let d = t.pose.pos.dist(actor.pose.pos);
            assert!(
                d > 0.5 * (t.length_m + 2.0 * actor.half_length),
                "vehicle {} inside the parked car: {d:.2} m",
                t.id
            );
        }
    }
}

/// Every `TrafficMode` that serde reads (its JSON Schema) round-trips through `parse` and
/// `as_str`, and each deprecated name still reads as the mode it now means.
#[test]
fn traffic_mode_names_round_trip_and_old_names_still_read() {
    let schema = schemars::schema_for!(TrafficMode).to_value();
    let one_of = schema.get("oneOf").and_then(|a| a.as_array()).cloned().unwrap_or_default();
    let names: Vec<String> = std::iter::once(&schema)
        .chain(&one_of)
        .flat_map(|a| {
            let consts = a.get("const").into_iter();
            consts.chain(a.get("enum").and_then(|e| e.as_array()).into_iter().flatten())
        })
        .filter_map(|v| v.as_str().map(str::to_owned))
        .collect();
    assert_eq!(names, ["sumo", "idm", "none"]);
    for n in &names {
        let m = TrafficMode::parse(n).unwrap();
        assert_eq!(m.as_str(), n);
        assert_eq!(serde_json::from_value::<TrafficMode>(serde_json::json!(n)).unwrap(), m);
    }
    for (old, new) in TrafficMode::DEPRECATED_NAMES {
        assert!(!names.iter().any(|n| n == old), "{old} is still a current name");
        assert_eq!(TrafficMode::parse(old), Some(new));
        assert_eq!(serde_json::from_value::<TrafficMode>(serde_json::json!(old)).unwrap(), new);
    }
}
