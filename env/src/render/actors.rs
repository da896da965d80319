//! One actor's triangles: the dispatch from an actor's kind to its mesh (vehicles, people, and
//! the small kinds drawn here: motorcycles, cones, barriers, static objects). Kept apart from
//! `mesh` (the primitives) so that `vehicles` and `people` build on `mesh` without a cycle.

use super::mesh::{actor_dims, all, scale, Frame, Mesh, Tri3};
use crate::geom::Vec2;
use crate::view::{ActorKind, ActorView};

const TYRE: [u8; 3] = [22, 22, 24];
const AMBER: [u8; 3] = [255, 165, 0];
const SKIN: [u8; 3] = [224, 172, 135];
const TROUSERS: [u8; 3] = [55, 75, 140];

fn lights(m: &mut Mesh, fr: &Frame, hl: f32, hw: f32, z: f32, braking: bool, blinkers: u8) {
    let brake = match (braking, m.lit) {
        (true, _) => [255, 25, 25],
        (false, true) => [190, 18, 18],
        (false, false) => [120, 20, 20],
    };
    let head = if m.lit { [255, 250, 228] } else { [235, 235, 210] };
    for side in [-1.0f32, 1.0] {
        let left = side * (hw - 0.25);
        // Rear lamps protrude 3 cm so they win the depth test against the body.
        m.out_lamp(fr, -hl - 0.03, left, z, 0.18, 0.09, brake, braking || m.lit);
        m.out_lamp(fr, hl + 0.03, left, z, 0.17, 0.07, head, m.lit);
        // Indicators at the outer corners, front and rear. A lit one is drawn steadily (not
        // flashing) so a single frame, which is all a VLM sees per decision, shows it.
        // Only lit ones are drawn: the body colour stands in for the unlit housing.
        let bit = if side > 0.0 { crate::view::BLINKER_LEFT } else { crate::view::BLINKER_RIGHT };
        if blinkers & bit != 0 {
            let corner = side * (hw - 0.035);
            m.out_lamp(fr, -hl - 0.03, corner, z, 0.035, 0.08, AMBER, true);
            m.out_lamp(fr, hl + 0.03, corner, z, 0.035, 0.07, AMBER, true);
        }
    }
}

/// Appends the triangles of one actor; `detail` = near the camera (rounder wheels); `lit` =
/// its lamps burn (night); `tick` = the world tick (the phase of flashing beacons).
pub(crate) fn actor(
    out: &mut Vec<Tri3>,
    a: &ActorView,
    origin: Vec2,
    id: u32,
    detail: bool,
    lit: bool,
    tick: u64,
) {
    let fr = Frame::new(a.pose.pos, a.pose.yaw, origin, 0.0);
    let (l, w, h) = actor_dims(a);
    let (hl, hw) = (l * 0.5, w * 0.5);
    let col = a.color;
    let mut m = Mesh { out, id, paint: Some(a.color), lit };
    match a.kind {
        ActorKind::Car | ActorKind::Bus | ActorKind::Truck => {
            super::vehicles::vehicle(&mut m, &fr, a, l, w, h, detail, tick);
        }
        ActorKind::Cyclist => super::people::cyclist(&mut m, &fr, a, l, h),
        ActorKind::Pedestrian => super::people::pedestrian(&mut m, &fr, a, h),
        ActorKind::Motorcycle => {
            let r = 0.32;
            let wb = (hl - r).max(0.3);
            for x in [wb, -wb] {
                m.wheel(&fr, x, 0.0, r, 0.07, if detail { 10 } else { 6 }, 0.0, TYRE, [120, 120, 125]);
            }
            // Tank and seat in the body colour over a dark engine block, forks to the front.
            m.bx(&fr, 0.0, 0.0, r * 0.6, r + 0.3, wb * 0.45, 0.16, &all([45, 45, 48]));
            m.tbox(
                &fr,
                0.05,
                0.0,
                r + 0.3,
                r + 0.55,
                [wb * 0.55, wb * 0.8, 0.17],
                [wb * 0.3, wb * 0.8, 0.14],
                &all(col),
            );
            m.strut(&fr, [wb, 0.0, r], [wb - 0.2, 0.0, r + 0.65], 0.04, 0.1, [60, 60, 64]);
            lights(&mut m, &fr, hl - 0.2, hw + 0.1, r + 0.45, a.braking, a.blinkers);
            rider(&mut m, &fr, -0.15, r + 0.35, h, [30, 30, 30], true);
        }
        ActorKind::Cone => {
            let orange = [255, 110, 20];
            m.bx(&fr, 0.0, 0.0, 0.0, 0.05, hl, hw, &all([30, 30, 30]));
            let t = |z: f32| (hw * 0.8) * (1.0 - z / h) + 0.04;
            let bands =
                [(0.05, h * 0.4, orange), (h * 0.4, h * 0.62, [245, 245, 245]), (h * 0.62, h, orange)];
            for (z0, z1, c) in bands {
                m.tbox(&fr, 0.0, 0.0, z0, z1, [t(z0), t(z0), t(z0)], [t(z1), t(z1), t(z1)], &all(c));
            }
        }
        ActorKind::Barrier => {
            let n = ((l / 0.5).round() as usize).clamp(1, 40);
            let seg = l / n as f32;
            for i in 0..n {
                let c = if i % 2 == 0 { [220, 30, 30] } else { [245, 245, 245] };
                let x = -hl + seg * (i as f32 + 0.5);
                m.bx(&fr, x, 0.0, h * 0.35, h, seg * 0.5, hw, &all(c));
            }
            for x in [-hl + 0.15, hl - 0.15] {
                m.bx(&fr, x, 0.0, 0.0, h * 0.35, 0.08, hw * 0.8, &all([70, 70, 70]));
            }
        }
        ActorKind::StaticObject => {
            m.bx(&fr, 0.0, 0.0, 0.0, h, hl, hw, &all(col));
        }
    }
}

/// A standing or riding person facing +forward: legs, torso with arms, head.
fn rider(m: &mut Mesh, fr: &Frame, fwd: f32, z0: f32, h: f32, shirt: [u8; 3], seated: bool) {
    let s = h / 1.75;
    let leg_top = if seated { z0 + 0.15 * s } else { z0 + 0.85 * s };
    let legs_col = TROUSERS;
    if seated {
        m.bx(fr, fwd + 0.15, 0.0, z0 - 0.25 * s, leg_top, 0.1 * s, 0.17 * s, &all(legs_col));
    } else {
        for side in [-1.0f32, 1.0] {
            m.bx(fr, fwd, side * 0.1 * s, z0, leg_top, 0.09 * s, 0.08 * s, &all(legs_col));
        }
    }
    let torso_top = leg_top + 0.62 * s;
    m.bx(fr, fwd, 0.0, leg_top, torso_top, 0.13 * s, 0.22 * s, &all(shirt));
    for side in [-1.0f32, 1.0] {
        m.bx(
            fr,
            fwd + if seated { 0.15 } else { 0.0 },
            side * 0.27 * s,
            leg_top + 0.12 * s,
            torso_top - 0.02,
            0.06 * s,
            0.055 * s,
            &all(scale(shirt, 0.85)),
        );
    }
    let head_r = 0.12 * s;
    m.bx(
        fr,
        fwd,
        0.0,
        torso_top + 0.02,
        torso_top + 0.02 + 2.0 * head_r,
        head_r,
        head_r,
        &[SKIN, [50, 35, 25], SKIN, SKIN, [50, 35, 25], SKIN],
    );
}
