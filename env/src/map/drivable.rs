//! Drivable-area index: which passenger lanes contain a point.
//!
//! A lane's area is the set of points within `width / 2` of its shape: segments are capsules
//! (round joins at interior vertices) except at the lane's first and last vertex, which are
//! cut square so the area ends at the stop line instead of bulging half a lane beyond it.
//! Junction outlines that carry passenger internal lanes are drivable too (they cover the
//! corners between internal lanes). Everything lives in a uniform grid (CSR cell lists).

use super::model::*;
use crate::geom::{closest_on_segment, point_in_polygon, Aabb, Projection, Vec2};
use smallvec::SmallVec;

#[derive(Debug, Clone, Copy)]
struct Seg {
    a: Vec2,
    b: Vec2,
    half_width: f64,
    lane: u32,
    /// Index of the segment within the lane shape.
    seg: u32,
    /// Bit 0: square cap at `a` (first segment); bit 1: square cap at `b` (last segment).
    caps: u8,
}

impl Seg {
    /// Whether `p` lies in this piece of lane area.
    #[inline]
    fn contains(&self, p: Vec2) -> bool {
        let ab = self.b - self.a;
        let len2 = ab.norm_sq();
        let raw = if len2 > 0.0 { (p - self.a).dot(ab) / len2 } else { 0.0 };
        if (raw < 0.0 && self.caps & 1 != 0) || (raw > 1.0 && self.caps & 2 != 0) {
            return false;
        }
        let t = raw.clamp(0.0, 1.0);
        p.dist_sq(self.a + ab * t) <= self.half_width * self.half_width
    }
}

#[derive(Debug, Clone)]
struct Poly {
    junction: JunctionIdx,
    aabb: Aabb,
    pts: Vec<Vec2>,
}

/// Uniform grid over the network bounds, holding lane segments and junction polygons.
#[derive(Debug, Clone, Default)]
pub struct DrivableIndex {
    origin: Vec2,
    cell: f64,
    nx: usize,
    ny: usize,
    segs: Vec<Seg>,
    seg_off: Vec<u32>,
    seg_list: Vec<u32>,
    polys: Vec<Poly>,
    poly_off: Vec<u32>,
    poly_list: Vec<u32>,
    /// Lane shapes' cumulative lengths, to turn a segment hit into an arc length.
    lane_cum: Vec<Vec<f64>>,
}

/// Cells along an axis for a given bound; the grid never exceeds ~2 M cells.
const MAX_CELLS: f64 = 2.0e6;
const MIN_CELL_M: f64 = 8.0;

impl DrivableIndex {
    /// Built from the network's tables (not from `Network`, which owns the index: see
    /// `super::network`), so this module sits below `network`.
    pub(crate) fn build(edges: &[Edge], lanes: &[Lane], junctions: &[Junction]) -> DrivableIndex {
        let mut segs = Vec::new();
        let mut bounds = Aabb::EMPTY;
        let mut lane_cum = vec![Vec::new(); lanes.len()];
        for (li, lane) in lanes.iter().enumerate() {
            let f = edges[lane.edge].function;
            if !lane.is_drivable() || !matches!(f, EdgeFunction::Normal | EdgeFunction::Internal) {
                continue;
            }
            let pts = lane.shape.points();
            if pts.len() < 2 {
                continue;
            }
            lane_cum[li] = lane.shape.cumulative().to_vec();
            let hw = 0.5 * lane.width_m.max(0.0);
            let n = pts.len() - 1;
            for i in 0..n {
                let mut caps = 0u8;
                if i == 0 {
                    caps |= 1;
                }
                if i == n - 1 {
                    caps |= 2;
                }
                segs.push(Seg {
                    a: pts[i],
                    b: pts[i + 1],
                    half_width: hw,
                    lane: li as u32,
                    seg: i as u32,
                    caps,
                });
                bounds.include(pts[i]);
                bounds.include(pts[i + 1]);
            }
        }
        let mut polys = Vec::new();
        for (ji, j) in junctions.iter().enumerate() {
            if j.kind == "internal" || j.shape.len() < 3 {
                continue;
            }
            let has_car_lane = j
                .int_lanes
                .iter()
                .any(|&l| lanes[l].is_drivable() && edges[lanes[l].edge].function == EdgeFunction::Internal);
            if has_car_lane {
                let aabb = Aabb::from_points(&j.shape);
                bounds.include(aabb.min);
                bounds.include(aabb.max);
                polys.push(Poly { junction: ji, aabb, pts: j.shape.clone() });
            }
        }
        if bounds.is_empty() {
            return DrivableIndex { lane_cum, ..Default::default() };
        }
        let max_hw = segs.iter().map(|s| s.half_width).fold(0.0, f64::max);
        let bounds = bounds.inflate(max_hw + 1.0);
        let (w, h) = (bounds.max.x - bounds.min.x, bounds.max.y - bounds.min.y);
        let cell = MIN_CELL_M.max((w * h / MAX_CELLS).sqrt());
        let nx = ((w / cell).ceil() as usize).max(1);
        let ny = ((h / cell).ceil() as usize).max(1);
        let mut idx =
            DrivableIndex { origin: bounds.min, cell, nx, ny, segs, polys, lane_cum, ..Default::default() };
        // Conservative rasterisation: a segment goes into every cell whose centre lies within
        // half_width + half the cell diagonal of it.
        let reach_extra = cell * std::f64::consts::FRAC_1_SQRT_2;
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for (si, s) in idx.segs.iter().enumerate() {
            let bb = Aabb::from_points(&[s.a, s.b]).inflate(s.half_width);
            let (x0, y0, x1, y1) = idx.cell_range(&bb);
            let r = s.half_width + reach_extra;
            for cy in y0..=y1 {
                for cx in x0..=x1 {
                    let c = Vec2::new(
                        idx.origin.x + (cx as f64 + 0.5) * cell,
                        idx.origin.y + (cy as f64 + 0.5) * cell,
                    );
                    if closest_on_segment(c, s.a, s.b).1 <= r * r {
                        pairs.push(((cy * nx + cx) as u32, si as u32));
                    }
                }
            }
        }
        (idx.seg_off, idx.seg_list) = csr(nx * ny, &mut pairs);
        let mut pairs: Vec<(u32, u32)> = Vec::new();
        for (pi, p) in idx.polys.iter().enumerate() {
            let (x0, y0, x1, y1) = idx.cell_range(&p.aabb);
            for cy in y0..=y1 {
                for cx in x0..=x1 {
                    pairs.push(((cy * nx + cx) as u32, pi as u32));
                }
            }
        }
        (idx.poly_off, idx.poly_list) = csr(nx * ny, &mut pairs);
        idx
    }

    /// Cell coordinate range (inclusive) covering a box, clamped to the grid.
    fn cell_range(&self, bb: &Aabb) -> (usize, usize, usize, usize) {
        let cx = |x: f64| (((x - self.origin.x) / self.cell).floor().max(0.0) as usize).min(self.nx - 1);
        let cy = |y: f64| (((y - self.origin.y) / self.cell).floor().max(0.0) as usize).min(self.ny - 1);
        (cx(bb.min.x), cy(bb.min.y), cx(bb.max.x), cy(bb.max.y))
    }

    /// Grid cell holding `p`, or `None` outside the grid.
    #[inline]
    fn cell_of(&self, p: Vec2) -> Option<usize> {
        if self.nx == 0 {
            return None;
        }
        let fx = (p.x - self.origin.x) / self.cell;
        let fy = (p.y - self.origin.y) / self.cell;
        if !(fx >= 0.0 && fy >= 0.0) {
            return None;
        }
        let (x, y) = (fx as usize, fy as usize);
        (x < self.nx && y < self.ny).then_some(y * self.nx + x)
    }

    #[inline]
    fn cell_segs(&self, c: usize) -> &[u32] {
        &self.seg_list[self.seg_off[c] as usize..self.seg_off[c + 1] as usize]
    }

    #[inline]
    fn cell_polys(&self, c: usize) -> &[u32] {
        &self.poly_list[self.poly_off[c] as usize..self.poly_off[c + 1] as usize]
    }

    /// Drivable lanes (passenger lanes, normal and internal) whose area contains `p`, each
    /// once, in index order. Points only inside a junction outline give no lane (see
    /// [`DrivableIndex::junction_at`]). `out` is cleared first.
    pub fn lanes_at(&self, p: Vec2, out: &mut SmallVec<[LaneIdx; 8]>) {
        out.clear();
        let Some(c) = self.cell_of(p) else { return };
        for &si in self.cell_segs(c) {
            let s = &self.segs[si as usize];
            let lane = s.lane as LaneIdx;
            if !out.contains(&lane) && s.contains(p) {
                out.push(lane);
            }
        }
        out.sort_unstable();
    }

    /// Junction whose outline contains `p`, among junctions with passenger internal lanes.
    pub fn junction_at(&self, p: Vec2) -> Option<JunctionIdx> {
        let c = self.cell_of(p)?;
        self.cell_polys(c).iter().map(|&pi| &self.polys[pi as usize]).find_map(|poly| {
            (poly.aabb.contains(p) && point_in_polygon(p, &poly.pts)).then_some(poly.junction)
        })
    }

    /// `p` lies on a drivable lane or inside a drivable junction outline.
    pub fn is_drivable(&self, p: Vec2) -> bool {
        let Some(c) = self.cell_of(p) else { return false };
        self.cell_segs(c).iter().any(|&si| self.segs[si as usize].contains(p))
            || self.junction_at(p).is_some()
    }

    /// Closest drivable lane centreline within `max_dist` of `p`, with the projection on that
    /// lane's shape (arc length `s` along the lane). Ties go to the lower segment index.
    pub fn nearest_lane(&self, p: Vec2, max_dist: f64) -> Option<(LaneIdx, Projection)> {
        if self.nx == 0 || !p.is_finite() || max_dist.is_nan() || max_dist < 0.0 {
            return None;
        }
        let fx = ((p.x - self.origin.x) / self.cell).floor();
        let fy = ((p.y - self.origin.y) / self.cell).floor();
        // Work in i64 cell coordinates: `p` may lie outside the grid.
        let clamp_i = |v: f64| v.clamp(-1.0e12, 1.0e12) as i64;
        let (px, py) = (clamp_i(fx), clamp_i(fy));
        let (nx, ny) = (self.nx as i64, self.ny as i64);
        // Rings beyond this reach no grid cell, or exceed max_dist.
        let to_grid = [-px, px - (nx - 1), -py, py - (ny - 1), 0].into_iter().max().unwrap_or(0);
        let span = (nx.max(ny)) + to_grid;
        let by_dist = ((max_dist / self.cell).ceil() as i64).saturating_add(1);
        let kmax = span.min(by_dist);
        let mut best: Option<(f64, u32)> = None;
        let max2 = max_dist * max_dist;
        let visit = |cx: i64, cy: i64, best: &mut Option<(f64, u32)>| {
            if cx < 0 || cy < 0 || cx >= nx || cy >= ny {
                return;
            }
            for &si in self.cell_segs((cy * nx + cx) as usize) {
                let s = &self.segs[si as usize];
                let d2 = closest_on_segment(p, s.a, s.b).1;
                let better = match *best {
                    None => true,
                    Some((bd, bs)) => d2 < bd || (d2 == bd && si < bs),
                };
                if d2 <= max2 && better {
                    *best = Some((d2, si));
                }
            }
        };
        for k in 0..=kmax {
            if k == 0 {
                visit(px, py, &mut best);
            } else {
                for cx in px - k..=px + k {
                    visit(cx, py - k, &mut best);
                    visit(cx, py + k, &mut best);
                }
                for cy in py - k + 1..=py + k - 1 {
                    visit(px - k, cy, &mut best);
                    visit(px + k, cy, &mut best);
                }
            }
            // Every cell of ring k+1 is at least k cells away from p.
            if let Some((bd, _)) = best {
                let reach = k as f64 * self.cell;
                if bd <= reach * reach {
                    break;
                }
            }
        }
        let (_, si) = best?;
        let s = &self.segs[si as usize];
        let (t, d2) = closest_on_segment(p, s.a, s.b);
        let lane = s.lane as LaneIdx;
        let cum = &self.lane_cum[lane];
        let i = s.seg as usize;
        let point = s.a.lerp(s.b, t);
        let distance = d2.sqrt();
        let side = (s.b - s.a).cross(p - s.a);
        Some((
            lane,
            Projection {
                s: cum[i] + t * (cum[i + 1] - cum[i]),
                distance,
                lateral: if side >= 0.0 { distance } else { -distance },
                segment: i,
                point,
            },
        ))
    }

    /// Number of indexed lane segments and junction outlines (for diagnostics).
    pub fn stats(&self) -> (usize, usize, usize, f64) {
        (self.segs.len(), self.polys.len(), self.nx * self.ny, self.cell)
    }
}

fn csr(n: usize, pairs: &mut [(u32, u32)]) -> (Vec<u32>, Vec<u32>) {
    pairs.sort_unstable();
    let mut off = vec![0u32; n + 1];
    for &(c, _) in pairs.iter() {
        off[c as usize + 1] += 1;
    }
    for i in 0..n {
        off[i + 1] += off[i];
    }
    (off, pairs.iter().map(|&(_, v)| v).collect())
}
