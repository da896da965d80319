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

/// Direction towards the noon sun (normalised in [`shade`]).
pub(crate) const SUN: [f32; 3] = [0.35, 0.25, 0.9];
/// Sky light every face gets, and the sun's share on a face turned fully to it. Sunlit faces
/// reach ~1.09 × their colour so paint reads as its name (white stays white, silver silver);
/// faces turned away keep 0.82, enough shape contrast without turning white into gray.
pub(crate) const AMBIENT: f32 = 0.82;
pub(crate) const DIFFUSE: f32 = 0.30;
/// A face is "sunlit" for the palette guarantee when cos(normal, sun) reaches this.
#[cfg(test)]
pub(crate) const LIT_MIN_COS: f32 = 0.3;

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
    let k = AMBIENT + DIFFUSE * dot(n, s).max(0.0);
    col.map(|c| (c as f32 * k).min(255.0) as u8)
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
    /// The actor's body colour: faces drawn in it carry [`PAINT_BIT`] in their id, so the id
    /// buffer tells paint from glazing, tyres, lamps and skin (colour naming reads paint only).
    pub paint: Option<[u8; 3]>,
    /// Lamps burn (night): head and tail lamps are drawn emissive.
    pub lit: bool,
}

/// Set in a [`Tri3::id`] (and the id buffer) on faces in the actor's body colour.
pub(crate) const PAINT_BIT: u32 = 1 << 31;

impl Mesh<'_> {
    #[inline]
    fn tri_id(&self, col: [u8; 3]) -> u32 {
        if self.id != 0 && self.id != u32::MAX && self.paint == Some(col) {
            self.id | PAINT_BIT
        } else {
            self.id
        }
    }
}

impl Mesh<'_> {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn quad(
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
        let id = self.tri_id(col);
        let col = if emissive { col } else { shade(col, n) };
        let t = |p: [[f32; 3]; 3]| Tri3 { p, n, col, emissive, two_sided: false, id };
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
        let id = self.tri_id(col);
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
                id,
            });
        }
    }
}

pub(crate) fn scale(c: [u8; 3], k: f32) -> [u8; 3] {
    [
        (c[0] as f32 * k).min(255.0) as u8,
        (c[1] as f32 * k).min(255.0) as u8,
        (c[2] as f32 * k).min(255.0) as u8,
    ]
}

impl Mesh<'_> {
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn out_lamp(
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

impl Mesh<'_> {
    /// A square-section bar from local point `a` to `b` (each (fwd, left, z) in `fr`): `hs` is
    /// its half thickness across the bar in the plane of the bar and the vertical, `hl` its
    /// half width along the frame's left axis (limbs, bicycle tubes, wheel rims).
    #[allow(clippy::too_many_arguments)]
    pub fn strut(&mut self, fr: &Frame, a: [f32; 3], b: [f32; 3], hs: f32, hl: f32, col: [u8; 3]) {
        let pa = fr.pt(a[0], a[1], a[2]);
        let pb = fr.pt(b[0], b[1], b[2]);
        let d = sub(pb, pa);
        if dot(d, d) < 1e-10 {
            return;
        }
        // Across the bar: the frame's left axis made perpendicular to the bar, then the third.
        let l = [fr.l[0], fr.l[1], 0.0];
        let dn = normalize(d);
        let u = normalize(sub(l, [dn[0] * dot(l, dn), dn[1] * dot(l, dn), dn[2] * dot(l, dn)]));
        let v = normalize(cross(dn, u));
        let off = |p: [f32; 3], su: f32, sv: f32| {
            [
                p[0] + u[0] * su * hl + v[0] * sv * hs,
                p[1] + u[1] * su * hl + v[1] * sv * hs,
                p[2] + u[2] * su * hl + v[2] * sv * hs,
            ]
        };
        let ring = |p| [off(p, 1.0, 1.0), off(p, -1.0, 1.0), off(p, -1.0, -1.0), off(p, 1.0, -1.0)];
        let (ra, rb) = (ring(pa), ring(pb));
        self.hexa([ra[0], ra[1], ra[2], ra[3], rb[0], rb[1], rb[2], rb[3]], &all(col), true);
    }

    /// An n-sided wheel (prism) on the axle line of `fr` at (fwd, left), radius `r`, half width
    /// `hw`: a tread in `tyre` and a hub disc in `hub` on the face towards `outward` (sign of
    /// the frame's left axis; 0 for a wheel seen from both sides, e.g. a bicycle's, which then
    /// gets the disc on its left face and is two-sided).
    #[allow(clippy::too_many_arguments)]
    pub fn wheel(
        &mut self,
        fr: &Frame,
        fwd: f32,
        left: f32,
        r: f32,
        hw: f32,
        n: usize,
        outward: f32,
        tyre: [u8; 3],
        hub: [u8; 3],
    ) {
        let start = self.out.len();
        let at = |i: usize, side: f32| {
            let a = std::f32::consts::TAU * (i as f32 + 0.5) / n as f32;
            fr.pt(fwd + r * a.cos(), left + side * hw, r + r * a.sin())
        };
        let centre = fr.pt(fwd, left, r);
        for i in 0..n {
            let (a0, a1, b0, b1) = (at(i, 1.0), at(i + 1, 1.0), at(i, -1.0), at(i + 1, -1.0));
            self.quad(a0, a1, b1, b0, centre, tyre, false);
        }
        // Outer side disc (the tyre as an n-gon, the hub a smaller one 1 cm proud of it); the
        // inner side faces the body and is never seen, so it is not drawn.
        let side = fr.offset(fwd, left, std::f32::consts::FRAC_PI_2);
        let face = if outward >= 0.0 {
            side
        } else {
            Frame { o: side.o, f: [-side.f[0], -side.f[1]], l: [-side.l[0], -side.l[1]] }
        };
        let rot = std::f32::consts::PI / n as f32;
        self.plate(&face, hw, 0.0, r, r, n, rot, tyre, false);
        self.plate(&face, hw + 0.01, 0.0, r, r * 0.55, n, rot, hub, false);
        if outward == 0.0 {
            for t in &mut self.out[start..] {
                t.two_sided = true;
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
    let mut m = Mesh { out, id: 0, paint: None, lit: false };
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
    let mut m = Mesh { out, id: 0, paint: None, lit: false };
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
    let mut m = Mesh { out, id: 0, paint: None, lit: false };
    m.bx(fr, 0.0, 0.0, 0.0, height * 0.4, 0.15, 0.15, &all([90, 65, 40]));
    let g = scale([60, 120, 50], shade_k);
    m.tbox(fr, 0.0, 0.0, height * 0.35, height * 0.75, [crown * 0.7; 3], [crown; 3], &all(g));
    m.tbox(fr, 0.0, 0.0, height * 0.75, height, [crown; 3], [crown * 0.45; 3], &all(scale(g, 1.1)));
}

/// A building block with window bands.
pub(crate) fn building(out: &mut Vec<Tri3>, fr: &Frame, hl: f32, hw: f32, height: f32, col: [u8; 3]) {
    let mut m = Mesh { out, id: 0, paint: None, lit: false };
    m.bx(fr, 0.0, 0.0, 0.0, height, hl, hw, &[col, scale(col, 0.7), col, col, col, col]);
    // Window bands on all four sides, 5 cm proud of the wall.
    let win = [70, 90, 115];
    let floors = ((height - 1.0) / 3.2).floor().max(1.0) as usize;
    for k in 0..floors {
        let z0 = 1.2 + k as f32 * 3.2;
        m.bx(fr, 0.0, 0.0, z0, z0 + 1.4, hl + 0.05, hw + 0.05, &all(win));
    }
}
