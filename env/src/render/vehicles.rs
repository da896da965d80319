//! Vehicle meshes: a low-poly body per type (sedan, SUV, van, bus, truck), glazing, round
//! wheels, head and tail lamps, brake lamps and indicators from the view's state, and the
//! emergency light bar of a vehicle whose beacons flash.
//!
//! Body paint is the actor's colour unscaled on every panel, so lighting alone decides how it
//! reads (see `palette`). The body type of a car follows its size: the scenario format and
//! traffic give vehicles as car/bus/truck with dimensions, so a tall car is an SUV or a van.

use super::mesh::{all, Frame, Mesh};
use crate::view::{ActorKind, ActorView, BLINKER_LEFT, BLINKER_RIGHT};

/// Glazing: dark, a little sky-blue from reflection.
pub(crate) const GLASS: [u8; 3] = [50, 64, 82];
const TYRE: [u8; 3] = [24, 24, 26];
const RIM: [u8; 3] = [165, 168, 172];
const TRIM: [u8; 3] = [30, 30, 33];
const AMBER: [u8; 3] = [255, 165, 0];
const HEADLAMP: [u8; 3] = [228, 230, 222];
const TAIL_OFF: [u8; 3] = [112, 24, 26];
const HEADLAMP_LIT: [u8; 3] = [255, 252, 235];
const TAIL_LIT: [u8; 3] = [205, 22, 22];
const BRAKE_ON: [u8; 3] = [255, 36, 30];
const PLATE: [u8; 3] = [225, 225, 215];
pub(crate) const BEACON_RED: [u8; 3] = [255, 28, 28];
pub(crate) const BEACON_RED_DIM: [u8; 3] = [118, 24, 28];
pub(crate) const BEACON_BLUE: [u8; 3] = [40, 105, 255];
pub(crate) const BEACON_BLUE_DIM: [u8; 3] = [26, 42, 118];
/// Beacons swap every 0.25 s (5 ticks of `DT_S`), a 2 Hz flash. A decision comes every
/// `DECISION_INTERVAL_TICKS` = 5 ticks, so consecutive decisions see the two halves swapped.
pub(crate) const BEACON_HALF_PERIOD_TICKS: u64 = 5;
const _: () = assert!(BEACON_HALF_PERIOD_TICKS as f64 * crate::DT_S == 0.25);

/// Whether the red half of a light bar is the bright one at world tick `tick` (the blue half
/// is bright otherwise): a pure function of sim time, so frames stay byte-identical.
pub(crate) fn beacon_red_lit(tick: u64) -> bool {
    (tick / BEACON_HALF_PERIOD_TICKS) % 2 == 0
}

/// What a vehicle looks like.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum BodyType {
    Sedan,
    Suv,
    Van,
    Bus,
    Truck,
}

pub(crate) fn body_type(kind: ActorKind, h: f32) -> BodyType {
    match kind {
        ActorKind::Bus => BodyType::Bus,
        ActorKind::Truck => BodyType::Truck,
        _ if h >= 1.95 => BodyType::Van,
        _ if h >= 1.62 => BodyType::Suv,
        _ => BodyType::Sedan,
    }
}

impl Mesh<'_> {
    /// A flat rectangle on a plane of constant forward offset `fwd` in `fr`, facing +forward
    /// (`facing` = 1) or backward (-1): centred at (left, z), half width `hw`, half height `hh`.
    #[allow(clippy::too_many_arguments)]
    pub fn panel(
        &mut self,
        fr: &Frame,
        fwd: f32,
        left: f32,
        z: f32,
        hw: f32,
        hh: f32,
        facing: f32,
        col: [u8; 3],
        emissive: bool,
    ) {
        let c = fr.pt(fwd - facing, left, z);
        let (a, b, cc, d) = (
            fr.pt(fwd, left + hw, z - hh),
            fr.pt(fwd, left - hw, z - hh),
            fr.pt(fwd, left - hw, z + hh),
            fr.pt(fwd, left + hw, z + hh),
        );
        self.quad(a, b, cc, d, c, col, emissive);
    }

    /// A flat rectangle on a side of the body (constant `left`), facing outward (sign of
    /// `left`): spans [f0, f1] forward and [z0, z1] up.
    #[allow(clippy::too_many_arguments)]
    pub fn side_panel(&mut self, fr: &Frame, left: f32, f0: f32, f1: f32, z0: f32, z1: f32, col: [u8; 3]) {
        let c = fr.pt((f0 + f1) * 0.5, left - left.signum(), (z0 + z1) * 0.5);
        let (a, b, cc, d) =
            (fr.pt(f0, left, z0), fr.pt(f1, left, z0), fr.pt(f1, left, z1), fr.pt(f0, left, z1));
        self.quad(a, b, cc, d, c, col, false);
    }
}

/// Lamps on the front (at `front`) and rear (at `rear`) faces, centred at height `z`, lamp
/// centres `hw_lamp` from the centre line.
#[allow(clippy::too_many_arguments)]
fn lamps(m: &mut Mesh, fr: &Frame, front: f32, rear: f32, z: f32, hw_lamp: f32, size: f32, a: &ActorView) {
    // At night the lamps burn: head lamps bright and a little larger (their glare), tail lamps
    // dim red until the brake lights them fully.
    let tail = match (a.braking, m.lit) {
        (true, _) => BRAKE_ON,
        (false, true) => TAIL_LIT,
        (false, false) => TAIL_OFF,
    };
    for side in [-1.0f32, 1.0] {
        let left = side * hw_lamp;
        if m.lit {
            m.panel(fr, front + 0.02, left, z, size * 1.35, size * 0.75, 1.0, HEADLAMP_LIT, true);
        } else {
            m.panel(fr, front + 0.02, left, z, size * 1.1, size * 0.55, 1.0, HEADLAMP, false);
        }
        m.panel(fr, rear - 0.02, left, z, size, size * 0.6, -1.0, tail, a.braking || m.lit);
        // Indicators beside the lamps; lit ones are drawn steadily (a single frame, which is all a
        // model sees per decision, must show them). Unlit ones stay as the lamp's housing.
        let bit = if side > 0.0 { BLINKER_LEFT } else { BLINKER_RIGHT };
        if a.blinkers & bit != 0 {
            let out = left + side * size * 1.5;
            m.panel(fr, front + 0.03, out, z, size * 0.42, size * 0.5, 1.0, AMBER, true);
            m.panel(fr, rear - 0.03, out, z, size * 0.42, size * 0.5, -1.0, AMBER, true);
        }
    }
}

/// Centre of a rear light bar ahead of the rear face: its lamps end flush with that face, so a
/// camera below a tall roof still sees them from behind.
const REAR_BAR: f32 = 0.15;

/// A light bar across the roof at (`fwd`, `z`), `half_across` wide each side: a dark base, the
/// red half on the vehicle's left and the blue half on its right. The bright half is emissive
/// (it reads at noon and glows at night); the dim one is a lit, unlit-lamp red or blue.
fn light_bar(m: &mut Mesh, fr: &Frame, fwd: f32, z: f32, half_across: f32, tick: u64) {
    let (hd, hh) = (0.15f32, 0.085f32);
    m.bx(fr, fwd, 0.0, z, z + 0.04, hd + 0.02, half_across + 0.02, &all(TRIM));
    let red_lit = beacon_red_lit(tick);
    let q = half_across * 0.5;
    for (left, lit, on, dim) in
        [(q, red_lit, BEACON_RED, BEACON_RED_DIM), (-q, !red_lit, BEACON_BLUE, BEACON_BLUE_DIM)]
    {
        let start = m.out.len();
        let col = if lit { on } else { dim };
        m.bx(fr, fwd, left, z + 0.04, z + 0.04 + 2.0 * hh, hd, q - 0.015, &all(col));
        if lit {
            for t in &mut m.out[start..] {
                t.col = on;
                t.emissive = true;
            }
        }
    }
}

fn wheels(m: &mut Mesh, fr: &Frame, hw: f32, r: f32, axles: &[f32], n: usize) {
    for &x in axles {
        for side in [-1.0f32, 1.0] {
            m.wheel(fr, x, side * (hw - 0.14), r, 0.14, n, side, TYRE, RIM);
        }
    }
}

/// Appends one vehicle (car, bus or truck) of length `l`, width `w`, height `h`; `tick` (the
/// world tick) sets the phase of its beacons, if they flash.
#[allow(clippy::too_many_arguments)]
pub(crate) fn vehicle(
    m: &mut Mesh,
    fr: &Frame,
    a: &ActorView,
    l: f32,
    w: f32,
    h: f32,
    detail: bool,
    tick: u64,
) {
    let (hl, hw) = (l * 0.5, w * 0.5);
    let col = a.color;
    let n = if detail { 10 } else { 5 };
    match body_type(a.kind, h) {
        BodyType::Sedan | BodyType::Suv => {
            let suv = body_type(a.kind, h) == BodyType::Suv;
            let r = if suv { (h * 0.2).clamp(0.33, 0.42) } else { (h * 0.21).clamp(0.28, 0.35) };
            let axle = hl - 0.8 - r * 0.4;
            wheels(m, fr, hw, r, &[axle, -axle], n);
            let z0 = r * 0.8;
            let zb = if suv { h * 0.56 } else { h * 0.55 };
            // Lower body: bonnet and boot taper back from the bumpers.
            m.tbox(fr, 0.0, 0.0, z0, zb, [hl, hl, hw], [hl - 0.14, hl - 0.06, hw - 0.03], &all(col));
            // Cabin: raked windscreen, near-vertical tailgate on an SUV, glass all round.
            let (cb, ct) = if suv {
                ([0.58 * hl, 0.92 * hl, hw - 0.05], [0.36 * hl, 0.88 * hl, hw - 0.14])
            } else {
                ([0.5 * hl, 0.58 * hl, hw - 0.05], [0.18 * hl, 0.34 * hl, hw - 0.18])
            };
            let cab = [col, col, GLASS, GLASS, GLASS, GLASS];
            m.tbox(fr, -0.06 * hl, 0.0, zb, h, cb, ct, &cab);
            if a.beacon {
                light_bar(m, fr, -0.06 * hl + (ct[0] - ct[1]) * 0.5, h, ct[2] - 0.04, tick);
            }
            // Grille and number plates.
            m.panel(fr, hl + 0.01, 0.0, zb - 0.2, hw * 0.42, 0.07, 1.0, TRIM, false);
            m.panel(fr, -hl - 0.01, 0.0, z0 + 0.14, 0.24, 0.055, -1.0, PLATE, false);
            lamps(m, fr, hl - 0.07, -hl + 0.03, zb - 0.1, hw - 0.24, 0.12, a);
            if a.braking {
                // Centre high-mounted brake lamp under the rear window.
                m.panel(fr, -hl + 0.03, 0.0, zb + 0.05, 0.16, 0.025, -1.0, BRAKE_ON, true);
            }
        }
        BodyType::Van => {
            let r = (h * 0.16).clamp(0.33, 0.4);
            let axle = hl - 0.75 - r * 0.3;
            wheels(m, fr, hw, r, &[axle, -axle + 0.1], n);
            let z0 = r * 0.8;
            let zb = h * 0.42;
            let nose = 0.7f32.min(hl * 0.3);
            m.tbox(fr, 0.0, 0.0, z0, zb, [hl, hl, hw], [hl - 0.08, hl, hw], &all(col));
            // Tall box with a short sloped windscreen at the front.
            m.tbox(
                fr,
                0.0,
                0.0,
                zb,
                h,
                [hl - nose * 0.6, hl, hw],
                [hl - nose * 1.5, hl, hw - 0.06],
                &[col, col, GLASS, col, col, col],
            );
            if a.beacon {
                light_bar(m, fr, hl - nose * 1.5 - 0.3, h, hw - 0.16, tick);
                light_bar(m, fr, REAR_BAR - hl, h, hw - 0.16, tick);
            }
            // Cab side windows over the front door, both sides.
            let (f1, f0) = (hl - nose * 0.9, hl - nose * 0.9 - 0.75);
            for side in [-1.0f32, 1.0] {
                m.side_panel(fr, side * (hw + 0.01), f0, f1, zb + 0.15, h - 0.3, GLASS);
            }
            m.panel(fr, hl + 0.01, 0.0, zb - 0.25, hw * 0.45, 0.08, 1.0, TRIM, false);
            m.panel(fr, -hl - 0.01, 0.0, z0 + 0.16, 0.24, 0.055, -1.0, PLATE, false);
            lamps(m, fr, hl - 0.06, -hl, zb - 0.12, hw - 0.2, 0.13, a);
        }
        BodyType::Bus => {
            let r = 0.52;
            wheels(m, fr, hw, r, &[hl - 2.6, -hl + 3.2], n);
            let zb = h * 0.38;
            m.bx(fr, 0.0, 0.0, r * 0.55, zb, hl, hw, &all(col));
            // Window band round the bus, a roof band above it.
            m.bx(fr, 0.0, 0.0, zb, h * 0.86, hl - 0.02, hw - 0.02, &[col, col, GLASS, GLASS, GLASS, GLASS]);
            m.bx(fr, 0.0, 0.0, h * 0.86, h, hl, hw, &all(col));
            if a.beacon {
                light_bar(m, fr, hl - 1.0, h, hw - 0.2, tick);
                light_bar(m, fr, REAR_BAR - hl, h, hw - 0.2, tick);
            }
            // Pillars every 2 m break the glazing into windows; the front door on the right.
            let k = ((l - 2.0) / 2.0).floor().max(1.0) as usize;
            for i in 0..=k {
                let x = -hl + 1.0 + i as f32 * (l - 2.0) / k as f32;
                for side in [-1.0f32, 1.0] {
                    m.side_panel(fr, side * (hw + 0.005), x - 0.09, x + 0.09, zb, h * 0.86, col);
                }
            }
            m.side_panel(fr, -(hw + 0.01), hl - 2.1, hl - 1.0, 0.35, h * 0.84, [60, 68, 80]);
            // Destination display over the windscreen.
            m.panel(fr, hl + 0.01, 0.0, h * 0.81, hw * 0.6, 0.12, 1.0, [255, 176, 40], true);
            lamps(m, fr, hl, -hl, r * 1.1, hw - 0.25, 0.14, a);
        }
        BodyType::Truck => {
            let r = 0.5;
            let cab_l = 2.3f32.min(l * 0.4);
            wheels(m, fr, hw - 0.05, r, &[hl - 1.2, -hl + 1.4, -hl + 2.6], n);
            let cab_c = hl - cab_l * 0.5;
            m.bx(fr, cab_c, 0.0, r * 0.6, h * 0.47, cab_l * 0.5, hw, &all(col));
            m.tbox(
                fr,
                cab_c,
                0.0,
                h * 0.47,
                h * 0.82,
                [cab_l * 0.5, cab_l * 0.5, hw],
                [cab_l * 0.5 - 0.25, cab_l * 0.5, hw - 0.05],
                &[col, col, GLASS, GLASS, col, GLASS],
            );
            m.panel(fr, hl + 0.01, 0.0, h * 0.3, hw * 0.6, 0.25, 1.0, TRIM, false);
            // Chassis rails under a cargo box in the body colour.
            let box_l = l - cab_l - 0.25;
            let box_c = -hl + box_l * 0.5;
            m.bx(fr, box_c, 0.0, r * 0.7, r * 1.45, box_l * 0.5, hw * 0.55, &all(TRIM));
            m.bx(fr, box_c, 0.0, r * 1.45, h, box_l * 0.5, hw, &all(col));
            // On the box roof just behind the cab, the highest surface, and at its rear edge.
            if a.beacon {
                light_bar(m, fr, box_c + box_l * 0.5 - 0.3, h, hw - 0.15, tick);
                light_bar(m, fr, REAR_BAR - hl, h, hw - 0.15, tick);
            }
            lamps(m, fr, hl, -hl, r * 1.3, hw - 0.3, 0.14, a);
        }
    }
}
