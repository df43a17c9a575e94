//! Plane geometry: points, segments and simple polygons in µm, validated at compile, with the
//! exact containment test and the signed distances the 2D screen and edges are built on.
//!
//! Containment and validation are exact (i64 cross products of i32 coordinates): whether a
//! finger is inside a window, or whether two edges of an outline meet, must not depend on
//! rounding. Distances are f32 from constants prepared at compile ([`Seg`]): they are only
//! compared with hysteresis bands of tens of µm, and f32 carries a coordinate of 1 m to 0.06 µm.

use heapless::Vec;

/// Most vertices of one polygon.
pub const MAX_VERTICES: usize = 16;

/// Largest coordinate magnitude, µm (1 m): differences then stay within 2·10⁶ and cross
/// products within 8·10¹², exact in i64.
pub const MAX_COORD_UM: i32 = 1_000_000;

/// A point of the plate, µm from its origin.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct PointUm {
    /// Along the plate's x axis, µm.
    pub x_um: i32,
    /// Along the plate's y axis, µm.
    pub y_um: i32,
}

impl PointUm {
    /// The point (`x_um`, `y_um`).
    pub const fn new(x_um: i32, y_um: i32) -> Self {
        Self { x_um, y_um }
    }

    /// True when both coordinates are within ±[`MAX_COORD_UM`].
    pub fn in_range(&self) -> bool {
        self.x_um.unsigned_abs() <= MAX_COORD_UM as u32
            && self.y_um.unsigned_abs() <= MAX_COORD_UM as u32
    }
}

/// A straight segment from `a` to `b`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SegmentUm {
    /// Start.
    pub a: PointUm,
    /// End.
    pub b: PointUm,
}

/// The square root of an f32, correctly rounded (IEEE 754), bit-identical on every target.
///
/// On a hard-float Arm target (the M4F) this is the FPU's `vsqrt.f32`, one instruction, where
/// `libm::sqrtf` is a software routine of about 76 instructions (issue #36's profile: 1.55
/// calls a reading). Both are correctly rounded, so the result is the same bits as the host's
/// `libm::sqrtf` and the golden vectors stay bit-exact. The callers pass sums of squares, never
/// a negative number, so the NaNs' payloads (which could differ) do not arise.
#[inline(always)]
pub(crate) fn sqrt_f32(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        let mut bits = x.to_bits();
        // SAFETY: moves the bits into s15, takes the root there and moves it back; s15 is
        // declared clobbered and nothing else (memory, stack, flags) is touched. Through a core
        // register because this toolchain's rustc does not report the `vfp2` feature that the
        // `sreg` operand class needs, although the target (`+vfp4d16sp`) has the FPU.
        unsafe {
            core::arch::asm!(
                "vmov s15, {0}",
                "vsqrt.f32 s15, s15",
                "vmov {0}, s15",
                inout(reg) bits,
                out("s15") _,
                options(pure, nomem, nostack, preserves_flags)
            );
        }
        f32::from_bits(bits)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

/// `libm::roundf(x) as i32` (half away from zero, saturating, NaN → 0) without the call:
/// libm's `roundf` is a software routine (~19 instructions and a call on the M4F, issue #36's
/// profile), where this is a truncating conversion, its difference and two compares. Same
/// result for every f32: below 2^23 in magnitude x − trunc(x) is exact, so the half is
/// decided exactly; from 2^23 on every f32 is an integer and the difference is 0 (or, past
/// i32's range, the saturated side, which the saturating step keeps).
#[inline(always)]
pub(crate) fn round_to_i32(x: f32) -> i32 {
    let i = x as i32;
    let frac = x - i as f32;
    if frac >= 0.5 {
        i.saturating_add(1)
    } else if frac <= -0.5 {
        i.saturating_sub(1)
    } else {
        i
    }
}

/// (a − o) × (b − o), exact while one of the two vectors is within a validated polygon's
/// range (2·10⁶) and the other within i32 (products ≤ 8.6·10¹⁵): positive when o, a, b turn
/// counter-clockwise. Wrapping, so a polygon nobody validated gives a wrong answer, not a
/// panic.
#[inline(always)]
pub(crate) fn cross(o: PointUm, a: PointUm, b: PointUm) -> i64 {
    let (ax, ay) = (a.x_um as i64 - o.x_um as i64, a.y_um as i64 - o.y_um as i64);
    let (bx, by) = (b.x_um as i64 - o.x_um as i64, b.y_um as i64 - o.y_um as i64);
    ax.wrapping_mul(by).wrapping_sub(ay.wrapping_mul(bx))
}

/// (a − o) · (b − o), exact in range (wrapping, as [`cross`]).
fn dot(o: PointUm, a: PointUm, b: PointUm) -> i64 {
    let (ax, ay) = (a.x_um as i64 - o.x_um as i64, a.y_um as i64 - o.y_um as i64);
    let (bx, by) = (b.x_um as i64 - o.x_um as i64, b.y_um as i64 - o.y_um as i64);
    ax.wrapping_mul(bx).wrapping_add(ay.wrapping_mul(by))
}

/// `p`, known collinear with `a`–`b`, lies on the closed segment.
fn within(a: PointUm, b: PointUm, p: PointUm) -> bool {
    p.x_um >= a.x_um.min(b.x_um)
        && p.x_um <= a.x_um.max(b.x_um)
        && p.y_um >= a.y_um.min(b.y_um)
        && p.y_um <= a.y_um.max(b.y_um)
}

/// The closed segments p1–p2 and q1–q2 share a point (touching counts). Exact.
pub fn segments_meet(p1: PointUm, p2: PointUm, q1: PointUm, q2: PointUm) -> bool {
    let d1 = cross(q1, q2, p1).signum();
    let d2 = cross(q1, q2, p2).signum();
    let d3 = cross(p1, p2, q1).signum();
    let d4 = cross(p1, p2, q2).signum();
    if d1 * d2 < 0 && d3 * d4 < 0 {
        return true;
    }
    (d1 == 0 && within(q1, q2, p1))
        || (d2 == 0 && within(q1, q2, p2))
        || (d3 == 0 && within(p1, p2, q1))
        || (d4 == 0 && within(p1, p2, q2))
}

/// Why a polygon was refused. Each variant carries the values its sentence (`Display`) names,
/// shown in mm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum GeometryError {
    /// Fewer than 3 or more than [`MAX_VERTICES`] vertices.
    VertexCount {
        /// Vertices given.
        vertices: usize,
    },
    /// A vertex beyond ±[`MAX_COORD_UM`].
    OutOfRange {
        /// Its index.
        vertex: u8,
        /// Its position.
        at: PointUm,
    },
    /// Edge `edge` (from vertex `edge` to the next) has zero length.
    ZeroLengthEdge {
        /// Its index.
        edge: u8,
        /// Where both its ends are.
        at: PointUm,
    },
    /// Two edges share a point they should not: the outline crosses or touches itself, or an
    /// edge folds back onto the one before it.
    SelfIntersecting {
        /// The first edge.
        edge: u8,
        /// The edge it meets.
        other: u8,
    },
}

/// A signed µm count shown in mm.
struct Mm(i32);

impl core::fmt::Display for Mm {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.0 < 0 {
            f.write_str("-")?;
        }
        write!(f, "{}", crate::fmt::Milli(self.0.unsigned_abs() as u64))
    }
}

impl core::fmt::Display for GeometryError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            GeometryError::VertexCount { vertices } => write!(
                f,
                "a polygon has {vertices} vertices and needs 3 to {MAX_VERTICES}"
            ),
            GeometryError::OutOfRange { vertex, at } => write!(
                f,
                "vertex {vertex} at ({} mm, {} mm) is beyond the plane's ±{} mm",
                Mm(at.x_um),
                Mm(at.y_um),
                Mm(MAX_COORD_UM)
            ),
            GeometryError::ZeroLengthEdge { edge, at } => write!(
                f,
                "edge {edge} has zero length: its two vertices are both at ({} mm, {} mm)",
                Mm(at.x_um),
                Mm(at.y_um)
            ),
            GeometryError::SelfIntersecting { edge, other } => write!(
                f,
                "edges {edge} and {other} meet: a polygon's outline must not cross, touch or \
                 fold back on itself (concave is allowed)"
            ),
        }
    }
}

/// A polygon as the scene states it: vertices in order (either turn), the last joined to the
/// first. Checked by [`Polygon::validate`]: 3 ..= [`MAX_VERTICES`] vertices, no zero-length
/// edge, simple (concave allowed).
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Polygon {
    /// The vertices, µm.
    pub vertices: Vec<PointUm, MAX_VERTICES>,
}

impl Polygon {
    /// A polygon through `points`, validated.
    pub fn from_points(points: &[PointUm]) -> Result<Self, GeometryError> {
        let vertices = Vec::from_slice(points).map_err(|_| GeometryError::VertexCount {
            vertices: points.len(),
        })?;
        let p = Self { vertices };
        p.validate()?;
        Ok(p)
    }

    /// The axis-aligned rectangle with corners `lo` and `hi` (counter-clockwise from `lo`),
    /// validated.
    pub fn rectangle(lo: PointUm, hi: PointUm) -> Result<Self, GeometryError> {
        Self::from_points(&[
            lo,
            PointUm::new(hi.x_um, lo.y_um),
            hi,
            PointUm::new(lo.x_um, hi.y_um),
        ])
    }

    /// Edge `i`: from vertex `i` to the next (the last closes the outline).
    pub fn edge(&self, i: usize) -> Option<SegmentUm> {
        let n = self.vertices.len();
        let a = *self.vertices.get(i)?;
        let b = *self.vertices.get((i + 1) % n)?;
        Some(SegmentUm { a, b })
    }

    /// The edges in order.
    pub fn edges(&self) -> impl Iterator<Item = SegmentUm> + '_ {
        (0..self.vertices.len()).filter_map(|i| self.edge(i))
    }

    /// Checks the count, the range, the edges' lengths and that the outline is simple. O(n²)
    /// exact tests, once at compile.
    pub fn validate(&self) -> Result<(), GeometryError> {
        let n = self.vertices.len();
        if !(3..=MAX_VERTICES).contains(&n) {
            return Err(GeometryError::VertexCount { vertices: n });
        }
        for (i, v) in self.vertices.iter().enumerate() {
            if !v.in_range() {
                return Err(GeometryError::OutOfRange {
                    vertex: i as u8,
                    at: *v,
                });
            }
        }
        for (i, e) in self.edges().enumerate() {
            if e.a == e.b {
                return Err(GeometryError::ZeroLengthEdge {
                    edge: i as u8,
                    at: e.a,
                });
            }
        }
        for i in 0..n {
            let (Some(e), Some(next)) = (self.edge(i), self.edge((i + 1) % n)) else {
                continue;
            };
            // Neighbours share e.b: they overlap only when collinear and folding back.
            if cross(e.b, e.a, next.b) == 0 && dot(e.b, e.a, next.b) > 0 {
                return Err(GeometryError::SelfIntersecting {
                    edge: i as u8,
                    other: ((i + 1) % n) as u8,
                });
            }
            for j in i + 2..n {
                if i == 0 && j == n - 1 {
                    continue; // the closing edge is edge 0's other neighbour
                }
                let Some(f) = self.edge(j) else { continue };
                if segments_meet(e.a, e.b, f.a, f.b) {
                    return Err(GeometryError::SelfIntersecting {
                        edge: i as u8,
                        other: j as u8,
                    });
                }
            }
        }
        Ok(())
    }

    /// `p` is inside (crossing number, exact). A point exactly on the outline may read either
    /// way; every caller compares distances with a band of µm around the outline, where that
    /// does not matter.
    pub fn contains(&self, p: PointUm) -> bool {
        contains(&self.vertices, p)
    }

    /// Distance from `p` to the outline, µm: positive inside, negative outside.
    pub fn signed_distance_um(&self, p: PointUm) -> f32 {
        let d2 = self
            .edges()
            .map(|e| Seg::new(e).distance2_um2(p))
            .fold(f32::INFINITY, f32::min);
        let d = sqrt_f32(d2);
        if self.contains(p) {
            d
        } else {
            -d
        }
    }

    /// The smallest box holding the polygon: (lower-left, upper-right).
    pub fn bounds(&self) -> (PointUm, PointUm) {
        let mut lo = PointUm::new(i32::MAX, i32::MAX);
        let mut hi = PointUm::new(i32::MIN, i32::MIN);
        for v in &self.vertices {
            lo = PointUm::new(lo.x_um.min(v.x_um), lo.y_um.min(v.y_um));
            hi = PointUm::new(hi.x_um.max(v.x_um), hi.y_um.max(v.y_um));
        }
        (lo, hi)
    }
}

/// Crossing-number containment of `p` in the closed outline through `vertices`, exact.
#[inline]
pub(crate) fn contains(vertices: &[PointUm], p: PointUm) -> bool {
    let mut inside = false;
    let mut prev = match vertices.last() {
        Some(v) => *v,
        None => return false,
    };
    for &v in vertices {
        // Edge prev → v straddles the horizontal through p (half-open, so a vertex at p's
        // height counts once).
        if (v.y_um > p.y_um) != (prev.y_um > p.y_um) {
            // The crossing lies right of p when p is left of the upward edge (or right of
            // the downward one).
            let c = cross(prev, v, p);
            if (c > 0) == (v.y_um > prev.y_um) {
                inside = !inside;
            }
        }
        prev = v;
    }
    inside
}

/// A segment prepared for distances: its start, its direction and 1/|b − a|², f32.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Seg {
    ax: f32,
    ay: f32,
    dx: f32,
    dy: f32,
    inv_len2: f32,
}

impl Seg {
    /// Prepares `s` (of non-zero length; a zero-length one measures to `s.a`).
    pub fn new(s: SegmentUm) -> Self {
        // Exact for coordinates within ±MAX_COORD_UM (< 2^24), as the i64 difference was,
        // without the M4's i64 → f32 library call.
        let dx = s.b.x_um as f32 - s.a.x_um as f32;
        let dy = s.b.y_um as f32 - s.a.y_um as f32;
        let len2 = dx * dx + dy * dy;
        Self {
            ax: s.a.x_um as f32,
            ay: s.a.y_um as f32,
            dx,
            dy,
            inv_len2: if len2 > 0.0 { 1.0 / len2 } else { 0.0 },
        }
    }

    /// Squared distance from `p` to the closed segment, µm².
    #[inline]
    pub fn distance2_um2(&self, p: PointUm) -> f32 {
        let (px, py) = (p.x_um as f32 - self.ax, p.y_um as f32 - self.ay);
        let t = ((px * self.dx + py * self.dy) * self.inv_len2).clamp(0.0, 1.0);
        let (ex, ey) = (px - t * self.dx, py - t * self.dy);
        ex * ex + ey * ey
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec as StdVec;

    fn pt(x: i32, y: i32) -> PointUm {
        PointUm::new(x, y)
    }

    /// An L: the 10 × 10 mm square with its upper-right 5 × 5 mm quarter cut away; the reflex
    /// (concave) corner is at (5, 5) mm.
    pub(crate) fn ell() -> Polygon {
        Polygon::from_points(&[
            pt(0, 0),
            pt(10_000, 0),
            pt(10_000, 5_000),
            pt(5_000, 5_000),
            pt(5_000, 10_000),
            pt(0, 10_000),
        ])
        .unwrap()
    }

    /// Reference containment: the winding number from summed angles (f64), for points not on
    /// the outline. Independent of the crossing number under test.
    fn winding(poly: &[PointUm], p: PointUm) -> bool {
        let mut total = 0.0f64;
        for i in 0..poly.len() {
            let a = poly[i];
            let b = poly[(i + 1) % poly.len()];
            let (ax, ay) = ((a.x_um - p.x_um) as f64, (a.y_um - p.y_um) as f64);
            let (bx, by) = ((b.x_um - p.x_um) as f64, (b.y_um - p.y_um) as f64);
            total += (ax * by - ay * bx).atan2(ax * bx + ay * by);
        }
        total.abs() > core::f64::consts::PI
    }

    /// Reference distance: the outline sampled every 1 µm, nearest sample (brute force).
    fn sampled_distance(poly: &Polygon, p: PointUm) -> f64 {
        let mut best = f64::INFINITY;
        for e in poly.edges() {
            let (dx, dy) = ((e.b.x_um - e.a.x_um) as f64, (e.b.y_um - e.a.y_um) as f64);
            let len = (dx * dx + dy * dy).sqrt();
            let steps = len.ceil() as i64;
            for k in 0..=steps {
                let t = k as f64 / steps as f64;
                let (x, y) = (e.a.x_um as f64 + t * dx, e.a.y_um as f64 + t * dy);
                let d = ((x - p.x_um as f64).powi(2) + (y - p.y_um as f64).powi(2)).sqrt();
                best = best.min(d);
            }
        }
        best
    }

    /// Distance to the outline in f64 by the textbook projection, to skip points on it.
    fn closed_form_distance(poly: &[PointUm], p: PointUm) -> f64 {
        let mut best = f64::INFINITY;
        for i in 0..poly.len() {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            let (dx, dy) = ((b.x_um - a.x_um) as f64, (b.y_um - a.y_um) as f64);
            let (px, py) = ((p.x_um - a.x_um) as f64, (p.y_um - a.y_um) as f64);
            let t = ((px * dx + py * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
            best = best.min(((px - t * dx).powi(2) + (py - t * dy).powi(2)).sqrt());
        }
        best
    }

    /// A random star-shaped polygon (angles sorted, radii random): simple, usually concave.
    fn star(rng: &mut u64, n: usize) -> StdVec<PointUm> {
        let mut next = || {
            *rng ^= *rng << 13;
            *rng ^= *rng >> 7;
            *rng ^= *rng << 17;
            (*rng >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut angles: StdVec<f64> = (0..n)
            .map(|k| (k as f64 + 0.1 + 0.8 * next()) * core::f64::consts::TAU / n as f64)
            .collect();
        angles.sort_by(|a, b| a.partial_cmp(b).unwrap());
        angles
            .iter()
            .map(|a| {
                let r = 2_000.0 + 8_000.0 * next();
                pt(20_000 + (r * a.cos()) as i32, 20_000 + (r * a.sin()) as i32)
            })
            .collect()
    }

    #[test]
    fn round_to_i32_is_libms_roundf_as_i32() {
        // Every f32 near a half-integer (where rounding is decided) up to 2^24, the specials,
        // and a million random bit patterns over the whole range.
        let check = |x: f32| {
            assert_eq!(
                round_to_i32(x),
                libm::roundf(x) as i32,
                "{x:e} ({:#x})",
                x.to_bits()
            );
        };
        for k in -(1 << 15)..(1 << 15) {
            for base in [k as f32 + 0.5, (k * 511) as f32 + 0.5, (k * 256) as f32] {
                let mut x = base;
                for _ in 0..3 {
                    x = f32::from_bits(x.to_bits().wrapping_sub(1));
                }
                for _ in 0..7 {
                    check(x);
                    check(-x);
                    x = f32::from_bits(x.to_bits().wrapping_add(1));
                }
            }
        }
        for x in [
            0.0,
            -0.0,
            0.49999997,
            8_388_607.5,
            8_388_608.0,
            16_777_217.0,
            2_147_483_520.0,
            2_147_483_648.0,
            -2_147_483_648.0,
            -2_147_483_904.0,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::MIN_POSITIVE,
        ] {
            check(x);
            check(-x);
        }
        let mut seed = 0x9e37_79b9u32;
        for _ in 0..1_000_000 {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            check(f32::from_bits(seed));
        }
    }

    #[test]
    fn containment_matches_the_winding_number_on_random_concave_polygons() {
        let mut rng = 0x9e37_79b9_7f4a_7c15u64;
        let mut concave = 0;
        for n in 3..=MAX_VERTICES {
            for _ in 0..20 {
                let pts = star(&mut rng, n);
                let Ok(poly) = Polygon::from_points(&pts) else {
                    continue; // rounding may make a thin star touch itself: refused is fine
                };
                concave += (0..n)
                    .filter(|&i| {
                        let (a, b, c) = (pts[i], pts[(i + 1) % n], pts[(i + 2) % n]);
                        cross(a, b, c) < 0
                    })
                    .count()
                    .min(1);
                for x in (9_000..31_000).step_by(997) {
                    for y in (9_000..31_000).step_by(1_003) {
                        let p = pt(x, y);
                        if closed_form_distance(&pts, p) < 2.0 {
                            continue; // on the outline: either answer is allowed
                        }
                        assert_eq!(poly.contains(p), winding(&pts, p), "{pts:?} {p:?}");
                    }
                }
            }
        }
        assert!(
            concave > 100,
            "the stars were too seldom concave: {concave}"
        );
    }

    #[test]
    fn signed_distance_matches_a_sampled_outline() {
        let mut rng = 0x1234_5678_9abc_def1u64;
        for n in [3, 5, 9, 16] {
            let pts = star(&mut rng, n);
            let Ok(poly) = Polygon::from_points(&pts) else {
                continue;
            };
            for x in (10_000..30_000).step_by(4_311) {
                for y in (10_000..30_000).step_by(4_179) {
                    let p = pt(x, y);
                    let reference = sampled_distance(&poly, p);
                    let sign = if winding(&pts, p) { 1.0 } else { -1.0 };
                    let got = poly.signed_distance_um(p) as f64;
                    // The sampled outline is at most 0.5 µm farther than the true one.
                    assert!(
                        (got - sign * reference).abs() <= 0.6,
                        "{p:?}: {got} against {}",
                        sign * reference
                    );
                }
            }
        }
    }

    #[test]
    fn distances_by_hand_at_a_concave_corner() {
        let l = ell();
        // Inside, 1 mm below the reflex corner and 4 mm from the right edge: nearest is the
        // notch's floor 1 mm up.
        assert_eq!(l.signed_distance_um(pt(7_000, 4_000)), 1_000.0);
        // In the notch (outside), 3 mm right of and 4 mm above the reflex corner: nearest is
        // the notch's left wall (3 mm), not its floor (4 mm).
        assert_eq!(l.signed_distance_um(pt(8_000, 9_000)), -3_000.0);
        // Inside, 0.3 mm left of and 0.4 mm below the reflex corner: beyond the end of both
        // edges that meet there, so the corner itself is nearest, 0.5 mm away (3-4-5), not
        // either edge's line (0.3 and 0.4 mm).
        assert_eq!(l.signed_distance_um(pt(4_700, 4_600)), 500.0);
        assert!(l.contains(pt(4_999, 4_999)) && !l.contains(pt(5_001, 5_001)));
    }

    #[test]
    fn refusals_name_the_fault() {
        // Too few, too many.
        let two = Polygon::from_points(&[pt(0, 0), pt(1, 0)]);
        assert_eq!(two, Err(GeometryError::VertexCount { vertices: 2 }));
        let many: StdVec<_> = (0..17).map(|k| pt(k, k * k)).collect();
        assert_eq!(
            Polygon::from_points(&many),
            Err(GeometryError::VertexCount { vertices: 17 })
        );
        // Out of range.
        assert_eq!(
            Polygon::from_points(&[pt(0, 0), pt(1_000_001, 0), pt(0, 5)]),
            Err(GeometryError::OutOfRange {
                vertex: 1,
                at: pt(1_000_001, 0)
            })
        );
        // Zero length.
        assert_eq!(
            Polygon::from_points(&[pt(0, 0), pt(5, 0), pt(5, 0), pt(0, 5)]),
            Err(GeometryError::ZeroLengthEdge {
                edge: 1,
                at: pt(5, 0)
            })
        );
        // A bow tie: edges 0 and 2 cross.
        assert_eq!(
            Polygon::from_points(&[pt(0, 0), pt(10, 10), pt(10, 0), pt(0, 10)]),
            Err(GeometryError::SelfIntersecting { edge: 0, other: 2 })
        );
        // A vertex touching a non-adjacent edge (vertex 4 on edge 0 at (5, 0)): touching counts.
        assert_eq!(
            Polygon::from_points(&[
                pt(0, 0),
                pt(10, 0),
                pt(10, 10),
                pt(6, 10),
                pt(5, 0),
                pt(0, 10)
            ]),
            Err(GeometryError::SelfIntersecting { edge: 0, other: 3 })
        );
        // Collinear triangle: every pair is adjacent, so only the fold-back test refuses it.
        assert_eq!(
            Polygon::from_points(&[pt(0, 0), pt(10, 0), pt(4, 0)]),
            Err(GeometryError::SelfIntersecting { edge: 0, other: 1 })
        );
        // A redundant vertex on a straight run is not a fold: accepted.
        assert!(Polygon::from_points(&[pt(0, 0), pt(5, 0), pt(10, 0), pt(0, 10)]).is_ok());
        assert!(Polygon::rectangle(pt(0, 0), pt(10_000, 5_000)).is_ok());
        ell().validate().unwrap();
    }

    #[test]
    fn sentences_name_field_value_and_limit() {
        let s = |e: GeometryError| std::format!("{e}");
        assert_eq!(
            s(GeometryError::VertexCount { vertices: 2 }),
            "a polygon has 2 vertices and needs 3 to 16"
        );
        assert_eq!(
            s(GeometryError::OutOfRange {
                vertex: 1,
                at: pt(-1_000_500, 20)
            }),
            "vertex 1 at (-1000.5 mm, 0.02 mm) is beyond the plane's ±1000 mm"
        );
        assert_eq!(
            s(GeometryError::ZeroLengthEdge {
                edge: 1,
                at: pt(5_000, 0)
            }),
            "edge 1 has zero length: its two vertices are both at (5 mm, 0 mm)"
        );
        assert!(s(GeometryError::SelfIntersecting { edge: 0, other: 2 })
            .starts_with("edges 0 and 2 meet"));
    }

    #[test]
    fn any_input_answers_without_panicking() {
        // An outline nobody validated, at i32's ends, and a finger there: an answer, no
        // overflow panic (the tests build with overflow checks).
        let m = i32::MAX;
        let wild = Polygon {
            vertices: Vec::from_slice(&[pt(-m, -m), pt(m, -m), pt(m, m), pt(-m, m)]).unwrap(),
        };
        let _ = wild.contains(pt(i32::MIN, 0));
        let _ = wild.signed_distance_um(pt(0, i32::MIN));
        let _ = wild.validate();
        let l = ell();
        assert!(!l.contains(pt(i32::MIN, i32::MAX)));
        assert!(l.signed_distance_um(pt(i32::MAX, i32::MIN)) < -1e9);
    }

    #[test]
    fn extreme_coordinates_stay_exact() {
        // The corners of the allowed range: cross products reach 8·10¹², exact in i64.
        let m = MAX_COORD_UM;
        let sq = Polygon::rectangle(pt(-m, -m), pt(m, m)).unwrap();
        assert!(sq.contains(pt(m - 1, m - 1)) && !sq.contains(pt(m, m + 1)));
        assert!(sq.contains(pt(0, 0)));
        // A sliver one µm thick over 2 m: still a valid, simple outline.
        assert!(Polygon::from_points(&[pt(-m, 0), pt(m, 0), pt(m, 1)]).is_ok());
    }
}
