//! Planar geometry shared by the map, world, drive, score and render modules.
//!
//! World frame = SUMO network frame: x east, y north, metres; yaw counter-clockwise from +x,
//! radians. The ego frame used by the protocol is (forward, right).

use serde::{Deserialize, Serialize};
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub, SubAssign};

#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Vec2 {
    pub x: f64,
    pub y: f64,
}

impl Vec2 {
    pub const ZERO: Vec2 = Vec2 { x: 0.0, y: 0.0 };

    #[inline]
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }
    /// Unit vector pointing along `yaw`.
    #[inline]
    pub fn from_angle(yaw: f64) -> Self {
        let (s, c) = yaw.sin_cos();
        Self { x: c, y: s }
    }
    #[inline]
    pub fn dot(self, o: Vec2) -> f64 {
        self.x * o.x + self.y * o.y
    }
    /// z component of the 3-D cross product; > 0 when `o` is counter-clockwise of `self`.
    #[inline]
    pub fn cross(self, o: Vec2) -> f64 {
        self.x * o.y - self.y * o.x
    }
    #[inline]
    pub fn norm_sq(self) -> f64 {
        self.dot(self)
    }
    #[inline]
    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }
    #[inline]
    pub fn dist(self, o: Vec2) -> f64 {
        (self - o).norm()
    }
    #[inline]
    pub fn dist_sq(self, o: Vec2) -> f64 {
        (self - o).norm_sq()
    }
    /// Angle of the vector, radians counter-clockwise from +x.
    #[inline]
    pub fn angle(self) -> f64 {
        self.y.atan2(self.x)
    }
    /// Rotated 90° counter-clockwise (the left normal).
    #[inline]
    pub fn perp(self) -> Vec2 {
        Vec2::new(-self.y, self.x)
    }
    #[inline]
    pub fn rotate(self, angle: f64) -> Vec2 {
        let (s, c) = angle.sin_cos();
        Vec2::new(c * self.x - s * self.y, s * self.x + c * self.y)
    }
    /// Unit vector, or zero for a zero vector.
    #[inline]
    pub fn normalized(self) -> Vec2 {
        let n = self.norm();
        if n > 0.0 {
            self / n
        } else {
            Vec2::ZERO
        }
    }
    #[inline]
    pub fn lerp(self, o: Vec2, t: f64) -> Vec2 {
        self + (o - self) * t
    }
    #[inline]
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}

impl Add for Vec2 {
    type Output = Vec2;
    #[inline]
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}
impl AddAssign for Vec2 {
    #[inline]
    fn add_assign(&mut self, o: Vec2) {
        self.x += o.x;
        self.y += o.y;
    }
}
impl Sub for Vec2 {
    type Output = Vec2;
    #[inline]
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}
impl SubAssign for Vec2 {
    #[inline]
    fn sub_assign(&mut self, o: Vec2) {
        self.x -= o.x;
        self.y -= o.y;
    }
}
impl Mul<f64> for Vec2 {
    type Output = Vec2;
    #[inline]
    fn mul(self, k: f64) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}
impl Div<f64> for Vec2 {
    type Output = Vec2;
    #[inline]
    fn div(self, k: f64) -> Vec2 {
        Vec2::new(self.x / k, self.y / k)
    }
}
impl Neg for Vec2 {
    type Output = Vec2;
    #[inline]
    fn neg(self) -> Vec2 {
        Vec2::new(-self.x, -self.y)
    }
}

/// Position and heading in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose {
    pub pos: Vec2,
    /// Radians, counter-clockwise from +x (east).
    pub yaw: f64,
}

impl Pose {
    pub const fn new(pos: Vec2, yaw: f64) -> Self {
        Self { pos, yaw }
    }
    #[inline]
    pub fn forward(&self) -> Vec2 {
        Vec2::from_angle(self.yaw)
    }
    /// Unit vector to the right of the heading.
    #[inline]
    pub fn right(&self) -> Vec2 {
        -self.forward().perp()
    }
    /// A world point expressed in this pose's (forward, right) frame, as the protocol's prompt does.
    #[inline]
    pub fn to_forward_right(&self, p: Vec2) -> (f64, f64) {
        let d = p - self.pos;
        (d.dot(self.forward()), d.dot(self.right()))
    }
    /// A point given in this pose's (forward, left) frame, back in the world frame.
    #[inline]
    pub fn local_to_world(&self, forward: f64, left: f64) -> Vec2 {
        let f = self.forward();
        self.pos + f * forward + f.perp() * left
    }
}

/// Wraps an angle to (-π, π].
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    let mut r = a.rem_euclid(std::f64::consts::TAU);
    if r > std::f64::consts::PI {
        r -= std::f64::consts::TAU;
    }
    r
}

/// Axis-aligned bounding box.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    pub min: Vec2,
    pub max: Vec2,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec2::new(f64::INFINITY, f64::INFINITY),
        max: Vec2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
    };
    pub fn from_points<'a>(pts: impl IntoIterator<Item = &'a Vec2>) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in pts {
            b.include(*p);
        }
        b
    }
    #[inline]
    pub fn include(&mut self, p: Vec2) {
        self.min.x = self.min.x.min(p.x);
        self.min.y = self.min.y.min(p.y);
        self.max.x = self.max.x.max(p.x);
        self.max.y = self.max.y.max(p.y);
    }
    #[inline]
    pub fn inflate(self, r: f64) -> Aabb {
        Aabb {
            min: Vec2::new(self.min.x - r, self.min.y - r),
            max: Vec2::new(self.max.x + r, self.max.y + r),
        }
    }
    #[inline]
    pub fn contains(&self, p: Vec2) -> bool {
        p.x >= self.min.x && p.x <= self.max.x && p.y >= self.min.y && p.y <= self.max.y
    }
    #[inline]
    pub fn intersects(&self, o: &Aabb) -> bool {
        self.min.x <= o.max.x && o.min.x <= self.max.x && self.min.y <= o.max.y && o.min.y <= self.max.y
    }
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y
    }
}

/// Closest point of segment `a`–`b` to `p`: (parameter t ∈ [0,1], squared distance).
#[inline]
pub fn closest_on_segment(p: Vec2, a: Vec2, b: Vec2) -> (f64, f64) {
    let ab = b - a;
    let len2 = ab.norm_sq();
    let t = if len2 > 0.0 { ((p - a).dot(ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    (t, p.dist_sq(a + ab * t))
}

/// Even-odd point-in-polygon test (polygon given without a repeated closing vertex, or with one).
pub fn point_in_polygon(p: Vec2, poly: &[Vec2]) -> bool {
    let n = poly.len();
    if n < 3 {
        return false;
    }
    let mut inside = false;
    let mut j = n - 1;
    for i in 0..n {
        let (pi, pj) = (poly[i], poly[j]);
        if (pi.y > p.y) != (pj.y > p.y) {
            let x = pj.x + (p.y - pj.y) * (pi.x - pj.x) / (pi.y - pj.y);
            if p.x < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

/// Result of projecting a point onto a [`Polyline`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// Arc length of the closest point from the polyline start, metres.
    pub s: f64,
    /// Euclidean distance from the point to the polyline.
    pub distance: f64,
    /// Signed lateral offset: > 0 when the point lies left of the polyline direction.
    pub lateral: f64,
    /// Index of the closest segment (first one on ties).
    pub segment: usize,
    pub point: Vec2,
}

/// A polyline with cumulative arc lengths; the reference geometry of lanes and routes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Polyline {
    pts: Vec<Vec2>,
    cum: Vec<f64>,
}

impl Polyline {
    /// Builds a polyline, dropping consecutive duplicate points (zero-length segments).
    pub fn new(points: Vec<Vec2>) -> Self {
        let mut pts: Vec<Vec2> = Vec::with_capacity(points.len());
        for p in points {
            if pts.last().is_none_or(|q| q.dist_sq(p) > 1e-18) {
                pts.push(p);
            }
        }
        let mut cum = Vec::with_capacity(pts.len());
        let mut acc = 0.0;
        for (i, p) in pts.iter().enumerate() {
            if i > 0 {
                acc += p.dist(pts[i - 1]);
            }
            cum.push(acc);
        }
        Self { pts, cum }
    }
    #[inline]
    pub fn points(&self) -> &[Vec2] {
        &self.pts
    }
    /// Cumulative arc length at each vertex.
    #[inline]
    pub fn cumulative(&self) -> &[f64] {
        &self.cum
    }
    #[inline]
    pub fn len(&self) -> usize {
        self.pts.len()
    }
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.pts.is_empty()
    }
    /// Total length, metres.
    #[inline]
    pub fn length(&self) -> f64 {
        self.cum.last().copied().unwrap_or(0.0)
    }

    /// Global closest-segment projection (ties go to the first segment), as the protocol's
    /// route tracker does. `None` for an empty polyline.
    pub fn project(&self, p: Vec2) -> Option<Projection> {
        match self.pts.len() {
            0 => None,
            1 => {
                let d = p.dist(self.pts[0]);
                Some(Projection { s: 0.0, distance: d, lateral: 0.0, segment: 0, point: self.pts[0] })
            }
            n => {
                let mut best = (f64::INFINITY, 0usize, 0.0f64);
                for i in 0..n - 1 {
                    let (t, d2) = closest_on_segment(p, self.pts[i], self.pts[i + 1]);
                    if d2 < best.0 {
                        best = (d2, i, t);
                    }
                }
                let (d2, i, t) = best;
                let (a, b) = (self.pts[i], self.pts[i + 1]);
                let point = a.lerp(b, t);
                let side = (b - a).cross(p - a);
                let distance = d2.sqrt();
                Some(Projection {
                    s: self.cum[i] + t * (self.cum[i + 1] - self.cum[i]),
                    distance,
                    lateral: if side >= 0.0 { distance } else { -distance },
                    segment: i,
                    point,
                })
            }
        }
    }

    /// Closest point among the segments overlapping arc lengths [`s_min`, `s_max`] (progress
    /// tracking along a route that passes near itself). `None` if no segment overlaps.
    pub fn project_within(&self, p: Vec2, s_min: f64, s_max: f64) -> Option<Projection> {
        let n = self.pts.len();
        if n < 2 {
            return self.project(p);
        }
        let mut best: Option<(f64, usize, f64)> = None;
        for i in self.segment_at(s_min.max(0.0))..n - 1 {
            if self.cum[i] > s_max {
                break;
            }
            let (t, d2) = closest_on_segment(p, self.pts[i], self.pts[i + 1]);
            if best.is_none_or(|b| d2 < b.0) {
                best = Some((d2, i, t));
            }
        }
        let (d2, i, t) = best?;
        let (a, b) = (self.pts[i], self.pts[i + 1]);
        let distance = d2.sqrt();
        Some(Projection {
            s: self.cum[i] + t * (self.cum[i + 1] - self.cum[i]),
            distance,
            lateral: if (b - a).cross(p - a) >= 0.0 { distance } else { -distance },
            segment: i,
            point: a.lerp(b, t),
        })
    }

    /// Index of the segment containing arc length `s` (clamped).
    fn segment_at(&self, s: f64) -> usize {
        let n = self.pts.len();
        if n < 2 {
            return 0;
        }
        // partition_point: first vertex with cum > s; the segment starts one before it.
        let k = self.cum.partition_point(|&c| c <= s);
        k.saturating_sub(1).min(n - 2)
    }

    /// [`Polyline::project`] onto the polyline extended past its ends: when the closest point
    /// is the first vertex with `p` before it (or the last vertex with `p` beyond it), `s`
    /// continues along that end segment (< 0 or > length) and `lateral`, `distance` and `point`
    /// refer to the segment's line. A point just before a lane's start is thus not counted as
    /// off to its side.
    pub fn project_extended(&self, p: Vec2) -> Option<Projection> {
        let pr = self.project(p)?;
        let n = self.pts.len();
        if n < 2 {
            return Some(pr);
        }
        let i = pr.segment;
        let (a, b) = (self.pts[i], self.pts[i + 1]);
        let ab = b - a;
        let u = (p - a).dot(ab) / ab.norm_sq();
        if !((i == 0 && u < 0.0) || (i == n - 2 && u > 1.0)) {
            return Some(pr);
        }
        let lateral = ab.cross(p - a) / ab.norm();
        Some(Projection {
            s: self.cum[i] + u * (self.cum[i + 1] - self.cum[i]),
            distance: lateral.abs(),
            lateral,
            segment: i,
            point: a + ab * u,
        })
    }

    /// Pose at arc length `s` on the polyline extended past its ends (along the first segment
    /// for `s` < 0, the last for `s` > length), heading of that segment.
    pub fn pose_extended(&self, s: f64) -> Pose {
        match self.pts.len() {
            0 => Pose::new(Vec2::ZERO, 0.0),
            1 => Pose::new(self.pts[0], 0.0),
            _ => {
                let i = self.segment_at(s.clamp(0.0, self.length()));
                let (a, b) = (self.pts[i], self.pts[i + 1]);
                let dir = (b - a) / (self.cum[i + 1] - self.cum[i]);
                Pose::new(a + dir * (s - self.cum[i]), dir.angle())
            }
        }
    }

    /// The point at arc length `s`, clamped to [0, length].
    pub fn point_at(&self, s: f64) -> Vec2 {
        match self.pts.len() {
            0 => Vec2::ZERO,
            1 => self.pts[0],
            _ => {
                let s = s.clamp(0.0, self.length());
                let i = self.segment_at(s);
                let seg = self.cum[i + 1] - self.cum[i];
                let t = if seg > 0.0 { (s - self.cum[i]) / seg } else { 0.0 };
                self.pts[i].lerp(self.pts[i + 1], t)
            }
        }
    }

    /// Direction of travel at arc length `s`, radians.
    pub fn heading_at(&self, s: f64) -> f64 {
        if self.pts.len() < 2 {
            return 0.0;
        }
        let i = self.segment_at(s.clamp(0.0, self.length()));
        (self.pts[i + 1] - self.pts[i]).angle()
    }

    /// The sub-polyline between arc lengths `s0` and `s1` (clamped, s0 ≤ s1).
    pub fn slice(&self, s0: f64, s1: f64) -> Polyline {
        if self.pts.len() < 2 {
            return self.clone();
        }
        let len = self.length();
        let s0 = s0.clamp(0.0, len);
        let s1 = s1.clamp(s0, len);
        let mut out = vec![self.point_at(s0)];
        for (i, &c) in self.cum.iter().enumerate() {
            if c > s0 && c < s1 {
                out.push(self.pts[i]);
            }
        }
        out.push(self.point_at(s1));
        Polyline::new(out)
    }

    /// Appends points, skipping a first point that repeats the current last one.
    pub fn extend(&mut self, more: &[Vec2]) {
        let mut pts = std::mem::take(&mut self.pts);
        pts.extend_from_slice(more);
        *self = Polyline::new(pts);
    }

    pub fn aabb(&self) -> Aabb {
        Aabb::from_points(&self.pts)
    }
}

/// Oriented rectangle (vehicle footprint), centre + half extents along heading.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Obb {
    pub pose: Pose,
    pub half_length: f64,
    pub half_width: f64,
}

impl Obb {
    /// Corners counter-clockwise starting front-left.
    pub fn corners(&self) -> [Vec2; 4] {
        let f = self.pose.forward() * self.half_length;
        let l = self.pose.forward().perp() * self.half_width;
        let c = self.pose.pos;
        [c + f + l, c - f + l, c - f - l, c + f - l]
    }
    pub fn aabb(&self) -> Aabb {
        Aabb::from_points(&self.corners())
    }
    /// Whether two rectangles overlap, touching included (separating-axis test).
    pub fn overlaps(&self, o: &Obb) -> bool {
        let (ca, cb) = (self.corners(), o.corners());
        for axis in
            [self.pose.forward(), self.pose.forward().perp(), o.pose.forward(), o.pose.forward().perp()]
        {
            let span = |cs: &[Vec2; 4]| {
                cs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
                    let d = c.dot(axis);
                    (lo.min(d), hi.max(d))
                })
            };
            let ((a0, a1), (b0, b1)) = (span(&ca), span(&cb));
            if a1 < b0 || b1 < a0 {
                return false;
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn l_shape() -> Polyline {
        Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(10.0, 0.0), Vec2::new(10.0, 10.0)])
    }

    #[test]
    fn projection_arc_length_and_side() {
        let pl = l_shape();
        assert_eq!(pl.length(), 20.0);
        let p = pl.project(Vec2::new(4.0, 2.0)).unwrap();
        assert_eq!(p.s, 4.0);
        assert_eq!(p.lateral, 2.0);
        let p = pl.project(Vec2::new(12.0, 5.0)).unwrap();
        assert_eq!(p.s, 15.0);
        assert_eq!(p.lateral, -2.0);
    }

    #[test]
    fn extended_projection_continues_past_the_ends() {
        let pl = l_shape();
        // Inside: the same as `project`.
        assert_eq!(pl.project_extended(Vec2::new(4.0, 2.0)), pl.project(Vec2::new(4.0, 2.0)));
        // Before the start: s < 0 and the offset is measured square to the first segment,
        // where `project` reports the distance to the start point.
        let p = pl.project_extended(Vec2::new(-3.0, 4.0)).unwrap();
        assert_eq!((p.s, p.lateral, p.distance, p.point), (-3.0, 4.0, 4.0, Vec2::new(-3.0, 0.0)));
        assert_eq!(pl.project(Vec2::new(-3.0, 4.0)).unwrap().lateral, 5.0);
        // Beyond the end, right of the northbound leg.
        let p = pl.project_extended(Vec2::new(11.0, 12.0)).unwrap();
        assert_eq!((p.s, p.lateral, p.segment), (22.0, -1.0, 1));
        // An outer corner vertex is not an end: no extrapolation.
        let p = pl.project_extended(Vec2::new(12.0, -2.0)).unwrap();
        assert_eq!((p.s, p.point), (10.0, Vec2::new(10.0, 0.0)));
        assert!((p.distance - 8.0f64.sqrt()).abs() < 1e-12);
        assert_eq!(Polyline::new(vec![]).project_extended(Vec2::ZERO), None);
    }

    #[test]
    fn extended_pose_and_box_overlap() {
        let pl = l_shape();
        assert_eq!(pl.pose_extended(4.0), Pose::new(Vec2::new(4.0, 0.0), 0.0));
        assert_eq!(pl.pose_extended(-2.0), Pose::new(Vec2::new(-2.0, 0.0), 0.0));
        let p = pl.pose_extended(23.0);
        assert!(p.pos.dist(Vec2::new(10.0, 13.0)) < 1e-12);
        assert!((p.yaw - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        let b = |x: f64, y: f64, yaw: f64| Obb {
            pose: Pose::new(Vec2::new(x, y), yaw),
            half_length: 2.0,
            half_width: 1.0,
        };
        assert!(b(0.0, 0.0, 0.0).overlaps(&b(3.9, 0.0, 0.0)));
        assert!(b(0.0, 0.0, 0.0).overlaps(&b(4.0, 0.0, 0.0)), "touching counts");
        assert!(!b(0.0, 0.0, 0.0).overlaps(&b(4.1, 0.0, 0.0)));
        // Axis-aligned boxes of the two would overlap; the rotated ones do not.
        let q = std::f64::consts::FRAC_PI_4;
        assert!(b(0.0, 0.0, q).aabb().intersects(&b(2.4, -2.4, q).aabb()));
        assert!(!b(0.0, 0.0, q).overlaps(&b(2.4, -2.4, q)));
        assert!(b(0.0, 0.0, q).overlaps(&b(0.9, -0.9, q)));
    }

    #[test]
    fn point_slice_heading() {
        let pl = l_shape();
        assert_eq!(pl.point_at(15.0), Vec2::new(10.0, 5.0));
        assert_eq!(pl.point_at(99.0), Vec2::new(10.0, 10.0));
        assert_eq!(pl.point_at(10.0), Vec2::new(10.0, 0.0));
        let s = pl.slice(5.0, 12.0);
        assert_eq!(s.points(), &[Vec2::new(5.0, 0.0), Vec2::new(10.0, 0.0), Vec2::new(10.0, 2.0)]);
        assert!((pl.heading_at(15.0) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn ego_frame_is_forward_right() {
        let pose = Pose::new(Vec2::new(1.0, 1.0), std::f64::consts::FRAC_PI_2);
        let (f, r) = pose.to_forward_right(Vec2::new(2.0, 3.0));
        assert!((f - 2.0).abs() < 1e-12 && (r - 1.0).abs() < 1e-12);
    }

    #[test]
    fn polygon_and_wrap() {
        let sq = [Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)];
        assert!(point_in_polygon(Vec2::new(0.5, 0.5), &sq));
        assert!(!point_in_polygon(Vec2::new(1.5, 0.5), &sq));
        assert!((wrap_angle(3.0 * std::f64::consts::PI) - std::f64::consts::PI).abs() < 1e-12);
    }
}
