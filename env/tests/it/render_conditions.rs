//! Light and weather (`[conditions]`, `[variation] conditions`, the run-wide override) and the
//! camera-fault control: parsing and its errors, what each condition draws, and determinism.

use crate::common::Town01Scenarios;
use dh_env::conditions::{Conditions, TimeOfDay, Weather};
use dh_env::drive::Decision;
use dh_env::geom::Pose;
use dh_env::map::Network;
use dh_env::render::{Ambience, CameraConfig, CameraFault, FrameInput, Image, RenderMap, Renderer};
use dh_env::scenario::LoadOptions;
use dh_env::sim::{Action, Sim, SimConfig};
use dh_env::view::{ActorKind, ActorView};
use std::path::Path;
use std::sync::OnceLock;

const S: Town01Scenarios = Town01Scenarios { id: "conditions", category: "01_pedestrian" };

fn world() -> &'static (Network, RenderMap) {
    static W: OnceLock<(Network, RenderMap)> = OnceLock::new();
    W.get_or_init(|| {
        let net =
            Network::from_file(Path::new("../scenarios/maps/town01/town01.net.xml")).expect("town01 net");
        let map = RenderMap::build(&net);
        (net, map)
    })
}

fn car(id: u32, pose: Pose, color: [u8; 3]) -> ActorView {
    ActorView { speed_mps: 5.0, ..ActorView::at_rest(id, ActorKind::Car, pose, color) }
}

/// The ego on W2C_1 60 m before its end (a junction ahead), a car 18 m ahead, one oncoming.
fn scene() -> (ActorView, [ActorView; 2]) {
    let (net, _) = world();
    let lane = net.lane_by_id("W2C_1").expect("lane W2C_1");
    let e = net.lane_position(lane, net.lanes[lane].shape.length() - 60.0);
    let ego = car(0, e, [30, 110, 230]);
    let lead = car(1, Pose::new(e.local_to_world(18.0, 0.0), e.yaw), [200, 40, 40]);
    let oncoming =
        car(2, Pose::new(e.local_to_world(35.0, 3.4), e.yaw + std::f64::consts::PI), [230, 230, 230]);
    (ego, [lead, oncoming])
}

fn render(r: &mut Renderer, c: Conditions, seed: u64, tick: u64) -> Image {
    let (_, map) = world();
    let (ego, actors) = scene();
    let frame = FrameInput {
        ego: &ego,
        actors: &actors,
        lights: &[],
        signs: &[],
        route_points: &[],
        ambience: Ambience { conditions: c, seed, tick },
    };
    let mut img = Image::default();
    r.render_camera(map, &frame, &CameraConfig::front(), &mut img).unwrap();
    img
}

/// Mean brightness (sum of channels / 3) of a pixel box.
fn mean(img: &Image, x0: u32, y0: u32, x1: u32, y1: u32) -> f64 {
    let mut acc = 0u64;
    for y in y0..y1 {
        for x in x0..x1 {
            let p = img.pixel(x, y).unwrap();
            acc += p.iter().map(|&v| v as u64).sum::<u64>();
        }
    }
    acc as f64 / 3.0 / f64::from((x1 - x0) * (y1 - y0))
}

#[test]
fn scenario_conditions_parse_default_and_name_bad_values() {
    let s = S.load("plain", 8.0, "");
    assert_eq!(s.conditions, Conditions::default());
    assert!(s.condition_choices.is_empty());
    let s = S.load("night_fog", 8.0, "[conditions]\ntime_of_day = \"night\"\nweather = \"fog\"\n");
    assert_eq!(s.conditions, Conditions { time_of_day: TimeOfDay::Night, weather: Weather::Fog });
    assert_eq!(s.varied(3).conditions, s.conditions, "no [variation] conditions: every seed keeps them");

    let (p, e) = S.load_err("snow", "[conditions]\nweather = \"snow\"\n");
    assert!(
        e.contains(&p.display().to_string()) && e.contains("conditions.weather") && e.contains("snow"),
        "{e}"
    );
    let (_, e) = S.load_err("key", "[conditions]\nlight = \"night\"\n");
    assert!(e.contains("light"), "{e}");
    let (p, e) = S.load_err("var", "[variation]\nconditions = [\"night\", \"midnight\"]\n");
    assert!(
        e.contains(&p.display().to_string())
            && e.contains("variation.conditions[1]")
            && e.contains("midnight"),
        "{e}"
    );
}

#[test]
fn variation_draws_conditions_per_seed_deterministically() {
    let body = "[conditions]\nweather = \"overcast\"\n\n[variation]\nconditions = [\"noon\", \"night\", \"rain\", \"dusk+fog\"]\n";
    let s = S.load("drawn", 8.0, body);
    assert_eq!(s.condition_choices.len(), 4);
    assert_eq!(s.varied(0).conditions, s.conditions, "seed 0 is the file as written");
    let drawn: Vec<Conditions> = (1..41).map(|k| s.varied(k).conditions).collect();
    assert_eq!(drawn, (1..41).map(|k| s.varied(k).conditions).collect::<Vec<_>>());
    for c in &s.condition_choices {
        assert!(drawn.contains(c), "{} never drawn in 40 seeds", c.name());
    }
    assert!(drawn.iter().all(|c| s.condition_choices.contains(c)));
}

#[test]
fn every_condition_renders_deterministically_and_differently() {
    let noon = render(&mut Renderer::new(), Conditions::default(), 0, 0);
    let mut warm = Renderer::new();
    for c in Conditions::all() {
        let a = render(&mut Renderer::new(), c, 5, 40);
        // A renderer that drew other conditions before gives the same bytes.
        render(&mut warm, Conditions { time_of_day: TimeOfDay::Night, weather: Weather::Rain }, 9, 3);
        let b = render(&mut warm, c, 5, 40);
        assert!(a.data == b.data, "{}: not deterministic", c.name());
        if c != Conditions::default() {
            assert!(a.data != noon.data, "{} draws like noon", c.name());
        }
        // Only rain (its lens) depends on the seed and the tick.
        let other = render(&mut warm, c, 6, 41);
        assert_eq!(other.data == a.data, c.weather != Weather::Rain, "{}", c.name());
    }
    // Noon/clear ignores the seed and tick.
    assert!(render(&mut warm, Conditions::default(), 77, 500).data == noon.data);
}

#[test]
fn night_is_dark_but_head_lamps_light_the_road_ahead() {
    let mut r = Renderer::new();
    let noon = render(&mut r, Conditions::default(), 0, 0);
    let night = render(&mut r, Conditions { time_of_day: TimeOfDay::Night, ..Default::default() }, 0, 0);
    // Sky, and the road ahead of the ego (its head lamps' pool, 8-20 m out).
    let (sky_noon, sky_night) = (mean(&noon, 300, 10, 500, 40), mean(&night, 300, 10, 500, 40));
    assert!(sky_night < 0.25 * sky_noon, "night sky {sky_night} vs noon {sky_noon}");
    let (ahead, kerb_far) = (mean(&night, 340, 300, 460, 360), mean(&night, 0, 215, 40, 225));
    assert!(ahead > 80.0 && ahead > 3.0 * kerb_far, "lit road {ahead} vs unlit {kerb_far}");
    // The lead car's tail lamps burn red.
    let (_, map) = world();
    let (ego, actors) = scene();
    let frame = FrameInput {
        ego: &ego,
        actors: &actors,
        lights: &[],
        signs: &[],
        route_points: &[],
        ambience: Ambience { conditions: Conditions::parse("night").unwrap(), seed: 0, tick: 0 },
    };
    let found = r.project_actors(map, &frame, &CameraConfig::front()).unwrap();
    let lead = found.iter().find(|p| p.id == 1).expect("lead car in view");
    let [x0, y0, x1, y1] = lead.bbox_px.map(|v| v as u32);
    let red = (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let p = night.pixel(x, y).unwrap();
            p[0] > 170 && p[1] < 60 && p[2] < 60
        })
        .count();
    assert!(red >= 4, "lit tail lamps: {red} red pixels");
}

#[test]
fn fog_fades_the_distance_and_rain_puts_drops_on_the_lens() {
    let mut r = Renderer::new();
    let noon = render(&mut r, Conditions::default(), 0, 0);
    let fog = render(&mut r, Conditions::parse("fog").unwrap(), 0, 0);
    // Far along the road (near the vanishing point) fog is the fog colour; near the bottom the
    // road keeps its contrast.
    let far_off = |img: &Image| {
        let mut worst = 0i32;
        for y in 185..200 {
            for x in 380..420 {
                let p = img.pixel(x, y).unwrap();
                let d =
                    (p[0] as i32 - 196).abs().max((p[1] as i32 - 198).abs()).max((p[2] as i32 - 204).abs());
                worst = worst.max(d);
            }
        }
        worst
    };
    assert!(far_off(&fog) < 30 && far_off(&noon) > 60, "fog {} noon {}", far_off(&fog), far_off(&noon));
    let spread = |img: &Image, y: u32| {
        let (mut lo, mut hi) = (255u8, 0u8);
        for x in 100..700 {
            let p = img.pixel(x, y).unwrap();
            lo = lo.min(p[1]);
            hi = hi.max(p[1]);
        }
        hi - lo
    };
    assert!(spread(&fog, 440) > 60, "the near road keeps its contrast");
    let a = render(&mut r, Conditions::parse("rain").unwrap(), 1, 10);
    let b = render(&mut r, Conditions::parse("rain").unwrap(), 1, 11);
    let changed = a.data.chunks(3).zip(b.data.chunks(3)).filter(|(p, q)| p != q).count();
    assert!(changed > 500 && changed < 60_000, "rain changes a little between ticks: {changed} px");
}

#[test]
fn camera_faults_are_deterministic() {
    let img = |v: u8| Image { width: 4, height: 2, data: vec![v; 24] };
    // Frozen: from its decision on, the last delivered image repeats.
    let at = CameraFault::freeze_at(3);
    assert!((4..=12).contains(&at));
    let mut last = None;
    for k in 0..20u64 {
        let mut i = img(k as u8);
        CameraFault::Frozen.apply(&mut i, &mut last, 3, k);
        assert_eq!(i.data[0], k.min(at - 1) as u8, "decision {k}");
    }
    // Dropped: about one in four repeats the previous image, the same ones for the same seed.
    let run = |seed: u64| -> Vec<u8> {
        let mut last = None;
        (0..200u64)
            .map(|k| {
                let mut i = img((k % 250) as u8);
                CameraFault::Dropped.apply(&mut i, &mut last, seed, k);
                i.data[0]
            })
            .collect()
    };
    let (a, b) = (run(5), run(5));
    assert_eq!(a, b);
    let repeats = a.windows(2).filter(|w| w[0] == w[1]).count();
    assert!((25..=75).contains(&repeats), "{repeats} dropped of 200");
    assert_eq!(a[0], 0);
    assert_ne!(run(6), a);
    // Dirty: the same smudges for the same seed, elsewhere for another.
    let mut r = Renderer::new();
    let clean = render(&mut r, Conditions::default(), 0, 0);
    let dirty = |seed| {
        let mut i = clean.clone();
        CameraFault::Dirty.apply(&mut i, &mut None, seed, 0);
        i
    };
    assert!(dirty(1).data == dirty(1).data && dirty(1).data != clean.data && dirty(1).data != dirty(2).data);
}

fn sim_frames(config: SimConfig) -> Vec<Vec<u8>> {
    dh_env::scenario::set_builtin_maps_dir(
        std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios/maps"),
    );
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../scenarios/r4/01_pedestrian/town01_01_midblock_crossing.toml");
    let mut s = Sim::new(&path, config, &LoadOptions::default()).unwrap();
    let (obs, _) = s.reset(3).unwrap();
    let mut out = vec![obs.front.unwrap().data];
    for _ in 0..8 {
        let o = s.step(Action::Decision(Decision { steer: 0.0, target_speed_mps: 5.0 })).unwrap();
        out.push(o.observation.front.unwrap().data);
        if o.terminated {
            break;
        }
    }
    out
}

#[test]
fn the_sim_override_and_camera_fault_apply_to_observations_deterministically() {
    let small = |conditions: Option<&str>, fault| SimConfig {
        front: Some(CameraConfig { width: 160, height: 90, ..Default::default() }),
        bev: None,
        conditions: conditions.map(str::to_owned),
        camera_fault: fault,
        ..SimConfig::default()
    };
    let plain = sim_frames(small(None, None));
    let night_rain = sim_frames(small(Some("night+rain"), None));
    assert_eq!(night_rain, sim_frames(small(Some("night+rain"), None)), "same seed, same frames");
    assert!(night_rain.iter().zip(&plain).all(|(a, b)| a != b));
    let frozen = sim_frames(small(None, Some(CameraFault::Frozen)));
    let at = CameraFault::freeze_at(3) as usize;
    for (k, f) in frozen.iter().enumerate() {
        assert!(*f == plain[k.min(at - 1)], "decision {k}");
    }
    let bad = SimConfig { conditions: Some("snow".into()), ..small(None, None) };
    let e = bad.validate().unwrap_err().to_string();
    assert!(e.contains("conditions") && e.contains("snow"), "{e}");
    let e = SimConfig::from_json(r#"{"action_mode": "decision", "decision_interval_ticks": 5, "front": null, "bev": null, "prompt": false, "camera_fault": "cracked"}"#)
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera_fault") && e.contains("cracked"), "{e}");
}
