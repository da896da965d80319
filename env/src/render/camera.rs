//! Perspective cameras: a pinhole model; projected, near-clipped polygons go to a
//! [`RasterBackend`] (by default the z-buffered scanline rasterizer).
//!
//! Ground layers (roads, sidewalks, markings) lie on z = 0 and can never hide anything standing
//! above the ground from a camera above it, so they are painted in layer order without depth;
//! actors, signals, signs and props are then depth-tested among themselves.

use super::conditions::{self, Basis, Eye, Look};
use super::frame::{FrameInput, Renderer};
use super::image::Image;
use super::map::{Mat, RenderMap, N_LAYERS, N_MATS};
use super::mesh::{self, dot, Frame, Tri3, PAINT_BIT};
use super::raster::{fill_mask, Planes, RasterBackend, SV};
use crate::error::{Error, Result};
use crate::view::{ActorKind, ActorView};
use serde::{Deserialize, Serialize};

/// A camera rigidly mounted on the ego vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    pub width: u32,
    pub height: u32,
    /// Horizontal field of view, degrees.
    pub fov_deg: f64,
    /// Mount position relative to the vehicle centre on the ground, metres.
    pub mount_forward_m: f64,
    pub mount_left_m: f64,
    pub mount_height_m: f64,
    /// Positive looks down, degrees.
    pub pitch_deg: f64,
    /// Positive looks left of the vehicle heading, degrees.
    pub yaw_deg: f64,
    /// Render at `supersample`× resolution per axis and box-filter down (1 = off, max 4).
    pub supersample: u8,
    /// Draw the ego vehicle itself (chase cameras); mounted cameras leave it out.
    pub draw_ego: bool,
    /// Nothing farther than this is drawn, metres.
    pub draw_distance_m: f64,
}

impl Default for CameraConfig {
    /// docs/protocol.md#r4-loop front camera: 800×450, FOV 100°, 1.5 m ahead, 2.4 m up, pitched 5° down.
    fn default() -> Self {
        CameraConfig {
            width: 800,
            height: 450,
            fov_deg: 100.0,
            mount_forward_m: 1.5,
            mount_left_m: 0.0,
            mount_height_m: 2.4,
            pitch_deg: 5.0,
            yaw_deg: 0.0,
            supersample: 1,
            draw_ego: false,
            draw_distance_m: 200.0,
        }
    }
}

impl CameraConfig {
    /// The protocol front camera (same as `Default`).
    pub fn front() -> Self {
        Self::default()
    }

    /// A chase camera 7 m behind and 3.2 m above the ego, looking down 12°, ego drawn.
    pub fn chase() -> Self {
        CameraConfig {
            fov_deg: 90.0,
            mount_forward_m: -7.0,
            mount_height_m: 3.2,
            pitch_deg: 12.0,
            draw_ego: true,
            ..Self::default()
        }
    }

    /// Six-camera surround rig modelled on nuScenes (names as in nuScenes), 800×450 each.
    pub fn surround_rig() -> [(&'static str, CameraConfig); 6] {
        let cam = |fwd: f64, left: f64, yaw: f64, fov: f64| CameraConfig {
            fov_deg: fov,
            mount_forward_m: fwd,
            mount_left_m: left,
            mount_height_m: 1.6,
            pitch_deg: 0.0,
            yaw_deg: yaw,
            ..Self::default()
        };
        [
            ("CAM_FRONT", cam(1.7, 0.0, 0.0, 70.0)),
            ("CAM_FRONT_LEFT", cam(1.5, 0.5, 55.0, 70.0)),
            ("CAM_FRONT_RIGHT", cam(1.5, -0.5, -55.0, 70.0)),
            ("CAM_BACK", cam(-2.0, 0.0, 180.0, 110.0)),
            ("CAM_BACK_LEFT", cam(-0.5, 0.5, 110.0, 70.0)),
            ("CAM_BACK_RIGHT", cam(-0.5, -0.5, -110.0, 70.0)),
        ]
    }

    /// Checks sizes and angles; names the offending field.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 || self.width > 8192 || self.height > 8192 {
            return Err(Error::config(
                "camera.width/height",
                format!("{}x{}", self.width, self.height),
                "must be 1..=8192",
            ));
        }
        if !(self.fov_deg > 1.0 && self.fov_deg < 170.0) {
            return Err(Error::config("camera.fov_deg", self.fov_deg, "must be in (1, 170)"));
        }
        if !(1..=4).contains(&self.supersample) {
            return Err(Error::config("camera.supersample", self.supersample, "must be 1..=4"));
        }
        for (f, v) in [
            ("camera.mount_forward_m", self.mount_forward_m),
            ("camera.mount_left_m", self.mount_left_m),
            ("camera.mount_height_m", self.mount_height_m),
            ("camera.pitch_deg", self.pitch_deg),
            ("camera.yaw_deg", self.yaw_deg),
        ] {
            if !v.is_finite() {
                return Err(Error::config(f, v, "must be finite"));
            }
        }
        if self.mount_height_m.is_nan() || self.mount_height_m <= 0.05 {
            return Err(Error::config(
                "camera.mount_height_m",
                self.mount_height_m,
                "must be above the ground (> 0.05)",
            ));
        }
        if self.pitch_deg.abs() >= 89.0 {
            return Err(Error::config("camera.pitch_deg", self.pitch_deg, "must be within ±89"));
        }
        if !(self.draw_distance_m > 1.0 && self.draw_distance_m.is_finite()) {
            return Err(Error::config(
                "camera.draw_distance_m",
                self.draw_distance_m,
                "must be finite and > 1",
            ));
        }
        Ok(())
    }
}

/// One actor as a camera sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProjectedActor {
    pub id: u32,
    /// Pixel box [x_min, y_min, x_max, y_max] of the actor's silhouette clipped to the image
    /// (max exclusive).
    pub bbox_px: [f32; 4],
    /// Projection of the actor's centre at half its height (may lie outside the image).
    pub center_px: [f32; 2],
    /// 2-D distance from the ego centre to the actor centre, metres.
    pub distance_m: f64,
    /// Unoccluded in-image share of the actor's whole silhouette, 0..=1: pixels hidden by
    /// nearer geometry and those the image border cuts off both count as hidden.
    pub visible_fraction: f32,
    /// Silhouette pixels, those cut off by the image border included (the in-image count
    /// scaled by the projected area's in-image share).
    pub pixel_count: u32,
    /// Pixel box [x_min, y_min, x_max, y_max] of the unoccluded pixels only (max exclusive;
    /// all zero when none is unoccluded): what a viewer can see of the actor, e.g. a roof
    /// sliver above a nearer car is wide but only a few pixels high.
    pub visible_bbox_px: [f32; 4],
    /// The colour name a viewer gives the actor from the visible pixels of its body paint
    /// (vehicle panels, a person's top, a bicycle's frame) in this image
    /// ([`super::palette::name_pixels`]); `None` when no paint is visible.
    pub colour_name: Option<&'static str>,
    /// Per-channel median colour of the unoccluded pixels as rendered (lit, shaded, fogged) in
    /// the rows that show the body colour (vehicles: below the windows, above the wheels;
    /// people: the torso); [0, 0, 0] when none is unoccluded.
    pub visible_rgb: [u8; 3],
}

const NEAR: f32 = 0.1;
const MARKING_MAX_M: f32 = 130.0;
const TRACK_MAX_M: f32 = 60.0;
/// Actors nearer than this get their detailed mesh (rounder wheels).
const DETAIL_M: f64 = 35.0;

fn mat_colors() -> [[u8; 3]; N_MATS] {
    let mut c = [[0u8; 3]; N_MATS];
    c[Mat::Junction as usize] = [92, 92, 96];
    c[Mat::Sidewalk as usize] = [168, 164, 156];
    c[Mat::Road as usize] = [88, 88, 92];
    c[Mat::BikeLane as usize] = [120, 80, 78];
    c[Mat::White as usize] = [238, 238, 232];
    c[Mat::Yellow as usize] = [235, 190, 40];
    c[Mat::Kerb as usize] = [196, 194, 188];
    c[Mat::Track as usize] = [81, 81, 85];
    c
}

/// Camera pose and intrinsics in the map frame (f32): the [`Basis`] the conditions share, plus
/// the raster size and frustum slopes only the camera needs.
pub(crate) struct Cam {
    pub b: Basis,
    pub w: usize,
    pub h: usize,
    /// tan of the half FOVs (frustum side planes), with a small margin.
    pub tx: f32,
    pub ty: f32,
}

impl Cam {
    pub fn new(map: &RenderMap, frame: &FrameInput, cfg: &CameraConfig, scale: usize) -> Cam {
        let ego = &frame.ego.pose;
        let mount = ego.local_to_world(cfg.mount_forward_m, cfg.mount_left_m) - map.origin;
        let yaw = ego.yaw + cfg.yaw_deg.to_radians();
        let pitch = cfg.pitch_deg.to_radians();
        let (sy, cy) = yaw.sin_cos();
        let (sp, cp) = pitch.sin_cos();
        let f = [(cy * cp) as f32, (sy * cp) as f32, (-sp) as f32];
        let r = [sy as f32, -cy as f32, 0.0];
        // down = f × r
        let d = [f[1] * r[2] - f[2] * r[1], f[2] * r[0] - f[0] * r[2], f[0] * r[1] - f[1] * r[0]];
        let w = cfg.width as usize * scale;
        let h = cfg.height as usize * scale;
        let fx = (w as f64 * 0.5 / (cfg.fov_deg.to_radians() * 0.5).tan()) as f32;
        Cam {
            b: Basis {
                pos: [mount.x as f32, mount.y as f32, cfg.mount_height_m as f32],
                r,
                d,
                f,
                fx,
                cx: w as f32 * 0.5,
                cy: h as f32 * 0.5,
                far: cfg.draw_distance_m as f32,
            },
            w,
            h,
            tx: (w as f32 * 0.5 + 2.0) / fx,
            ty: (h as f32 * 0.5 + 2.0) / fx,
        }
    }

    #[inline(always)]
    pub fn to_cam(&self, p: [f32; 3]) -> [f32; 3] {
        let q = [p[0] - self.b.pos[0], p[1] - self.b.pos[1], p[2] - self.b.pos[2]];
        [dot(q, self.b.r), dot(q, self.b.d), dot(q, self.b.f)]
    }

    #[inline(always)]
    fn project(&self, c: [f32; 3]) -> SV {
        let iw = 1.0 / c[2];
        SV { x: self.b.cx + self.b.fx * c[0] * iw, y: self.b.cy + self.b.fx * c[1] * iw, w: iw }
    }

    /// True when all points lie outside one frustum plane.
    #[inline(always)]
    fn outside(&self, c: &[[f32; 3]]) -> bool {
        let all = |f: &dyn Fn(&[f32; 3]) -> bool| c.iter().all(f);
        all(&|p| p[2] < NEAR)
            || all(&|p| p[2] > self.b.far)
            || all(&|p| p[0] > p[2] * self.tx)
            || all(&|p| p[0] < -p[2] * self.tx)
            || all(&|p| p[1] > p[2] * self.ty)
            || all(&|p| p[1] < -p[2] * self.ty)
    }

    /// Clips a camera-space triangle against the near plane and projects it: returns the
    /// number of screen vertices (0, 3 or 4) of the resulting convex polygon.
    #[inline(always)]
    fn clip_project(&self, c: [[f32; 3]; 3], out: &mut [SV; 4]) -> usize {
        if c.iter().all(|p| p[2] >= NEAR) {
            for k in 0..3 {
                out[k] = self.project(c[k]);
            }
            return 3;
        }
        let mut n = 0;
        for i in 0..3 {
            let a = c[i];
            let b = c[(i + 1) % 3];
            let ina = a[2] >= NEAR;
            let inb = b[2] >= NEAR;
            if ina {
                if n < 4 {
                    out[n] = self.project(a);
                }
                n += 1;
            }
            if ina != inb {
                let t = (NEAR - a[2]) / (b[2] - a[2]);
                let p = [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, NEAR];
                if n < 4 {
                    out[n] = self.project(p);
                }
                n += 1;
            }
        }
        n.min(4)
    }

    /// Frustum test of a map-frame box [min x, min y, max x, max y] × [0, zmax].
    fn sees_box(&self, bb: [f32; 4], zmax: f32) -> bool {
        if bb[0] > bb[2] {
            return false;
        }
        let mut c = [[0f32; 3]; 8];
        let mut k = 0;
        for x in [bb[0], bb[2]] {
            for y in [bb[1], bb[3]] {
                for z in [0.0, zmax] {
                    c[k] = self.to_cam([x, y, z]);
                    k += 1;
                }
            }
        }
        !self.outside(&c)
    }
}

impl Eye for Cam {
    fn basis(&self) -> &Basis {
        &self.b
    }
    fn to_cam(&self, p: [f32; 3]) -> [f32; 3] {
        Cam::to_cam(self, p)
    }
    fn outside(&self, c: &[[f32; 3]]) -> bool {
        Cam::outside(self, c)
    }
    fn clip_project(&self, c: [[f32; 3]; 3], out: &mut [SV; 4]) -> usize {
        Cam::clip_project(self, c, out)
    }
}

#[inline(always)]
fn fogged(col: [u8; 3], k: f32, fog: [f32; 3]) -> [u8; 3] {
    if k <= 0.0 {
        return col;
    }
    [
        (col[0] as f32 + (fog[0] - col[0] as f32) * k) as u8,
        (col[1] as f32 + (fog[1] - col[1] as f32) * k) as u8,
        (col[2] as f32 + (fog[2] - col[2] as f32) * k) as u8,
    ]
}

fn lerp3(a: [f32; 3], b: [f32; 3], t: f32) -> [u8; 3] {
    [(a[0] + (b[0] - a[0]) * t) as u8, (a[1] + (b[1] - a[1]) * t) as u8, (a[2] + (b[2] - a[2]) * t) as u8]
}

/// cos of the half-angle within which a signal's lit lamp is visible (visor cone, 55°).
const VISOR_COS: f64 = 0.57;

/// Whether any part of actor `a` can be in the camera's view (its bounding box vs the frustum
/// and the draw distance): actors outside are not meshed at all.
fn may_see(cam: &Cam, map: &RenderMap, a: &ActorView) -> bool {
    let (l, w, h) = mesh::actor_dims(a);
    let r = 0.5 * (l * l + w * w).sqrt() + 0.1;
    let p = a.pose.pos - map.origin;
    let (x, y) = (p.x as f32, p.y as f32);
    let (dx, dy) = (x - cam.b.pos[0], y - cam.b.pos[1]);
    if dx * dx + dy * dy > (cam.b.far + r) * (cam.b.far + r) {
        return false;
    }
    cam.sees_box([x - r, y - r, x + r, y + r], h + 0.3)
}

/// Appends the dynamic scene (actors, signals, signs) the camera may see to `out`; actor
/// triangles carry id = index in `frame.actors` + 1, the ego `u32::MAX` when drawn. `lit`:
/// vehicle lamps burn (night).
pub(crate) fn dynamic_tris(
    cam: &Cam,
    map: &RenderMap,
    frame: &FrameInput,
    draw_ego: bool,
    lit: bool,
    out: &mut Vec<Tri3>,
) {
    if draw_ego {
        super::actors::actor(out, frame.ego, map.origin, u32::MAX, true, lit, frame.ambience.tick);
    }
    for (i, a) in frame.actors.iter().enumerate() {
        if a.id == frame.ego.id && a.pose == frame.ego.pose {
            continue;
        }
        if !may_see(cam, map, a) {
            continue;
        }
        let near = a.pose.pos.dist(frame.ego.pose.pos) < DETAIL_M;
        super::actors::actor(out, a, map.origin, i as u32 + 1, near, lit, frame.ambience.tick);
    }
    for l in frame.lights {
        let place = map.signal_places.get(&l.lane_id);
        let far = place.map_or(15.0, |p| p.far_m);
        let right = place.map_or(l.lane_width_m as f32 * 0.5 + 0.8, |p| p.right_m);
        let fr = Frame::new(l.stop_line.pos, l.stop_line.yaw, map.origin, 0.0).offset(far, 0.0, 0.0);
        // The head faces back along the lane; its lit lamp shows within the visor's cone only.
        let head = l.stop_line.pos + l.stop_line.forward() * f64::from(far);
        let to_viewer = (frame.ego.pose.pos - head).normalized();
        let lit_visible = to_viewer.dot(-l.stop_line.forward()) >= VISOR_COS;
        mesh::signal(out, &fr, 5.2, l.color, Some(right), lit_visible);
    }
    for s in frame.signs {
        let fr = Frame::new(s.pose.pos, s.pose.yaw, map.origin, 0.0);
        mesh::sign(out, &fr, s.kind);
    }
}

impl Renderer {
    /// Renders one camera into `out` (resized to the configured size, allocation reused).
    pub fn render_camera(
        &mut self,
        map: &RenderMap,
        frame: &FrameInput,
        cfg: &CameraConfig,
        out: &mut Image,
    ) -> Result<()> {
        cfg.validate()?;
        frame.validate()?;
        out.resize(cfg.width, cfg.height);
        let s = cfg.supersample as usize;
        let cam = Cam::new(map, frame, cfg, s);
        let mut raster = std::mem::take(&mut self.raster);
        if s == 1 {
            raster.begin(std::mem::take(&mut out.data), cam.w, cam.h, Planes::Depth);
            self.draw_scene(map, frame, cfg, &cam, &mut raster);
            out.data = raster.finish();
        } else {
            raster.begin(std::mem::take(&mut self.ss), cam.w, cam.h, Planes::Depth);
            self.draw_scene(map, frame, cfg, &cam, &mut raster);
            let ss = raster.finish();
            downsample(&ss, cam.w, s, &mut out.data, cfg.width as usize, cfg.height as usize);
            self.ss = ss;
        }
        self.raster = raster;
        self.lens_effects(frame, cfg, out);
        Ok(())
    }

    /// What the weather leaves on the lens of a camera mounted on the ego (rain drops).
    fn lens_effects(&mut self, frame: &FrameInput, cfg: &CameraConfig, out: &mut Image) {
        if !cfg.draw_ego && Look::of(frame.ambience.conditions).drops {
            conditions::rain_on_lens(out, &frame.ambience, &mut self.lens);
        }
    }

    /// Issues one camera's view to `b`: backdrop, ground layers and markings in painter's
    /// order, then props and the dynamic scene depth-tested.
    pub(crate) fn draw_scene<B: RasterBackend>(
        &mut self,
        map: &RenderMap,
        frame: &FrameInput,
        cfg: &CameraConfig,
        cam: &Cam,
        b: &mut B,
    ) {
        let look = Look::of(frame.ambience.conditions);
        background(cam, &look, b);

        // Cells in the draw-distance square, frustum-tested.
        self.cells.clear();
        let r = cam.b.far;
        map.for_cells([cam.b.pos[0] - r, cam.b.pos[1] - r], [cam.b.pos[0] + r, cam.b.pos[1] + r], |i, c| {
            if cam.sees_box(c.bb, c.zmax) {
                self.cells.push(i);
            }
        });
        let mut cols = mat_colors();
        if !look.is_noon_clear() {
            for (i, c) in cols.iter_mut().enumerate() {
                *c = look.lit(*c);
                if i == Mat::Road as usize || i == Mat::Junction as usize || i == Mat::Track as usize {
                    *c = c.map(|v| (v as f32 * look.road) as u8);
                }
            }
        }
        let mut poly = [SV { x: 0.0, y: 0.0, w: 0.0 }; 4];
        for layer in 0..N_LAYERS {
            for &off in &self.cells {
                let c = &map.cells[off];
                let (i0, i1) = c.tris[layer];
                for gt in &map.tris[i0 as usize..i1 as usize] {
                    let p = gt.p.map(|q| cam.to_cam([q[0], q[1], 0.0]));
                    if cam.outside(&p) {
                        continue;
                    }
                    let cxy = [
                        (gt.p[0][0] + gt.p[1][0] + gt.p[2][0]) / 3.0,
                        (gt.p[0][1] + gt.p[1][1] + gt.p[2][1]) / 3.0,
                    ];
                    let d = ((cxy[0] - cam.b.pos[0]).powi(2) + (cxy[1] - cam.b.pos[1]).powi(2)).sqrt();
                    let col = fogged(cols[gt.mat as usize], look.fog_k(d), look.fog);
                    let n = cam.clip_project(p, &mut poly);
                    b.fill_convex(&poly[..n], col);
                }
            }
        }
        // Markings: quads around their centre line, at least ~1.3 px wide.
        let min_px = 1.3 / cam.b.fx;
        for &off in &self.cells {
            let c = &map.cells[off];
            for sg in &map.segs[c.segs.0 as usize..c.segs.1 as usize] {
                let (dx, dy) = (sg.b[0] - sg.a[0], sg.b[1] - sg.a[1]);
                let len = (dx * dx + dy * dy).sqrt();
                if len <= 0.0 {
                    continue;
                }
                let mid =
                    [(sg.a[0] + sg.b[0]) * 0.5 - cam.b.pos[0], (sg.a[1] + sg.b[1]) * 0.5 - cam.b.pos[1]];
                let d = (mid[0] * mid[0] + mid[1] * mid[1]).sqrt();
                // Far markings shrink below a pixel and turn into speckle: widen them up to
                // 60 m, drop them past MARKING_MAX_M.
                if d > MARKING_MAX_M || (sg.mat == Mat::Track && d > TRACK_MAX_M) {
                    continue;
                }
                // Wheel tracks are texture, not paint: never widened, so they fade out with
                // distance instead of turning into lines.
                let min_px = if sg.mat == Mat::Track { 0.0 } else { min_px };
                // Width from each end's own distance, so joined pieces share their end edges.
                let hw_at = |p: [f32; 2]| {
                    let dd = ((p[0] - cam.b.pos[0]).powi(2) + (p[1] - cam.b.pos[1]).powi(2)).sqrt();
                    sg.hw.max(dd.min(60.0) * min_px * 0.5)
                };
                let (ha, hb) = (hw_at(sg.a), hw_at(sg.b));
                let (na, nb) = ([sg.na[0] * ha, sg.na[1] * ha], [sg.nb[0] * hb, sg.nb[1] * hb]);
                let q = [
                    cam.to_cam([sg.a[0] - na[0], sg.a[1] - na[1], 0.0]),
                    cam.to_cam([sg.b[0] - nb[0], sg.b[1] - nb[1], 0.0]),
                    cam.to_cam([sg.b[0] + nb[0], sg.b[1] + nb[1], 0.0]),
                    cam.to_cam([sg.a[0] + na[0], sg.a[1] + na[1], 0.0]),
                ];
                if cam.outside(&q) {
                    continue;
                }
                let col = fogged(cols[sg.mat as usize], look.fog_k(d), look.fog);
                // In front of the near plane: one quad with anti-aliased long sides (edges 0
                // and 2); the ends stay hard so consecutive pieces join without a seam.
                if q.iter().all(|p| p[2] >= NEAR) {
                    let quad = q.map(|p| cam.project(p));
                    b.fill_convex_aa(&quad, col, 0b0101);
                    continue;
                }
                for tri in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                    let n = cam.clip_project(tri, &mut poly);
                    b.fill_convex(&poly[..n], col);
                }
            }
        }

        if look.night {
            conditions::light_pools(cam, map, frame.ego, frame.actors, b, &mut poly);
        }

        // Shadows of the actors on the ground, under everything standing on it.
        if let Some((k, len)) = look.shadow {
            for a in frame.actors {
                if a.id == frame.ego.id && a.pose == frame.ego.pose {
                    continue;
                }
                if may_see(cam, map, a) {
                    shadow(cam, map, a, b, &mut poly, (look.sun, k, len));
                }
            }
            if cfg.draw_ego {
                shadow(cam, map, frame.ego, b, &mut poly, (look.sun, k, len));
            }
        }

        // 3-D: props, then the dynamic scene.
        let mut dynamic = std::mem::take(&mut self.tris);
        dynamic.clear();
        dynamic_tris(cam, map, frame, cfg.draw_ego, look.night, &mut dynamic);
        if look.night {
            conditions::street_lamp_tris(cam.basis(), map, &mut dynamic);
        }
        for &off in &self.cells {
            let c = &map.cells[off];
            for tr in &map.props[c.props.0 as usize..c.props.1 as usize] {
                draw_tri3(cam, b, tr, &mut poly, &look);
            }
        }
        for tr in &dynamic {
            draw_tri3(cam, b, tr, &mut poly, &look);
        }
        self.tris = dynamic;
        if look.wet || look.haze_m.is_some() {
            b.post(&mut |rgb, depth, w, h| conditions::post(&look, &cam.b, rgb, depth, w, h));
        }
    }

    /// Every actor of `frame.actors` the camera sees: silhouette box, centre, distance and the
    /// unoccluded share of its silhouette (from an id buffer of the full scene).
    pub fn project_actors(
        &mut self,
        map: &RenderMap,
        frame: &FrameInput,
        cfg: &CameraConfig,
    ) -> Result<Vec<ProjectedActor>> {
        cfg.validate()?;
        frame.validate()?;
        let cam = Cam::new(map, frame, cfg, 1);
        let mut raster = std::mem::take(&mut self.raster);
        raster.begin(std::mem::take(&mut self.ss), cam.w, cam.h, Planes::DepthIds);
        self.draw_scene(map, frame, cfg, &cam, &mut raster);
        self.ss = raster.finish();
        let ids = raster.ids();
        let (w, h) = (cam.w, cam.h);
        let mut mask = std::mem::take(&mut self.mask);
        mask.clear();
        mask.resize(w * h, 0);
        let mut tris = std::mem::take(&mut self.tris);
        let mut poly = [SV { x: 0.0, y: 0.0, w: 0.0 }; 4];
        let mut res = Vec::new();
        for (i, a) in frame.actors.iter().enumerate() {
            if a.id == frame.ego.id && a.pose == frame.ego.pose {
                continue;
            }
            let stamp = i as u32 + 1;
            if !may_see(&cam, map, a) {
                continue;
            }
            tris.clear();
            super::actors::actor(
                &mut tris,
                a,
                map.origin,
                stamp,
                a.pose.pos.dist(frame.ego.pose.pos) < DETAIL_M,
                frame.ambience.conditions.time_of_day == crate::conditions::TimeOfDay::Night,
                frame.ambience.tick,
            );
            let mut total = 0usize;
            // Projected area of the whole silhouette and of its part inside the image (faces
            // overlap in both sums alike): the share the image border cuts off counts as hidden.
            let (mut area_all, mut area_in) = (0.0f64, 0.0f64);
            for tr in &tris {
                let c = tr.p.map(|p| cam.to_cam(p));
                if c.iter().all(|p| p[2] < NEAR) {
                    continue;
                }
                let n = cam.clip_project(c, &mut poly);
                for k in 1..n.saturating_sub(1) {
                    let t = [poly[0], poly[k], poly[k + 1]];
                    area_all += tri_area(&t);
                    area_in += area_inside(&t, w as f32, h as f32);
                    total += fill_mask(&mut mask, w, h, t[0], t[1], t[2], stamp);
                }
            }
            if total == 0 {
                continue;
            }
            let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
            let mut visible = 0usize;
            let (mut vx0, mut vy0, mut vx1, mut vy1) = (usize::MAX, usize::MAX, 0, 0);
            let mut px = std::mem::take(&mut self.px);
            px.clear();
            for y in 0..h {
                let row = &mask[y * w..(y + 1) * w];
                if !row.contains(&stamp) {
                    continue;
                }
                for (x, m) in row.iter().enumerate() {
                    if *m == stamp {
                        x0 = x0.min(x);
                        x1 = x1.max(x + 1);
                        y0 = y0.min(y);
                        y1 = y1.max(y + 1);
                        let id = ids[y * w + x];
                        if id & !PAINT_BIT == stamp {
                            visible += 1;
                            vx0 = vx0.min(x);
                            vx1 = vx1.max(x + 1);
                            vy0 = vy0.min(y);
                            vy1 = vy1.max(y + 1);
                            if id & PAINT_BIT != 0 {
                                let o = (y * w + x) * 3;
                                px.push([self.ss[o], self.ss[o + 1], self.ss[o + 2]]);
                            }
                        }
                    }
                }
            }
            // The colour the image shows: per-channel median of the unoccluded pixels in the
            // band of the silhouette's rows where the body colour is (below a vehicle's windows
            // and above its wheels; a person's torso), all of them when the band shows few.
            let (b0, b1) = match a.kind {
                ActorKind::Pedestrian | ActorKind::Cyclist => (0.2, 0.5),
                ActorKind::Car | ActorKind::Bus | ActorKind::Truck | ActorKind::Motorcycle => (0.5, 0.85),
                _ => (0.0, 1.0),
            };
            let mut visible_rgb = [0u8; 3];
            for band in [(b0, b1), (0.0, 1.0)] {
                let (r0, r1) =
                    (y0 + ((y1 - y0) as f32 * band.0) as usize, y0 + ((y1 - y0) as f32 * band.1) as usize);
                let mut hist = [[0u32; 256]; 3];
                let mut n = 0usize;
                for y in r0..r1.max(r0 + 1).min(h) {
                    for x in x0..x1 {
                        if mask[y * w + x] == stamp && ids[y * w + x] & !PAINT_BIT == stamp {
                            n += 1;
                            for (k, hk) in hist.iter_mut().enumerate() {
                                hk[self.ss[(y * w + x) * 3 + k] as usize] += 1;
                            }
                        }
                    }
                }
                if n >= 10 || (band == (0.0, 1.0) && n > 0) {
                    visible_rgb = hist.map(|hk| median(&hk, n));
                    break;
                }
            }
            let (_, _, hgt) = mesh::actor_dims(a);
            let centre = a.pose.pos - map.origin;
            let cc = cam.to_cam([centre.x as f32, centre.y as f32, hgt * 0.5]);
            let cp = if cc[2] > 1e-3 { cam.project(cc) } else { SV { x: f32::NAN, y: f32::NAN, w: 0.0 } };
            let inside = if area_all > 0.0 { (area_in / area_all).clamp(1e-6, 1.0) } else { 1.0 };
            let whole = ((total as f64 / inside).round() as usize).max(total);
            res.push(ProjectedActor {
                id: a.id,
                bbox_px: [x0 as f32, y0 as f32, x1 as f32, y1 as f32],
                center_px: [cp.x, cp.y],
                distance_m: a.pose.pos.dist(frame.ego.pose.pos),
                visible_fraction: visible as f32 / whole as f32,
                pixel_count: whole as u32,
                visible_bbox_px: if visible > 0 {
                    [vx0 as f32, vy0 as f32, vx1 as f32, vy1 as f32]
                } else {
                    [0.0; 4]
                },
                colour_name: super::palette::name_pixels(&px),
                visible_rgb,
            });
            self.px = px;
        }
        self.tris = tris;
        self.mask = mask;
        self.raster = raster;
        Ok(res)
    }
}

impl Renderer {
    /// [`Renderer::project_actors`] plus the camera image from the same raster pass (the id
    /// pass draws colour too), so a caller needing both renders the scene once. With
    /// supersampling the image is rendered separately (the id pass runs at 1×).
    pub fn render_and_project(
        &mut self,
        map: &RenderMap,
        frame: &FrameInput,
        cfg: &CameraConfig,
        out: &mut Image,
    ) -> Result<Vec<ProjectedActor>> {
        let found = self.project_actors(map, frame, cfg)?;
        if cfg.supersample == 1 {
            out.resize(cfg.width, cfg.height);
            let n = out.data.len();
            out.data.copy_from_slice(&self.ss[..n]);
            self.lens_effects(frame, cfg, out);
        } else {
            self.render_camera(map, frame, cfg, out)?;
        }
        Ok(found)
    }
}

/// Ground shadow of an actor: the convex hull of its footprint and the footprint moved away
/// from the sun by its height × `len` (a cheap projected shadow), darkened to k / 256 (noon:
/// 62 %). `light` = (towards the sun, k, len). Deterministic and allocation-free.
fn shadow<B: RasterBackend>(
    cam: &Cam,
    map: &RenderMap,
    a: &ActorView,
    b: &mut B,
    poly: &mut [SV; 4],
    light: ([f32; 3], u16, f32),
) {
    let (sun, dark, len) = light;
    let (l, w, h) = mesh::actor_dims(a);
    let (hl, hw) = (l * 0.5 + 0.05, w * 0.5 + 0.05);
    // People and bicycles are narrower than their footprint box: a slimmer blob.
    let (hl, hw) = match a.kind {
        crate::view::ActorKind::Pedestrian => (0.22 * h / 1.75, 0.22 * h / 1.75),
        _ => (hl, hw),
    };
    let p = a.pose.pos - map.origin;
    let (s, c) = a.pose.yaw.sin_cos();
    let (f, lft) = ([c as f32, s as f32], [-s as f32, c as f32]);
    let k = len * h / sun[2];
    let off = [-sun[0] * k, -sun[1] * k];
    let mut pts = [[0f32; 2]; 8];
    for (j, (u, v)) in [(hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw)].into_iter().enumerate() {
        let q = [p.x as f32 + f[0] * u + lft[0] * v, p.y as f32 + f[1] * u + lft[1] * v];
        pts[j] = q;
        pts[j + 4] = [q[0] + off[0], q[1] + off[1]];
    }
    // Convex hull (monotone chain) of the 8 points.
    pts.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross =
        |o: [f32; 2], a: [f32; 2], b: [f32; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull = [[0f32; 2]; 16];
    let mut n = 0;
    for pass in 0..2 {
        let start = n;
        for k in 0..8 {
            let q = if pass == 0 { pts[k] } else { pts[7 - k] };
            while n >= start + 2 && cross(hull[n - 2], hull[n - 1], q) <= 0.0 {
                n -= 1;
            }
            hull[n] = q;
            n += 1;
        }
        n -= 1;
    }
    if n < 3 {
        return;
    }
    let g = |q: [f32; 2]| cam.to_cam([q[0], q[1], 0.0]);
    let c0 = g(hull[0]);
    for k in 1..n - 1 {
        let t = [c0, g(hull[k]), g(hull[k + 1])];
        if cam.outside(&t) {
            continue;
        }
        let m = cam.clip_project(t, poly);
        b.darken_convex(&poly[..m], dark);
    }
}

/// Median of `n` values given as a 256-bin histogram.
fn median(hist: &[u32; 256], n: usize) -> u8 {
    let mut acc = 0usize;
    for (v, c) in hist.iter().enumerate() {
        acc += *c as usize;
        if n > 0 && 2 * acc >= n {
            return v as u8;
        }
    }
    0
}

/// Area of a screen triangle, pixels².
fn tri_area(t: &[SV; 3]) -> f64 {
    let (a, b, c) = (t[0], t[1], t[2]);
    (f64::from((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y)) * 0.5).abs()
}

/// Area of a screen triangle's part inside the `w × h` image (Sutherland–Hodgman clip).
fn area_inside(t: &[SV; 3], w: f32, h: f32) -> f64 {
    let mut pts: Vec<[f32; 2]> = t.iter().map(|p| [p.x, p.y]).collect();
    // (axis, bound, keep below the bound?)
    for (ax, bound, below) in [(0, 0.0, false), (0, w, true), (1, 0.0, false), (1, h, true)] {
        let inside = |p: &[f32; 2]| if below { p[ax] <= bound } else { p[ax] >= bound };
        let mut out = Vec::with_capacity(pts.len() + 2);
        for i in 0..pts.len() {
            let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
            if inside(&a) {
                out.push(a);
            }
            if inside(&a) != inside(&b) {
                let s = (bound - a[ax]) / (b[ax] - a[ax]);
                out.push([a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s]);
            }
        }
        pts = out;
        if pts.len() < 3 {
            return 0.0;
        }
    }
    let mut twice = 0.0f64;
    for i in 0..pts.len() {
        let (a, b) = (pts[i], pts[(i + 1) % pts.len()]);
        twice += f64::from(a[0] * b[1] - b[0] * a[1]);
    }
    (twice * 0.5).abs()
}

#[inline(always)]
fn draw_tri3<B: RasterBackend>(cam: &Cam, b: &mut B, tr: &Tri3, poly: &mut [SV; 4], look: &Look) {
    let p0 = tr.p[0];
    if !tr.two_sided {
        let v = [p0[0] - cam.b.pos[0], p0[1] - cam.b.pos[1], p0[2] - cam.b.pos[2]];
        if dot(v, tr.n) >= 0.0 {
            return;
        }
    }
    let c = tr.p.map(|p| cam.to_cam(p));
    if cam.outside(&c) {
        return;
    }
    let col = if tr.emissive {
        tr.col
    } else {
        let d = ((p0[0] - cam.b.pos[0]).powi(2) + (p0[1] - cam.b.pos[1]).powi(2)).sqrt();
        fogged(look.lit(tr.col), look.fog_k(d), look.fog)
    };
    let n = cam.clip_project(c, poly);
    b.fill_convex_depth(&poly[..n], col, tr.id);
}

/// Sky gradient above the horizon, fogged grass below; constant along each row because the
/// camera has no roll.
fn background<B: RasterBackend>(cam: &Cam, look: &Look, b: &mut B) {
    let (sky_top, horizon, grass) = (look.sky_top, look.horizon, look.grass.map(|v| v as u8));
    let (fog0, fog1, fog_on) = (look.fog0, look.fog1, look.fog_max > 0.0);
    b.fill_rows(&|y| {
        let yc = (y as f32 + 0.5 - cam.b.cy) / cam.b.fx;
        let dir = [cam.b.d[0] * yc + cam.b.f[0], cam.b.d[1] * yc + cam.b.f[1], cam.b.d[2] * yc + cam.b.f[2]];
        let horiz = (dir[0] * dir[0] + dir[1] * dir[1]).sqrt();
        if dir[2] >= 0.0 {
            let elev = dir[2] / horiz.max(1e-6);
            lerp3(horizon, sky_top, (elev * 2.5).min(1.0))
        } else if fog_on {
            let dist = cam.b.pos[2] / -dir[2] * horiz;
            fogged(grass, ((dist - fog0) / (fog1 * 1.6 - fog0)).clamp(0.0, 1.0), horizon)
        } else {
            grass
        }
    });
}

/// Box-filters an s×-supersampled RGB buffer down to `w × h`.
fn downsample(src: &[u8], sw: usize, s: usize, dst: &mut [u8], w: usize, h: usize) {
    let n = (s * s) as u32;
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0u32; 3];
            for dy in 0..s {
                let base = ((y * s + dy) * sw + x * s) * 3;
                for dx in 0..s {
                    for k in 0..3 {
                        acc[k] += src[base + dx * 3 + k] as u32;
                    }
                }
            }
            let o = (y * w + x) * 3;
            for k in 0..3 {
                dst[o + k] = ((acc[k] + n / 2) / n) as u8;
            }
        }
    }
}
