//! A 2D screen: windows (simple polygons, each with a texture) over a background texture, and
//! which of them is under the finger, with a hysteresis band around every outline.
//!
//! Rules (docs/plane.md):
//! - **Topmost wins.** Windows may touch, overlap or nest; declaration order is the stacking
//!   order, window 0 on top. Declare a nested window before the one that holds it, or it is
//!   never entered.
//! - **Stay.** The finger stays in the current window until it is more than band/2 outside it.
//! - **Enter.** From the background, or from a window below it, a window is entered once the
//!   finger is band/2 inside it (the topmost such).
//! - **Leave.** Leaving a window lands in the topmost window containing the finger, or the
//!   background. Two windows that share an edge so switch band/2 past it either way.
//!
//! Every rule reads the signed distance to an outline (positive inside), which changes by at
//! most the distance the finger moves: a switch happens within band/2 of the outline, plus the
//! position noise, plus one sample's travel (docs/plane.md derives it). The same property
//! makes the per-sample path cheap: after a full evaluation the tracker keeps how far the
//! finger may move before any rule's answer can change, and skips every sample inside that.

use heapless::Vec;

use super::geometry::{contains, GeometryError, PointUm, Polygon, Seg, MAX_VERTICES};

/// Most windows a screen may have.
pub const MAX_WINDOWS: usize = 8;
/// Default hysteresis band, µm: band/2 = 100 µm either side of an outline, the 1D regions'
/// default (> 8 σ of 3 LSB noise per axis, 12 µm).
pub const DEFAULT_BAND_UM: u32 = 200;
/// Widest band, µm: band/2 = 5 mm, the 1D regions' largest hysteresis.
pub const MAX_BAND_UM: u32 = 10_000;

/// One window as the scene states it.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Window {
    /// Its outline.
    pub outline: Polygon,
    /// Index of its texture in the scene's texture table.
    pub texture: u8,
}

/// A screen as the scene states it.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Screen {
    /// The windows, topmost first.
    pub windows: Vec<Window, MAX_WINDOWS>,
    /// Texture index of the background (outside every window).
    pub background_texture: u8,
    /// Hysteresis band around every outline, µm (band/2 each side).
    pub band_um: u32,
}

/// What is under the finger.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Place {
    /// No window: the background.
    #[default]
    Background,
    /// Window `i` (its index in [`Screen::windows`]).
    Window(u8),
}

/// Why a screen was refused. Each variant carries the values its sentence (`Display`) names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum ScreenError {
    /// A window's outline is not a valid polygon.
    Outline {
        /// The window.
        window: u8,
        /// Why.
        error: GeometryError,
    },
    /// The band is zero or above [`MAX_BAND_UM`].
    Band {
        /// The band asked for, µm.
        band_um: u32,
    },
    /// A texture index beyond the scene's textures (`window` None: the background's).
    Texture {
        /// The window, or None for the background.
        window: Option<u8>,
        /// The index given.
        texture: u8,
        /// How many textures the scene has.
        textures: usize,
    },
    /// A window no wider (or taller) than the band: the finger could never be band/2 inside.
    TooSmall {
        /// The window.
        window: u8,
        /// Its bounding box's smaller side, µm.
        side_um: u32,
        /// The band, µm.
        band_um: u32,
    },
}

impl core::fmt::Display for ScreenError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::Milli;
        let mm = |um: u32| Milli(um as u64);
        match *self {
            ScreenError::Outline { window, error } => write!(f, "window {window}: {error}"),
            ScreenError::Band { band_um } => write!(
                f,
                "band {} mm is outside 0.001 mm to {} mm",
                mm(band_um),
                mm(MAX_BAND_UM)
            ),
            ScreenError::Texture {
                window,
                texture,
                textures,
            } => {
                match window {
                    Some(w) => write!(f, "window {w}")?,
                    None => f.write_str("the background")?,
                }
                write!(
                    f,
                    " names texture {texture}, but the scene has {textures} (0 to {})",
                    textures.saturating_sub(1)
                )
            }
            ScreenError::TooSmall {
                window,
                side_um,
                band_um,
            } => write!(
                f,
                "window {window} is {} mm across, not wider than the band ({} mm): it could \
                 never be entered",
                mm(side_um),
                mm(band_um)
            ),
        }
    }
}

/// A window, compiled: its vertices for the exact containment test, its edges prepared for
/// distances, and its bounding box (f32, µm).
#[derive(Clone, Debug)]
struct Compiled {
    vertices: Vec<PointUm, MAX_VERTICES>,
    segs: Vec<Seg, MAX_VERTICES>,
    lo: (f32, f32),
    hi: (f32, f32),
    texture: u8,
}

impl Compiled {
    /// Distance from `p` to the outline, µm (unsigned).
    fn distance_um(&self, p: PointUm) -> f32 {
        let d2 = self
            .segs
            .iter()
            .map(|s| s.distance2_um2(p))
            .fold(f32::INFINITY, f32::min);
        super::geometry::sqrt_f32(d2)
    }

    /// How far `p` lies outside the bounding box grown by `grow` µm (Chebyshev: a lower bound
    /// of the Euclidean distance); ≤ 0 inside it.
    #[inline]
    fn box_gap(&self, x: f32, y: f32, grow: f32) -> f32 {
        (self.lo.0 - grow - x)
            .max(x - self.hi.0 - grow)
            .max(self.lo.1 - grow - y)
            .max(y - self.hi.1 - grow)
    }
}

/// A validated screen, ready for [`ScreenTracker::update`].
#[derive(Clone, Debug)]
pub struct CompiledScreen {
    windows: Vec<Compiled, MAX_WINDOWS>,
    background_texture: u8,
    /// band/2, µm.
    half_band_um: f32,
}

impl Screen {
    /// Validates the screen against a scene of `textures` textures and prepares it.
    pub fn compile(&self, textures: usize) -> Result<CompiledScreen, ScreenError> {
        if self.band_um == 0 || self.band_um > MAX_BAND_UM {
            return Err(ScreenError::Band {
                band_um: self.band_um,
            });
        }
        if self.background_texture as usize >= textures {
            return Err(ScreenError::Texture {
                window: None,
                texture: self.background_texture,
                textures,
            });
        }
        let mut windows = Vec::new();
        for (i, w) in self.windows.iter().enumerate() {
            let window = i as u8;
            w.outline
                .validate()
                .map_err(|error| ScreenError::Outline { window, error })?;
            if w.texture as usize >= textures {
                return Err(ScreenError::Texture {
                    window: Some(window),
                    texture: w.texture,
                    textures,
                });
            }
            let (lo, hi) = w.outline.bounds();
            // Coordinates are within ±1 m (validated): the differences fit u32.
            let side_um = (hi.x_um.abs_diff(lo.x_um)).min(hi.y_um.abs_diff(lo.y_um));
            if side_um <= self.band_um {
                return Err(ScreenError::TooSmall {
                    window,
                    side_um,
                    band_um: self.band_um,
                });
            }
            let mut segs = Vec::new();
            for e in w.outline.edges() {
                // Capacity: as many edges as vertices.
                let _ = segs.push(Seg::new(e));
            }
            // Capacity: as many compiled windows as declared ones.
            let _ = windows.push(Compiled {
                vertices: w.outline.vertices.clone(),
                segs,
                lo: (lo.x_um as f32, lo.y_um as f32),
                hi: (hi.x_um as f32, hi.y_um as f32),
                texture: w.texture,
            });
        }
        Ok(CompiledScreen {
            windows,
            background_texture: self.background_texture,
            half_band_um: self.band_um as f32 / 2.0,
        })
    }
}

impl CompiledScreen {
    /// The texture index of `place`.
    pub fn texture(&self, place: Place) -> u8 {
        match place {
            Place::Background => self.background_texture,
            Place::Window(i) => self
                .windows
                .get(i as usize)
                .map_or(self.background_texture, |w| w.texture),
        }
    }

    /// Number of windows.
    pub fn windows(&self) -> usize {
        self.windows.len()
    }

    /// Where the finger at `p` is, having been in `current` (the module's rules, evaluated in
    /// full). Also returns a distance the finger may move, µm, before the answer can change
    /// (0 after a switch).
    pub fn locate(&self, p: PointUm, current: Place) -> (Place, f32) {
        let h = self.half_band_um;
        let (x, y) = (p.x_um as f32, p.y_um as f32);
        let n = self.windows.len();
        let above = match current {
            Place::Window(c) if (c as usize) < n => c as usize,
            _ => n,
        };
        let mut clear = f32::INFINITY;
        // Enter: the topmost window above the current one the finger is band/2 inside.
        for (v, w) in self.windows.iter().enumerate().take(above) {
            // {sd ≥ h} lies within the box shrunk by h.
            let gap = w.box_gap(x, y, -h);
            if gap > 0.0 {
                clear = clear.min(gap);
                continue;
            }
            if !contains(&w.vertices, p) {
                // sd < 0: at least h from the threshold.
                clear = clear.min(h);
                continue;
            }
            let sd = w.distance_um(p);
            if sd >= h {
                return (Place::Window(v as u8), 0.0);
            }
            clear = clear.min(h - sd);
        }
        let Some(c) = self.windows.get(above) else {
            return (Place::Background, clear);
        };
        // Stay: the current window until the finger is more than band/2 outside it.
        let gap = c.box_gap(x, y, h);
        if gap <= 0.0 {
            if contains(&c.vertices, p) {
                // sd ≥ 0: sd + h from the threshold −h. The distance is worked out only when
                // it can widen the clearance beyond h (the windows above may bound it first):
                // one distance here lets the finger cross most of a window with no full
                // evaluation, where h alone (100 µm by default) asked for one every h of travel.
                if clear <= h {
                    return (current, clear);
                }
                return (current, clear.min(h + c.distance_um(p)));
            }
            let sd = -c.distance_um(p);
            if sd >= -h {
                return (current, clear.min(sd + h));
            }
        }
        // Leave: the topmost window holding the finger, or the background.
        let place = self
            .windows
            .iter()
            .position(|w| contains(&w.vertices, p))
            .map_or(Place::Background, |v| Place::Window(v as u8));
        (place, 0.0)
    }
}

/// The finger's place on a screen, carried from sample to sample.
#[derive(Clone, Copy, Debug, Default)]
pub struct ScreenTracker {
    place: Place,
    /// Where the last full evaluation was made and how far from there the finger may move
    /// (L1, µm) with nothing changing.
    settled: Option<(PointUm, f32)>,
    /// Full evaluations made (tests: the fast path is the optimisation, and only a count can
    /// tell it from a full evaluation, which gives the same answer).
    #[cfg(test)]
    evaluations: u32,
}

/// Rounding allowance of the settled distance, µm: f32 distances of coordinates up to 1 m are
/// good to 0.1 µm; 1 µm leaves room.
const SETTLE_MARGIN_UM: f32 = 1.0;

impl ScreenTracker {
    /// Starts in `place` (the background after a fault or a load: the first sample places the
    /// finger by the entry rule).
    pub fn new(place: Place) -> Self {
        Self {
            place,
            ..Self::default()
        }
    }

    /// Forgets the place (fault, scene load): back to the background.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Full evaluations made so far (tests).
    #[cfg(test)]
    pub(crate) fn evaluations(&self) -> u32 {
        self.evaluations
    }

    /// The place now.
    pub fn place(&self) -> Place {
        self.place
    }

    /// One sample at `p`: the place under the finger.
    ///
    /// Every rule compares a signed distance to an outline, which moves by at most the finger's
    /// travel (Euclidean ≤ L1). So while the finger is within the settled distance (L1) of the
    /// last full evaluation, the answer is the same and nothing is computed.
    #[inline]
    pub fn update(&mut self, screen: &CompiledScreen, p: PointUm) -> Place {
        self.track(screen, p).0
    }

    /// [`Self::update`], and whether the rules were evaluated on this sample: false means the
    /// place is the one the last sample answered (a caller keeping its own copy of the place
    /// needs no compare then).
    #[inline(always)]
    pub fn track(&mut self, screen: &CompiledScreen, p: PointUm) -> (Place, bool) {
        if let Some((at, clear)) = self.settled {
            let moved = p.x_um.abs_diff(at.x_um) as f32 + p.y_um.abs_diff(at.y_um) as f32;
            if moved < clear {
                return (self.place, false);
            }
        }
        #[cfg(test)]
        {
            self.evaluations += 1;
        }
        let (place, clear) = screen.locate(p, self.place);
        self.place = place;
        self.settled = (clear > SETTLE_MARGIN_UM).then_some((p, clear - SETTLE_MARGIN_UM));
        (place, true)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plane::testing::{directions, sigma_um, Noise, PERIOD_US};
    use std::vec::Vec as StdVec;

    fn pt(x: i32, y: i32) -> PointUm {
        PointUm::new(x, y)
    }

    fn rect(x0: i32, y0: i32, x1: i32, y1: i32) -> Polygon {
        Polygon::rectangle(pt(x0, y0), pt(x1, y1)).unwrap()
    }

    /// The L of geometry's tests, 20 mm: reflex corner at (10, 10) mm.
    fn ell() -> Polygon {
        Polygon::from_points(&[
            pt(0, 0),
            pt(20_000, 0),
            pt(20_000, 10_000),
            pt(10_000, 10_000),
            pt(10_000, 20_000),
            pt(0, 20_000),
        ])
        .unwrap()
    }

    fn screen(windows: &[Polygon], band_um: u32) -> CompiledScreen {
        Screen {
            windows: windows
                .iter()
                .enumerate()
                .map(|(i, o)| Window {
                    outline: o.clone(),
                    texture: i as u8 + 1,
                })
                .collect(),
            background_texture: 0,
            band_um,
        }
        .compile(windows.len() + 1)
        .unwrap()
    }

    /// Signed distance by the textbook formula in f64 (independent of the code under test),
    /// and containment by the winding angle.
    fn sd_ref(poly: &Polygon, x: f64, y: f64) -> f64 {
        let v = &poly.vertices;
        let (mut best, mut wind) = (f64::INFINITY, 0.0f64);
        for i in 0..v.len() {
            let (a, b) = (v[i], v[(i + 1) % v.len()]);
            let (ax, ay) = (a.x_um as f64 - x, a.y_um as f64 - y);
            let (bx, by) = (b.x_um as f64 - x, b.y_um as f64 - y);
            let (dx, dy) = (bx - ax, by - ay);
            let t = (-(ax * dx + ay * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            best = best.min(((ax + t * dx).powi(2) + (ay + t * dy).powi(2)).sqrt());
            wind += (ax * by - ay * bx).atan2(ax * bx + ay * by);
        }
        if wind.abs() > core::f64::consts::PI {
            best
        } else {
            -best
        }
    }

    #[test]
    fn hysteresis_by_hand_on_a_square() {
        // A 10 mm square, band 200 µm: enter 100 µm inside, leave 100 µm outside.
        let s = screen(&[rect(0, 0, 10_000, 10_000)], 200);
        let mut t = ScreenTracker::default();
        for (x, want) in [
            (-500, Place::Background),
            (50, Place::Background),   // inside, but not band/2 in
            (99, Place::Background),   // 1 µm short
            (100, Place::Window(0)),   // band/2 in: entered
            (-100, Place::Window(0)),  // band/2 out: stays
            (-101, Place::Background), // past band/2: left
            (99, Place::Background),   // not re-entered short of band/2
            (10_000 - 100, Place::Window(0)),
            (10_100, Place::Window(0)),
            (10_101, Place::Background),
        ] {
            assert_eq!(t.update(&s, pt(x, 5_000)), want, "x = {x}");
        }
    }

    #[test]
    fn touching_windows_switch_band_half_past_the_shared_edge_either_way() {
        // A (0) and B (1) share the edge x = 10 mm.
        let s = screen(
            &[rect(0, 0, 10_000, 10_000), rect(10_000, 0, 20_000, 10_000)],
            200,
        );
        let mut t = ScreenTracker::default();
        assert_eq!(t.update(&s, pt(5_000, 5_000)), Place::Window(0));
        assert_eq!(t.update(&s, pt(10_100, 5_000)), Place::Window(0));
        assert_eq!(t.update(&s, pt(10_101, 5_000)), Place::Window(1));
        // Back: B is below A, so A is entered band/2 inside it.
        assert_eq!(t.update(&s, pt(9_901, 5_000)), Place::Window(1));
        assert_eq!(t.update(&s, pt(9_900, 5_000)), Place::Window(0));
    }

    #[test]
    fn across_a_shared_edge_with_noise_the_switch_is_direct_in_any_direction() {
        // A (0) and B (1) share x = 10 mm. Strokes through (10, 5) mm in the 6 directions not
        // parallel to it, 20–200 mm/s, 2 LSB: one switch each, straight from one window to the
        // other (never through the background), within [h − E, h + E + vT] past the edge.
        let s = screen(
            &[rect(0, 0, 10_000, 10_000), rect(10_000, 0, 20_000, 10_000)],
            200,
        );
        let mut noise = Noise::new(12);
        let sigma = sigma_um(2.0);
        let mut strokes = 0;
        for (dx, dy) in directions() {
            if dx.abs() < 0.5 {
                continue;
            }
            for v_mm_s in [20.0, 50.0, 100.0, 200.0] {
                let step = v_mm_s * 1000.0 * PERIOD_US as f64 / 1e6;
                let (x0, y0) = (10_000.0 - 3_000.0 * dx, 5_000.0 - 3_000.0 * dy);
                let mut t = ScreenTracker::default();
                let (mut last, mut switches, mut e_max) = (None, StdVec::new(), 0.0f64);
                for k in 0..=(6_000.0 / step) as usize {
                    let (x, y) = (x0 + k as f64 * step * dx, y0 + k as f64 * step * dy);
                    let (ex, ey) = (noise.gauss() * sigma, noise.gauss() * sigma);
                    e_max = e_max.max((ex * ex + ey * ey).sqrt());
                    let place = t.update(&s, pt((x + ex).round() as i32, (y + ey).round() as i32));
                    if last.is_some_and(|l| l != place) {
                        switches.push((place, (x - 10_000.0) * dx.signum()));
                    }
                    last = Some(place);
                }
                let e = e_max + 0.71;
                assert_eq!(switches.len(), 1, "({dx}, {dy}) {v_mm_s}: {switches:?}");
                let (place, past_um) = switches[0];
                let want = if dx > 0.0 {
                    Place::Window(1)
                } else {
                    Place::Window(0)
                };
                assert_eq!(place, want);
                // Past the edge along x (the distance to it), E and one sample's travel.
                assert!(
                    past_um >= 100.0 - e && past_um <= 100.0 + e + step,
                    "{past_um}"
                );
                strokes += 1;
            }
        }
        assert_eq!(strokes, 6 * 4);
    }

    #[test]
    fn nested_windows_topmost_wins() {
        // A small window (0) declared before the big one (1) that holds it.
        let s = screen(
            &[rect(4_000, 4_000, 6_000, 6_000), rect(0, 0, 10_000, 10_000)],
            200,
        );
        let mut t = ScreenTracker::default();
        assert_eq!(t.update(&s, pt(1_000, 5_000)), Place::Window(1));
        assert_eq!(t.update(&s, pt(4_099, 5_000)), Place::Window(1));
        assert_eq!(t.update(&s, pt(4_100, 5_000)), Place::Window(0));
        assert_eq!(t.update(&s, pt(3_900, 5_000)), Place::Window(0));
        assert_eq!(t.update(&s, pt(3_899, 5_000)), Place::Window(1));
        // Declared the other way round the small one is covered: never entered.
        let hidden = screen(
            &[rect(0, 0, 10_000, 10_000), rect(4_000, 4_000, 6_000, 6_000)],
            200,
        );
        let mut t = ScreenTracker::default();
        for x in (1_000..9_000).step_by(10) {
            assert_eq!(t.update(&hidden, pt(x, 5_000)), Place::Window(0));
        }
    }

    #[test]
    fn the_settled_skip_answers_as_a_full_evaluation() {
        // Random walks (steps up to 300 µm, some jumps) over overlapping, touching, nested and
        // concave windows: the tracker with its skip and a full evaluation on every sample
        // agree on every sample, and the skip saves most evaluations.
        let s = screen(
            &[
                rect(4_000, 4_000, 6_000, 6_000),
                ell(),
                rect(15_000, 5_000, 30_000, 25_000),
                rect(20_000, 0, 30_000, 5_000),
            ],
            200,
        );
        let mut noise = Noise::new(7);
        let (mut skipped, mut samples) = (0u32, 0u32);
        for _ in 0..20 {
            let mut t = ScreenTracker::default();
            let mut full = Place::Background;
            let (mut x, mut y) = (noise.uniform() * 30_000.0, noise.uniform() * 25_000.0);
            for _ in 0..5_000 {
                if noise.uniform() < 0.002 {
                    (x, y) = (noise.uniform() * 30_000.0, noise.uniform() * 25_000.0);
                } else {
                    x += noise.gauss() * 60.0;
                    y += noise.gauss() * 60.0;
                }
                let p = pt(x as i32, y as i32);
                full = s.locate(p, full).0;
                assert_eq!(t.update(&s, p), full, "{p:?}");
                samples += 1;
            }
            skipped += samples - t.evaluations;
            samples = 0;
        }
        assert!(skipped > 20 * 2_500, "only {skipped} samples skipped");
    }

    /// Strokes at 20–200 mm/s in 8 directions through points on an outline, with 2 LSB noise:
    /// one switch per stroke that crosses the outline once, placed where the band says. Leaving
    /// window c: the true signed distance to c at the switch is within
    /// [−h − E − vT, −h + E]; entering v: within [h − E, h + E + vT] (E the largest noise
    /// vector of the stroke, vT one sample's travel).
    #[test]
    fn switches_fall_within_the_band_plus_noise_and_a_sample_in_any_direction() {
        let l = ell();
        let s = screen(&[l.clone()], 200);
        let h = 100.0;
        // On-outline targets: edge midpoints, and 0.3 mm either side of the reflex corner.
        let targets = [
            (10_000.0, 0.0),
            (20_000.0, 5_000.0),
            (15_000.0, 10_000.0),
            (10_000.0, 15_000.0),
            (0.0, 10_000.0),
            (10_300.0, 10_000.0),
            (10_000.0, 10_300.0),
            (0.0, 300.0), // 0.3 mm from a convex corner
        ];
        let sigma = sigma_um(2.0);
        let mut noise = Noise::new(36);
        let (mut strokes, mut worst_late) = (0, 0.0f64);
        for &(tx, ty) in &targets {
            for (dx, dy) in directions() {
                for v_mm_s in [20.0, 50.0, 100.0, 200.0] {
                    let step = v_mm_s * 1000.0 * PERIOD_US as f64 / 1e6;
                    // From 3 mm before the target to 3 mm past it.
                    let (x0, y0) = (tx - 3_000.0 * dx, ty - 3_000.0 * dy);
                    let n = (6_000.0 / step) as usize;
                    let path: StdVec<(f64, f64)> = (0..=n)
                        .map(|k| (x0 + k as f64 * step * dx, y0 + k as f64 * step * dy))
                        .collect();
                    // Keep strokes that cross the outline exactly once, clearly (start and end
                    // more than the band away), by the reference distance.
                    let sds: StdVec<f64> = path.iter().map(|&(x, y)| sd_ref(&l, x, y)).collect();
                    let changes = sds
                        .windows(2)
                        .filter(|w| (w[0] > 0.0) != (w[1] > 0.0))
                        .count();
                    if changes != 1 || sds[0].abs() < 500.0 || sds[n].abs() < 500.0 {
                        continue;
                    }
                    strokes += 1;
                    let mut t = ScreenTracker::new(if sds[0] > 0.0 {
                        Place::Window(0)
                    } else {
                        Place::Background
                    });
                    let mut e_max = 0.0f64;
                    let mut switches = StdVec::new();
                    let mut last = t.place();
                    for (k, &(x, y)) in path.iter().enumerate() {
                        let (ex, ey) = (noise.gauss() * sigma, noise.gauss() * sigma);
                        e_max = e_max.max((ex * ex + ey * ey).sqrt());
                        let p = pt((x + ex).round() as i32, (y + ey).round() as i32);
                        let place = t.update(&s, p);
                        if place != last {
                            switches.push((k, place, sds[k]));
                            last = place;
                        }
                    }
                    // Rounding to the µm grid adds up to 0.71 µm.
                    let e = e_max + 0.71;
                    assert_eq!(
                        switches.len(),
                        1,
                        "{tx},{ty} dir ({dx},{dy}) {v_mm_s}: {switches:?}"
                    );
                    let (_, place, sd) = switches[0];
                    if place == Place::Window(0) {
                        assert!(sd >= h - e && sd <= h + e + step, "enter at {sd} (E {e})");
                        worst_late = worst_late.max(sd - h);
                    } else {
                        assert!(sd <= -h + e && sd >= -h - e - step, "leave at {sd} (E {e})");
                        worst_late = worst_late.max(-sd - h);
                    }
                }
            }
        }
        // 8 targets × 8 directions × 4 speeds = 256, less the grazing and double crossings.
        assert!(strokes >= 120, "only {strokes} strokes crossed cleanly");
        std::println!("{strokes} strokes; worst switch {worst_late:.1} µm past band/2");
    }

    #[test]
    fn a_finger_anywhere_answers_without_panicking() {
        let s = screen(&[ell(), rect(30_000, 0, 40_000, 10_000)], 200);
        let mut t = ScreenTracker::default();
        for p in [
            pt(i32::MIN, i32::MIN),
            pt(5_000, 5_000),
            pt(i32::MAX, 0),
            pt(0, i32::MAX),
        ] {
            let _ = t.update(&s, p);
        }
        assert_eq!(t.update(&s, pt(i32::MIN, 0)), Place::Background);
        assert_eq!(
            s.texture(Place::Window(200)),
            0,
            "an unknown window reads as background"
        );
    }

    #[test]
    fn refusals() {
        let ok = Screen {
            windows: [Window {
                outline: rect(0, 0, 1_000, 1_000),
                texture: 1,
            }]
            .into_iter()
            .collect(),
            background_texture: 0,
            band_um: 200,
        };
        assert!(ok.compile(2).is_ok());
        let e = |s: &Screen, n| s.compile(n).err().map(|e| std::format!("{e}"));
        assert_eq!(
            e(&ok, 1),
            Some("window 0 names texture 1, but the scene has 1 (0 to 0)".into())
        );
        let mut bg = ok.clone();
        bg.background_texture = 2;
        assert_eq!(
            e(&bg, 2),
            Some("the background names texture 2, but the scene has 2 (0 to 1)".into())
        );
        let mut band = ok.clone();
        band.band_um = 0;
        assert_eq!(
            e(&band, 2),
            Some("band 0 mm is outside 0.001 mm to 10 mm".into())
        );
        band.band_um = 10_001;
        assert!(band.compile(2).is_err());
        band.band_um = 1_000;
        assert_eq!(
            e(&band, 2),
            Some(
                "window 0 is 1 mm across, not wider than the band (1 mm): it could never be \
                 entered"
                    .into()
            )
        );
        let mut bad = ok.clone();
        bad.windows[0].outline.vertices.truncate(2);
        assert_eq!(
            e(&bad, 2),
            Some("window 0: a polygon has 2 vertices and needs 3 to 16".into())
        );
    }
}
