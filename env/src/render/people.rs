//! People: articulated pedestrians with a walking gait, and riders on bicycles that pedal.
//!
//! The pose is a pure function of the actor's view: the gait phase comes from the distance the
//! person has covered along their heading (their position projected on it), so it advances
//! with speed, repeats across processes, and never reads a clock. The stride grows with speed;
//! below [`STILL_MPS`] the person stands.

use super::mesh::{all, Frame, Mesh};
use crate::geom::Vec2;
use crate::view::ActorView;
use std::f32::consts::{PI, TAU};

/// Slower than this, a person stands and a cyclist stops pedalling.
pub(crate) const STILL_MPS: f64 = 0.15;

const SHOE: [u8; 3] = [35, 32, 30];
const SKINS: [[u8; 3]; 4] = [[232, 190, 160], [205, 160, 120], [160, 112, 80], [105, 72, 50]];
const HAIR: [[u8; 3]; 4] = [[45, 32, 24], [20, 18, 18], [120, 82, 45], [80, 80, 82]];
/// Trouser colours, picked against the shirt so the two read as separate garments.
const DARK_TROUSERS: [[u8; 3]; 2] = [[48, 62, 110], [52, 52, 56]];
const LIGHT_TROUSERS: [[u8; 3]; 2] = [[168, 150, 112], [150, 160, 175]];

/// Clothing and skin for one person: shirt = the actor's colour, the rest varied by id.
pub(crate) struct Look {
    pub shirt: [u8; 3],
    pub trousers: [u8; 3],
    pub skin: [u8; 3],
    pub hair: [u8; 3],
}

impl Look {
    pub fn of(a: &ActorView) -> Look {
        let k = a.id as usize;
        let luma = 299 * a.color[0] as u32 + 587 * a.color[1] as u32 + 114 * a.color[2] as u32;
        let trousers = if luma < 60_000 { LIGHT_TROUSERS[k % 2] } else { DARK_TROUSERS[k % 2] };
        Look { shirt: a.color, trousers, skin: SKINS[(k / 2) % 4], hair: HAIR[(k / 3) % 4] }
    }
}

/// Gait phase (radians) and swing amplitude (0 standing … ~1.3 running) from the view.
pub(crate) fn gait(a: &ActorView, cycle_m: f32) -> (f32, f32) {
    let dist = a.pose.pos.dot(Vec2::from_angle(a.pose.yaw));
    // rem_euclid in f64 before narrowing keeps the phase exact far from the origin.
    let phase = (dist.rem_euclid(cycle_m as f64) / cycle_m as f64) as f32 * TAU;
    let amp = if a.speed_mps < STILL_MPS { 0.0 } else { (a.speed_mps as f32 / 1.4).clamp(0.35, 1.3) };
    (phase, amp)
}

/// Knee (or elbow) of a two-bone limb from `hip` to `foot` (local (fwd, z) points), bending
/// towards +fwd when `forward`; the bones have lengths `l1`, `l2`.
fn knee(hip: [f32; 2], foot: [f32; 2], l1: f32, l2: f32, forward: bool) -> [f32; 2] {
    let d = [foot[0] - hip[0], foot[1] - hip[1]];
    let len = (d[0] * d[0] + d[1] * d[1]).sqrt().clamp(1e-4, (l1 + l2) * 0.999);
    let u = [d[0] / len, d[1] / len];
    let a = (l1 * l1 - l2 * l2 + len * len) / (2.0 * len);
    let h = (l1 * l1 - a * a).max(0.0).sqrt();
    // Perpendicular to the limb, pointing forward.
    let mut p = [u[1], -u[0]];
    if (p[0] < 0.0) == forward {
        p = [-p[0], -p[1]];
    }
    [hip[0] + u[0] * a + p[0] * h, hip[1] + u[1] * a + p[1] * h]
}

/// Body proportions for a person of height `h`: a child's head is larger for its height.
struct Body {
    s: f32,
    head: f32,
    hip_z: f32,
    shoulder_z: f32,
    thigh: f32,
    arm: f32,
}

impl Body {
    fn new(h: f32) -> Body {
        let s = h / 1.75;
        let child = (1.0 - s).clamp(0.0, 0.5);
        let head = 0.115 * s * (1.0 + child * 0.9);
        let neck_z = h - 2.0 * head - 0.02 * s;
        let shoulder_z = neck_z - 0.03 * s;
        let hip_z = 0.52 * h - child * 0.06 * h;
        Body { s, head, hip_z, shoulder_z, thigh: (hip_z - 0.05 * s) * 0.5, arm: (shoulder_z - hip_z) * 1.08 }
    }
}

/// One adult pedestrian in [`WHEELCHAIR_ONE_IN`] (by a hash of the actor id, so the same
/// person always is) is drawn as a wheelchair user. The world has no wheelchair class; this only
/// changes the picture, never the footprint or the motion.
pub(crate) const WHEELCHAIR_ONE_IN: u64 = 16;

/// Whether the pedestrian `a` of height `h` is drawn in a wheelchair.
pub(crate) fn in_wheelchair(a: &ActorView, h: f32) -> bool {
    let mut x = u64::from(a.id).wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h >= 1.5 && (x ^ (x >> 31)) % WHEELCHAIR_ONE_IN == 0
}

/// A walking or standing pedestrian facing +forward of `fr` (or a wheelchair user).
pub(crate) fn pedestrian(m: &mut Mesh, fr: &Frame, a: &ActorView, h: f32) {
    if in_wheelchair(a, h) {
        return wheelchair(m, fr, a, h);
    }
    let b = Body::new(h);
    let s = b.s;
    let look = Look::of(a);
    let (phase, amp) = gait(a, 1.5 * s);
    let stride = 0.30 * s * amp;
    let ankle = 0.05 * s;
    // The hip drops just enough for the planted (rear-most) leg to stay nearly straight.
    let leg_l = 2.0 * b.thigh;
    let spread = stride * phase.sin().abs();
    let hip_z = ankle + ((leg_l * 0.995).powi(2) - spread * spread).max(0.0).sqrt();
    let lean = 0.04 * s * amp;
    let dz = hip_z - b.hip_z;
    for (side, ph) in [(1.0f32, phase), (-1.0, phase + PI)] {
        let y = side * 0.095 * s;
        // Foot path: swings forward lifted (cos > 0), pushes back on the ground.
        let (fx, fz) =
            if amp > 0.0 { (stride * ph.sin(), 0.10 * s * amp * ph.cos().max(0.0)) } else { (0.0, 0.0) };
        let y_foot = if amp > 0.0 { y } else { side * 0.12 * s };
        let hip = [0.0, hip_z];
        let foot = [fx, fz + ankle];
        let k = knee(hip, foot, b.thigh, b.thigh, true);
        let leg = 0.068 * s;
        m.strut(fr, [hip[0], y, hip[1]], [k[0], y, k[1]], leg, leg, look.trousers);
        m.strut(fr, [k[0], y, k[1]], [foot[0], y_foot, foot[1]], leg * 0.85, leg * 0.85, look.trousers);
        m.bx(fr, foot[0] + 0.05 * s, y_foot, fz, fz + 0.07 * s, 0.12 * s, 0.055 * s, &all(SHOE));
        // Arm swings against the leg on its side.
        let sh = [lean, side * 0.225 * s, b.shoulder_z + dz - 0.03 * s];
        let swing = if amp > 0.0 { -0.42 * amp * ph.sin() } else { 0.0 };
        let out = if amp > 0.0 { 0.0 } else { side * 0.02 * s };
        let hand = [sh[0] + b.arm * swing.sin(), sh[1] + out, sh[2] - b.arm * swing.cos()];
        let arm = 0.05 * s;
        m.strut(fr, sh, hand, arm, arm, look.shirt);
        m.bx(
            fr,
            hand[0],
            hand[1],
            hand[2] - 0.04 * s,
            hand[2] + 0.03 * s,
            0.04 * s,
            0.04 * s,
            &all(look.skin),
        );
    }
    torso_and_head(m, fr, &b, dz, lean, &look);
}

/// Torso, neck and head, raised by `dz` from the standing pose.
fn torso_and_head(m: &mut Mesh, fr: &Frame, b: &Body, dz: f32, lean: f32, look: &Look) {
    let s = b.s;
    let hip_z = b.hip_z + dz;
    let shoulder_z = b.shoulder_z + dz;
    m.tbox(
        fr,
        0.0,
        0.0,
        hip_z - 0.04 * s,
        shoulder_z,
        [0.11 * s, 0.11 * s, 0.18 * s],
        [0.12 * s + lean, 0.11 * s - lean, 0.205 * s],
        &[look.trousers, look.shirt, look.shirt, look.shirt, look.shirt, look.shirt],
    );
    neck_and_head(m, fr, b, lean, shoulder_z, look);
}

/// Neck and head over the shoulders at (`x` forward, `shoulder_z` up) in `fr`.
fn neck_and_head(m: &mut Mesh, fr: &Frame, b: &Body, x: f32, shoulder_z: f32, look: &Look) {
    let s = b.s;
    let hz = shoulder_z + 0.05 * s;
    let hr = b.head;
    m.bx(fr, x, 0.0, shoulder_z, hz, 0.04 * s, 0.04 * s, &all(look.skin));
    m.bx(
        fr,
        x,
        0.0,
        hz,
        hz + 2.0 * hr,
        hr * 0.92,
        hr * 0.85,
        &[look.skin, look.hair, look.skin, look.skin, look.hair, look.skin],
    );
}

/// A person seated in a manual wheelchair facing +forward of `fr`: two large rear wheels with
/// push rims, small front casters, seat, backrest and footrest; hands on the rims.
fn wheelchair(m: &mut Mesh, fr: &Frame, a: &ActorView, h: f32) {
    const CHAIR: [u8; 3] = [55, 58, 66];
    const TYRE: [u8; 3] = [25, 25, 27];
    let (r, track) = (0.30f32, 0.30f32);
    for side in [1.0f32, -1.0] {
        m.wheel(fr, -0.08, side * track, r, 0.02, 14, side, TYRE, [170, 172, 178]);
        m.wheel(fr, 0.30, side * 0.2, 0.07, 0.02, 6, side, TYRE, CHAIR);
        // Side frame: from the caster fork up to the seat rail and back to the push handle.
        m.strut(fr, [0.30, side * 0.22, 0.12], [0.26, side * 0.22, 0.50], 0.015, 0.015, CHAIR);
        m.strut(fr, [0.26, side * 0.22, 0.50], [-0.14, side * 0.22, 0.50], 0.015, 0.015, CHAIR);
        m.strut(fr, [-0.14, side * 0.22, 0.50], [-0.20, side * 0.22, 0.98], 0.015, 0.015, CHAIR);
    }
    m.bx(fr, 0.06, 0.0, 0.48, 0.52, 0.21, 0.22, &all(CHAIR));
    m.bx(fr, -0.18, 0.0, 0.52, 0.95, 0.02, 0.2, &all(CHAIR));
    m.bx(fr, 0.40, 0.0, 0.10, 0.13, 0.07, 0.16, &all(CHAIR));

    let b = Body::new(h);
    let s = b.s;
    let look = Look::of(a);
    let hip = [-0.06, 0.62];
    for side in [1.0f32, -1.0] {
        let y = side * 0.1 * s;
        let knee = [0.30, 0.60];
        let foot = [0.38, 0.16];
        let leg = 0.068 * s;
        m.strut(fr, [hip[0], y, hip[1]], [knee[0], y, knee[1]], leg, leg, look.trousers);
        m.strut(fr, [knee[0], y, knee[1]], [foot[0], y, foot[1]], leg * 0.85, leg * 0.85, look.trousers);
        m.bx(fr, foot[0] + 0.04, y, 0.13, 0.20, 0.11 * s, 0.055 * s, &all(SHOE));
    }
    let torso = (b.shoulder_z - b.hip_z).max(0.3);
    let shoulder = [hip[0] + 0.04, hip[1] + torso];
    m.strut(fr, [hip[0], 0.0, hip[1]], [shoulder[0], 0.0, shoulder[1]], 0.11 * s, 0.19 * s, look.shirt);
    for side in [1.0f32, -1.0] {
        let sh = [shoulder[0], side * 0.2 * s, shoulder[1] - 0.04];
        let hand = [0.0, side * (track - 0.03), 0.55];
        m.strut(fr, sh, hand, 0.045 * s, 0.045 * s, look.shirt);
        m.bx(fr, hand[0], hand[1], hand[2] - 0.04, hand[2] + 0.03, 0.04, 0.03, &all(look.skin));
    }
    neck_and_head(m, fr, &b, shoulder[0], shoulder[1], &look);
}

/// A person riding a bicycle along +forward of `fr`: two wheels, a diamond frame, handlebar,
/// saddle, and legs on pedals that turn with the distance covered.
pub(crate) fn cyclist(m: &mut Mesh, fr: &Frame, a: &ActorView, l: f32, h: f32) {
    const FRAME_COL: [u8; 3] = [40, 44, 52];
    let r = 0.34f32.min(l * 0.2);
    let wb = (l * 0.5 - r).max(0.35);
    for x in [wb, -wb] {
        m.wheel(fr, x, 0.0, r, 0.025, 10, 0.0, [25, 25, 27], [150, 150, 155]);
    }
    // Frame points (fwd, z): rear axle, bottom bracket, seat cluster, head tube, front axle.
    let rear = [-wb, r];
    let bb = [-0.05, r * 0.85];
    let seat = [-0.25 * wb / 0.55, r + 0.5];
    let head = [wb - 0.12, r + 0.55];
    let front = [wb, r];
    let tube = 0.022;
    let p = |q: [f32; 2]| [q[0], 0.0, q[1]];
    for (u, v) in [(rear, bb), (rear, seat), (bb, seat), (bb, head), (seat, head), (head, front)] {
        m.strut(fr, p(u), p(v), tube, tube, a.color);
    }
    let bar = [head[0] - 0.04, head[1] + 0.16];
    m.strut(fr, p(head), p(bar), tube, tube, FRAME_COL);
    m.bx(fr, bar[0], 0.0, bar[1] - 0.02, bar[1] + 0.02, 0.025, 0.26, &all(FRAME_COL));
    let saddle = [seat[0] - 0.02, seat[1] + 0.08];
    m.strut(fr, p(seat), p(saddle), tube, tube, FRAME_COL);
    m.bx(fr, saddle[0], 0.0, saddle[1], saddle[1] + 0.05, 0.13, 0.07, &all([20, 20, 20]));

    // Rider: seated on the saddle, leaning to the bar; height from the view.
    let b = Body::new(h);
    let s = b.s;
    let look = Look::of(a);
    let (phase, amp) = gait(a, TAU * r * 2.2);
    let crank = if amp > 0.0 { phase } else { 0.3 * PI };
    let hip = [saddle[0], saddle[1] + 0.07];
    let leg_len = (b.hip_z * 0.5).max(0.3);
    for (side, ph) in [(1.0f32, crank), (-1.0, crank + PI)] {
        let y = side * 0.1;
        let pedal = [bb[0] + 0.17 * ph.cos(), bb[1] + 0.17 * ph.sin()];
        let k = knee(hip, pedal, leg_len, leg_len, true);
        let leg = 0.065 * s;
        m.strut(fr, [hip[0], y, hip[1]], [k[0], y, k[1]], leg, leg, look.trousers);
        m.strut(fr, [k[0], y, k[1]], [pedal[0], y, pedal[1]], leg * 0.85, leg * 0.85, look.trousers);
        m.bx(fr, pedal[0] + 0.04, y + side * 0.03, pedal[1] - 0.02, pedal[1] + 0.04, 0.1, 0.05, &all(SHOE));
    }
    // Torso from the hip towards the bar, head above the shoulders, arms to the grips.
    let torso = (b.shoulder_z - b.hip_z).max(0.3);
    let lean = 0.55f32;
    let shoulder = [hip[0] + torso * lean.sin(), hip[1] + torso * lean.cos()];
    m.strut(fr, [hip[0], 0.0, hip[1]], [shoulder[0], 0.0, shoulder[1]], 0.11 * s, 0.19 * s, look.shirt);
    for side in [1.0f32, -1.0] {
        let sh = [shoulder[0], side * 0.2 * s, shoulder[1] - 0.04];
        let grip = [bar[0], side * 0.24, bar[1] + 0.02];
        m.strut(fr, sh, grip, 0.045 * s, 0.045 * s, look.shirt);
    }
    let hr = b.head;
    let hc = [shoulder[0] + 0.06, shoulder[1] + 0.05 * s];
    m.bx(
        fr,
        hc[0],
        0.0,
        hc[1],
        hc[1] + 2.0 * hr,
        hr * 0.92,
        hr * 0.85,
        &[look.skin, look.hair, look.skin, look.skin, look.hair, look.skin],
    );
}

/// Two-bone limb solver used by tests.
#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wheelchair_users_are_a_fixed_share_of_adults_by_id() {
        let view = |id: u32| ActorView {
            id,
            kind: crate::view::ActorKind::Pedestrian,
            pose: crate::geom::Pose::new(Vec2::ZERO, 0.0),
            speed_mps: 0.0,
            length_m: 0.0,
            width_m: 0.0,
            height_m: 0.0,
            color: [200, 30, 30],
            braking: false,
            blinkers: 0,
            beacon: false,
        };
        let n = (0..4000).filter(|&i| in_wheelchair(&view(i), 1.75)).count();
        let want = 4000 / WHEELCHAIR_ONE_IN as usize;
        assert!(n.abs_diff(want) < want / 4, "{n} of 4000 in a wheelchair, want about {want}");
        // Children never; the same id always gives the same answer.
        assert!((0..4000).all(|i| !in_wheelchair(&view(i), 1.2)));
        assert!((0..4000).all(|i| in_wheelchair(&view(i), 1.75) == in_wheelchair(&view(i), 1.75)));
    }

    #[test]
    fn knee_keeps_bone_lengths() {
        let k = knee([0.0, 0.9], [0.2, 0.05], 0.46, 0.46, true);
        let d1 = ((k[0] - 0.0).powi(2) + (k[1] - 0.9).powi(2)).sqrt();
        let d2 = ((k[0] - 0.2).powi(2) + (k[1] - 0.05).powi(2)).sqrt();
        assert!((d1 - 0.46).abs() < 1e-3 && (d2 - 0.46).abs() < 1e-3, "{d1} {d2}");
        assert!(k[0] > 0.1, "knee bends forward: {k:?}");
    }
}
