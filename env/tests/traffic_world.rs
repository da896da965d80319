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
