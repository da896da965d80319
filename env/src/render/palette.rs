//! Colour names and the one body-colour palette: which sRGB colour a name renders with, and
//! which rendered colours a careful person (and the question generator) calls by that name.
//!
//! A name's range is a region of HSV space (hue in degrees, saturation and value in 0..=1).
//! The renderer's noon lighting keeps every palette entry inside its own range on the faces the
//! sun lights (see `mesh::shade`); `tests` render each entry and check it. The generator names a
//! colour from an actor's rendered pixels with [`name_pixels`].

use serde::Serialize;

/// A range of HSV space that one colour name covers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ColourRange {
    /// Hue interval in degrees [from, to); `from > to` wraps through 0. Ignored for achromatic
    /// names (`max_saturation` < 1).
    pub hue_deg: [f32; 2],
    pub min_saturation: f32,
    pub max_saturation: f32,
    /// Value (max channel / 255) interval [from, to).
    pub value: [f32; 2],
}

/// One named colour: the sRGB body colour it renders with and the range of its name.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NamedColour {
    pub name: &'static str,
    pub rgb: [u8; 3],
    pub range: ColourRange,
}

/// Saturation below which a colour is achromatic (white, silver, gray, black).
const GRAY_S: f32 = 0.16;

const fn achromatic(v0: f32, v1: f32) -> ColourRange {
    ColourRange { hue_deg: [0.0, 360.0], min_saturation: 0.0, max_saturation: GRAY_S, value: [v0, v1] }
}
const fn hue(h0: f32, h1: f32, v0: f32, v1: f32) -> ColourRange {
    ColourRange { hue_deg: [h0, h1], min_saturation: GRAY_S, max_saturation: 1.01, value: [v0, v1] }
}

/// Every colour name, in the order [`name_of`] tries them. Black is any very dark colour, so it
/// comes first; brown is dark orange
/// (orange is the same hues above it).
pub const PALETTE: [NamedColour; 11] = [
    NamedColour { name: "black", rgb: [34, 34, 36], range: hue_any_dark() },
    NamedColour { name: "white", rgb: [240, 240, 238], range: achromatic(0.75, 1.01) },
    NamedColour { name: "silver", rgb: [166, 167, 169], range: achromatic(0.53, 0.75) },
    NamedColour { name: "gray", rgb: [112, 112, 116], range: achromatic(0.27, 0.53) },
    NamedColour { name: "brown", rgb: [122, 74, 38], range: hue(14.0, 42.0, 0.27, 0.58) },
    NamedColour { name: "red", rgb: [200, 32, 32], range: hue(336.0, 14.0, 0.27, 1.01) },
    NamedColour { name: "orange", rgb: [240, 128, 24], range: hue(14.0, 42.0, 0.58, 1.01) },
    NamedColour { name: "yellow", rgb: [226, 190, 30], range: hue(42.0, 70.0, 0.27, 1.01) },
    NamedColour { name: "green", rgb: [40, 150, 68], range: hue(70.0, 170.0, 0.27, 1.01) },
    NamedColour { name: "blue", rgb: [36, 88, 204], range: hue(170.0, 258.0, 0.27, 1.01) },
    NamedColour { name: "purple", rgb: [138, 58, 160], range: hue(258.0, 336.0, 0.27, 1.01) },
];

const fn hue_any_dark() -> ColourRange {
    ColourRange { hue_deg: [0.0, 360.0], min_saturation: 0.0, max_saturation: 1.01, value: [0.0, 0.27] }
}

/// Body colours handed out in turn to actors without one (scenario actors, native traffic):
/// indices into [`PALETTE`], chosen so neighbours differ strongly.
pub const ACTOR_CYCLE: [usize; 8] = [5, 9, 1, 0, 7, 8, 10, 3];

/// The `i`-th default actor colour (see [`ACTOR_CYCLE`]).
pub fn cycle_colour(i: usize) -> [u8; 3] {
    PALETTE[ACTOR_CYCLE[i % ACTOR_CYCLE.len()]].rgb
}

/// sRGB → (hue degrees 0..360, saturation 0..=1, value 0..=1).
pub fn hsv(rgb: [u8; 3]) -> (f32, f32, f32) {
    let [r, g, b] = rgb.map(|c| c as f32 / 255.0);
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let s = if max > 0.0 { d / max } else { 0.0 };
    let h = if d <= 0.0 {
        0.0
    } else if max == r {
        60.0 * ((g - b) / d).rem_euclid(6.0)
    } else if max == g {
        60.0 * ((b - r) / d + 2.0)
    } else {
        60.0 * ((r - g) / d + 4.0)
    };
    (h, s, max)
}

impl ColourRange {
    pub fn contains(&self, rgb: [u8; 3]) -> bool {
        let (h, s, v) = hsv(rgb);
        if !(s >= self.min_saturation && s < self.max_saturation) {
            return false;
        }
        if !(v >= self.value[0] && v < self.value[1]) {
            return false;
        }
        let [h0, h1] = self.hue_deg;
        if h0 <= h1 {
            h >= h0 && h < h1
        } else {
            h >= h0 || h < h1
        }
    }
}

/// The name of one rendered colour: the first [`PALETTE`] entry whose range holds it. Every
/// sRGB colour has exactly one name (the ranges tile HSV space; a test checks it).
pub fn name_of(rgb: [u8; 3]) -> &'static str {
    PALETTE.iter().find(|c| c.range.contains(rgb)).map_or("gray", |c| c.name)
}

/// The colour name a person gives an object from its rendered pixels (e.g. the pixels an id
/// buffer assigns to one actor). Glazing, tyres and shaded faces are darker than sunlit paint,
/// so the brightest half of the pixels decides, by majority of their names (ties go to the
/// earlier palette entry). `None` for no pixels.
pub fn name_pixels(pixels: &[[u8; 3]]) -> Option<&'static str> {
    if pixels.is_empty() {
        return None;
    }
    let luma = |p: &[u8; 3]| 299 * p[0] as u32 + 587 * p[1] as u32 + 114 * p[2] as u32;
    let mut l: Vec<u32> = pixels.iter().map(luma).collect();
    l.sort_unstable();
    let cut = l[l.len() / 2];
    let mut votes = [0usize; PALETTE.len()];
    for p in pixels.iter().filter(|p| luma(p) >= cut) {
        let name = name_of(*p);
        if let Some(i) = PALETTE.iter().position(|c| c.name == name) {
            votes[i] += 1;
        }
    }
    let best = (0..PALETTE.len()).max_by_key(|&i| (votes[i], std::cmp::Reverse(i)))?;
    Some(PALETTE[best].name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::{Pose, Vec2};
    use crate::map::Network;
    use crate::render::mesh::{self, dot, LIT_MIN_COS, PAINT_BIT, SUN};
    use crate::render::{CameraConfig, FrameInput, RenderMap, Renderer};
    use crate::view::{ActorKind, ActorView};

    #[test]
    fn every_colour_has_exactly_one_name() {
        for r in (0..=255u32).step_by(5) {
            for g in (0..=255u32).step_by(5) {
                for b in (0..=255u32).step_by(5) {
                    let c = [r as u8, g as u8, b as u8];
                    // Black (any dark colour) overlaps the others by design: it is tried first.
                    let n = PALETTE[1..].iter().filter(|p| p.range.contains(c)).count();
                    let dark = PALETTE[0].range.contains(c);
                    assert!(n == 1 || (dark && n <= 1), "{c:?} is in {n} ranges");
                }
            }
        }
    }

    #[test]
    fn palette_entries_are_named_by_their_own_range() {
        for c in PALETTE {
            assert_eq!(name_of(c.rgb), c.name, "{c:?}");
        }
    }

    fn view(kind: ActorKind, rgb: [u8; 3], yaw: f64, (l, w, h): (f64, f64, f64)) -> ActorView {
        ActorView {
            id: 1,
            kind,
            pose: Pose::new(Vec2::new(12.0, -0.5), yaw),
            speed_mps: 0.0,
            length_m: l,
            width_m: w,
            height_m: h,
            color: rgb,
            braking: false,
            blinkers: 0,
        }
    }

    const BODIES: [(ActorKind, (f64, f64, f64)); 8] = [
        (ActorKind::Car, (4.6, 1.85, 1.45)),
        (ActorKind::Car, (4.8, 1.95, 1.75)),
        (ActorKind::Car, (5.4, 2.05, 2.35)),
        (ActorKind::Bus, (0.0, 0.0, 0.0)),
        (ActorKind::Truck, (0.0, 0.0, 0.0)),
        (ActorKind::Motorcycle, (0.0, 0.0, 0.0)),
        (ActorKind::Cyclist, (0.0, 0.0, 0.0)),
        (ActorKind::Pedestrian, (0.0, 0.0, 0.0)),
    ];

    /// Every sunlit painted face of every body, in every palette colour, at any heading, is
    /// shaded into its colour's range.
    #[test]
    fn sunlit_paint_stays_in_its_name_range() {
        let sun = {
            let n = dot(SUN, SUN).sqrt();
            SUN.map(|v| v / n)
        };
        let mut tris = Vec::new();
        for c in PALETTE {
            for (kind, dims) in BODIES {
                for k in 0..16 {
                    tris.clear();
                    let yaw = k as f64 * std::f64::consts::TAU / 16.0;
                    mesh::actor(&mut tris, &view(kind, c.rgb, yaw, dims), Vec2::new(0.0, 0.0), 1, true);
                    let mut lit = 0;
                    for t in tris.iter().filter(|t| t.id & PAINT_BIT != 0 && dot(t.n, sun) >= LIT_MIN_COS) {
                        assert!(
                            c.range.contains(t.col),
                            "{} {kind:?} yaw {yaw:.2}: lit face {:?}",
                            c.name,
                            t.col
                        );
                        lit += 1;
                    }
                    assert!(lit > 0, "{} {kind:?} yaw {yaw:.2}: no sunlit paint", c.name);
                }
            }
        }
    }

    /// Rendered through the front camera at 12 m on town01 at noon, each palette colour is named
    /// by its own name from the actor's visible paint, from several headings.
    #[test]
    fn rendered_actors_are_named_by_their_colour() {
        let net =
            Network::from_file(std::path::Path::new("../scenarios/maps/town01/town01.net.xml")).unwrap();
        let map = RenderMap::build(&net);
        let lane = net.lane_by_id("W2C_1").unwrap();
        let ego_pose = net.lane_position(lane, net.lanes[lane].shape.length() - 75.0);
        let ego =
            ActorView { id: 0, pose: ego_pose, ..view(ActorKind::Car, [30, 110, 230], 0.0, (0.0, 0.0, 0.0)) };
        let mut r = Renderer::new();
        let mut failures = Vec::new();
        for c in PALETTE {
            for (kind, dims) in BODIES {
                for dyaw in [0.0, 0.6, 1.6, 2.6, 3.1] {
                    let d = if kind == ActorKind::Bus || kind == ActorKind::Truck { 20.0 } else { 12.0 };
                    let pose = Pose::new(ego_pose.local_to_world(d, -0.5), ego_pose.yaw + dyaw);
                    let a = ActorView { pose, ..view(kind, c.rgb, 0.0, dims) };
                    let frame =
                        FrameInput { ego: &ego, actors: &[a], lights: &[], signs: &[], route_points: &[] };
                    let found = r.project_actors(&map, &frame, &CameraConfig::front()).unwrap();
                    let got = found.first().and_then(|p| p.colour_name);
                    if got != Some(c.name) {
                        failures.push(format!("{} {kind:?} {dims:?} dyaw {dyaw}: named {got:?}", c.name));
                    }
                }
            }
        }
        assert!(failures.is_empty(), "{} misnamed:\n{}", failures.len(), failures.join("\n"));
    }

    #[test]
    fn brightest_pixels_decide() {
        let white = [240, 240, 238];
        let glass = [40, 55, 75];
        let px = [white, white, white, glass, glass, [20, 20, 20]];
        assert_eq!(name_pixels(&px), Some("white"));
        assert_eq!(name_pixels(&[]), None);
    }
}
