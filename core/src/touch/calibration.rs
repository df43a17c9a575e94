//! Touch calibration: three touched points and where they should be give the affine map from
//! raw X/Y codes to µm on the screen — offset, scale, rotation and shear in one — as touch
//! controllers calibrate (TI, "Calibration in touch-screen systems", Analog Applications
//! Journal 3Q 2007, SLYT277: X = A·x + B·y + C, Y = D·x + E·y + F from three point pairs).
//!
//! Solved exactly in integers: with the third pair as origin, u_i = x_i − x_3, v_i = y_i − y_3
//! and P_i = X_i − X_3 for i = 1, 2, Cramer's rule gives A = (P_1·v_2 − P_2·v_1)/Δ and
//! B = (u_1·P_2 − u_2·P_1)/Δ with Δ = u_1·v_2 − u_2·v_1 (likewise D, E from the Y targets). The
//! map keeps the numerators and Δ and divides once per axis per frame, so no coefficient is
//! rounded: X = X_3 + (A_n·(x − x_3) + B_n·(y − y_3))/Δ. Codes are 16 bits and targets at most
//! 10^6 µm (21 bits with sign), so a numerator is under 2^38 and a product sum under 2^55: i64
//! holds every step. (The core's `fixed` crate has I16F16, whose 15 integer bits do not hold
//! a µm coordinate; a wider fixed type would still round the coefficients.)
//!
//! Refused: points too close together or too nearly on one line (their triangle's least height
//! below a floor), for the touched codes and for the targets, and touched codes in a rail band.

use super::fault::RailBands;
use crate::sample::CODE_FULL_SCALE;
use core::fmt;

/// One calibration pair: where the finger touched (raw codes, the 16-conversion sums of the X
/// and Y phases) and where the target was drawn, µm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CalPoint {
    /// X phase code at the touch.
    pub x_code: u16,
    /// Y phase code at the touch.
    pub y_code: u16,
    /// The target's X, µm.
    pub x_um: i32,
    /// The target's Y, µm.
    pub y_um: i32,
}

/// Least distance between two touched points, codes: an eighth of full scale (7.5 mm on a
/// 60 mm axis). Closer points leave the map's scale to a few hundred codes of noise.
pub const MIN_SEPARATION_CODE: u32 = CODE_FULL_SCALE / 8;
/// Least height of the touched points' triangle, codes: a sixteenth of full scale. Nearly on
/// one line, the map's component across that line rests on the height alone.
pub const MIN_HEIGHT_CODE: u32 = CODE_FULL_SCALE / 16;
/// Least distance, and least triangle height, of the targets, µm.
pub const MIN_TARGET_SEPARATION_UM: u32 = 1_000;
/// Largest target coordinate magnitude, µm (1 m, the 1D stage's longest substrate).
pub const MAX_TARGET_UM: i32 = 1_000_000;

/// Why a calibration was refused. Points are numbered 1 to 3 as given.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum AffineError {
    /// Two touched points closer than [`MIN_SEPARATION_CODE`].
    TouchesTooClose {
        /// The first point's number.
        first: u8,
        /// The second point's number.
        second: u8,
        /// Their distance, codes (rounded down).
        distance_code: u32,
    },
    /// The touched points' triangle is lower than [`MIN_HEIGHT_CODE`].
    TouchesCollinear {
        /// Its least height, codes (rounded down).
        height_code: u32,
    },
    /// A touched code lies in a rail band: it would read as a fault.
    TouchInRail {
        /// The point's number.
        point: u8,
        /// `x_code` rather than `y_code`.
        x: bool,
        /// The code.
        code: u16,
    },
    /// Two targets closer than [`MIN_TARGET_SEPARATION_UM`].
    TargetsTooClose {
        /// The first point's number.
        first: u8,
        /// The second point's number.
        second: u8,
        /// Their distance, µm (rounded down).
        distance_um: u32,
    },
    /// The targets' triangle is lower than [`MIN_TARGET_SEPARATION_UM`].
    TargetsCollinear {
        /// Its least height, µm (rounded down).
        height_um: u32,
    },
    /// A target coordinate beyond ±[`MAX_TARGET_UM`].
    TargetOutOfRange {
        /// The point's number.
        point: u8,
        /// `x_um` rather than `y_um`.
        x: bool,
        /// The coordinate, µm.
        um: i32,
    },
}

impl fmt::Display for AffineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            AffineError::TouchesTooClose {
                first,
                second,
                distance_code,
            } => write!(
                f,
                "touched points {first} and {second} are {distance_code} codes apart, fewer \
                 than the {MIN_SEPARATION_CODE} a calibration needs"
            ),
            AffineError::TouchesCollinear { height_code } => write!(
                f,
                "the touched points lie nearly on one line: their triangle is {height_code} \
                 codes high, less than the {MIN_HEIGHT_CODE} a calibration needs"
            ),
            AffineError::TouchInRail { point, x, code } => write!(
                f,
                "touched point {point}'s {} {code} is inside a rail band and would read as a \
                 fault",
                if x { "x_code" } else { "y_code" }
            ),
            AffineError::TargetsTooClose {
                first,
                second,
                distance_um,
            } => write!(
                f,
                "targets {first} and {second} are {distance_um} µm apart, fewer than the \
                 {MIN_TARGET_SEPARATION_UM} µm a calibration needs"
            ),
            AffineError::TargetsCollinear { height_um } => write!(
                f,
                "the targets lie nearly on one line: their triangle is {height_um} µm high, \
                 less than the {MIN_TARGET_SEPARATION_UM} µm a calibration needs"
            ),
            AffineError::TargetOutOfRange { point, x, um } => write!(
                f,
                "target {point}'s {} {um} µm is beyond ±{MAX_TARGET_UM} µm",
                if x { "x_um" } else { "y_um" }
            ),
        }
    }
}

/// The affine map from raw codes to µm, kept as exact integer numerators over Δ > 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Affine {
    /// The third pair, the map's origin: codes and µm.
    x3_code: i64,
    y3_code: i64,
    x3_um: i64,
    y3_um: i64,
    /// A·Δ, B·Δ, D·Δ, E·Δ.
    a: i64,
    b: i64,
    d: i64,
    e: i64,
    /// Δ, made positive.
    det: i64,
}

/// Twice the signed area of the triangle, and its longest side squared.
fn triangle(p: [(i64, i64); 3]) -> (i64, i128) {
    let [(x1, y1), (x2, y2), (x3, y3)] = p;
    let det = (x1 - x3) * (y2 - y3) - (x2 - x3) * (y1 - y3);
    let sq = |(ax, ay): (i64, i64), (bx, by): (i64, i64)| {
        let (dx, dy) = ((ax - bx) as i128, (ay - by) as i128);
        dx * dx + dy * dy
    };
    let longest = sq(p[0], p[1]).max(sq(p[1], p[2])).max(sq(p[2], p[0]));
    (det, longest)
}

/// The least height of the triangle: 2·area / longest side, floored.
fn least_height(det: i64, longest_sq: i128) -> u32 {
    if longest_sq == 0 {
        return 0;
    }
    // h² = det² / longest², floored, then its integer square root.
    let h_sq = (det as i128 * det as i128) / longest_sq;
    isqrt(h_sq)
}

/// Distance between two points, floored.
fn distance(a: (i64, i64), b: (i64, i64)) -> u32 {
    let (dx, dy) = ((a.0 - b.0) as i128, (a.1 - b.1) as i128);
    isqrt(dx * dx + dy * dy)
}

/// ⌊√n⌋ for n ≥ 0, saturated to u32 (Newton's method on integers).
fn isqrt(n: i128) -> u32 {
    if n <= 0 {
        return 0;
    }
    let n = n as u128;
    let mut x = n;
    let mut y = x.div_ceil(2);
    while y < x {
        x = y;
        y = (x + n / x) / 2;
    }
    u32::try_from(x).unwrap_or(u32::MAX)
}

const PAIRS: [(usize, usize); 3] = [(0, 1), (1, 2), (0, 2)];

impl Affine {
    /// Solves the map from three pairs, checking them against `rails` and the floors above.
    pub fn from_points(points: [CalPoint; 3], rails: &RailBands) -> Result<Self, AffineError> {
        for (i, p) in points.iter().enumerate() {
            let point = i as u8 + 1;
            for (x, code) in [(true, p.x_code), (false, p.y_code)] {
                if !rails.inside(code) {
                    return Err(AffineError::TouchInRail { point, x, code });
                }
            }
            for (x, um) in [(true, p.x_um), (false, p.y_um)] {
                if um.unsigned_abs() > MAX_TARGET_UM as u32 {
                    return Err(AffineError::TargetOutOfRange { point, x, um });
                }
            }
        }
        let raw = points.map(|p| (p.x_code as i64, p.y_code as i64));
        let target = points.map(|p| (p.x_um as i64, p.y_um as i64));
        for (i, j) in PAIRS {
            let (first, second) = (i as u8 + 1, j as u8 + 1);
            let (Some(ri), Some(rj)) = (raw.get(i), raw.get(j)) else {
                continue;
            };
            let distance_code = distance(*ri, *rj);
            if distance_code < MIN_SEPARATION_CODE {
                return Err(AffineError::TouchesTooClose {
                    first,
                    second,
                    distance_code,
                });
            }
            let (Some(ti), Some(tj)) = (target.get(i), target.get(j)) else {
                continue;
            };
            let distance_um = distance(*ti, *tj);
            if distance_um < MIN_TARGET_SEPARATION_UM {
                return Err(AffineError::TargetsTooClose {
                    first,
                    second,
                    distance_um,
                });
            }
        }
        let (det, longest) = triangle(raw);
        let height_code = least_height(det, longest);
        if height_code < MIN_HEIGHT_CODE {
            return Err(AffineError::TouchesCollinear { height_code });
        }
        let (tdet, tlongest) = triangle(target);
        let height_um = least_height(tdet, tlongest);
        if height_um < MIN_TARGET_SEPARATION_UM {
            return Err(AffineError::TargetsCollinear { height_um });
        }
        let [(x1, y1), (x2, y2), (x3, y3)] = raw;
        let [(tx1, ty1), (tx2, ty2), (tx3, ty3)] = target;
        let (u1, v1, u2, v2) = (x1 - x3, y1 - y3, x2 - x3, y2 - y3);
        let (p1, p2) = (tx1 - tx3, tx2 - tx3);
        let (q1, q2) = (ty1 - ty3, ty2 - ty3);
        // Δ > 0: flip every numerator with it.
        let s = if det < 0 { -1 } else { 1 };
        Ok(Self {
            x3_code: x3,
            y3_code: y3,
            x3_um: tx3,
            y3_um: ty3,
            a: s * (p1 * v2 - p2 * v1),
            b: s * (u1 * p2 - u2 * p1),
            d: s * (q1 * v2 - q2 * v1),
            e: s * (u1 * q2 - u2 * q1),
            det: s * det,
        })
    }

    /// The µm a raw code pair maps to, rounded to the nearest µm (halves away from zero) and
    /// saturated to `i32`. Not clamped to the screen: a touch outside the calibrated triangle
    /// maps outside it, as the 1D map's slack does before its clamp.
    pub fn map(&self, x_code: u16, y_code: u16) -> (i32, i32) {
        let du = x_code as i64 - self.x3_code;
        let dv = y_code as i64 - self.y3_code;
        let x = self.x3_um + div_round(self.a * du + self.b * dv, self.det);
        let y = self.y3_um + div_round(self.d * du + self.e * dv, self.det);
        (saturate(x), saturate(y))
    }
}

/// n / d rounded half away from zero, for d > 0 (the map keeps Δ positive; 0 answers 0).
fn div_round(n: i64, d: i64) -> i64 {
    if d <= 0 {
        return 0;
    }
    if n >= 0 {
        (n + d / 2) / d
    } else {
        -((-n + d / 2) / d)
    }
}

fn saturate(v: i64) -> i32 {
    // A clamp, not a try_from with a sign test: the same values, and no `<` whose `<=`
    // twin (equal only at 0, which fits) would be an equivalent mutant.
    v.clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ground-truth screen: the panel is rotated by `angle_deg`, scaled by `um_per_code` on
    /// each axis and offset, so a touch at screen point (X, Y) µm reads the codes got by
    /// inverting that — built in floating point here, independently of the integer solver.
    struct Truth {
        angle_deg: f64,
        sx_um_per_code: f64,
        sy_um_per_code: f64,
        x0_code: f64,
        y0_code: f64,
    }

    impl Truth {
        /// Codes read at screen point (x_um, y_um): rotate the point by −angle, divide by the
        /// scales, add the offset.
        fn codes(&self, x_um: f64, y_um: f64) -> (u16, u16) {
            let (s, c) = self.angle_deg.to_radians().sin_cos();
            let xr = c * x_um + s * y_um;
            let yr = -s * x_um + c * y_um;
            let xc = self.x0_code + xr / self.sx_um_per_code;
            let yc = self.y0_code + yr / self.sy_um_per_code;
            (xc.round() as u16, yc.round() as u16)
        }
    }

    fn cal(truth: &Truth, targets: [(i32, i32); 3]) -> Result<Affine, AffineError> {
        let points = targets.map(|(x_um, y_um)| {
            let (x_code, y_code) = truth.codes(x_um as f64, y_um as f64);
            CalPoint {
                x_code,
                y_code,
                x_um,
                y_um,
            }
        });
        Affine::from_points(points, &RailBands::default())
    }

    /// SLYT277's three targets on a 95 × 54 mm screen: (10 %, 10 %), (90 %, 50 %), (50 %, 90 %).
    const TARGETS: [(i32, i32); 3] = [(9_500, 5_400), (85_500, 27_000), (47_500, 48_600)];

    /// Rotated 3°, scaled 1.6 and 1.0 µm per code (95 mm over 59 000 codes, 54 mm over
    /// 54 000), offset by 3 000 and 10 000 codes: every point of a grid over the screen maps
    /// back within 2 µm (each code's rounding is ±0.5 code = ±0.8 µm on each axis).
    #[test]
    fn rotated_scaled_offset_screen_maps_back() {
        let truth = Truth {
            angle_deg: 3.0,
            sx_um_per_code: 1.6,
            sy_um_per_code: 1.0,
            x0_code: 3_000.0,
            y0_code: 10_000.0,
        };
        let m = cal(&truth, TARGETS).unwrap();
        let mut worst = 0;
        for i in 0..=19 {
            for j in 0..=10 {
                let (x, y) = (1_000 + 4_900 * i, 5_000 * j);
                let (xc, yc) = truth.codes(x as f64, y as f64);
                let (mx, my) = m.map(xc, yc);
                worst = worst.max((mx - x).abs()).max((my - y).abs());
            }
        }
        assert!(worst <= 2, "worst {worst} µm");
    }

    /// A panel mounted upside down and mirrored (180° and swapped sense) is just another
    /// affine map: a −90° rotation with the Y scale negative.
    #[test]
    fn quarter_turn_and_mirror_are_handled() {
        let truth = Truth {
            angle_deg: -90.0,
            sx_um_per_code: 1.2,
            sy_um_per_code: -1.5,
            x0_code: 50_000.0,
            y0_code: 60_000.0,
        };
        let m = cal(&truth, TARGETS).unwrap();
        for (x, y) in [(0, 0), (20_000, 40_000), (60_000, 10_000)] {
            let (xc, yc) = truth.codes(x as f64, y as f64);
            let (mx, my) = m.map(xc, yc);
            assert!(
                (mx - x).abs() <= 2 && (my - y).abs() <= 2,
                "{x},{y} → {mx},{my}"
            );
        }
    }

    /// A pure offset and scale, worked by hand: codes (10 000, 10 000) → (0, 0) µm,
    /// (50 000, 10 000) → (40 000, 0), (10 000, 40 000) → (0, 60 000): 1 µm per x code and
    /// 2 µm per y code. Code (30 000, 25 000) is then (20 000, 30 000) µm, exactly; and a code
    /// one past the triangle maps past it, unclamped.
    #[test]
    fn hand_worked_offset_and_scale() {
        let p = |x_code, y_code, x_um, y_um| CalPoint {
            x_code,
            y_code,
            x_um,
            y_um,
        };
        let m = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(50_000, 10_000, 40_000, 0),
                p(10_000, 40_000, 0, 60_000),
            ],
            &RailBands::default(),
        )
        .unwrap();
        assert_eq!(m.map(30_000, 25_000), (20_000, 30_000));
        assert_eq!(m.map(9_999, 10_000), (-1, 0));
        // Half a µm rounds away from zero: y code 10 000.25 does not exist, but a 1:2 map
        // of x gives halves — here 3 µm per 2 codes.
        let m = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(30_000, 10_000, 30_000, 0),
                p(10_000, 40_000, 0, 30_000),
            ],
            &RailBands::default(),
        )
        .unwrap();
        assert_eq!(m.map(10_001, 10_000), (2, 0)); // 1.5 → 2
        assert_eq!(m.map(9_999, 10_000), (-2, 0)); // −1.5 → −2
    }

    #[test]
    fn collinear_or_close_points_are_refused_with_a_sentence() {
        let p = |x_code, y_code, x_um, y_um| CalPoint {
            x_code,
            y_code,
            x_um,
            y_um,
        };
        let rails = RailBands::default();
        // On one line: heights 0.
        let e = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(30_000, 30_000, 40_000, 0),
                p(50_000, 50_000, 0, 60_000),
            ],
            &rails,
        )
        .unwrap_err();
        assert_eq!(e, AffineError::TouchesCollinear { height_code: 0 });
        assert_eq!(
            std::format!("{e}"),
            "the touched points lie nearly on one line: their triangle is 0 codes high, less \
             than the 4096 a calibration needs"
        );
        // Nearly: the third point off the line y = x through the first two by 3 000 codes of
        // x − y, 3 000/√2 = 2 121 codes from it (the height onto the longest side).
        let e = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(50_000, 50_000, 40_000, 0),
                p(31_500, 28_500, 0, 60_000),
            ],
            &rails,
        )
        .unwrap_err();
        assert!(
            matches!(e, AffineError::TouchesCollinear { height_code } if (2_100..2_130).contains(&height_code)),
            "{e:?}"
        );
        // Too close: points 1 and 2, 5 000 codes apart.
        let e = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(13_000, 14_000, 40_000, 0),
                p(10_000, 40_000, 0, 60_000),
            ],
            &rails,
        )
        .unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "touched points 1 and 2 are 5000 codes apart, fewer than the 8192 a calibration needs"
        );
        // Targets on one line.
        let e = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(50_000, 10_000, 40_000, 0),
                p(10_000, 40_000, 80_000, 0),
            ],
            &rails,
        )
        .unwrap_err();
        assert_eq!(e, AffineError::TargetsCollinear { height_um: 0 });
        // A touch in the low rail band.
        let e = Affine::from_points(
            [
                p(600, 10_000, 0, 0),
                p(50_000, 10_000, 40_000, 0),
                p(10_000, 40_000, 0, 60_000),
            ],
            &rails,
        )
        .unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "touched point 1's x_code 600 is inside a rail band and would read as a fault"
        );
        let e = Affine::from_points(
            [
                p(10_000, 10_000, 2_000_000, 0),
                p(50_000, 10_000, 40_000, 0),
                p(10_000, 40_000, 0, 60_000),
            ],
            &rails,
        )
        .unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "target 1's x_um 2000000 µm is beyond ±1000000 µm"
        );
    }

    /// Out-of-range results saturate to the side they overflow (cargo-mutants' `<` → `>` /
    /// `==` in `saturate` survived the map tests, which stay in range).
    #[test]
    fn saturate_keeps_the_sign() {
        assert_eq!(saturate(-(1 << 40)), i32::MIN);
        assert_eq!(saturate(1 << 40), i32::MAX);
        assert_eq!(saturate(-5), -5);
    }

    #[test]
    fn isqrt_floors() {
        for n in 0..2_000i128 {
            let r = isqrt(n) as i128;
            assert!(r * r <= n && (r + 1) * (r + 1) > n, "{n}");
        }
        assert_eq!(isqrt(1i128 << 62), 1 << 31);
        // 2^32 does not fit u32: saturated.
        assert_eq!(isqrt(1i128 << 64), u32::MAX);
    }
}
