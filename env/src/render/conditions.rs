//! Light and weather on the cameras ([`crate::conditions::Conditions`]) and the camera-fault
//! control: a [`Look`] per frame (sky, sun, shadows, tint, fog) that the camera applies while it
//! draws, night light pools (head lamps, street lights) on the ground, a per-pixel pass for fog
//! and the wet road, and lens effects (rain drops, a dirty lens). Noon/clear is the identity:
//! its look reproduces the constant lighting byte for byte.
//!
//! Everything is a pure function of the frame (no RNG but the seeded hash below) and works in
//! the caller's buffers, so the hot path stays allocation-free.

use super::frame::Ambience;
use super::image::Image;
use super::map::RenderMap;
use super::mesh::{self, Tri3};
use super::raster::{RasterBackend, SV};
use crate::conditions::{Conditions, TimeOfDay, Weather};
use crate::view::{ActorKind, ActorView};
use serde::{Deserialize, Serialize};

/// A camera's pose and intrinsics as the conditions need them (the camera's `Cam` holds one and
/// implements [`Eye`]; this module does not depend on it).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Basis {
    pub pos: [f32; 3],
    pub r: [f32; 3],
    pub d: [f32; 3],
    pub f: [f32; 3],
    pub fx: f32,
    pub cx: f32,
    pub cy: f32,
    pub far: f32,
}

/// What the conditions draw through: a pinhole camera without roll.
pub(crate) trait Eye {
    fn basis(&self) -> &Basis;
    fn to_cam(&self, p: [f32; 3]) -> [f32; 3];
    /// True when all points lie outside one frustum plane.
    fn outside(&self, c: &[[f32; 3]]) -> bool;
    /// Near-clips and projects a camera-space triangle; returns the polygon's vertex count.
    fn clip_project(&self, c: [[f32; 3]; 3], out: &mut [SV; 4]) -> usize;
}

/// Noon sky and ground (the constant lighting before conditions existed).
pub(crate) const SKY_TOP: [f32; 3] = [92.0, 145.0, 215.0];
pub(crate) const HORIZON: [f32; 3] = [205.0, 215.0, 225.0];
pub(crate) const GRASS: [f32; 3] = [110.0, 128.0, 88.0];

/// How a camera draws one frame's light and weather.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Look {
    pub sky_top: [f32; 3],
    pub horizon: [f32; 3],
    pub grass: [f32; 3],
    /// Colour distant faces fade to, and the fade's start, end and cap (per face).
    pub fog: [f32; 3],
    pub fog0: f32,
    pub fog1: f32,
    pub fog_max: f32,
    /// Multiplier of every lit (non-emissive) colour; `None` = 1 (noon, clear).
    pub light: Option<[f32; 3]>,
    /// Road and junction surfaces, on top of `light` (wet asphalt is darker).
    pub road: f32,
    /// Direction towards the sun (shadows fall away from it).
    pub sun: [f32; 3],
    /// Shadow darkening (k / 256) and length factor; `None`: no shadows.
    pub shadow: Option<(u16, f32)>,
    /// Head lamps and street lights burn and light the ground.
    pub night: bool,
    /// Per-pixel fog: visibility distance (m) where 63 % of the colour is fog.
    pub haze_m: Option<f32>,
    /// The wet ground mirrors the sky at grazing angles.
    pub wet: bool,
    /// Rain drops on the lens of mounted cameras.
    pub drops: bool,
}

impl Look {
    pub fn of(c: Conditions) -> Look {
        let mut l = Look {
            sky_top: SKY_TOP,
            horizon: HORIZON,
            grass: GRASS,
            fog: HORIZON,
            fog0: 45.0,
            fog1: 260.0,
            fog_max: 0.8,
            light: None,
            road: 1.0,
            sun: mesh::SUN,
            shadow: Some((158, 0.55)),
            night: false,
            haze_m: None,
            wet: false,
            drops: false,
        };
        // Brightness of the sky light, for the weathers' grey skies.
        let b = match c.time_of_day {
            TimeOfDay::Noon => 1.0,
            TimeOfDay::Dusk => {
                l.sky_top = [62.0, 78.0, 140.0];
                l.horizon = [238.0, 158.0, 104.0];
                l.grass = [92.0, 92.0, 62.0];
                l.fog = [196.0, 140.0, 110.0];
                l.light = Some([0.92, 0.74, 0.58]);
                // Low in the west-south-west: shadows three times as long, softer.
                l.sun = [0.8, 0.42, 0.28];
                l.shadow = Some((176, 0.5));
                0.6
            }
            TimeOfDay::Night => {
                l.sky_top = [6.0, 8.0, 20.0];
                l.horizon = [24.0, 28.0, 44.0];
                l.grass = [30.0, 36.0, 30.0];
                l.fog = [14.0, 16.0, 26.0];
                l.fog0 = 25.0;
                l.fog1 = 150.0;
                l.fog_max = 0.85;
                l.light = Some([0.24, 0.26, 0.34]);
                l.shadow = None;
                l.night = true;
                0.14
            }
        };
        let grey = |v: f32| [v * b, v * b * 1.01, v * b * 1.04];
        let mul = |a: Option<[f32; 3]>, k: [f32; 3]| {
            let a = a.unwrap_or([1.0; 3]);
            Some([a[0] * k[0], a[1] * k[1], a[2] * k[2]])
        };
        match c.weather {
            Weather::Clear => {}
            Weather::Overcast | Weather::Rain => {
                let rain = c.weather == Weather::Rain;
                let (top, hor) = if rain { (112.0, 150.0) } else { (150.0, 190.0) };
                l.sky_top = grey(top);
                l.horizon = grey(hor);
                l.fog = grey(hor);
                l.grass = [l.grass[0] * 0.85, l.grass[1] * 0.88, l.grass[2] * 0.85];
                let k = if rain { 0.72 } else { 0.85 };
                l.light = mul(l.light, [k, k * 1.01, k * 1.04]);
                // Sky light from everywhere: a faint contact shadow right under each body.
                l.shadow = if l.night { None } else { Some((205, 0.06)) };
                if rain {
                    l.road = 0.72;
                    l.wet = true;
                    l.drops = true;
                    l.fog0 = 20.0;
                    l.fog1 = 220.0;
                }
            }
            Weather::Fog => {
                let f = if l.night { [20.0, 22.0, 28.0] } else { grey(196.0) };
                l.sky_top = f;
                l.horizon = f;
                l.fog = f;
                l.fog_max = 0.0; // the per-pixel haze does it
                l.haze_m = Some(if l.night { 30.0 } else { 38.0 });
                l.light = mul(l.light, [0.9, 0.9, 0.92]);
                l.shadow = if l.night { None } else { Some((215, 0.06)) };
            }
        }
        l
    }

    /// A lit colour under this look.
    #[inline(always)]
    pub fn lit(&self, col: [u8; 3]) -> [u8; 3] {
        match self.light {
            None => col,
            Some(k) => [
                (col[0] as f32 * k[0]).min(255.0) as u8,
                (col[1] as f32 * k[1]).min(255.0) as u8,
                (col[2] as f32 * k[2]).min(255.0) as u8,
            ],
        }
    }

    /// The fade of a face at distance `d` towards [`Look::fog`].
    #[inline(always)]
    pub fn fog_k(&self, d: f32) -> f32 {
        ((d - self.fog0) / (self.fog1 - self.fog0)).clamp(0.0, self.fog_max)
    }

    /// Whether anything beyond the constant noon look is drawn.
    pub fn is_noon_clear(&self) -> bool {
        self.light.is_none() && !self.night && !self.wet && self.haze_m.is_none() && !self.drops
    }
}

/// Ray direction (not normalised, forward component 1) through pixel centre (x, y).
#[inline(always)]
fn ray(cam: &Basis, xc: f32, yc: f32) -> [f32; 3] {
    [
        cam.r[0] * xc + cam.d[0] * yc + cam.f[0],
        cam.r[1] * xc + cam.d[1] * yc + cam.f[1],
        cam.r[2] * xc + cam.d[2] * yc + cam.f[2],
    ]
}

/// Adds light `l` (0..~1, daylight-equivalent) of colour `c` to a night pixel: the surface's
/// own colour brought back towards its daylight value, plus a little of the lamp's. The gain
/// reads the surface from at most an unlit night value, so overlapping pools add up instead of
/// compounding.
#[inline(always)]
fn add_light(px: &mut [u8], l: f32, c: [f32; 3]) {
    for k in 0..3 {
        let v = px[k] as f32;
        px[k] = (v + (v.min(64.0) * 2.6 + 10.0) * l * c[k]).min(255.0) as u8;
    }
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

const HEADLAMP_REACH_M: f32 = 42.0;
/// Vehicles whose head lamps light the ground in one frame (the ego included).
const MAX_BEAMS: usize = 8;
const HEADLAMP: [f32; 3] = [1.0, 0.97, 0.86];
const STREET_LAMP: [f32; 3] = [1.0, 0.82, 0.55];
/// Radius of a street light's pool on the ground, m.
const POOL_M: f32 = 11.0;
/// Street lights farther than this from the camera are not drawn (their pools are specks), m.
const STREET_LIGHTS_M: f32 = 100.0;
/// Height of a street light's head, m.
pub(crate) const LAMP_HEAD_M: f32 = 7.0;

fn has_headlamps(a: &ActorView) -> bool {
    matches!(a.kind, ActorKind::Car | ActorKind::Bus | ActorKind::Truck | ActorKind::Motorcycle)
}

/// Draws a ground quad (map frame, z = 0) through `b.light_convex`: `shade(row, g0, step)`
/// lights one covered run of pixels whose ground points are `g0 + i · step` (flat ground, no
/// roll: linear along a row).
fn ground_light<B: RasterBackend, F: Fn(&mut [u8], [f32; 2], [f32; 2])>(
    eye: &impl Eye,
    b: &mut B,
    quad: [[f32; 2]; 4],
    poly: &mut [SV; 4],
    shade: F,
) {
    let q = quad.map(|p| eye.to_cam([p[0], p[1], 0.0]));
    let cam = eye.basis();
    let (pos, fx, cx, cy) = (cam.pos, cam.fx, cam.cx, cam.cy);
    for tri in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
        if eye.outside(&tri) {
            continue;
        }
        let n = eye.clip_project(tri, poly);
        b.light_convex(&poly[..n], &mut |y, x0, row| {
            let yc = (y as f32 + 0.5 - cy) / fx;
            let d0 = ray(cam, (x0 as f32 + 0.5 - cx) / fx, yc);
            if d0[2] >= -1e-4 {
                return;
            }
            let t = -pos[2] / d0[2];
            let g0 = [pos[0] + t * d0[0], pos[1] + t * d0[1]];
            shade(row, g0, [t * cam.r[0] / fx, t * cam.r[1] / fx]);
        });
    }
}

/// The index range [lo, hi) of `0..n` where `a + b·i > 0` holds, intersected with `range`.
#[inline(always)]
fn keep_positive(range: (f32, f32), a: f32, b: f32) -> (f32, f32) {
    if b.abs() < 1e-9 {
        return if a > 0.0 { range } else { (0.0, 0.0) };
    }
    let root = -a / b;
    if b > 0.0 {
        (range.0.max(root), range.1)
    } else {
        (range.0, range.1.min(root))
    }
}

/// Night: the pools of light on the ground from every vehicle's head lamps (the ego's too) and
/// from the street lights near the camera. Drawn over the ground, under everything standing;
/// each run of pixels is first cut to where its light is non-zero.
pub(crate) fn light_pools<B: RasterBackend>(
    eye: &impl Eye,
    map: &RenderMap,
    ego: &ActorView,
    actors: &[ActorView],
    b: &mut B,
    poly: &mut [SV; 4],
) {
    let cam = eye.basis();
    let reach = HEADLAMP_REACH_M;
    // Brightness along the beam by distance from the lamps, in 64 steps over the reach.
    let mut along = [0f32; 65];
    for (i, v) in along.iter_mut().enumerate() {
        let u = reach * i as f32 / 64.0;
        *v = 0.8 * smoothstep(0.0, 9.0, u) / (1.0 + (u / 22.0).powi(2))
            * (1.0 - smoothstep(0.6 * reach, reach, u));
    }
    // The ego and the MAX_BEAMS - 1 nearest other vehicles light the ground (a bound on the cost
    // in dense traffic; the others' lamps still burn). Chosen by distance, then index: stable.
    let mut near = [(f32::INFINITY, usize::MAX); MAX_BEAMS];
    near[0] = (0.0, usize::MAX - 1);
    for (i, a) in actors.iter().enumerate() {
        if !has_headlamps(a) || (a.id == ego.id && a.pose == ego.pose) {
            continue;
        }
        let p = a.pose.pos - map.origin;
        let d2 = (p.x as f32 - cam.pos[0]).powi(2) + (p.y as f32 - cam.pos[1]).powi(2);
        if d2 > (cam.far + reach).powi(2) || d2 >= near[MAX_BEAMS - 1].0 {
            continue;
        }
        let mut k = MAX_BEAMS - 1;
        while k > 1 && near[k - 1].0 > d2 {
            near[k] = near[k - 1];
            k -= 1;
        }
        near[k] = (d2, i);
    }
    for &(_, i) in &near {
        let a = match i {
            usize::MAX => continue,
            i if i == usize::MAX - 1 => ego,
            i => &actors[i],
        };
        if !has_headlamps(a) {
            continue;
        }
        let p = a.pose.pos - map.origin;
        let (ax, ay) = (p.x as f32, p.y as f32);
        let (l, w, _) = mesh::actor_dims(a);
        let (s, c) = a.pose.yaw.sin_cos();
        let (f, lft) = ([c as f32, s as f32], [-s as f32, c as f32]);
        let (hl, hw) = (l * 0.5, w * 0.5);
        let base = [ax + f[0] * hl, ay + f[1] * hl];
        let at = |u: f32, v: f32| [base[0] + f[0] * u + lft[0] * v, base[1] + f[1] * u + lft[1] * v];
        let spread = 0.32;
        let quad =
            [at(0.0, hw), at(0.0, -hw), at(reach, -(hw + reach * spread)), at(reach, hw + reach * spread)];
        let shade = |row: &mut [u8], g0: [f32; 2], st: [f32; 2]| {
            // Beam coordinates along the run: u ahead of the lamps, v to the left, both linear.
            let (gx, gy) = (g0[0] - base[0], g0[1] - base[1]);
            let (u0, du) = (gx * f[0] + gy * f[1], st[0] * f[0] + st[1] * f[1]);
            let (v0, dv) = (gx * lft[0] + gy * lft[1], st[0] * lft[0] + st[1] * lft[1]);
            let mut r = (0.0, (row.len() / 3) as f32);
            r = keep_positive(r, u0, du);
            r = keep_positive(r, reach - u0, -du);
            r = keep_positive(r, hw + spread * u0 - v0, spread * du - dv);
            r = keep_positive(r, hw + spread * u0 + v0, spread * du + dv);
            let (lo, hi) = (r.0.max(0.0).ceil() as usize, (r.1.max(0.0).ceil() as usize).min(row.len() / 3));
            for i in lo..hi {
                let fi = i as f32;
                let (u, v) = (u0 + du * fi, (v0 + dv * fi).abs());
                let edge = hw + u * spread;
                let across = 1.0 - smoothstep(0.55, 1.0, v / edge);
                // Linear between table steps (a step is 0.66 m: bands would show near the car).
                let t = (u / reach * 64.0).clamp(0.0, 63.999);
                let (k, fr) = (t as usize, t.fract());
                let l = (along[k] + (along[k + 1] - along[k]) * fr) * across;
                add_light(&mut row[i * 3..i * 3 + 3], l, HEADLAMP);
            }
        };
        ground_light(eye, b, quad, poly, shade);
    }
    let r2 = STREET_LIGHTS_M * STREET_LIGHTS_M;
    for lamp in &map.street_lamps {
        let (x, y) = (lamp[0], lamp[1]);
        if (x - cam.pos[0]).powi(2) + (y - cam.pos[1]).powi(2) > r2 {
            continue;
        }
        let quad = [
            [x - POOL_M, y - POOL_M],
            [x + POOL_M, y - POOL_M],
            [x + POOL_M, y + POOL_M],
            [x - POOL_M, y + POOL_M],
        ];
        let shade = |row: &mut [u8], g0: [f32; 2], st: [f32; 2]| {
            // |g0 + i·st − centre|² < R²: a quadratic in i; light only between its roots.
            let (px, py) = (g0[0] - x, g0[1] - y);
            let qa = st[0] * st[0] + st[1] * st[1];
            let qb = 2.0 * (px * st[0] + py * st[1]);
            let qc = px * px + py * py - POOL_M * POOL_M;
            let disc = qb * qb - 4.0 * qa * qc;
            if qa <= 0.0 || disc <= 0.0 {
                return;
            }
            let sq = disc.sqrt();
            let n = row.len() / 3;
            let lo = ((-qb - sq) / (2.0 * qa)).max(0.0).ceil() as usize;
            let hi = (((-qb + sq) / (2.0 * qa)).max(0.0).ceil() as usize).min(n);
            for i in lo..hi {
                let fi = i as f32;
                let d2 = ((px + st[0] * fi).powi(2) + (py + st[1] * fi).powi(2)) / (POOL_M * POOL_M);
                if d2 < 1.0 {
                    add_light(&mut row[i * 3..i * 3 + 3], 0.55 * (1.0 - d2) * (1.0 - d2), STREET_LAMP);
                }
            }
        };
        ground_light(eye, b, quad, poly, shade);
    }
}

/// Night: street-light poles with a burning head over the road, near the camera.
pub(crate) fn street_lamp_tris(cam: &Basis, map: &RenderMap, out: &mut Vec<Tri3>) {
    let r2 = STREET_LIGHTS_M * STREET_LIGHTS_M;
    for lamp in &map.street_lamps {
        let (x, y) = (lamp[0], lamp[1]);
        if (x - cam.pos[0]).powi(2) + (y - cam.pos[1]).powi(2) > r2 {
            continue;
        }
        // The pole stands `arm` m outward from the pool's centre, the arm reaching over it.
        let (dx, dy, arm) = (lamp[2], lamp[3], 2.4);
        let fr = mesh::Frame { o: [x + dx * arm, y + dy * arm, 0.0], f: [-dx, -dy], l: [dy, -dx] };
        let mut m = mesh::Mesh { out: &mut *out, id: 0, paint: None, lit: true };
        m.bx(&fr, 0.0, 0.0, 0.0, LAMP_HEAD_M, 0.09, 0.09, &mesh::all([48, 50, 54]));
        m.bx(
            &fr,
            arm * 0.5,
            0.0,
            LAMP_HEAD_M - 0.08,
            LAMP_HEAD_M + 0.04,
            arm * 0.5,
            0.05,
            &mesh::all([48, 50, 54]),
        );
        m.out_lamp(&fr, arm, 0.0, LAMP_HEAD_M - 0.12, 0.3, 0.09, [255, 226, 170], true);
    }
}

/// Per-pixel fog and wet-ground sheen over a finished camera frame, from its depth plane
/// (ground layers leave depth empty; their distance follows from the row). Distances are taken
/// along the row's centre ray (the cosine of the horizontal angle is dropped), so ground and sky
/// blends are one constant per row and faces read one table: about a nanosecond a pixel.
pub(crate) fn post(look: &Look, cam: &Basis, rgb: &mut [u8], depth: &[f32], w: usize, h: usize) {
    if look.haze_m.is_none() && !look.wet {
        return;
    }
    let fog = look.fog.map(|v| v as i32);
    let refl = look.horizon.map(|v| v as i32);
    let inv_vis = look.haze_m.map_or(0.0, |v| 1.0 / v);
    // Fog of a face by its distance in units of visibility / 32.
    const STEPS: f32 = 32.0;
    let mut lut = [0i32; 257];
    for (i, k) in lut.iter_mut().enumerate() {
        *k = ((1.0 - (-(i as f32) / STEPS).exp()) * 256.0) as i32;
    }
    lut[256] = 256;
    let blend = |px: &mut [u8], to: [i32; 3], k: i32| {
        for c in 0..3 {
            let v = px[c] as i32;
            px[c] = (v + (((to[c] - v) * k) >> 8)) as u8;
        }
    };
    for y in 0..h {
        let yc = (y as f32 + 0.5 - cam.cy) / cam.fx;
        let d2 = cam.d[2] * yc + cam.f[2];
        let len = (1.0 + yc * yc).sqrt();
        // Depth-0 pixels of this row: ground below the horizon, sky above.
        let (ground, z_ground) = (d2 < -1e-5, -cam.pos[2] / d2.min(-1e-5));
        let k_wet = if look.wet && ground {
            // Fresnel-like: the flatter the view onto the wet ground, the more sky it mirrors.
            (0.6 * (1.0 - (-d2 / len) / 0.32).clamp(0.0, 1.0).powi(2) * 256.0) as i32
        } else {
            0
        };
        let k_empty = if inv_vis == 0.0 {
            0
        } else if ground {
            lut[((z_ground * len * inv_vis * STEPS) as usize).min(256)]
        } else {
            256
        };
        let row = &mut rgb[y * w * 3..(y + 1) * w * 3];
        let drow = if depth.is_empty() { None } else { Some(&depth[y * w..(y + 1) * w]) };
        for (x, px) in row.chunks_exact_mut(3).enumerate() {
            let z = drow.map_or(0.0, |d| d[x]);
            if z <= 0.0 {
                if k_wet > 0 {
                    blend(px, refl, k_wet);
                }
                if k_empty > 0 {
                    blend(px, fog, k_empty);
                }
            } else if inv_vis > 0.0 {
                let k = lut[((len / z * inv_vis * STEPS) as usize).min(256)];
                blend(px, fog, k);
            }
        }
    }
}

/// splitmix64 finaliser: the lens effects' only source of randomness.
fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

fn unit(h: u64) -> f32 {
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Rain on a mounted camera: falling streaks, and drops on the lens that each sit a while, slide
/// a little and are replaced, showing the scene upside down and blurred as a real drop does.
/// A pure function of (seed, tick).
pub(crate) fn rain_on_lens(img: &mut Image, amb: &Ambience, scratch: &mut Vec<u8>) {
    let (w, h) = (img.width as usize, img.height as usize);
    if w < 8 || h < 8 {
        return;
    }
    let s = w as f32 / 800.0;
    let seed = mix(amb.seed ^ 0x5241_494E);
    // Streaks: thin light lines slanting down, new every tick.
    let n_streaks = (90.0 * s) as u64 + 10;
    for i in 0..n_streaks {
        let r = mix(seed ^ mix(amb.tick.wrapping_mul(1_000_003) ^ i));
        let (x0, y0) = (unit(r) * w as f32, unit(mix(r)) * h as f32);
        let len = (10.0 + unit(mix(r ^ 1)) * 16.0) * s;
        for k in 0..len as usize {
            let (x, y) = ((x0 + k as f32 * 0.18) as usize, (y0 + k as f32) as usize);
            if x < w && y < h {
                let o = (y * w + x) * 3;
                for c in 0..3 {
                    let v = img.data[o + c] as u32;
                    img.data[o + c] = ((v * 3 + 200) / 4) as u8;
                }
            }
        }
    }
    // Drops: each slot lives `life` ticks, then reappears elsewhere.
    let n_drops = 16u64;
    for i in 0..n_drops {
        let hs = mix(seed ^ (i << 32));
        let life = 60 + hs % 120;
        let t = amb.tick + hs % life;
        let epoch = t / life;
        let age = (t % life) as f32;
        let r = mix(hs ^ epoch.wrapping_mul(0x2545_F491_4F6C_DD1D));
        let rad = (6.0 + unit(r) * 16.0) * s;
        let cx = unit(mix(r ^ 2)) * w as f32;
        let cy = unit(mix(r ^ 3)) * h as f32 * 0.9 + age * 0.08 * s;
        drop_at(img, scratch, cx, cy, rad);
    }
}

/// One drop of radius `rad` at (cx, cy): inverted, shrunken view of its surroundings, brighter,
/// with a dark rim and a highlight.
fn drop_at(img: &mut Image, scratch: &mut Vec<u8>, cx: f32, cy: f32, rad: f32) {
    let (w, h) = (img.width as i64, img.height as i64);
    let (x0, x1) = (((cx - rad).floor() as i64).max(0), ((cx + rad).ceil() as i64).min(w - 1));
    let (y0, y1) = (((cy - rad).floor() as i64).max(0), ((cy + rad).ceil() as i64).min(h - 1));
    if x0 > x1 || y0 > y1 {
        return;
    }
    let bw = (x1 - x0 + 1) as usize;
    scratch.clear();
    for y in y0..=y1 {
        let o = ((y * w + x0) * 3) as usize;
        scratch.extend_from_slice(&img.data[o..o + bw * 3]);
    }
    let sample = |x: f32, y: f32| -> [f32; 3] {
        let xi = (x.round() as i64).clamp(x0, x1);
        let yi = (y.round() as i64).clamp(y0, y1);
        let o = (((yi - y0) as usize) * bw + (xi - x0) as usize) * 3;
        [scratch[o] as f32, scratch[o + 1] as f32, scratch[o + 2] as f32]
    };
    for y in y0..=y1 {
        for x in x0..=x1 {
            let (dx, dy) = (x as f32 + 0.5 - cx, y as f32 + 0.5 - cy);
            let r = (dx * dx + dy * dy).sqrt() / rad;
            if r >= 1.0 {
                continue;
            }
            // Refraction: the view through the drop, flipped and shrunk, lightly blurred.
            let (sx, sy) = (cx - dx * 0.55, cy - dy * 0.55 - rad * 0.25);
            let a = sample(sx, sy);
            let b2 = sample(sx + 1.5, sy + 1.0);
            let mut c = [0.0f32; 3];
            for k in 0..3 {
                c[k] = (a[k] + b2[k]) * 0.5 * 1.08 + 10.0;
            }
            let rim = smoothstep(0.72, 1.0, r);
            let spec =
                1.0 - smoothstep(0.0, 0.22, ((dx / rad + 0.35).powi(2) + (dy / rad + 0.4).powi(2)).sqrt());
            let o = ((y * w + x) * 3) as usize;
            // The highlight mirrors the sky: faint in a dark scene.
            let glint = 120.0 * spec * (0.25 + 0.75 * (c[0] + c[1] + c[2]) / 765.0);
            for (k, ck) in c.iter().enumerate() {
                let v = ck * (1.0 - 0.45 * rim) + glint;
                // Soft edge: blend with the frame behind over the outer 10 %.
                let e = smoothstep(0.9, 1.0, r);
                img.data[o + k] = (v * (1.0 - e) + img.data[o + k] as f32 * e).clamp(0.0, 255.0) as u8;
            }
        }
    }
}

/// A fault of the observation's front camera (a robustness control, `SimConfig::camera_fault`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraFault {
    /// The image stops updating: from a decision drawn from the seed (the 4th to the 12th)
    /// every observation repeats the last image delivered before it.
    Frozen,
    /// About one observation in four (drawn per decision from the seed) repeats the previous
    /// image instead of a new one; a dropped frame never comes first.
    Dropped,
    /// Fixed smudges on the lens (placed by the seed): dark, blurred blotches.
    Dirty,
}

impl CameraFault {
    pub const ALL: [CameraFault; 3] = [CameraFault::Frozen, CameraFault::Dropped, CameraFault::Dirty];

    pub fn as_str(self) -> &'static str {
        match self {
            CameraFault::Frozen => "frozen",
            CameraFault::Dropped => "dropped",
            CameraFault::Dirty => "dirty",
        }
    }

    /// The decision from which a frozen camera repeats its last image.
    pub fn freeze_at(seed: u64) -> u64 {
        4 + mix(seed ^ 0xF0_2E2E) % 9
    }

    /// Whether observation `decision` of a dropping camera is a repeat.
    pub fn dropped(seed: u64, decision: u64) -> bool {
        decision > 0 && mix(mix(seed ^ 0xD209) ^ decision) % 4 == 0
    }

    /// Applies the fault to the freshly rendered observation `img` (decision `decision` of an
    /// episode of `seed`); `last` is the image delivered before (updated).
    pub fn apply(self, img: &mut Image, last: &mut Option<Image>, seed: u64, decision: u64) {
        match self {
            CameraFault::Dirty => smudge(img, seed),
            CameraFault::Frozen | CameraFault::Dropped => {
                let repeat = match self {
                    CameraFault::Frozen => decision >= Self::freeze_at(seed),
                    _ => Self::dropped(seed, decision),
                };
                match last {
                    Some(prev) if repeat && prev.width == img.width && prev.height == img.height => {
                        img.data.copy_from_slice(&prev.data);
                    }
                    _ => *last = Some(img.clone()),
                }
            }
        }
    }
}

/// Dirty lens: a few fixed brownish blotches, denser at their centre, placed by the seed.
fn smudge(img: &mut Image, seed: u64) {
    let (w, h) = (img.width as usize, img.height as usize);
    let s = w as f32 / 800.0;
    for i in 0..7u64 {
        let r = mix(seed ^ 0xD127 ^ (i << 20));
        let (cx, cy) = (unit(r) * w as f32, unit(mix(r)) * h as f32);
        let (rx, ry) = ((30.0 + unit(mix(r ^ 1)) * 70.0) * s, (20.0 + unit(mix(r ^ 2)) * 45.0) * s);
        let dens = 0.45 + unit(mix(r ^ 3)) * 0.35;
        let (x0, x1) = ((cx - rx).max(0.0) as usize, ((cx + rx) as usize).min(w));
        let (y0, y1) = ((cy - ry).max(0.0) as usize, ((cy + ry) as usize).min(h));
        for y in y0..y1 {
            for x in x0..x1 {
                let (dx, dy) = ((x as f32 + 0.5 - cx) / rx, (y as f32 + 0.5 - cy) / ry);
                let d = dx * dx + dy * dy;
                if d >= 1.0 {
                    continue;
                }
                let a = dens * (1.0 - d) * (1.0 - d);
                let o = (y * w + x) * 3;
                for (k, dirt) in [72.0f32, 62.0, 48.0].into_iter().enumerate() {
                    let v = img.data[o + k] as f32;
                    img.data[o + k] = (v + (dirt - v) * a) as u8;
                }
            }
        }
    }
}
