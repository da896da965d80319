//! Route tracker (docs/protocol.md#r4-prompt): progress along the route, distance to go and the eight
//! future route points in the ego frame.

use crate::geom::{Polyline, Pose};

/// Arc-length offsets (from the ego's projection) at which the future route is sampled.
pub const SAMPLE_DISTANCES_M: [f64; 8] = [5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0];
/// Length of the route slice ahead of the ego that the samples are taken from.
pub const LOOKAHEAD_M: f64 = 60.0;

/// What the route tracker tells the prompt and the navigation command at one decision.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RouteView {
    /// Arc length of the ego's projection on the route, metres (0 when unknown).
    pub progress_m: f64,
    /// `max(0, L − progress)`; `None` when the route is empty or degenerate.
    pub distance_to_go_m: Option<f64>,
    /// Up to 8 route points as (forward, right) metres in the ego frame; empty when unknown.
    pub points: Vec<(f64, f64)>,
}

/// Follows the ego along a fixed route polyline.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RouteTracker {
    route: Polyline,
}

impl RouteTracker {
    pub fn new(route: Polyline) -> Self {
        Self { route }
    }

    pub fn route(&self) -> &Polyline {
        &self.route
    }

    /// Route length L, metres.
    pub fn length_m(&self) -> f64 {
        self.route.length()
    }

    /// Projects the ego (global closest segment, first on ties), slices the route over
    /// [progress, min(L, progress + 60)] and samples the slice at 5, 10, 15, 20, 30, 40, 50 and
    /// 60 m, clamped to the slice end. A route with fewer than two distinct points, or a
    /// non-finite ego pose, yields no points and an unknown distance.
    pub fn future_points(&self, ego: &Pose) -> RouteView {
        let len = self.route.length();
        let degenerate = self.route.len() < 2 || !len.is_finite() || len <= 0.0;
        if degenerate || !ego.pos.is_finite() || !ego.yaw.is_finite() {
            return RouteView::default();
        }
        let Some(proj) = self.route.project(ego.pos) else {
            return RouteView::default();
        };
        let progress = proj.s;
        let slice = self.route.slice(progress, len.min(progress + LOOKAHEAD_M));
        let slice_len = slice.length();
        let points = SAMPLE_DISTANCES_M
            .iter()
            .map(|&d| ego.to_forward_right(slice.point_at(d.min(slice_len))))
            .collect();
        RouteView { progress_m: progress, distance_to_go_m: Some((len - progress).max(0.0)), points }
    }

    /// The local route slice [progress, min(L, progress + 60 m)] that the BEV overlay draws
    /// (its vertices, not the 8 samples); empty when the route or the pose is unusable.
    pub fn local_slice(&self, ego: &Pose) -> Polyline {
        let len = self.route.length();
        if self.route.len() < 2 || !len.is_finite() || len <= 0.0 || !ego.pos.is_finite() {
            return Polyline::default();
        }
        match self.route.project(ego.pos) {
            Some(proj) => self.route.slice(proj.s, len.min(proj.s + LOOKAHEAD_M)),
            None => Polyline::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Vec2;

    fn close(a: (f64, f64), b: (f64, f64)) -> bool {
        (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9
    }

    #[test]
    fn straight_route_samples_in_ego_frame() {
        // Route along +x from 0 to 100; ego at x = 10, 1 m left of it (y = +1), heading +x.
        let tr = RouteTracker::new(Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(100.0, 0.0)]));
        let ego = Pose::new(Vec2::new(10.0, 1.0), 0.0);
        let v = tr.future_points(&ego);
        assert_eq!(v.progress_m, 10.0);
        assert_eq!(v.distance_to_go_m, Some(90.0));
        assert_eq!(v.points.len(), 8);
        // Route is 1 m to the right of the ego (ego is left of it).
        for (p, d) in v.points.iter().zip(SAMPLE_DISTANCES_M) {
            assert!(close(*p, (d, 1.0)), "{p:?} vs {d}");
        }
    }

    #[test]
    fn samples_clamp_to_slice_end_near_destination() {
        let tr = RouteTracker::new(Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(100.0, 0.0)]));
        let ego = Pose::new(Vec2::new(78.0, 0.0), 0.0);
        let v = tr.future_points(&ego);
        assert_eq!(v.distance_to_go_m, Some(22.0));
        let f: Vec<f64> = v.points.iter().map(|p| p.0).collect();
        assert_eq!(f, vec![5.0, 10.0, 15.0, 20.0, 22.0, 22.0, 22.0, 22.0]);
        // Past the end: progress = L, distance 0, every sample at the end point.
        let v = tr.future_points(&Pose::new(Vec2::new(130.0, 0.0), 0.0));
        assert_eq!(v.distance_to_go_m, Some(0.0));
        assert!(v.points.iter().all(|p| close(*p, (-30.0, 0.0))));
    }

    #[test]
    fn corner_and_heading_rotation() {
        // L-shaped route: 20 m east then north. Ego at the start heading north (yaw = π/2):
        // forward = +y, right = +x.
        let tr = RouteTracker::new(Polyline::new(vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(20.0, 0.0),
            Vec2::new(20.0, 100.0),
        ]));
        let ego = Pose::new(Vec2::new(0.0, 0.0), std::f64::consts::FRAC_PI_2);
        let v = tr.future_points(&ego);
        assert!(close(v.points[0], (0.0, 5.0)));
        assert!(close(v.points[3], (0.0, 20.0)));
        assert!(close(v.points[4], (10.0, 20.0)));
        assert!(close(v.points[7], (40.0, 20.0)));
        assert_eq!(v.distance_to_go_m, Some(120.0));
    }

    #[test]
    fn degenerate_routes_give_nothing() {
        let ego = Pose::new(Vec2::new(1.0, 2.0), 0.3);
        for route in [
            Polyline::default(),
            Polyline::new(vec![Vec2::new(3.0, 3.0)]),
            Polyline::new(vec![Vec2::new(3.0, 3.0), Vec2::new(3.0, 3.0)]),
        ] {
            let v = RouteTracker::new(route).future_points(&ego);
            assert_eq!(v, RouteView { progress_m: 0.0, distance_to_go_m: None, points: vec![] });
        }
        let tr = RouteTracker::new(Polyline::new(vec![Vec2::new(0.0, 0.0), Vec2::new(10.0, 0.0)]));
        let nan = Pose::new(Vec2::new(f64::NAN, 0.0), 0.0);
        assert_eq!(tr.future_points(&nan), RouteView::default());
    }
}
