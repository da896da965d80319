//! Bird's-eye view (docs/protocol.md#r4-loop): top-down, ego at the centre, ego forward = up, with the
//! local route overlay drawn exactly as the original draws it (pixel sizes and colours): a
//! (255, 90, 90) 3 px polyline from the ego centre through every vertex of the local route
//! slice, a white dot with a 2 px (255, 90, 90) outline on every visible vertex (radius 4 px,
//! the last 5 px), and the ego as a (255, 230, 80) disc of radius 6 px with a 2 px
//! (20, 20, 20) outline. The scale stays 8 px/m: the original derived its overlay scale from
//! the BEV camera's world height and so drew the route at about 6.3 px/m on tongji, a bug we
//! do not copy. Same precomputed geometry as the cameras, drawn as 2-D shapes through a
//! [`RasterBackend`] (by default the scanline rasterizer: no anti-aliasing, deterministic and
//! fast).

use super::frame::{FrameInput, Renderer};
use super::image::Image;
use super::map::{Mat, RenderMap, N_LAYERS, N_MATS};
use super::mesh::actor_dims;
use super::raster::{Planes, RasterBackend, SV};
use super::vehicles::{BEACON_BLUE, BEACON_BLUE_DIM, BEACON_RED, BEACON_RED_DIM};
use crate::error::{Error, Result};
use crate::geom::Vec2;
use crate::view::{ActorKind, LightColor};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BevConfig {
    /// Square image side, pixels.
    pub size_px: u32,
    /// Scale, pixels per metre (protocol: 50 m up, FOV 90°, 800 px → 8 px/m).
    pub px_per_m: f64,
}

impl Default for BevConfig {
    fn default() -> Self {
        BevConfig { size_px: 800, px_per_m: 8.0 }
    }
}

impl BevConfig {
    /// Small view for RL: 128×128 px at 2 px/m (64 m across).
    pub fn rl() -> Self {
        BevConfig { size_px: 128, px_per_m: 2.0 }
    }

    pub fn validate(&self) -> Result<()> {
        if self.size_px == 0 || self.size_px > 8192 {
            return Err(Error::config("bev.size_px", self.size_px, "must be 1..=8192"));
        }
        if !(self.px_per_m.is_finite() && self.px_per_m > 0.01 && self.px_per_m <= 1000.0) {
            return Err(Error::config("bev.px_per_m", self.px_per_m, "must be in (0.01, 1000]"));
        }
        Ok(())
    }
}

const BACKGROUND: [u8; 3] = [46, 54, 44];
/// The original's overlay, in pixels.
pub(crate) const ROUTE_RED: [u8; 3] = [255, 90, 90];
pub(crate) const ROUTE_LINE_PX: f32 = 3.0;
pub(crate) const ROUTE_DOT_PX: f32 = 4.0;
pub(crate) const ROUTE_LAST_DOT_PX: f32 = 5.0;
pub(crate) const DOT_OUTLINE_PX: f32 = 2.0;
pub(crate) const EGO_YELLOW: [u8; 3] = [255, 230, 80];
pub(crate) const EGO_OUTLINE: [u8; 3] = [20, 20, 20];
pub(crate) const EGO_DISC_PX: f32 = 6.0;

fn mat_colors() -> [[u8; 3]; N_MATS] {
    let mut c = [[0u8; 3]; N_MATS];
    c[Mat::Junction as usize] = [100, 100, 106];
    c[Mat::Sidewalk as usize] = [150, 148, 140];
    c[Mat::Road as usize] = [100, 100, 106];
    c[Mat::BikeLane as usize] = [125, 88, 84];
    c[Mat::White as usize] = [240, 240, 240];
    c[Mat::Yellow as usize] = [235, 190, 40];
    c[Mat::Kerb as usize] = [150, 148, 140];
    c[Mat::Track as usize] = [100, 100, 106];
    c
}

/// Map-frame → pixel transform.
struct View {
    ego: [f32; 2],
    f: [f32; 2],
    r: [f32; 2],
    s: f32,
    c: f32,
}

impl View {
    #[inline(always)]
    fn px(&self, q: [f32; 2]) -> SV {
        let d = [q[0] - self.ego[0], q[1] - self.ego[1]];
        SV {
            x: self.c + (d[0] * self.r[0] + d[1] * self.r[1]) * self.s,
            y: self.c - (d[0] * self.f[0] + d[1] * self.f[1]) * self.s,
            w: 1.0,
        }
    }
}

impl Renderer {
    /// Renders the bird's-eye view into `out` (resized to `size_px`², allocation reused).
    pub fn render_bev(
        &mut self,
        map: &RenderMap,
        frame: &FrameInput,
        cfg: &BevConfig,
        out: &mut Image,
    ) -> Result<()> {
        cfg.validate()?;
        frame.validate()?;
        out.resize(cfg.size_px, cfg.size_px);
        let n = cfg.size_px as usize;
        let mut raster = std::mem::take(&mut self.raster);
        raster.begin(std::mem::take(&mut out.data), n, n, Planes::Colour);
        self.draw_bev(map, frame, cfg, &mut raster);
        out.data = raster.finish();
        self.raster = raster;
        Ok(())
    }

    /// Issues the bird's-eye view of a validated frame and config to `b`, back to front.
    pub(crate) fn draw_bev<B: RasterBackend>(
        &mut self,
        map: &RenderMap,
        frame: &FrameInput,
        cfg: &BevConfig,
        b: &mut B,
    ) {
        let n = cfg.size_px as usize;
        b.fill_rows(&|_| BACKGROUND);
        let ego = frame.ego.pose.pos - map.origin;
        let (sy, cy) = frame.ego.pose.yaw.sin_cos();
        let v = View {
            ego: [ego.x as f32, ego.y as f32],
            f: [cy as f32, sy as f32],
            r: [sy as f32, -cy as f32],
            s: cfg.px_per_m as f32,
            c: n as f32 * 0.5,
        };
        let half = n as f32 * 0.5 / v.s * std::f32::consts::SQRT_2 + 2.0;

        self.cells.clear();
        map.for_cells([v.ego[0] - half, v.ego[1] - half], [v.ego[0] + half, v.ego[1] + half], |i, c| {
            // Cell box vs the view's circumscribed circle.
            let cx = v.ego[0].clamp(c.bb[0], c.bb[2]);
            let cy = v.ego[1].clamp(c.bb[1], c.bb[3]);
            if (cx - v.ego[0]).powi(2) + (cy - v.ego[1]).powi(2) <= half * half {
                self.cells.push(i);
            }
        });
        let cols = mat_colors();
        let nf = n as f32;
        let off = |p: &[SV]| {
            p.iter().all(|q| q.x < 0.0)
                || p.iter().all(|q| q.y < 0.0)
                || p.iter().all(|q| q.x > nf)
                || p.iter().all(|q| q.y > nf)
        };
        for layer in 0..N_LAYERS {
            for &ci in &self.cells {
                let (i0, i1) = map.cells[ci].tris[layer];
                for gt in &map.tris[i0 as usize..i1 as usize] {
                    let p = gt.p.map(|q| v.px(q));
                    if off(&p) {
                        continue;
                    }
                    b.fill_convex(&p, cols[gt.mat as usize]);
                }
            }
        }
        for &ci in &self.cells {
            let c = &map.cells[ci];
            for sg in &map.segs[c.segs.0 as usize..c.segs.1 as usize] {
                // Surface detail for the cameras; the BEV stays a clean plan.
                if matches!(sg.mat, Mat::Kerb | Mat::Track) {
                    continue;
                }
                let (p, q) = (v.px(sg.a), v.px(sg.b));
                if off(&[p, q]) {
                    continue;
                }
                // Mitred quad (see `Seg`), at least one pixel wide.
                let hw = sg.hw.max(0.5 / v.s);
                let at =
                    |c: [f32; 2], n: [f32; 2], k: f32| v.px([c[0] + n[0] * hw * k, c[1] + n[1] * hw * k]);
                b.fill_convex(
                    &[
                        at(sg.a, sg.na, -1.0),
                        at(sg.b, sg.nb, -1.0),
                        at(sg.b, sg.nb, 1.0),
                        at(sg.a, sg.na, 1.0),
                    ],
                    cols[sg.mat as usize],
                );
            }
        }
        // Signal state bars across the controlled lane at its stop line.
        for l in frame.lights {
            let col = match l.color {
                LightColor::Red => [235, 30, 30],
                LightColor::Yellow => [250, 200, 0],
                LightColor::Green => [40, 220, 70],
                LightColor::Off => [130, 130, 130],
            };
            let p = l.stop_line.pos - map.origin;
            let f = Vec2::from_angle(l.stop_line.yaw);
            let across = f.perp() * (l.lane_width_m * 0.5);
            let (l0, l1) = (p - across, p + across);
            b.stroke_segment(
                v.px([l0.x as f32, l0.y as f32]),
                v.px([l1.x as f32, l1.y as f32]),
                (0.5 * v.s).max(1.0),
                col,
            );
        }
        for s in frame.signs {
            let p = s.pose.pos - map.origin;
            b.fill_disc(v.px([p.x as f32, p.y as f32]), (0.5 * v.s).max(1.5), [220, 30, 30]);
        }
        // Actors: dark outline, body colour, a light bar marking the front.
        for a in frame.actors {
            if a.id == frame.ego.id && a.pose == frame.ego.pose {
                continue;
            }
            let (l, w, _) = actor_dims(a);
            let (l, w) = if a.kind == ActorKind::Pedestrian { (l.max(0.7), w.max(0.7)) } else { (l, w) };
            let p = a.pose.pos - map.origin;
            let (s, c) = a.pose.yaw.sin_cos();
            let (fx, fy, lx, ly) = (c as f32, s as f32, -s as f32, c as f32);
            let (px, py) = (p.x as f32, p.y as f32);
            let corner = |fw: f32, lf: f32| v.px([px + fx * fw + lx * lf, py + fy * fw + ly * lf]);
            let o = 1.0 / v.s; // one pixel of outline
            let (hl, hw) = (l * 0.5, w * 0.5);
            b.fill_convex(
                &[
                    corner(hl + o, hw + o),
                    corner(-hl - o, hw + o),
                    corner(-hl - o, -hw - o),
                    corner(hl + o, -hw - o),
                ],
                [15, 15, 15],
            );
            b.fill_convex(&[corner(hl, hw), corner(-hl, hw), corner(-hl, -hw), corner(hl, -hw)], a.color);
            if !a.kind.is_static() {
                let fl = (l * 0.22).max(2.0 / v.s).min(l * 0.5);
                b.fill_convex(
                    &[
                        corner(hl, hw * 0.8),
                        corner(hl - fl, hw * 0.8),
                        corner(hl - fl, -hw * 0.8),
                        corner(hl, -hw * 0.8),
                    ],
                    [245, 245, 245],
                );
            }
            if a.beacon {
                // The light bar: a red (left) and a blue (right) half across the middle, the
                // bright one swapping with the camera's (`vehicles::beacon_red_lit`).
                let red_lit = super::vehicles::beacon_red_lit(frame.ambience.tick);
                let (red, blue) =
                    if red_lit { (BEACON_RED, BEACON_BLUE_DIM) } else { (BEACON_RED_DIM, BEACON_BLUE) };
                let (d, q) = ((0.3f32).max(1.5 / v.s).min(hl), hw * 0.85);
                b.fill_convex(&[corner(d, q), corner(-d, q), corner(-d, 0.0), corner(d, 0.0)], red);
                b.fill_convex(&[corner(d, 0.0), corner(-d, 0.0), corner(-d, -q), corner(d, -q)], blue);
            }
        }
        // Route overlay: polyline from the ego centre through the slice vertices, a dot on every
        // visible vertex (outline colour first, white inside), then the ego disc.
        let mut pts = std::mem::take(&mut self.pts);
        pts.clear();
        let centre = v.px(v.ego);
        pts.push(centre);
        pts.extend(frame.route_points.iter().map(|q| {
            let r = *q - map.origin;
            v.px([r.x as f32, r.y as f32])
        }));
        if pts.len() > 1 {
            b.stroke_polyline(&pts, ROUTE_LINE_PX * 0.5, ROUTE_RED);
        }
        let last = pts.len().saturating_sub(1);
        for (i, p) in pts.iter().enumerate().skip(1) {
            if p.x < 0.0 || p.y < 0.0 || p.x >= nf || p.y >= nf {
                continue;
            }
            let r = if i == last { ROUTE_LAST_DOT_PX } else { ROUTE_DOT_PX };
            b.fill_disc(*p, r, ROUTE_RED);
            b.fill_disc(*p, r - DOT_OUTLINE_PX, [255, 255, 255]);
        }
        b.fill_disc(centre, EGO_DISC_PX, EGO_OUTLINE);
        b.fill_disc(centre, EGO_DISC_PX - DOT_OUTLINE_PX, EGO_YELLOW);
        self.pts = pts;
    }
}
