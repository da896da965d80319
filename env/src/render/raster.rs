//! The drawing seam of the renderer: [`RasterBackend`], the primitives both the cameras and the
//! BEV issue, and [`SoftwareRaster`], its scanline implementation into RGB8 buffers (with an
//! optional depth and id plane).
//!
//! The views compute geometry (projection, clipping, culling, colours) and hand screen-space
//! shapes to a backend; a backend only turns shapes into pixels (or, in tests, records them).
//!
//! Pixel centres sit at (x + 0.5, y + 0.5); a pixel is covered when its centre lies in
//! [left, right) × [top, bottom) of the triangle's span — a top-left style rule, so shared edges
//! are filled exactly once and results are deterministic.

/// A per-pixel pass over a finished frame: `(rgb, depth, width, height)`.
pub(crate) type PostPass<'a> = dyn FnMut(&mut [u8], &[f32], usize, usize) + 'a;

/// A colour target: RGB8 rows (`width * 3` bytes each) plus its size in pixels.
pub(crate) struct Target<'a> {
    pub rgb: &'a mut [u8],
    pub width: usize,
    pub height: usize,
}

/// Depth (1/z, larger is nearer) and optional id planes matching a [`Target`].
pub(crate) struct DepthPlanes<'a> {
    pub depth: &'a mut [f32],
    /// When present, every written pixel stores `id` (actor index + 1; 0 = none).
    pub ids: Option<&'a mut [u32]>,
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct SV {
    pub x: f32,
    pub y: f32,
    /// 1 / camera depth (only used by the depth-tested fill).
    pub w: f32,
}

/// Iterates the covered rows of a triangle: calls `span(y, x0, x1, xf)` with integer pixel
/// bounds `[x0, x1)` and the row's centre y as float.
#[inline(always)]
fn for_spans(a: SV, b: SV, c: SV, width: usize, height: usize, mut span: impl FnMut(usize, usize, usize)) {
    // Sort by y.
    let (mut v0, mut v1, mut v2) = (a, b, c);
    if v1.y < v0.y {
        std::mem::swap(&mut v0, &mut v1);
    }
    if v2.y < v1.y {
        std::mem::swap(&mut v1, &mut v2);
    }
    if v1.y < v0.y {
        std::mem::swap(&mut v0, &mut v1);
    }
    if !(v0.y.is_finite() && v2.y.is_finite() && v0.x.is_finite() && v1.x.is_finite() && v2.x.is_finite()) {
        return;
    }
    let hf = height as f32;
    let wf = width as f32;
    let y_start = ((v0.y - 0.5).ceil().max(0.0)) as i64;
    let y_end = ((v2.y - 0.5).ceil().min(hf)) as i64; // exclusive
    if y_start >= y_end {
        return;
    }
    let dy_long = v2.y - v0.y;
    if dy_long <= 0.0 {
        return;
    }
    let inv_long = (v2.x - v0.x) / dy_long;
    // Which side is the long edge on? Compare x of the long edge at v1.y with v1.x.
    let x_long_at_mid = v0.x + inv_long * (v1.y - v0.y);
    let long_is_left = x_long_at_mid < v1.x;
    let inv_top = if v1.y > v0.y { (v1.x - v0.x) / (v1.y - v0.y) } else { 0.0 };
    let inv_bot = if v2.y > v1.y { (v2.x - v1.x) / (v2.y - v1.y) } else { 0.0 };
    for y in y_start..y_end {
        let yc = y as f32 + 0.5;
        let xl_long = v0.x + inv_long * (yc - v0.y);
        let xs = if yc < v1.y { v0.x + inv_top * (yc - v0.y) } else { v1.x + inv_bot * (yc - v1.y) };
        let (xl, xr) = if long_is_left { (xl_long, xs) } else { (xs, xl_long) };
        let x0 = (xl - 0.5).ceil().max(0.0);
        let x1 = (xr - 0.5).ceil().min(wf);
        if x0 < x1 {
            span(y as usize, x0 as usize, x1 as usize);
        }
    }
}

/// 64 pixels of one colour, for span copies (3-byte pixels do not vectorise one by one).
#[inline(always)]
pub(crate) fn pattern(col: [u8; 3]) -> [u8; 192] {
    let mut p = [0u8; 192];
    for px in p.chunks_exact_mut(3) {
        px.copy_from_slice(&col);
    }
    p
}

/// Fills RGB8 bytes with a repeated colour pattern (`row.len()` a multiple of 3).
#[inline(always)]
pub(crate) fn fill_row(row: &mut [u8], pat: &[u8; 192]) {
    for chunk in row.chunks_mut(192) {
        let n = chunk.len();
        chunk.copy_from_slice(&pat[..n]);
    }
}

/// Fills a triangle with a flat colour (given as its [`pattern`]), no depth (painter's order).
pub(crate) fn fill_flat(t: &mut Target, a: SV, b: SV, c: SV, pat: &[u8; 192]) {
    let w = t.width;
    let rgb = &mut *t.rgb;
    for_spans(a, b, c, t.width, t.height, |y, x0, x1| {
        fill_row(&mut rgb[(y * w + x0) * 3..(y * w + x1) * 3], pat);
    });
}

/// Fills a triangle with depth test on 1/z (perspective-correct: 1/z is affine in screen space).
pub(crate) fn fill_depth(t: &mut Target, d: &mut DepthPlanes, a: SV, b: SV, c: SV, col: [u8; 3], id: u32) {
    // Plane of w over the screen: w = w0 + dwdx (x - a.x) + dwdy (y - a.y).
    let e1x = b.x - a.x;
    let e1y = b.y - a.y;
    let e2x = c.x - a.x;
    let e2y = c.y - a.y;
    let det = e1x * e2y - e2x * e1y;
    if det.abs() < 1e-12 {
        return;
    }
    let dw1 = b.w - a.w;
    let dw2 = c.w - a.w;
    let dwdx = (dw1 * e2y - dw2 * e1y) / det;
    let dwdy = (dw2 * e1x - dw1 * e2x) / det;
    let w = t.width;
    let rgb = &mut *t.rgb;
    let depth = &mut *d.depth;
    let mut ids = d.ids.as_deref_mut();
    for_spans(a, b, c, t.width, t.height, |y, x0, x1| {
        let yc = y as f32 + 0.5;
        let base = a.w + dwdy * (yc - a.y) + dwdx * (x0 as f32 + 0.5 - a.x);
        let drow = &mut depth[y * w + x0..y * w + x1];
        let crow = &mut rgb[(y * w + x0) * 3..(y * w + x1) * 3];
        let mut z = base;
        match ids.as_deref_mut() {
            None => {
                for (dz, px) in drow.iter_mut().zip(crow.chunks_exact_mut(3)) {
                    if z > *dz {
                        *dz = z;
                        px.copy_from_slice(&col);
                    }
                    z += dwdx;
                }
            }
            Some(ids) => {
                let irow = &mut ids[y * w + x0..y * w + x1];
                for ((dz, px), pid) in drow.iter_mut().zip(crow.chunks_exact_mut(3)).zip(irow.iter_mut()) {
                    if z > *dz {
                        *dz = z;
                        px.copy_from_slice(&col);
                        *pid = id;
                    }
                    z += dwdx;
                }
            }
        }
    });
}

/// Stamps the pixels a triangle covers into a mask (no depth), counting newly stamped ones.
pub(crate) fn fill_mask(
    mask: &mut [u32],
    width: usize,
    height: usize,
    a: SV,
    b: SV,
    c: SV,
    stamp: u32,
) -> usize {
    let mut n = 0;
    for_spans(a, b, c, width, height, |y, x0, x1| {
        for m in &mut mask[y * width + x0..y * width + x1] {
            if *m != stamp {
                *m = stamp;
                n += 1;
            }
        }
    });
    n
}

/// [`RasterBackend::fill_convex_aa`] into an RGB8 buffer: per row, the span where every edge's
/// half-plane (grown by half a pixel on anti-aliased edges) holds the pixel centre; the part where
/// anti-aliased edges are at least half a pixel away is filled solid, the fringe pixels blend by
/// the product of the edges' coverages `clamp(0.5 + distance, 0, 1)`.
pub(crate) fn fill_aa(rgb: &mut [u8], width: usize, height: usize, pts: &[SV], col: [u8; 3], aa_edges: u8) {
    let n = pts.len();
    if !(3..=8).contains(&n) || pts.iter().any(|p| !(p.x.is_finite() && p.y.is_finite())) {
        return;
    }
    let mut area = 0.0f32;
    for k in 0..n {
        let (a, b) = (pts[k], pts[(k + 1) % n]);
        area += a.x * b.y - b.x * a.y;
    }
    if area.abs() < 1e-6 {
        return;
    }
    let orient = area.signum();
    // Edge k: inward unit normal (nx, ny) and offset c, distance d(p) = nx px + ny py + c.
    let mut edges = [(0f32, 0f32, 0f32, false); 8];
    for (k, e) in edges.iter_mut().enumerate().take(n) {
        let (a, b) = (pts[k], pts[(k + 1) % n]);
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let len = (dx * dx + dy * dy).sqrt();
        if len < 1e-6 {
            *e = (0.0, 0.0, 1.0, false);
            continue;
        }
        // Left normal for counter-clockwise (y down: area < 0 is clockwise on screen).
        let (nx, ny) = (-dy / len * orient, dx / len * orient);
        *e = (nx, ny, -(nx * a.x + ny * a.y), aa_edges & (1 << k) != 0);
    }
    let (mut y0, mut y1) = (f32::MAX, f32::MIN);
    for p in pts {
        y0 = y0.min(p.y);
        y1 = y1.max(p.y);
    }
    let ys = ((y0 - 1.0).floor().max(0.0)) as usize;
    let ye = ((y1 + 1.0).ceil().min(height as f32)).max(0.0) as usize;
    let wf = width as f32;
    let pat = pattern(col);
    for y in ys..ye {
        let yc = y as f32 + 0.5;
        // Outer span (any coverage) and inner span (full coverage), as pixel-centre x bounds.
        let (mut lo, mut hi, mut ilo, mut ihi) = (0.5f32, wf - 0.5, 0.5f32, wf - 0.5);
        let mut empty = false;
        for &(nx, ny, c, aa) in &edges[..n] {
            let base = ny * yc + c;
            let (grow, shrink) = if aa { (0.5, 0.5) } else { (0.0, 0.0) };
            if nx.abs() < 1e-6 {
                if base < -grow {
                    empty = true;
                    break;
                }
                if base < shrink {
                    ilo = f32::MAX;
                }
                continue;
            }
            // d(x) = nx x + base ≥ t  ⇔  x ≥ (t - base) / nx  (nx > 0), else ≤.
            let xo = (-grow - base) / nx;
            let xi = (shrink - base) / nx;
            if nx > 0.0 {
                lo = lo.max(xo);
                ilo = ilo.max(xi);
            } else {
                hi = hi.min(xo);
                ihi = ihi.min(xi);
            }
        }
        if empty || lo > hi {
            continue;
        }
        // Pixels whose centre x + 0.5 lies in [lo, hi] (hard edges: half-open like the fills).
        let x0 = ((lo - 0.5).ceil().max(0.0)) as usize;
        let x1 = ((hi - 0.5).ceil().min(wf)).max(0.0) as usize;
        if x0 >= x1 {
            continue;
        }
        let (i0, i1) = if ilo <= ihi {
            let a = ((ilo - 0.5).ceil().max(x0 as f32)) as usize;
            let b = ((ihi - 0.5).ceil().min(x1 as f32)).max(a as f32) as usize;
            (a.min(x1), b.min(x1))
        } else {
            (x1, x1)
        };
        let row = &mut rgb[y * width * 3..(y + 1) * width * 3];
        for x in (x0..i0).chain(i1..x1) {
            let xc = x as f32 + 0.5;
            let mut cov = 1.0f32;
            for &(nx, ny, c, aa) in &edges[..n] {
                let d = nx * xc + ny * yc + c;
                cov *= if aa {
                    (d + 0.5).clamp(0.0, 1.0)
                } else if d >= 0.0 {
                    1.0
                } else {
                    0.0
                };
            }
            let k = (cov * 256.0) as u32;
            if k == 0 {
                continue;
            }
            for (px, c) in row[x * 3..x * 3 + 3].iter_mut().zip(col) {
                *px = ((*px as u32 * (256 - k) + c as u32 * k) >> 8) as u8;
            }
        }
        if i0 < i1 {
            fill_row(&mut row[i0 * 3..i1 * 3], &pat);
        }
    }
}

/// The primitives the cameras and the BEV draw with, in screen space (pixels; `SV::w` = 1/z
/// for depth-tested fills, ignored otherwise). Calls are made in painter's order; the views
/// are generic over the backend, so the per-primitive calls dispatch statically.
///
/// Only the fills are required; strokes and discs default to their fixed tessellation into
/// fills (the bytes every golden image depends on), and a backend may override them to keep
/// the shapes (a recorder, a vector backend).
pub(crate) trait RasterBackend {
    /// Paints each pixel row `y` in one colour `row_colour(y)`: a flat clear or the sky
    /// gradient. Depth and ids are not touched.
    fn fill_rows(&mut self, row_colour: &dyn Fn(usize) -> [u8; 3]);

    /// Fills a convex polygon (fewer than 3 points draw nothing), fanned from its first
    /// vertex, without a depth test.
    fn fill_convex(&mut self, pts: &[SV], col: [u8; 3]);

    /// Fills a convex polygon fanned from its first vertex, keeping pixels where it is nearer
    /// than what was drawn there (larger `w`); covered pixels take `id` (actor index + 1,
    /// 0 = none) for the projection helper.
    fn fill_convex_depth(&mut self, pts: &[SV], col: [u8; 3], id: u32);

    /// Fills a convex polygon without depth, anti-aliasing the edges whose bit is set in
    /// `aa_edges` (edge k runs from `pts[k]` to `pts[k + 1]`): their pixels blend the colour
    /// by analytic coverage. Edges shared with a neighbour drawn in the same colour stay hard,
    /// so pieces join without seams. Backends that cannot blend fill it hard.
    fn fill_convex_aa(&mut self, pts: &[SV], col: [u8; 3], _aa_edges: u8) {
        self.fill_convex(pts, col);
    }

    /// Darkens the pixels a convex polygon covers to `k / 256` of their colour (shadows on the
    /// ground), fanned from its first vertex, without depth. Backends that cannot blend skip it.
    fn darken_convex(&mut self, _pts: &[SV], _k: u16) {}

    /// Lights the pixels a convex polygon covers, without depth (light pools on the ground):
    /// `span(y, x0, row)` gets each covered run of row `y` from column `x0` as RGB bytes.
    /// Backends that cannot blend skip it.
    fn light_convex(&mut self, _pts: &[SV], _span: &mut dyn FnMut(usize, usize, &mut [u8])) {}

    /// Runs `f(rgb, depth, width, height)` over the finished frame (per-pixel weather); `depth`
    /// is empty without a depth plane. Backends that keep no pixels skip it.
    fn post(&mut self, _f: &mut PostPass) {}

    /// A thick segment a→b with square (butt) ends, half width `hw`.
    fn stroke_segment(&mut self, a: SV, b: SV, hw: f32, col: [u8; 3]) {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        let len = (dx * dx + dy * dy).sqrt();
        if len <= 1e-6 {
            return;
        }
        let (nx, ny) = (-dy / len * hw, dx / len * hw);
        let p = |s: &SV, k: f32| SV { x: s.x + nx * k, y: s.y + ny * k, w: 1.0 };
        self.fill_convex(&[p(&a, 1.0), p(&b, 1.0), p(&b, -1.0), p(&a, -1.0)], col);
    }

    /// A thick polyline, half width `hw`: round joins and a round cap at its last point (the
    /// first point stays square; the BEV's ego disc sits there).
    fn stroke_polyline(&mut self, pts: &[SV], hw: f32, col: [u8; 3]) {
        for w in pts.windows(2) {
            self.stroke_segment(w[0], w[1], hw, col);
            self.fill_disc(w[1], hw, col);
        }
    }

    /// A filled disc of radius `r`: a 12-gon, 24-gon above 6 px, fanned from the centre.
    fn fill_disc(&mut self, c: SV, r: f32, col: [u8; 3]) {
        let n = if r > 6.0 { 24 } else { 12 };
        let v = |i: usize| {
            let a = std::f32::consts::TAU * i as f32 / n as f32;
            SV { x: c.x + r * a.cos(), y: c.y + r * a.sin(), w: 1.0 }
        };
        for i in 0..n {
            self.fill_convex(&[c, v(i), v(i + 1)], col);
        }
    }
}

/// Which planes a [`SoftwareRaster`] frame keeps besides colour.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Planes {
    /// Colour only (the BEV); depth-tested fills then draw untested, in painter's order.
    #[default]
    Colour,
    /// Colour and depth (cameras).
    Depth,
    /// Colour, depth and actor ids (the projection helper).
    DepthIds,
}

/// The default backend: the scanline rasterizer above, into an RGB8 buffer it holds for one
/// frame (taken from the caller's [`super::Image`] and handed back, so no copy) plus depth and
/// id planes it keeps allocated across frames.
#[derive(Default)]
pub(crate) struct SoftwareRaster {
    rgb: Vec<u8>,
    width: usize,
    height: usize,
    planes: Planes,
    depth: Vec<f32>,
    ids: Vec<u32>,
}

impl SoftwareRaster {
    /// Starts a `width × height` frame on `rgb` (resized; colour unspecified until painted),
    /// with the `planes` reset to "nothing drawn" (depth 0 = infinitely far, id 0).
    pub fn begin(&mut self, mut rgb: Vec<u8>, width: usize, height: usize, planes: Planes) {
        rgb.resize(width * height * 3, 0);
        self.rgb = rgb;
        self.width = width;
        self.height = height;
        self.planes = planes;
        if planes != Planes::Colour {
            self.depth.clear();
            self.depth.resize(width * height, 0.0);
        }
        if planes == Planes::DepthIds {
            self.ids.clear();
            self.ids.resize(width * height, 0);
        }
    }

    /// Ends the frame, handing the colour buffer back.
    pub fn finish(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.rgb)
    }

    /// The id plane of the last [`Planes::DepthIds`] frame (row-major, one per pixel).
    pub fn ids(&self) -> &[u32] {
        &self.ids
    }

    fn target(&mut self) -> Target<'_> {
        Target { rgb: &mut self.rgb, width: self.width, height: self.height }
    }
}

impl std::fmt::Debug for SoftwareRaster {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SoftwareRaster")
            .field("depth_len", &self.depth.len())
            .field("ids_len", &self.ids.len())
            .finish()
    }
}

impl RasterBackend for SoftwareRaster {
    fn fill_rows(&mut self, row_colour: &dyn Fn(usize) -> [u8; 3]) {
        let w3 = self.width * 3;
        let mut last: Option<([u8; 3], [u8; 192])> = None;
        for (y, row) in self.rgb.chunks_exact_mut(w3.max(1)).enumerate() {
            let col = row_colour(y);
            let pat = match last {
                Some((c, p)) if c == col => p,
                _ => pattern(col),
            };
            fill_row(row, &pat);
            last = Some((col, pat));
        }
    }

    #[inline]
    fn fill_convex(&mut self, pts: &[SV], col: [u8; 3]) {
        if pts.len() < 3 {
            return;
        }
        let pat = pattern(col);
        let mut t = self.target();
        for k in 1..pts.len() - 1 {
            fill_flat(&mut t, pts[0], pts[k], pts[k + 1], &pat);
        }
    }

    fn fill_convex_aa(&mut self, pts: &[SV], col: [u8; 3], aa_edges: u8) {
        let (w, h) = (self.width, self.height);
        fill_aa(&mut self.rgb, w, h, pts, col, aa_edges);
    }

    fn darken_convex(&mut self, pts: &[SV], k: u16) {
        if pts.len() < 3 {
            return;
        }
        let (w, k) = (self.width, k as u32);
        for i in 1..pts.len() - 1 {
            let rgb = &mut self.rgb;
            for_spans(pts[0], pts[i], pts[i + 1], self.width, self.height, |y, x0, x1| {
                for c in &mut rgb[(y * w + x0) * 3..(y * w + x1) * 3] {
                    *c = ((*c as u32 * k) >> 8) as u8;
                }
            });
        }
    }

    fn light_convex(&mut self, pts: &[SV], span: &mut dyn FnMut(usize, usize, &mut [u8])) {
        if pts.len() < 3 {
            return;
        }
        let w = self.width;
        for i in 1..pts.len() - 1 {
            let rgb = &mut self.rgb;
            for_spans(pts[0], pts[i], pts[i + 1], self.width, self.height, |y, x0, x1| {
                span(y, x0, &mut rgb[(y * w + x0) * 3..(y * w + x1) * 3]);
            });
        }
    }

    fn post(&mut self, f: &mut PostPass) {
        let depth: &[f32] = if self.planes == Planes::Colour { &[] } else { &self.depth };
        f(&mut self.rgb, depth, self.width, self.height);
    }

    #[inline]
    fn fill_convex_depth(&mut self, pts: &[SV], col: [u8; 3], id: u32) {
        if self.planes == Planes::Colour {
            return self.fill_convex(pts, col);
        }
        if pts.len() < 3 {
            return;
        }
        let mut t = Target { rgb: &mut self.rgb, width: self.width, height: self.height };
        let ids = if self.planes == Planes::DepthIds { Some(&mut self.ids[..]) } else { None };
        let mut d = DepthPlanes { depth: &mut self.depth, ids };
        for k in 1..pts.len() - 1 {
            fill_depth(&mut t, &mut d, pts[0], pts[k], pts[k + 1], col, id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sv(x: f32, y: f32) -> SV {
        SV { x, y, w: 1.0 }
    }

    #[test]
    fn two_triangles_of_a_square_cover_each_pixel_once() {
        let (w, h) = (16, 16);
        let mut mask = vec![0u32; w * h];
        let n1 = fill_mask(&mut mask, w, h, sv(2.0, 2.0), sv(10.0, 2.0), sv(10.0, 10.0), 1);
        let n2 = fill_mask(&mut mask, w, h, sv(2.0, 2.0), sv(10.0, 10.0), sv(2.0, 10.0), 2);
        // No pixel of the shared diagonal is claimed by both triangles, none is missed.
        assert_eq!(n1 + n2, 64);
        assert_eq!(mask.iter().filter(|m| **m == 1).count(), n1);
        assert_eq!(mask.iter().filter(|m| **m != 0).count(), 64);
    }

    #[test]
    fn depth_test_keeps_nearest() {
        let (w, h) = (8, 8);
        let mut rgb = vec![0u8; w * h * 3];
        let mut depth = vec![0f32; w * h];
        let mut t = Target { rgb: &mut rgb, width: w, height: h };
        let mut d = DepthPlanes { depth: &mut depth, ids: None };
        let far = |x, y| SV { x, y, w: 0.1 };
        let near = |x, y| SV { x, y, w: 0.5 };
        fill_depth(&mut t, &mut d, near(0.0, 0.0), near(8.0, 0.0), near(0.0, 8.0), [255, 0, 0], 1);
        fill_depth(&mut t, &mut d, far(0.0, 0.0), far(8.0, 0.0), far(0.0, 8.0), [0, 255, 0], 2);
        assert_eq!(&rgb[0..3], &[255, 0, 0]);
    }
}

#[cfg(test)]
mod aa_tests {
    use super::*;

    fn sv(x: f32, y: f32) -> SV {
        SV { x, y, w: 1.0 }
    }

    fn render(pts: &[SV], aa: u8) -> Vec<u8> {
        let (w, h) = (48, 32);
        let mut rgb = vec![0u8; w * h * 3];
        fill_aa(&mut rgb, w, h, pts, [200, 200, 200], aa);
        rgb
    }

    #[test]
    fn hard_edges_match_the_plain_fill_and_aa_only_touches_the_edge() {
        // A slanted bar: long sides 0 and 2, ends 1 and 3.
        let quad = [sv(4.0, 6.0), sv(44.0, 14.0), sv(43.0, 19.0), sv(3.0, 11.0)];
        let mut plain = vec![0u8; 48 * 32 * 3];
        {
            let mut t = Target { rgb: &mut plain, width: 48, height: 32 };
            let pat = pattern([200, 200, 200]);
            fill_flat(&mut t, quad[0], quad[1], quad[2], &pat);
            fill_flat(&mut t, quad[0], quad[2], quad[3], &pat);
        }
        let hard = render(&quad, 0);
        let differ = plain.chunks_exact(3).zip(hard.chunks_exact(3)).filter(|(a, b)| a != b).count();
        // Only tie-breaking on the edges differs (the scanline fill rounds per row end).
        assert!(differ <= 12, "hard-edged fill differs from the scanline fill in {differ} pixels");
        let soft = render(&quad, 0b0101);
        assert_eq!(soft, render(&quad, 0b0101), "deterministic");
        let mut partial = 0;
        for (i, (a, b)) in hard.chunks_exact(3).zip(soft.chunks_exact(3)).enumerate() {
            if a != b {
                let (x, y) = ((i % 48) as f32 + 0.5, (i / 48) as f32 + 0.5);
                // Distance to either long side's line is under a pixel.
                let side = |p: SV, q: SV| {
                    let (dx, dy) = (q.x - p.x, q.y - p.y);
                    ((x - p.x) * dy - (y - p.y) * dx).abs() / (dx * dx + dy * dy).sqrt()
                };
                let d = side(quad[0], quad[1]).min(side(quad[2], quad[3]));
                assert!(d < 1.0, "pixel ({x}, {y}) {d} px from the long sides changed");
            }
            if b[0] > 0 && b[0] < 200 {
                partial += 1;
            }
        }
        assert!(partial >= 40, "too few partially covered pixels: {partial}");
    }

    #[test]
    fn joined_pieces_have_no_seam() {
        // Two pieces of one bar sharing a hard end edge: the joint's pixels are fully painted.
        let a = [sv(2.0, 10.0), sv(24.0, 12.0), sv(23.7, 16.0), sv(1.7, 14.0)];
        let b = [sv(24.0, 12.0), sv(46.0, 14.0), sv(45.7, 18.0), sv(23.7, 16.0)];
        let (w, h) = (48, 32);
        let mut rgb = vec![0u8; w * h * 3];
        fill_aa(&mut rgb, w, h, &a, [200, 200, 200], 0b0101);
        fill_aa(&mut rgb, w, h, &b, [200, 200, 200], 0b0101);
        for x in 20..28 {
            assert_eq!(rgb[(14 * w + x) * 3], 200, "seam at x = {x}");
        }
    }
}
