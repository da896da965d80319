//! The conditions gallery of docs/rendering.md: one town01 scene (a lead car braking, oncoming
//! traffic, a pedestrian at the kerb, a junction ahead) under every time of day and weather, as
//! the protocol's 800×450 front camera, plus the dirty-lens camera fault and the BEV (which every
//! condition draws alike; the example checks that).
//!
//! `cargo run --release -p dh-env --example render_conditions -- scenarios/maps/town01/town01.net.xml docs/gallery/conditions`
//!
//! Prints the Markdown that embeds the images (paths relative to docs/).

mod common;

use common::{at, frame, view, Town};
use dh_env::conditions::Conditions;
use dh_env::render::{render_bev, render_camera, Ambience, BevConfig, CameraConfig, CameraFault, Image};
use dh_env::view::{ActorKind, ActorView};
use std::f64::consts::{FRAC_PI_2, PI};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let town = Town::from_args("render_conditions")?;
    let (map, dir) = (&town.map, &town.dir);
    let ego_pose = town.approach("W2C_1", 60.0)?;
    let moving = |v: ActorView, speed_mps: f64| ActorView { speed_mps, ..v };
    let ego = moving(view(0, ActorKind::Car, ego_pose, [30, 110, 230]), 6.0);
    let at = |f: f64, l: f64, dyaw: f64| at(ego_pose, f, l, dyaw);
    let mut lead = moving(view(1, ActorKind::Car, at(16.0, 0.0, 0.0), [200, 40, 40]), 3.0);
    lead.braking = true;
    let oncoming = moving(view(2, ActorKind::Car, at(34.0, 3.4, PI), [230, 230, 230]), 7.0);
    let van = moving(view(3, ActorKind::Car, at(55.0, 3.4, PI), [220, 180, 30]), 7.0);
    let van = ActorView { length_m: 5.2, width_m: 2.0, height_m: 2.3, ..van };
    let walker = view(4, ActorKind::Pedestrian, at(24.0, -4.3, FRAC_PI_2), [40, 150, 70]);
    let actors = [lead, oncoming, van, walker];

    let names = ["noon", "dusk", "night", "overcast", "rain", "fog", "night+rain", "dusk+fog"];
    let mut md = vec!["| conditions | front camera |".to_owned(), "|---|---|".to_owned()];
    let mut bev0: Option<Image> = None;
    let (mut front, mut bev) = (Image::default(), Image::default());
    for name in names {
        let conditions = Conditions::parse(name)?;
        let ambience = Ambience { conditions, seed: 7, tick: 120 };
        let frame = frame(&ego, &actors, ambience);
        render_camera(map, &frame, &CameraConfig::front(), &mut front)?;
        render_bev(map, &frame, &BevConfig::default(), &mut bev)?;
        let file = name.replace('+', "_");
        front.save(dir.join(format!("{file}.png")))?;
        match &bev0 {
            None => {
                bev.save(dir.join("bev.png"))?;
                bev0 = Some(bev.clone());
            }
            Some(b) if b.data != bev.data => {
                return Err(format!("{name}: the BEV differs from noon's").into())
            }
            Some(_) => {}
        }
        md.push(format!("| `{name}` | ![{name}](gallery/conditions/{file}.png) |"));
    }
    let frame = frame(&ego, &actors, Ambience::default());
    render_camera(map, &frame, &CameraConfig::front(), &mut front)?;
    CameraFault::Dirty.apply(&mut front, &mut None, 7, 0);
    front.save(dir.join("fault_dirty.png"))?;
    md.push(String::new());
    md.push("Camera fault `dirty` (seed 7): ![dirty lens](gallery/conditions/fault_dirty.png)".to_owned());
    md.push(String::new());
    md.push(
        "The BEV of this scene, the same under every condition: ![BEV](gallery/conditions/bev.png)"
            .to_owned(),
    );
    println!("{}", md.join("\n"));
    Ok(())
}
