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
pub const fn cycle_colour(i: usize) -> [u8; 3] {
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
