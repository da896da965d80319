//! The rendering gallery of docs/rendering.md: people walking and standing at 10/25/40 m, each
//! vehicle body at 15 and 60 m, an emergency vehicle's light bar at 15 and 60 m by day and
//! night, every palette colour, a curved road's markings and a signalised
//! approach's stop lines and kerbs, all on
//! town01 through the protocol's 800×450 front camera (what a model sees, no supersampling).
//! Next to each frame it writes a ×4 nearest-neighbour crop around the subject, so a reviewer
//! sees the actual pixels.
//!
//! `cargo run --release -p dh-env --example render_gallery -- scenarios/maps/town01/town01.net.xml docs/gallery/look`
//!
//! Prints the Markdown that embeds the images (paths relative to docs/).

mod common;

use common::{frame, view, Town};
use dh_env::conditions::{Conditions, TimeOfDay};
use dh_env::geom::Pose;
use dh_env::render::palette::PALETTE;
use dh_env::render::{render_and_project, render_bev, Ambience, BevConfig, CameraConfig, Image, RenderMap};
use dh_env::view::{ActorKind, ActorView};
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::PathBuf;

/// Nearest-neighbour crop of `img` around `bbox` (padded, at least `min` px square), scaled ×k.
fn zoom(img: &Image, bbox: [f32; 4], k: u32, min: u32) -> Image {
    let (cx, cy) = ((bbox[0] + bbox[2]) * 0.5, (bbox[1] + bbox[3]) * 0.5);
    let side = ((bbox[2] - bbox[0]).max(bbox[3] - bbox[1]) * 1.5).max(min as f32) as u32;
    let x0 = (cx - side as f32 * 0.5).clamp(0.0, (img.width - side.min(img.width)) as f32) as u32;
    let y0 = (cy - side as f32 * 0.5).clamp(0.0, (img.height - side.min(img.height)) as f32) as u32;
    let (w, h) = (side.min(img.width), side.min(img.height));
    let mut out = Image::new(w * k, h * k);
    for y in 0..h * k {
        for x in 0..w * k {
            let p = img.pixel(x0 + x / k, y0 + y / k).unwrap_or([0, 0, 0]);
            let o = ((y * w * k + x) * 3) as usize;
            out.data[o..o + 3].copy_from_slice(&p);
        }
    }
    out
}

struct Shot<'a> {
    map: &'a RenderMap,
    dir: PathBuf,
    md: Vec<String>,
}

impl Shot<'_> {
    /// Renders the front camera (and optionally the BEV) of `ego` with `actors`; writes a zoom of
    /// actor `subject` when it is in view. Returns the Markdown cell.
    fn take(
        &mut self,
        name: &str,
        ego: &ActorView,
        actors: &[ActorView],
        subject: Option<u32>,
        bev: bool,
    ) -> String {
        self.take_in(name, ego, actors, subject, bev, Ambience::default())
    }

    /// [`Shot::take`] under `ambience` (time of day, and the tick that sets beacon phases).
    fn take_in(
        &mut self,
        name: &str,
        ego: &ActorView,
        actors: &[ActorView],
        subject: Option<u32>,
        bev: bool,
        ambience: Ambience,
    ) -> String {
        let frame = frame(ego, actors, ambience);
        let mut img = Image::default();
        let found = render_and_project(self.map, &frame, &CameraConfig::front(), &mut img).unwrap();
        let file = format!("{name}.png");
        img.save(self.dir.join(&file)).unwrap();
        let rel = format!("gallery/look/{file}");
        let mut cell = format!("![{name}]({rel})");
        if let Some(id) = subject {
            if let Some(p) = found.iter().find(|p| p.id == id && p.pixel_count > 0) {
                let z = zoom(&img, p.bbox_px, 4, 48);
                let zf = format!("{name}_zoom.png");
                z.save(self.dir.join(&zf)).unwrap();
                cell += &format!(" ![{name} ×4](gallery/look/{zf})");
            }
        }
        if bev {
            render_bev(self.map, &frame, &BevConfig::default(), &mut img).unwrap();
            let bf = format!("{name}_bev.png");
            img.save(self.dir.join(&bf)).unwrap();
            cell += &format!(" ![{name} BEV](gallery/look/{bf})");
        }
        cell
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let town = Town::from_args("render_gallery")?;
    let net = &town.net;
    let mut shot = Shot { map: &town.map, dir: town.dir.clone(), md: Vec::new() };

    let lane = net.lane_by_id("W2C_1").ok_or("town01 has no lane W2C_1")?;
    let ego_pose = town.approach("W2C_1", 75.0)?;
    let ego = view(0, ActorKind::Car, ego_pose, [30, 110, 230]);
    let at = |f: f64, l: f64, dyaw: f64| common::at(ego_pose, f, l, dyaw);

    // People: walking across the lane (from the right) and standing at the kerb, facing the road.
    shot.md.push("### People\n\n| distance | walking (1.4 m/s) | standing |\n|---|---|---|".into());
    for d in [10.0, 25.0, 40.0] {
        let mut walker = view(1, ActorKind::Pedestrian, at(d, -1.2, FRAC_PI_2), [200, 32, 32]);
        walker.speed_mps = 1.4;
        let stander = view(2, ActorKind::Pedestrian, at(d, -4.6, FRAC_PI_2), [36, 88, 204]);
        let w = shot.take(&format!("pedestrian_walking_{d}m"), &ego, &[walker], Some(1), false);
        let s = shot.take(&format!("pedestrian_standing_{d}m"), &ego, &[stander], Some(2), false);
        shot.md.push(format!("| {d} m | {w} | {s} |"));
    }
    // A child and an adult walking side by side, a cyclist crossing, a cyclist riding ahead.
    let mut adult = view(3, ActorKind::Pedestrian, at(14.0, -2.0, FRAC_PI_2), [240, 128, 24]);
    adult.speed_mps = 1.2;
    let mut child = view(4, ActorKind::Pedestrian, at(14.0, -1.2, FRAC_PI_2), [226, 190, 30]);
    child.speed_mps = 1.2;
    child.height_m = 1.15;
    let c1 = shot.take("adult_and_child_14m", &ego, &[adult, child], Some(4), false);
    let mut bike = view(5, ActorKind::Cyclist, at(15.0, 0.5, -FRAC_PI_2), [40, 150, 68]);
    bike.speed_mps = 4.0;
    let c2 = shot.take("cyclist_crossing_15m", &ego, &[bike], Some(5), false);
    let mut bike2 = view(6, ActorKind::Cyclist, at(25.0, -1.0, 0.0), [138, 58, 160]);
    bike2.speed_mps = 5.0;
    let c3 = shot.take("cyclist_ahead_25m", &ego, &[bike2], Some(6), false);
    shot.md.push(format!("\n| adult and child, 14 m | cyclist crossing, 15 m | cyclist ahead, 25 m |\n|---|---|---|\n| {c1} | {c2} | {c3} |"));
    // Wheelchair users (ids 29 and 38 are among the one adult pedestrian in 16 drawn so).
    let mut roller = view(29, ActorKind::Pedestrian, at(12.0, -1.0, FRAC_PI_2), [36, 88, 204]);
    roller.speed_mps = 1.0;
    let w1 = shot.take("wheelchair_crossing_12m", &ego, &[roller], Some(29), false);
    let waiting = view(38, ActorKind::Pedestrian, at(25.0, -4.6, FRAC_PI_2), [200, 32, 32]);
    let w2 = shot.take("wheelchair_waiting_25m", &ego, &[waiting], Some(38), false);
    shot.md.push(format!("\n| wheelchair user crossing, 12 m | wheelchair user at the kerb, 25 m |\n|---|---|\n| {w1} | {w2} |"));

    // Vehicles: rear three-quarter view in the ego lane (15 m, braking) and head-on in the
    // oncoming lane (60 m).
    shot.md.push("\n### Vehicles\n\n| body | 15 m, ahead, braking | 60 m, oncoming |\n|---|---|---|".into());
    // (name, kind, length, width, height in metres, colour)
    type Body = (&'static str, ActorKind, f64, f64, f64, [u8; 3]);
    let bodies: [Body; 5] = [
        ("sedan", ActorKind::Car, 4.6, 1.85, 1.45, [200, 32, 32]),
        ("suv", ActorKind::Car, 4.8, 1.95, 1.75, [166, 167, 169]),
        ("van", ActorKind::Car, 5.4, 2.05, 2.35, [240, 240, 238]),
        ("bus", ActorKind::Bus, 12.0, 2.55, 3.2, [226, 190, 30]),
        ("truck", ActorKind::Truck, 8.0, 2.5, 3.4, [122, 74, 38]),
    ];
    for (name, kind, l, w, h, col) in bodies {
        let mut v = view(7, kind, at(15.0 + l * 0.5, -0.6, 0.25), col);
        (v.length_m, v.width_m, v.height_m, v.braking) = (l, w, h, true);
        let near = shot.take(&format!("{name}_15m"), &ego, &[v], Some(7), false);
        let mut o = view(8, kind, at(60.0, 3.3, PI), col);
        (o.length_m, o.width_m, o.height_m) = (l, w, h);
        let far = shot.take(&format!("{name}_60m"), &ego, &[o], Some(8), false);
        shot.md.push(format!("| {name} | {near} | {far} |"));
    }

    // Emergency vehicles (`emergency = true`): the white truck of the suite's emergency
    // scenarios and a sedan, ahead at 15 m and oncoming at 60 m, at noon and at night. Tick 0
    // shows the red half bright, tick 5 (a decision later) the blue half.
    shot.md.push(
        "\n### Emergency vehicles\n\n| vehicle, time | 15 m, ahead (tick 0: red bright) | 60 m, oncoming (tick 5: blue bright) |\n|---|---|---|"
            .into(),
    );
    let emergency: [Body; 2] = [
        ("emergency_truck", ActorKind::Truck, 6.5, 2.5, 3.4, [245, 245, 245]),
        ("emergency_sedan", ActorKind::Car, 4.8, 1.85, 1.5, [245, 245, 245]),
    ];
    for (name, kind, l, w, h, col) in emergency {
        for (time, tod) in [("noon", TimeOfDay::Noon), ("night", TimeOfDay::Night)] {
            let conditions = Conditions { time_of_day: tod, ..Default::default() };
            let mut v = view(10, kind, at(15.0 + l * 0.5, -0.6, 0.25), col);
            (v.length_m, v.width_m, v.height_m, v.beacon) = (l, w, h, true);
            let near = shot.take_in(
                &format!("{name}_15m_{time}"),
                &ego,
                &[v],
                Some(10),
                kind == ActorKind::Truck && tod == TimeOfDay::Noon,
                Ambience { conditions, seed: 0, tick: 0 },
            );
            let mut o = view(11, kind, at(60.0, 3.3, PI), col);
            (o.length_m, o.width_m, o.height_m, o.beacon) = (l, w, h, true);
            let far = shot.take_in(
                &format!("{name}_60m_{time}"),
                &ego,
                &[o],
                Some(11),
                false,
                Ambience { conditions, seed: 0, tick: 5 },
            );
            shot.md.push(format!("| {name}, {time} | {near} | {far} |"));
        }
    }

    // Every palette colour on a sedan at 12 m, rear three-quarter view.
    shot.md.push("\n### Palette (sedan at 12 m)\n".into());
    let mut row = Vec::new();
    for (i, c) in PALETTE.iter().enumerate() {
        let v = view(20 + i as u32, ActorKind::Car, at(12.0, -1.0, 0.5), c.rgb);
        let cell = shot.take(&format!("palette_{}", c.name), &ego, &[v], None, false);
        row.push(format!("{} {}", c.name, cell));
    }
    shot.md.push(row.join("\n\n"));

    // Curved road markings (town01 bend on T2R) with traffic, front and BEV.
    let bend = net.lane_by_id("T2R_0").ok_or("town01 has no lane T2R_0")?;
    let bp = net.lane_position(bend, 150.0);
    let bego = view(0, ActorKind::Car, bp, [30, 110, 230]);
    let bat = |f: f64, l: f64| {
        let p = net.lane_position(bend, 150.0 + f);
        Pose::new(p.local_to_world(0.0, l), p.yaw)
    };
    let lead = ActorView { braking: true, ..view(9, ActorKind::Car, bat(22.0, 0.0), [36, 88, 204]) };
    let c = shot.take("curve_markings", &bego, &[lead], None, true);
    shot.md.push(format!("\n### Curved road\n\n{c}"));

    // Road surface at a signalised approach: stop lines across both lanes, kerbs along the
    // road edges, the lanes' darker wheel tracks; front and BEV.
    let stop = net.stop_line(lane);
    let sego = view(0, ActorKind::Car, Pose::new(stop.local_to_world(-20.0, 0.0), stop.yaw), [30, 110, 230]);
    let c = shot.take("stop_line_kerbs", &sego, &[], None, true);
    shot.md.push(format!("\n### Road surface: stop line, kerbs, wheel tracks\n\n{c}"));

    println!("{}", shot.md.join("\n"));
    Ok(())
}
