//! 3-D triangles for everything that stands above the ground: actors, traffic lights, signs,
//! roadside props. Shapes are built from convex hexahedra ("tapered boxes") and thin n-gon
//! plates; each face is shaded once at build time by a fixed sun direction.

use crate::geom::Vec2;
use crate::view::{ActorKind, ActorView, LightColor, SignKind};

/// A shaded world-space triangle (coordinates relative to the render map origin, metres).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Tri3 {
    pub p: [[f32; 3]; 3],
    /// Outward face normal (for back-face culling).
    pub n: [f32; 3],
    pub col: [u8; 3],
    /// Emissive faces (lit lamps) ignore fog.
    pub emissive: bool,
    /// Never back-face culled (thin plates seen from both sides).
    pub two_sided: bool,
    /// Actor index + 1 for the id buffer; 0 for scenery.
    pub id: u32,
}

const SUN: [f32; 3] = [0.35, 0.25, 0.9];

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}
pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn normalize(a: [f32; 3]) -> [f32; 3] {
    let n = dot(a, a).sqrt();
    if n > 0.0 {
        [a[0] / n, a[1] / n, a[2] / n]
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// Lambert + ambient shading of a base colour for a face normal.
pub(crate) fn shade(col: [u8; 3], n: [f32; 3]) -> [u8; 3] {
    let s = normalize(SUN);
    let k = 0.58 + 0.42 * dot(n, s).max(0.0);
    [(col[0] as f32 * k) as u8, (col[1] as f32 * k) as u8, (col[2] as f32 * k) as u8]
}

/// Local frame on the ground: origin, forward and left unit vectors.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Frame {
    pub o: [f32; 3],
    pub f: [f32; 2],
    pub l: [f32; 2],
}

impl Frame {
    pub fn new(pos: Vec2, yaw: f64, origin: Vec2, z: f32) -> Self {
        let p = pos - origin;
        let (s, c) = yaw.sin_cos();
        Frame { o: [p.x as f32, p.y as f32, z], f: [c as f32, s as f32], l: [-s as f32, c as f32] }
    }
    #[inline]
    pub fn pt(&self, fwd: f32, left: f32, z: f32) -> [f32; 3] {
        [
            self.o[0] + self.f[0] * fwd + self.l[0] * left,
            self.o[1] + self.f[1] * fwd + self.l[1] * left,
            self.o[2] + z,
        ]
    }
    /// The same frame moved by (fwd, left) and turned by `dyaw` radians.
    pub fn offset(&self, fwd: f32, left: f32, dyaw: f32) -> Frame {
        let p = self.pt(fwd, left, 0.0);
        let (s, c) = dyaw.sin_cos();
        let f = [self.f[0] * c + self.l[0] * s, self.f[1] * c + self.l[1] * s];
        Frame { o: p, f, l: [-f[1], f[0]] }
    }
}

/// Per-face colours of a hexahedron: bottom, top, front, right, back, left.
pub(crate) type FaceCols = [[u8; 3]; 6];

pub(crate) fn all(c: [u8; 3]) -> FaceCols {
    [c; 6]
}

pub(crate) struct Mesh<'a> {
    pub out: &'a mut Vec<Tri3>,
    pub id: u32,
}

impl Mesh<'_> {
    #[allow(clippy::too_many_arguments)]
    fn quad(
        &mut self,
        a: [f32; 3],
        b: [f32; 3],
        c: [f32; 3],
        d: [f32; 3],
        centre: [f32; 3],
        col: [u8; 3],
        emissive: bool,
    ) {
        let mut n = normalize(cross(sub(b, a), sub(c, a)));
        if n == [0.0, 0.0, 1.0] && dot(sub(c, a), sub(c, a)) == 0.0 {
            return;
        }
        let fc = [(a[0] + c[0]) * 0.5, (a[1] + c[1]) * 0.5, (a[2] + c[2]) * 0.5];
        if dot(n, sub(fc, centre)) < 0.0 {
            n = [-n[0], -n[1], -n[2]];
        }
        let col = if emissive { col } else { shade(col, n) };
        let t = |p: [[f32; 3]; 3]| Tri3 { p, n, col, emissive, two_sided: false, id: self.id };
        let (t1, t2) = (t([a, b, c]), t([a, c, d]));
        self.out.push(t1);
        self.out.push(t2);
    }

    /// A convex hexahedron from 8 corners: bottom (front-left, front-right, rear-right,
    /// rear-left), then the top in the same order.
    pub fn hexa(&mut self, c: [[f32; 3]; 8], cols: &FaceCols, bottom: bool) {
        let mut centre = [0.0f32; 3];
        for p in &c {
            for k in 0..3 {
                centre[k] += p[k] / 8.0;
            }
        }
        if bottom {
            self.quad(c[0], c[1], c[2], c[3], centre, cols[0], false);
        }
        self.quad(c[4], c[5], c[6], c[7], centre, cols[1], false);
        self.quad(c[0], c[1], c[5], c[4], centre, cols[2], false);
        self.quad(c[1], c[2], c[6], c[5], centre, cols[3], false);
        self.quad(c[2], c[3], c[7], c[6], centre, cols[4], false);
        self.quad(c[3], c[0], c[4], c[7], centre, cols[5], false);
    }

    /// A box in frame `fr`: centre (fwd, left), from z0 to z1, half length `hl`, half width `hw`.
    #[allow(clippy::too_many_arguments)]
    pub fn bx(
        &mut self,
        fr: &Frame,
        fwd: f32,
        left: f32,
        z0: f32,
        z1: f32,
        hl: f32,
        hw: f32,
        cols: &FaceCols,
    ) {
        self.tbox(fr, fwd, left, z0, z1, [hl, hl, hw], [hl, hl, hw], cols);
    }

    /// A tapered box: bottom and top given as (front extent, rear extent, half width).
    #[allow(clippy::too_many_arguments)]
    pub fn tbox(
        &mut self,
        fr: &Frame,
        fwd: f32,
        left: f32,
        z0: f32,
        z1: f32,
        b: [f32; 3],
        t: [f32; 3],
        cols: &FaceCols,
    ) {
        let c = [
            fr.pt(fwd + b[0], left + b[2], z0),
            fr.pt(fwd + b[0], left - b[2], z0),
            fr.pt(fwd - b[1], left - b[2], z0),
            fr.pt(fwd - b[1], left + b[2], z0),
            fr.pt(fwd + t[0], left + t[2], z1),
            fr.pt(fwd + t[0], left - t[2], z1),
            fr.pt(fwd - t[1], left - t[2], z1),
            fr.pt(fwd - t[1], left + t[2], z1),
        ];
        self.hexa(c, cols, false);
    }

    /// A flat regular n-gon plate facing +forward of `fr`, centred at (fwd, left, z), radius r.
    /// `rot` turns the polygon in its plane (radians).
    #[allow(clippy::too_many_arguments)]
    pub fn plate(
        &mut self,
        fr: &Frame,
        fwd: f32,
        left: f32,
        z: f32,
        r: f32,
        n: usize,
        rot: f32,
        col: [u8; 3],
        emissive: bool,
    ) {
        let normal = [fr.f[0], fr.f[1], 0.0];
        let col = if emissive { col } else { shade(col, normal) };
        let centre = fr.pt(fwd, left, z);
        let vert = |i: usize| {
            let a = rot + std::f32::consts::TAU * i as f32 / n as f32;
            fr.pt(fwd, left - r * a.sin(), z + r * a.cos())
        };
        for i in 0..n {
            self.out.push(Tri3 {
                p: [centre, vert(i), vert(i + 1)],
                n: normal,
                col,
                emissive,
                two_sided: false,
                id: self.id,
            });
        }
    }
}

fn scale(c: [u8; 3], k: f32) -> [u8; 3] {
    [
        (c[0] as f32 * k).min(255.0) as u8,
        (c[1] as f32 * k).min(255.0) as u8,
        (c[2] as f32 * k).min(255.0) as u8,
    ]
}

const GLASS: [u8; 3] = [40, 55, 75];
const TYRE: [u8; 3] = [22, 22, 24];
const AMBER: [u8; 3] = [255, 165, 0];
const SKIN: [u8; 3] = [224, 172, 135];
const TROUSERS: [u8; 3] = [55, 75, 140];

fn wheels(m: &mut Mesh, fr: &Frame, hl: f32, hw: f32, r: f32, axles: &[f32]) {
    for &x in axles {
        let x = x.clamp(-hl + r, hl - r);
        for side in [-1.0f32, 1.0] {
            m.bx(fr, x, side * (hw - 0.13), 0.0, 2.0 * r, r, 0.14, &all(TYRE));
        }
    }
}

fn lights(m: &mut Mesh, fr: &Frame, hl: f32, hw: f32, z: f32, braking: bool, blinkers: u8) {
    let brake = if braking { [255, 25, 25] } else { [120, 20, 20] };
    for side in [-1.0f32, 1.0] {
        let left = side * (hw - 0.25);
        // Rear lamps protrude 3 cm so they win the depth test against the body.
        m.out_lamp(fr, -hl - 0.03, left, z, 0.18, 0.09, brake, braking);
        m.out_lamp(fr, hl + 0.03, left, z, 0.17, 0.07, [235, 235, 210], false);
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

impl Mesh<'_> {
    #[allow(clippy::too_many_arguments)]
    fn out_lamp(
        &mut self,
        fr: &Frame,
        fwd: f32,
        left: f32,
        z: f32,
        hw: f32,
        hh: f32,
        col: [u8; 3],
        emissive: bool,
    ) {
        let c = [
            fr.pt(fwd + 0.03, left + hw, z - hh),
            fr.pt(fwd + 0.03, left - hw, z - hh),
            fr.pt(fwd - 0.03, left - hw, z - hh),
            fr.pt(fwd - 0.03, left + hw, z - hh),
            fr.pt(fwd + 0.03, left + hw, z + hh),
            fr.pt(fwd + 0.03, left - hw, z + hh),
            fr.pt(fwd - 0.03, left - hw, z + hh),
            fr.pt(fwd - 0.03, left + hw, z + hh),
        ];
        let start = self.out.len();
        self.hexa(c, &all(col), false);
        if emissive {
            for t in &mut self.out[start..] {
                t.col = col;
                t.emissive = true;
            }
        }
    }
}

/// Default footprint and height when a view gives zeros.
pub(crate) fn actor_dims(a: &ActorView) -> (f32, f32, f32) {
    let (l, w, h) = match a.kind {
        ActorKind::Car => (4.6, 1.9, 1.5),
        ActorKind::Bus => (12.0, 2.55, 3.2),
        ActorKind::Truck => (8.0, 2.5, 3.4),
        ActorKind::Motorcycle => (2.2, 0.8, 1.5),
        ActorKind::Cyclist => (1.8, 0.7, 1.75),
        ActorKind::Pedestrian => (0.5, 0.6, 1.75),
        ActorKind::Cone => (0.4, 0.4, 0.7),
        ActorKind::Barrier => (2.0, 0.4, 1.0),
        ActorKind::StaticObject => (1.0, 1.0, 1.0),
    };
    let pick = |v: f64, d: f32| if v.is_finite() && v > 0.05 { v as f32 } else { d };
    (pick(a.length_m, l), pick(a.width_m, w), pick(a.height_m, h))
}

/// Appends the triangles of one actor.
pub(crate) fn actor(out: &mut Vec<Tri3>, a: &ActorView, origin: Vec2, id: u32) {
    let fr = Frame::new(a.pose.pos, a.pose.yaw, origin, 0.0);
    let (l, w, h) = actor_dims(a);
    let (hl, hw) = (l * 0.5, w * 0.5);
    let col = a.color;
    let mut m = Mesh { out, id };
    match a.kind {
        ActorKind::Car => {
            let r = (h * 0.22).clamp(0.25, 0.4);
            wheels(&mut m, &fr, hl, hw, r, &[hl - 0.85 - r * 0.5, -hl + 0.85 + r * 0.5]);
            let zb = h * 0.55;
            m.tbox(&fr, 0.0, 0.0, r * 0.7, zb, [hl, hl, hw], [hl - 0.1, hl - 0.05, hw], &all(col));
            // Cabin: sloped windshield and rear window, roof in body colour.
            let cab = [scale(col, 0.95), col, GLASS, GLASS, GLASS, GLASS];
            m.tbox(
                &fr,
                -0.25 * hl,
                0.0,
                zb,
                h,
                [0.55 * hl, 0.55 * hl, hw * 0.92],
                [0.28 * hl, 0.42 * hl, hw * 0.82],
                &cab,
            );
            lights(&mut m, &fr, hl - 0.05, hw, zb - 0.15, a.braking, a.blinkers);
        }
        ActorKind::Bus => {
            let r = 0.5;
            wheels(&mut m, &fr, hl, hw, r, &[hl - 2.6, -hl + 3.2]);
            m.bx(&fr, 0.0, 0.0, r * 0.6, h * 0.5, hl, hw, &all(col));
            m.bx(
                &fr,
                0.0,
                0.0,
                h * 0.5,
                h * 0.86,
                hl - 0.02,
                hw - 0.02,
                &[col, col, GLASS, GLASS, GLASS, GLASS],
            );
            m.bx(&fr, 0.0, 0.0, h * 0.86, h, hl, hw, &all(scale(col, 1.05)));
            lights(&mut m, &fr, hl, hw, h * 0.3, a.braking, a.blinkers);
        }
        ActorKind::Truck => {
            let r = 0.5;
            let cab_l = 2.3f32.min(l * 0.4);
            wheels(&mut m, &fr, hl, hw, r, &[hl - 1.2, -hl + 1.4, -hl + 2.6]);
            let cab_c = hl - cab_l * 0.5;
            let cab_col = scale(col, 0.8);
            m.bx(&fr, cab_c, 0.0, r * 0.6, h * 0.45, cab_l * 0.5, hw, &all(cab_col));
            m.tbox(
                &fr,
                cab_c,
                0.0,
                h * 0.45,
                h * 0.85,
                [cab_l * 0.5, cab_l * 0.5, hw],
                [cab_l * 0.5 - 0.25, cab_l * 0.5, hw - 0.05],
                &[cab_col, cab_col, GLASS, GLASS, cab_col, GLASS],
            );
            let box_l = l - cab_l - 0.2;
            m.bx(&fr, -hl + box_l * 0.5, 0.0, r * 1.4, h, box_l * 0.5, hw, &all(scale(col, 1.15)));
            lights(&mut m, &fr, hl, hw, r * 1.6, a.braking, a.blinkers);
        }
        ActorKind::Motorcycle | ActorKind::Cyclist => {
            let moto = a.kind == ActorKind::Motorcycle;
            let r = if moto { 0.32 } else { 0.34 };
            let wb = (hl - r).max(0.3);
            for x in [wb, -wb] {
                m.bx(&fr, x, 0.0, 0.0, 2.0 * r, r, if moto { 0.08 } else { 0.04 }, &all(TYRE));
            }
            let frame_col = if moto { col } else { [60, 60, 66] };
            m.bx(
                &fr,
                0.0,
                0.0,
                r,
                r + if moto { 0.45 } else { 0.12 },
                wb * 0.8,
                if moto { 0.18 } else { 0.04 },
                &all(frame_col),
            );
            rider(&mut m, &fr, -0.15, r + 0.25, h, if moto { [30, 30, 30] } else { col }, true);
        }
        ActorKind::Pedestrian => {
            rider(&mut m, &fr, 0.0, 0.0, h, col, false);
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

/// Colour of one lamp slot (0 top red, 1 yellow, 2 green) under a signal state.
fn lamp(slot: usize, state: LightColor) -> ([u8; 3], bool) {
    let lit =
        matches!((slot, state), (0, LightColor::Red) | (1, LightColor::Yellow) | (2, LightColor::Green));
    let on = [[255, 30, 20], [255, 200, 0], [30, 255, 90]][slot];
    let off = [[70, 25, 25], [70, 60, 25], [25, 65, 35]][slot];
    if lit {
        (on, true)
    } else {
        (off, false)
    }
}

/// Lamp plate radius: exaggerated (real lamps are 0.15 m) so the colour reads at 30 m.
pub(crate) const LAMP_R: f32 = 0.3;

/// A signal head facing `-fr.f` (towards approaching traffic), its lamps centred at height z,
/// hanging from a mast arm to a pole `pole_right` metres to the right of the head. `lit_visible`
/// = false draws every lamp dark: real heads have visors, so a lit lamp cannot be seen from far
/// off its axis (the cross street's red must not read as the ego's own signal).
pub(crate) fn signal(
    out: &mut Vec<Tri3>,
    fr: &Frame,
    z: f32,
    state: LightColor,
    pole_right: Option<f32>,
    lit_visible: bool,
) {
    let mut m = Mesh { out, id: 0 };
    let dark = [28, 28, 30];
    let hh = LAMP_R * 3.6;
    m.bx(fr, 0.0, 0.0, z - hh, z + hh, 0.2, LAMP_R + 0.12, &all(dark));
    // Lamps on the face looking back along -f.
    let back = Frame { o: fr.o, f: [-fr.f[0], -fr.f[1]], l: [-fr.l[0], -fr.l[1]] };
    let shown = if lit_visible { state } else { LightColor::Off };
    for slot in 0..3 {
        let (c, em) = lamp(slot, shown);
        let zc = z + (1.0 - slot as f32) * LAMP_R * 2.35;
        m.plate(&back, 0.22, 0.0, zc, LAMP_R, 12, 0.0, c, em);
    }
    if let Some(pr) = pole_right {
        let grey = [95, 98, 102];
        m.bx(fr, 0.0, -pr * 0.5, z + hh - 0.12, z + hh, 0.06, pr * 0.5, &all(grey));
        m.bx(fr, 0.0, -pr, 0.0, z + hh, 0.1, 0.1, &all(grey));
    }
}

/// A sign on a post; its face looks along `fr.f`.
pub(crate) fn sign(out: &mut Vec<Tri3>, fr: &Frame, kind: SignKind) {
    let mut m = Mesh { out, id: 0 };
    let z = 2.2;
    m.bx(fr, -0.05, 0.0, 0.0, z, 0.04, 0.04, &all([150, 150, 155]));
    let red = [210, 20, 25];
    let white = [245, 245, 245];
    match kind {
        SignKind::Stop => {
            let rot = std::f32::consts::PI / 8.0;
            m.plate(fr, 0.0, 0.0, z, 0.5, 8, rot, white, false);
            m.plate(fr, 0.01, 0.0, z, 0.45, 8, rot, red, false);
        }
        SignKind::Yield => {
            // Point-down triangle: rotate by π so the first vertex points down.
            m.plate(fr, 0.0, 0.0, z, 0.6, 3, std::f32::consts::PI, red, false);
            m.plate(fr, 0.01, 0.0, z - 0.05, 0.36, 3, std::f32::consts::PI, white, false);
        }
        SignKind::SpeedLimit => {
            m.plate(fr, 0.0, 0.0, z, 0.42, 16, 0.0, red, false);
            m.plate(fr, 0.01, 0.0, z, 0.32, 16, 0.0, white, false);
        }
    }
    // The back of the sign: a grey plate facing the other way.
    let back = Frame { o: fr.o, f: [-fr.f[0], -fr.f[1]], l: [-fr.l[0], -fr.l[1]] };
    m.plate(&back, 0.01, 0.0, z, 0.5, 8, 0.0, [140, 140, 140], false);
}

/// A tree: trunk and a two-tier crown.
pub(crate) fn tree(out: &mut Vec<Tri3>, fr: &Frame, height: f32, crown: f32, shade_k: f32) {
    let mut m = Mesh { out, id: 0 };
    m.bx(fr, 0.0, 0.0, 0.0, height * 0.4, 0.15, 0.15, &all([90, 65, 40]));
    let g = scale([60, 120, 50], shade_k);
    m.tbox(fr, 0.0, 0.0, height * 0.35, height * 0.75, [crown * 0.7; 3], [crown; 3], &all(g));
    m.tbox(fr, 0.0, 0.0, height * 0.75, height, [crown; 3], [crown * 0.45; 3], &all(scale(g, 1.1)));
}

/// A building block with window bands.
pub(crate) fn building(out: &mut Vec<Tri3>, fr: &Frame, hl: f32, hw: f32, height: f32, col: [u8; 3]) {
    let mut m = Mesh { out, id: 0 };
    m.bx(fr, 0.0, 0.0, 0.0, height, hl, hw, &[col, scale(col, 0.7), col, col, col, col]);
    // Window bands on all four sides, 5 cm proud of the wall.
    let win = [70, 90, 115];
    let floors = ((height - 1.0) / 3.2).floor().max(1.0) as usize;
    for k in 0..floors {
        let z0 = 1.2 + k as f32 * 3.2;
        m.bx(fr, 0.0, 0.0, z0, z0 + 1.4, hl + 0.05, hw + 0.05, &all(win));
    }
}
