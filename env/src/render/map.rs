//! Everything static about a road network, precomputed once per map for both views: road and
//! sidewalk surfaces as triangles, markings as width-carrying segments (so each view can keep
//! them at least a pixel wide), roadside props as shaded 3-D triangles, all bucketed into a grid
//! of cells so a frame only touches what is near the camera.

use super::mesh::{self, Frame, Tri3};
use crate::geom::{Aabb, Vec2};
use crate::map::{Edge, EdgeFunction, Junction, Lane, VClass};
use std::collections::HashMap;

/// Surface materials; each view maps them to its own colours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum Mat {
    Junction = 0,
    Sidewalk = 1,
    Road = 2,
    BikeLane = 3,
    White = 4,
    Yellow = 5,
    /// The kerb's top along a road's outer edge (cameras only).
    Kerb = 6,
    /// Darker, polished wheel tracks in a lane: the asphalt's texture (cameras only, near).
    Track = 7,
}
pub(crate) const N_MATS: usize = 8;

/// Draw layers of area triangles, bottom first.
pub(crate) const N_LAYERS: usize = 3;

fn layer_of(m: Mat) -> usize {
    match m {
        Mat::Junction => 0,
        Mat::Sidewalk => 1,
        _ => 2,
    }
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct GTri {
    pub p: [[f32; 2]; 3],
    pub mat: Mat,
}

/// A painted stripe: centre line a→b with half width `hw` metres. `na`/`nb` are the stripe's
/// left offset directions at a and b, unit length across a straight stripe and mitred (the
/// bisector, lengthened by 1/cos of the half turn) where a line turns, so consecutive pieces of a
/// curved line share their end edges exactly: no notches, overlaps or kinks on curves.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Seg {
    pub a: [f32; 2],
    pub b: [f32; 2],
    pub na: [f32; 2],
    pub nb: [f32; 2],
    pub hw: f32,
    pub mat: Mat,
}

/// Mitred left offset directions at every vertex of a polyline (see [`Seg`]); the mitre is
/// limited to 2× for sharp turns.
fn mitres(pts: &[Vec2]) -> Vec<Vec2> {
    let n = pts.len();
    let seg_n = |i: usize| (pts[i + 1] - pts[i]).normalized().perp();
    (0..n)
        .map(|i| {
            if n < 2 {
                return Vec2::new(0.0, 0.0);
            }
            if i == 0 {
                return seg_n(0);
            }
            if i == n - 1 {
                return seg_n(n - 2);
            }
            let (a, b) = (seg_n(i - 1), seg_n(i));
            let m = (a + b).normalized();
            let c = m.dot(a).max(0.5);
            m * (1.0 / c)
        })
        .collect()
}

#[derive(Clone, Debug)]
pub(crate) struct Cell {
    /// min x, min y, max x, max y (map frame).
    pub bb: [f32; 4],
    pub zmax: f32,
    pub tris: [(u32, u32); N_LAYERS],
    pub segs: (u32, u32),
    pub props: (u32, u32),
}

/// Where to hang the signal head of one incoming lane.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LaneSignalPlace {
    /// Distance past the stop line to the far side of the junction, metres.
    pub far_m: f32,
    /// Distance from the lane centre to the roadside on its right, metres.
    pub right_m: f32,
}

/// Precomputed render geometry of one road network. Immutable and `Send + Sync`; build once per
/// map and share between views, cameras and threads.
#[derive(Clone, Debug)]
pub struct RenderMap {
    /// World position of the map-frame origin (geometry is stored relative to it in f32).
    pub(crate) origin: Vec2,
    pub(crate) cell_m: f32,
    /// Map-frame corner of grid cell (0, 0).
    pub(crate) grid_min: [f32; 2],
    pub(crate) nx: usize,
    pub(crate) ny: usize,
    /// Grid → index into `cells` (u32::MAX = empty).
    pub(crate) grid: Vec<u32>,
    pub(crate) cells: Vec<Cell>,
    pub(crate) tris: Vec<GTri>,
    pub(crate) segs: Vec<Seg>,
    pub(crate) props: Vec<Tri3>,
    pub(crate) signal_places: HashMap<String, LaneSignalPlace>,
    /// Street lights (drawn at night): the centre of each one's pool on the ground (x, y) and
    /// the unit direction from it towards the pole at the roadside (map frame).
    pub(crate) street_lamps: Vec<[f32; 4]>,
    bounds: Aabb,
}

const CELL_M: f32 = 32.0;
const PIECE_M: f64 = 12.0;
/// How far each lane's surface reaches past its edge, under its neighbour (see `from_parts`).
const LANE_OVERLAP_M: f64 = 0.08;

fn is_sidewalk(l: &Lane) -> bool {
    l.allow.contains(VClass::Pedestrian)
        && !l.allow.contains(VClass::Passenger)
        && !l.allow.contains(VClass::Bicycle)
        && !l.allow.contains(VClass::Bus)
}
fn is_bike_only(l: &Lane) -> bool {
    l.allow.contains(VClass::Bicycle)
        && !l.allow.contains(VClass::Passenger)
        && !l.allow.contains(VClass::Bus)
}
fn is_vehicle_lane(l: &Lane) -> bool {
    !is_sidewalk(l) && (l.allow.0 != 0)
}

/// Offsets a polyline sideways by `d` (> 0 = left), mitring joins (limited for sharp turns).
pub(crate) fn offset_polyline(pts: &[Vec2], d: f64) -> Vec<Vec2> {
    let n = pts.len();
    if n < 2 {
        return pts.to_vec();
    }
    let seg_n = |i: usize| (pts[i + 1] - pts[i]).normalized().perp();
    (0..n)
        .map(|i| {
            let m = if i == 0 {
                seg_n(0)
            } else if i == n - 1 {
                seg_n(n - 2)
            } else {
                let (a, b) = (seg_n(i - 1), seg_n(i));
                let m = (a + b).normalized();
                if m == Vec2::ZERO {
                    b
                } else {
                    m / m.dot(b).max(0.35)
                }
            };
            pts[i] + m * d
        })
        .collect()
}

/// Ear-clipping triangulation of a simple polygon (either orientation; closing vertex optional).
/// Falls back to a fan for whatever remains if the polygon is not simple.
pub(crate) fn triangulate(poly: &[Vec2]) -> Vec<[Vec2; 3]> {
    let mut pts: Vec<Vec2> = Vec::with_capacity(poly.len());
    for &p in poly {
        if pts.last().is_none_or(|q: &Vec2| q.dist_sq(p) > 1e-8) {
            pts.push(p);
        }
    }
    while pts.len() > 2 && pts[0].dist_sq(pts[pts.len() - 1]) <= 1e-8 {
        pts.pop();
    }
    let mut out = Vec::new();
    if pts.len() < 3 {
        return out;
    }
    let area: f64 = (0..pts.len()).map(|i| pts[i].cross(pts[(i + 1) % pts.len()])).sum();
    if area < 0.0 {
        pts.reverse();
    }
    let mut idx: Vec<usize> = (0..pts.len()).collect();
    let mut guard = 0;
    while idx.len() > 3 && guard < idx.len() {
        let n = idx.len();
        let mut clipped = false;
        for k in 0..n {
            let (ia, ib, ic) = (idx[(k + n - 1) % n], idx[k], idx[(k + 1) % n]);
            let (a, b, c) = (pts[ia], pts[ib], pts[ic]);
            if (b - a).cross(c - b) <= 1e-12 {
                continue;
            }
            let inside = idx.iter().any(|&j| {
                if j == ia || j == ib || j == ic {
                    return false;
                }
                let p = pts[j];
                (b - a).cross(p - a) >= 0.0 && (c - b).cross(p - b) >= 0.0 && (a - c).cross(p - c) >= 0.0
            });
            if inside {
                continue;
            }
            out.push([a, b, c]);
            idx.remove(k);
            clipped = true;
            break;
        }
        if clipped {
            guard = 0;
        } else {
            guard = usize::MAX; // no ear: not simple; fan the rest
        }
    }
    for k in 1..idx.len().saturating_sub(1) {
        out.push([pts[idx[0]], pts[idx[k]], pts[idx[k + 1]]]);
    }
    out
}

fn splitmix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn hash_pos(p: Vec2) -> u64 {
    let qx = (p.x * 4.0).round() as i64 as u64;
    let qy = (p.y * 4.0).round() as i64 as u64;
    splitmix(qx ^ splitmix(qy))
}

/// Coarse occupancy grid used to keep props off roads and off each other.
struct Occupancy {
    min: Vec2,
    cell: f64,
    nx: usize,
    ny: usize,
    bits: Vec<bool>,
}

impl Occupancy {
    fn new(b: Aabb, cell: f64) -> Self {
        let nx = (((b.max.x - b.min.x) / cell).ceil() as usize + 1).min(20_000);
        let ny = (((b.max.y - b.min.y) / cell).ceil() as usize + 1).min(20_000);
        Occupancy { min: b.min, cell, nx, ny, bits: vec![false; nx * ny] }
    }
    fn idx(&self, p: Vec2) -> Option<usize> {
        let x = ((p.x - self.min.x) / self.cell).floor();
        let y = ((p.y - self.min.y) / self.cell).floor();
        if x < 0.0 || y < 0.0 || x >= self.nx as f64 || y >= self.ny as f64 {
            return None;
        }
        Some(y as usize * self.nx + x as usize)
    }
    fn mark_tri(&mut self, t: &[Vec2; 3]) {
        let b = Aabb::from_points(t.iter());
        let (Some(_), Some(_)) = (self.idx(b.min), self.idx(b.max)) else {
            for p in t {
                if let Some(i) = self.idx(*p) {
                    self.bits[i] = true;
                }
            }
            return;
        };
        let x0 = ((b.min.x - self.min.x) / self.cell).floor() as usize;
        let x1 = ((b.max.x - self.min.x) / self.cell).floor() as usize;
        let y0 = ((b.min.y - self.min.y) / self.cell).floor() as usize;
        let y1 = ((b.max.y - self.min.y) / self.cell).floor() as usize;
        for y in y0..=y1 {
            for x in x0..=x1 {
                let c = Vec2::new(
                    self.min.x + (x as f64 + 0.5) * self.cell,
                    self.min.y + (y as f64 + 0.5) * self.cell,
                );
                // Conservative: the cell centre within half a cell of the triangle.
                if dist_to_tri(c, t) <= self.cell * 0.75 {
                    self.bits[y * self.nx + x] = true;
                }
            }
        }
    }
    fn any(&self, pts: &[Vec2]) -> bool {
        pts.iter().any(|p| self.idx(*p).is_none_or(|i| self.bits[i]))
    }
    fn mark(&mut self, pts: &[Vec2]) {
        for p in pts {
            if let Some(i) = self.idx(*p) {
                self.bits[i] = true;
            }
        }
    }
}

fn dist_to_tri(p: Vec2, t: &[Vec2; 3]) -> f64 {
    let s0 = (t[1] - t[0]).cross(p - t[0]);
    let s1 = (t[2] - t[1]).cross(p - t[1]);
    let s2 = (t[0] - t[2]).cross(p - t[2]);
    if (s0 >= 0.0 && s1 >= 0.0 && s2 >= 0.0) || (s0 <= 0.0 && s1 <= 0.0 && s2 <= 0.0) {
        return 0.0;
    }
    (0..3)
        .map(|i| crate::geom::closest_on_segment(p, t[i], t[(i + 1) % 3]).1.sqrt())
        .fold(f64::INFINITY, f64::min)
}

/// Sample points covering an oriented rectangle every ~1.5 m (for occupancy tests).
fn rect_samples(c: Vec2, f: Vec2, hl: f64, hw: f64) -> Vec<Vec2> {
    let l = f.perp();
    let nl = ((2.0 * hl) / 1.5).ceil().max(1.0) as usize;
    let nw = ((2.0 * hw) / 1.5).ceil().max(1.0) as usize;
    let mut v = Vec::with_capacity((nl + 1) * (nw + 1));
    for i in 0..=nl {
        for j in 0..=nw {
            let a = -hl + 2.0 * hl * i as f64 / nl as f64;
            let b = -hw + 2.0 * hw * j as f64 / nw as f64;
            v.push(c + f * a + l * b);
        }
    }
    v
}

#[derive(Default)]
struct Collect {
    tris: Vec<(GTri, [Vec2; 3])>,
    segs: Vec<Seg>,
    props: Vec<Tri3>,
}

impl Collect {
    fn tri(&mut self, origin: Vec2, t: [Vec2; 3], mat: Mat) {
        let p = t.map(|v| {
            let r = v - origin;
            [r.x as f32, r.y as f32]
        });
        self.tris.push((GTri { p, mat }, t));
    }
    fn quad_strip(&mut self, origin: Vec2, right: &[Vec2], left: &[Vec2], mat: Mat) {
        for i in 0..right.len().saturating_sub(1) {
            let len = right[i].dist(right[i + 1]).max(left[i].dist(left[i + 1]));
            let k = (len / PIECE_M).ceil().max(1.0) as usize;
            for j in 0..k {
                let (t0, t1) = (j as f64 / k as f64, (j + 1) as f64 / k as f64);
                let r0 = right[i].lerp(right[i + 1], t0);
                let r1 = right[i].lerp(right[i + 1], t1);
                let l0 = left[i].lerp(left[i + 1], t0);
                let l1 = left[i].lerp(left[i + 1], t1);
                self.tri(origin, [r0, r1, l1], mat);
                self.tri(origin, [r0, l1, l0], mat);
            }
        }
    }
    /// A straight stripe a→b (split into pieces for the cell grid), with the offset directions
    /// `na`, `nb` at its ends (None = square ends).
    #[allow(clippy::too_many_arguments)]
    fn seg_mitred(
        &mut self,
        origin: Vec2,
        a: Vec2,
        b: Vec2,
        na: Option<Vec2>,
        nb: Option<Vec2>,
        hw: f64,
        mat: Mat,
    ) {
        let len = a.dist(b);
        if len < 1e-6 {
            return;
        }
        let perp = (b - a).normalized().perp();
        let f = |v: Vec2| [v.x as f32, v.y as f32];
        let k = (len / PIECE_M).ceil().max(1.0) as usize;
        for j in 0..k {
            let p0 = a.lerp(b, j as f64 / k as f64) - origin;
            let p1 = a.lerp(b, (j + 1) as f64 / k as f64) - origin;
            let n0 = if j == 0 { na.unwrap_or(perp) } else { perp };
            let n1 = if j == k - 1 { nb.unwrap_or(perp) } else { perp };
            self.segs.push(Seg { a: f(p0), b: f(p1), na: f(n0), nb: f(n1), hw: hw as f32, mat });
        }
    }
    fn seg(&mut self, origin: Vec2, a: Vec2, b: Vec2, hw: f64, mat: Mat) {
        self.seg_mitred(origin, a, b, None, None, hw, mat);
    }
    fn solid(&mut self, origin: Vec2, pts: &[Vec2], hw: f64, mat: Mat) {
        let m = mitres(pts);
        for (i, w) in pts.windows(2).enumerate() {
            self.seg_mitred(origin, w[0], w[1], Some(m[i]), Some(m[i + 1]), hw, mat);
        }
    }
    /// Dashes of `dash` metres every `period` metres along a polyline; a dash running over a
    /// vertex is mitred there.
    fn dashed(&mut self, origin: Vec2, pts: &[Vec2], hw: f64, mat: Mat, dash: f64, period: f64) {
        let m = mitres(pts);
        let mut s0 = 0.0;
        for (i, w) in pts.windows(2).enumerate() {
            let len = w[0].dist(w[1]);
            let mut s = 0.0;
            while s < len {
                let phase = (s0 + s) % period;
                if phase < dash {
                    let e = (s + dash - phase).min(len);
                    let na = (s == 0.0 && i > 0).then_some(m[i]);
                    let nb = (e >= len && i + 2 < pts.len()).then_some(m[i + 1]);
                    self.seg_mitred(
                        origin,
                        w[0].lerp(w[1], s / len),
                        w[0].lerp(w[1], e / len),
                        na,
                        nb,
                        hw,
                        mat,
                    );
                    s = e;
                } else {
                    s += period - phase;
                }
            }
            s0 += len;
        }
    }
}

/// Line half widths (metres): lane lines are 0.15 m wide in reality, drawn a bit wider to read.
const LINE_HW: f64 = 0.1;
/// Kerb top (0.25 m) and wheel track (0.6 m) half widths.
const KERB_HW: f64 = 0.125;
const TRACK_HW: f64 = 0.3;

impl RenderMap {
    /// Precomputes the render geometry of a network (once per map; ~linear in its size).
    pub fn build(net: &crate::map::Network) -> RenderMap {
        Self::from_parts(&net.edges, &net.lanes, &net.junctions)
    }

    /// Precomputes render geometry from the parts of a road network.
    pub fn from_parts(edges: &[Edge], lanes: &[Lane], junctions: &[Junction]) -> RenderMap {
        let mut bounds = Aabb::EMPTY;
        for l in lanes {
            for p in l.shape.points() {
                bounds.include(*p);
            }
        }
        for j in junctions {
            for p in &j.shape {
                bounds.include(*p);
            }
        }
        if bounds.is_empty() {
            bounds = Aabb { min: Vec2::ZERO, max: Vec2::ZERO };
        }
        let origin = bounds.min;
        let mut c = Collect::default();
        let mut occ = Occupancy::new(bounds.inflate(60.0), 2.0);

        // Junction polygons.
        for j in junctions {
            if j.kind == "internal" || j.shape.len() < 3 {
                continue;
            }
            for t in triangulate(&j.shape) {
                c.tri(origin, t, Mat::Junction);
            }
        }

        // Which normal edges have a reverse partner (the boundary between them is a centre line).
        let mut pair: HashMap<(usize, usize), usize> = HashMap::new();
        for (i, e) in edges.iter().enumerate() {
            if let (EdgeFunction::Normal, Some(a), Some(b)) = (e.function, e.from, e.to) {
                pair.insert((a, b), i);
            }
        }
        // Highest priority among normal edges entering each junction (minor roads get yield lines).
        let mut max_in_prio: HashMap<usize, i32> = HashMap::new();
        for e in edges {
            if let (EdgeFunction::Normal, Some(t)) = (e.function, e.to) {
                let m = max_in_prio.entry(t).or_insert(i32::MIN);
                *m = (*m).max(e.priority);
            }
        }
        let mut signal_places = HashMap::new();

        for e in edges {
            let lane_of = |i: &usize| lanes.get(*i);
            match e.function {
                EdgeFunction::Normal | EdgeFunction::Internal | EdgeFunction::Connector => {
                    for l in e.lanes.iter().filter_map(lane_of) {
                        if l.shape.len() < 2 {
                            continue;
                        }
                        // Each lane is its own strip, and neighbours' shared edges are offset from
                        // two centrelines with their own vertices: the edges meet in T-junctions
                        // that leave hairline cracks (a dotted seam between lanes). A small overlap
                        // closes them; the lane line is drawn over it.
                        let hw = l.width_m * 0.5 + LANE_OVERLAP_M;
                        let mat = if is_sidewalk(l) {
                            Mat::Sidewalk
                        } else if is_bike_only(l) {
                            Mat::BikeLane
                        } else if l.allow.0 == 0 {
                            continue;
                        } else {
                            Mat::Road
                        };
                        let left = offset_polyline(l.shape.points(), hw);
                        let right = offset_polyline(l.shape.points(), -hw);
                        c.quad_strip(origin, &right, &left, mat);
                    }
                }
                EdgeFunction::WalkingArea => {
                    for l in e.lanes.iter().filter_map(lane_of) {
                        for t in triangulate(l.shape.points()) {
                            c.tri(origin, t, Mat::Sidewalk);
                        }
                    }
                }
                EdgeFunction::Crossing => {
                    for l in e.lanes.iter().filter_map(lane_of) {
                        let pts = l.shape.points();
                        if pts.len() < 2 {
                            continue;
                        }
                        // Zebra: stripes along the traffic, 0.5 m wide, every 1 m across.
                        let total = l.shape.length();
                        let mut s = 0.5;
                        while s < total - 0.25 {
                            let p = l.shape.point_at(s);
                            let n = Vec2::from_angle(l.shape.heading_at(s)).perp() * (l.width_m * 0.5);
                            c.seg(origin, p - n, p + n, 0.25, Mat::White);
                            s += 1.0;
                        }
                    }
                }
            }
            if e.function != EdgeFunction::Normal {
                continue;
            }
            // Lane lines of a normal edge, from the rightmost vehicle lane leftwards.
            let vl: Vec<&Lane> = e
                .lanes
                .iter()
                .filter_map(lane_of)
                .filter(|l| is_vehicle_lane(l) && l.shape.len() >= 2)
                .collect();
            // Wheel tracks: where tyres run, asphalt is darker; drawn under the lines.
            for l in vl.iter().filter(|l| !is_bike_only(l) && l.width_m >= 2.5) {
                let pts = l.shape.points();
                for side in [-1.0, 1.0] {
                    c.solid(origin, &offset_polyline(pts, side * 0.85), TRACK_HW, Mat::Track);
                }
            }
            // Kerbs just outside the outermost lanes: on the right always, on the left when
            // no opposite edge shares the road (one-way roads and divided carriageways).
            let paved: Vec<&Lane> = e
                .lanes
                .iter()
                .filter_map(lane_of)
                .filter(|l| !is_sidewalk(l) && l.shape.len() >= 2)
                .collect();
            if let (Some(r), Some(l)) = (paved.first(), paved.last()) {
                c.solid(
                    origin,
                    &offset_polyline(r.shape.points(), -(r.width_m * 0.5 + KERB_HW)),
                    KERB_HW,
                    Mat::Kerb,
                );
                let two_way = matches!((e.from, e.to), (Some(a), Some(b)) if pair.contains_key(&(b, a)));
                if !two_way {
                    c.solid(
                        origin,
                        &offset_polyline(l.shape.points(), l.width_m * 0.5 + KERB_HW),
                        KERB_HW,
                        Mat::Kerb,
                    );
                }
            }
            for (k, l) in vl.iter().enumerate() {
                let pts = l.shape.points();
                let hw = l.width_m * 0.5;
                if k == 0 {
                    c.solid(origin, &offset_polyline(pts, -hw), LINE_HW, Mat::White);
                }
                if k + 1 < vl.len() {
                    let boundary = offset_polyline(pts, hw);
                    if is_bike_only(l) || is_bike_only(vl[k + 1]) {
                        c.solid(origin, &boundary, LINE_HW, Mat::White);
                    } else {
                        c.dashed(origin, &boundary, LINE_HW, Mat::White, 3.0, 9.0);
                    }
                } else {
                    let two_way = matches!((e.from, e.to), (Some(a), Some(b)) if pair.contains_key(&(b, a)));
                    let mat = if two_way { Mat::Yellow } else { Mat::White };
                    c.solid(origin, &offset_polyline(pts, hw), LINE_HW, mat);
                }
            }
            // Stop / yield lines where lanes enter a real junction.
            let Some(j) = e.to.and_then(|t| junctions.get(t)) else { continue };
            let kind = j.kind.as_str();
            let controlled = matches!(
                kind,
                "traffic_light"
                    | "traffic_light_unregulated"
                    | "traffic_light_right_on_red"
                    | "allway_stop"
                    | "priority_stop"
                    | "right_before_left"
                    | "left_before_right"
            );
            let minor =
                kind == "priority" && e.to.and_then(|t| max_in_prio.get(&t)).is_some_and(|&m| e.priority < m);
            let mut right_acc = 0.0;
            for l in e.lanes.iter().filter_map(lane_of) {
                let pts = l.shape.points();
                if pts.len() < 2 {
                    right_acc += l.width_m;
                    continue;
                }
                let end = pts[pts.len() - 1];
                let dir = (end - pts[pts.len() - 2]).normalized();
                let across = dir.perp() * (l.width_m * 0.5);
                if is_vehicle_lane(l) && (controlled || minor) {
                    let p = end - dir * 0.3;
                    if controlled {
                        c.seg(origin, p - across, p + across, 0.2, Mat::White);
                    } else {
                        c.dashed(origin, &[p - across, p + across], 0.15, Mat::White, 0.6, 1.2);
                    }
                }
                let far = if j.shape.len() >= 3 {
                    j.shape
                        .iter()
                        .filter(|v| (**v - end).dot(dir.perp()).abs() < 20.0)
                        .map(|v| (*v - end).dot(dir))
                        .fold(0.0f64, f64::max)
                } else {
                    12.0
                };
                signal_places.insert(
                    l.id.clone(),
                    LaneSignalPlace {
                        far_m: far.clamp(6.0, 40.0) as f32 + 1.5,
                        right_m: (right_acc + l.width_m * 0.5 + 0.8) as f32,
                    },
                );
                right_acc += l.width_m;
            }
        }

        for (_, t) in &c.tris {
            occ.mark_tri(t);
        }
        place_props(edges, lanes, origin, &mut occ, &mut c.props);
        let mut m = Self::bucket(origin, bounds, c, signal_places);
        m.street_lamps = street_lamps(edges, lanes, origin);
        m
    }

    fn bucket(
        origin: Vec2,
        bounds: Aabb,
        c: Collect,
        signal_places: HashMap<String, LaneSignalPlace>,
    ) -> RenderMap {
        let ext = bounds.inflate(80.0);
        let gmin = ext.min - origin;
        let nx = (((ext.max.x - ext.min.x) as f32 / CELL_M).ceil() as usize).max(1);
        let ny = (((ext.max.y - ext.min.y) as f32 / CELL_M).ceil() as usize).max(1);
        let key = |x: f32, y: f32| -> usize {
            let cx = (((x - gmin.x as f32) / CELL_M).floor().max(0.0) as usize).min(nx - 1);
            let cy = (((y - gmin.y as f32) / CELL_M).floor().max(0.0) as usize).min(ny - 1);
            cy * nx + cx
        };
        let mut tris: Vec<(usize, usize, GTri)> = c
            .tris
            .into_iter()
            .map(|(t, _)| {
                let cx = (t.p[0][0] + t.p[1][0] + t.p[2][0]) / 3.0;
                let cy = (t.p[0][1] + t.p[1][1] + t.p[2][1]) / 3.0;
                (key(cx, cy), layer_of(t.mat), t)
            })
            .collect();
        tris.sort_by_key(|(k, l, _)| (*k, *l));
        let mut segs: Vec<(usize, Seg)> =
            c.segs.into_iter().map(|s| (key((s.a[0] + s.b[0]) * 0.5, (s.a[1] + s.b[1]) * 0.5), s)).collect();
        segs.sort_by_key(|(k, _)| *k);
        // Props: keep the triangles of one prop together (they were appended per prop, and a
        // prop is small), keyed by each triangle's first vertex.
        let mut props: Vec<(usize, Tri3)> =
            c.props.into_iter().map(|t| (key(t.p[0][0], t.p[0][1]), t)).collect();
        props.sort_by_key(|(k, _)| *k);

        let mut grid = vec![u32::MAX; nx * ny];
        let mut cells: Vec<Cell> = Vec::new();
        let empty = Cell {
            bb: [f32::INFINITY, f32::INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY],
            zmax: 0.1,
            tris: [(0, 0); N_LAYERS],
            segs: (0, 0),
            props: (0, 0),
        };
        let cell_of = |k: usize, grid: &mut Vec<u32>, cells: &mut Vec<Cell>| -> usize {
            if grid[k] == u32::MAX {
                grid[k] = cells.len() as u32;
                cells.push(empty.clone());
            }
            grid[k] as usize
        };
        let grow = |cell: &mut Cell, x: f32, y: f32| {
            cell.bb[0] = cell.bb[0].min(x);
            cell.bb[1] = cell.bb[1].min(y);
            cell.bb[2] = cell.bb[2].max(x);
            cell.bb[3] = cell.bb[3].max(y);
        };
        let mut i = 0;
        while i < tris.len() {
            let (k, l, _) = (tris[i].0, tris[i].1, tris[i].2);
            let ci = cell_of(k, &mut grid, &mut cells);
            let start = i;
            while i < tris.len() && tris[i].0 == k && tris[i].1 == l {
                for p in tris[i].2.p {
                    grow(&mut cells[ci], p[0], p[1]);
                }
                i += 1;
            }
            cells[ci].tris[l] = (start as u32, i as u32);
        }
        let mut i = 0;
        while i < segs.len() {
            let k = segs[i].0;
            let ci = cell_of(k, &mut grid, &mut cells);
            let start = i;
            while i < segs.len() && segs[i].0 == k {
                let s = segs[i].1;
                for p in [s.a, s.b] {
                    grow(&mut cells[ci], p[0] - s.hw, p[1] - s.hw);
                    grow(&mut cells[ci], p[0] + s.hw, p[1] + s.hw);
                }
                i += 1;
            }
            cells[ci].segs = (start as u32, i as u32);
        }
        let mut i = 0;
        while i < props.len() {
            let k = props[i].0;
            let ci = cell_of(k, &mut grid, &mut cells);
            let start = i;
            while i < props.len() && props[i].0 == k {
                for p in props[i].1.p {
                    grow(&mut cells[ci], p[0], p[1]);
                    cells[ci].zmax = cells[ci].zmax.max(p[2]);
                }
                i += 1;
            }
            cells[ci].props = (start as u32, i as u32);
        }
        RenderMap {
            origin,
            cell_m: CELL_M,
            grid_min: [gmin.x as f32, gmin.y as f32],
            nx,
            ny,
            grid,
            cells,
            tris: tris.into_iter().map(|t| t.2).collect(),
            segs: segs.into_iter().map(|s| s.1).collect(),
            props: props.into_iter().map(|p| p.1).collect(),
            signal_places,
            street_lamps: Vec::new(),
            bounds,
        }
    }

    /// Bounding box of the network geometry (world frame).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Numbers of surface triangles, marking segments and prop triangles (for diagnostics).
    pub fn stats(&self) -> (usize, usize, usize) {
        (self.tris.len(), self.segs.len(), self.props.len())
    }

    /// Calls `f` with every non-empty cell whose grid square intersects the map-frame box.
    pub(crate) fn for_cells(&self, min: [f32; 2], max: [f32; 2], mut f: impl FnMut(usize, &Cell)) {
        let g = self.grid_min;
        let cx0 = ((min[0] - g[0]) / self.cell_m).floor().max(0.0) as usize;
        let cy0 = ((min[1] - g[1]) / self.cell_m).floor().max(0.0) as usize;
        let cx1 = ((max[0] - g[0]) / self.cell_m).floor();
        let cy1 = ((max[1] - g[1]) / self.cell_m).floor();
        if cx1 < 0.0 || cy1 < 0.0 {
            return;
        }
        let cx1 = (cx1 as usize).min(self.nx - 1);
        let cy1 = (cy1 as usize).min(self.ny - 1);
        for cy in cy0..=cy1 {
            for cx in cx0..=cx1 {
                let ci = self.grid[cy * self.nx + cx];
                if ci != u32::MAX {
                    f(ci as usize, &self.cells[ci as usize]);
                }
            }
        }
    }
}

/// Trees and buildings beside normal roads, placed by a hash of position (deterministic) where
/// the occupancy grid shows neither road nor another prop.
/// Street lights every 30 m along the right edge of each road (SUMO lane 0 is the rightmost),
/// the pool 1.5 m inside the edge, the pole 0.9 m outside it.
fn street_lamps(edges: &[Edge], lanes: &[Lane], origin: Vec2) -> Vec<[f32; 4]> {
    let mut out = Vec::new();
    for e in edges {
        if e.function != EdgeFunction::Normal {
            continue;
        }
        let Some(l) = e.lanes.first().and_then(|i| lanes.get(*i)) else { continue };
        if l.shape.len() < 2 || !e.lanes.iter().filter_map(|i| lanes.get(*i)).any(|l| l.is_drivable()) {
            continue;
        }
        let edge = crate::geom::Polyline::new(offset_polyline(l.shape.points(), -l.width_m * 0.5));
        let len = edge.length();
        let mut s = 6.0 + (hash_pos(edge.point_at(0.0)) % 7) as f64;
        while s < len - 3.0 {
            let p = edge.point_at(s);
            let right = -Vec2::from_angle(edge.heading_at(s)).perp();
            let q = p - right * 1.5 - origin;
            out.push([q.x as f32, q.y as f32, right.x as f32, right.y as f32]);
            s += 30.0;
        }
    }
    out
}

fn place_props(edges: &[Edge], lanes: &[Lane], origin: Vec2, occ: &mut Occupancy, out: &mut Vec<Tri3>) {
    for e in edges {
        if e.function != EdgeFunction::Normal {
            continue;
        }
        let Some(l) = e.lanes.first().and_then(|i| lanes.get(*i)) else { continue };
        if l.shape.len() < 2 || !e.lanes.iter().filter_map(|i| lanes.get(*i)).any(|l| l.is_drivable()) {
            continue;
        }
        let edge_pts = offset_polyline(l.shape.points(), -l.width_m * 0.5);
        let edge = crate::geom::Polyline::new(edge_pts);
        let len = edge.length();
        let mut s = (hash_pos(edge.point_at(0.0)) % 9) as f64;
        while s < len {
            let p = edge.point_at(s);
            let f = Vec2::from_angle(edge.heading_at(s));
            let right = -f.perp();
            let h = hash_pos(p);
            let is_tree = h % 10 < 6;
            let k = |shift: u32, n: u64| ((h >> shift) % n) as f64;
            if is_tree {
                let crown = 1.6 + k(8, 10) * 0.1;
                let height = 5.0 + k(16, 40) * 0.1;
                let c = p + right * (2.5 + crown + k(24, 3));
                let samples = rect_samples(c, f, crown, crown);
                if !occ.any(&samples) {
                    occ.mark(&rect_samples(c, f, crown + 1.0, crown + 1.0));
                    let fr = Frame::new(c, f.angle(), origin, 0.0);
                    mesh::tree(out, &fr, height as f32, crown as f32, 0.85 + k(32, 30) as f32 * 0.01);
                }
                s += 9.0 + k(40, 8);
            } else {
                let hl = 5.0 + k(8, 6);
                let hw = 4.0 + k(16, 5);
                let height = 6.0 + k(24, 15);
                let c = p + right * (5.0 + hw + k(32, 4));
                let samples = rect_samples(c, f, hl, hw);
                if !occ.any(&samples) {
                    occ.mark(&rect_samples(c, f, hl + 1.5, hw + 1.5));
                    let palette = [
                        [196, 180, 160],
                        [170, 160, 150],
                        [200, 200, 190],
                        [160, 120, 100],
                        [185, 190, 200],
                        [210, 190, 150],
                    ];
                    let col = palette[((h >> 40) % palette.len() as u64) as usize];
                    let fr = Frame::new(c, f.angle(), origin, 0.0);
                    mesh::building(out, &fr, hl as f32, hw as f32, height as f32, col);
                }
                s += 2.0 * hl + 4.0 + k(44, 6);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangulates_concave_polygon_with_full_area() {
        // An L shape of area 3.
        let poly = [
            Vec2::new(0.0, 0.0),
            Vec2::new(2.0, 0.0),
            Vec2::new(2.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 2.0),
            Vec2::new(0.0, 2.0),
            Vec2::new(0.0, 0.0),
        ];
        let tris = triangulate(&poly);
        assert_eq!(tris.len(), 4);
        let area: f64 = tris.iter().map(|t| (t[1] - t[0]).cross(t[2] - t[0]).abs() * 0.5).sum();
        assert!((area - 3.0).abs() < 1e-9, "{area}");
    }

    #[test]
    fn offset_is_perpendicular_on_straight_line() {
        let pts = [Vec2::new(0.0, 0.0), Vec2::new(10.0, 0.0), Vec2::new(20.0, 0.0)];
        let o = offset_polyline(&pts, 1.5);
        assert!(o.iter().all(|p| (p.y - 1.5).abs() < 1e-12));
    }
}
