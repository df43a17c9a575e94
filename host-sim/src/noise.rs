//! The sum of a sample's noisy, rounded conversions drawn in one step: the ADC model's fast
//! path, exact in distribution to the per-conversion model up to a fraction of an LSB in the
//! ideal value.
//!
//! One control sample is Σ round(v + nᵢ) over `oversample` conversions, nᵢ ~ N(0, σ). Drawing
//! every nᵢ costs 16 Gaussian draws per sample, most of the closed loop's time. Away from the
//! rails (where clamping cannot bite) round(v + nᵢ) = ⌊v⌋ + qᵢ with qᵢ = ⌊f + nᵢ + ½⌋ and
//! f = v − ⌊v⌋, so the sum is oversample·⌊v⌋ + Q where Q = Σ qᵢ depends only on f and σ. Its
//! exact distribution is the oversample-fold convolution of qᵢ's (from the normal CDF); it is
//! tabulated at f = j / [`BINS`] for j = 0 … BINS and drawn by inverting its CDF, found through
//! a guide table in about one step. One 64-bit draw serves a sample: 32 bits pick the grid
//! point, 32 the value. (rand_distr's `WeightedAliasIndex` takes three draws and twice the
//! time; this is the loop's hottest function.) An f
//! between two grid points picks the upper table with probability equal to its position between
//! them, so the mean is exact wherever the mean is linear in f (σ ≳ ½ LSB) and the
//! distribution is a mixture of its neighbours' within 1/BINS LSB.
//!
//! Where it fails: with σ much below 1/BINS of an LSB the sum jumps from one value to the next
//! over less than a grid step, and the mixture blurs that step; tables also grow with σ. So
//! the table is built only for σ in [`MIN_SIGMA_LSB`, `MAX_SIGMA_LSB`]; outside it, and within
//! [`TAIL_SIGMAS`] σ of a rail, the ADC model draws each conversion (`docs/streaming.md` has
//! the measured error and speed of both).

use std::sync::Arc;

use rand::RngCore;

/// Grid points per LSB of the ideal value's fraction.
pub const BINS: usize = 64;
/// Smallest σ the table serves, LSB RMS: a grid step is σ/16 there.
pub const MIN_SIGMA_LSB: f64 = 0.25;
/// Largest σ the table serves, LSB RMS: the tables' size and build time grow as σ².
pub const MAX_SIGMA_LSB: f64 = 8.0;
/// The per-conversion noise is cut at this many σ (mass beyond it: 2.6 × 10⁻¹²).
pub const TAIL_SIGMAS: f64 = 7.0;
/// Guide entries per value of the sum: more make the search's first guess right more often.
const GUIDE_PER_VALUE: usize = 4;
/// Probability below which the tails of a convolution are dropped.
const NEGLIGIBLE: f64 = 1e-16;

/// Q's distribution at one grid point of f.
#[derive(Debug)]
struct Grid {
    /// The smallest Q in the table.
    min_q: i64,
    /// P(Q ≤ min_q + i) × 2³², saturated at 2³² − 1 (the search stops at the last entry).
    /// u32 keeps a grid point's table small enough to stay in cache.
    cdf: Vec<u32>,
    /// For each of [`GUIDE_PER_VALUE`] × `cdf.len()` equal slices of the draws, the first entry
    /// the slice can end in: the search starts there and seldom takes a step. [`SETTLED`] set:
    /// every draw of the slice ends there, so the draw reads no `cdf` entry (most slices: the
    /// `cdf` read was the second cache miss of the loop's hottest function).
    guide: Vec<u16>,
}

/// The guide entry's flag for a slice whose draws all give the entry it names.
const SETTLED: u16 = 1 << 15;

impl Grid {
    fn new(min_q: i64, pmf: &[f64]) -> Option<Self> {
        let total: f64 = pmf.iter().sum();
        if total.is_nan() || total <= 0.0 {
            return None;
        }
        // The guide's entries are 15 bits (the 16th is [`SETTLED`]); σ ≤ 8 LSB over 16
        // conversions needs about 600.
        if pmf.len() >= SETTLED as usize {
            return None;
        }
        let mut acc = 0.0;
        let cdf: Vec<u32> = pmf
            .iter()
            .map(|p| {
                acc += p / total;
                (acc * 4_294_967_296.0).round().min(u32::MAX as f64) as u32
            })
            .collect();
        let last = cdf.len() - 1;
        let n = (GUIDE_PER_VALUE * cdf.len()) as u64;
        let mut guide = Vec::with_capacity(n as usize);
        let mut i = 0usize;
        for g in 0..n {
            let start = (g << 32) / n;
            while i < last && cdf[i] as u64 <= start {
                i += 1;
            }
            // The slice's draws are the u with ⌊u·n / 2³²⌋ = g, the largest ⌈(g + 1)·2³² / n⌉
            // − 1: all of them stop at i when cdf[i] is above that one, or when i is the last
            // entry (the search stops there).
            let largest = (((g + 1) << 32) + n - 1) / n - 1;
            let settled = i == last || cdf[i] as u64 > largest;
            guide.push(i as u16 | if settled { SETTLED } else { 0 });
        }
        Some(Self { min_q, cdf, guide })
    }

    /// The value a 32-bit uniform `u` stands for.
    #[cfg(test)]
    fn value(&self, u: u32) -> i64 {
        self.value_at(self.slice(u), u)
    }

    /// The guide's slice `u` falls in.
    #[inline(always)]
    fn slice(&self, u: u32) -> usize {
        ((u as u64 * self.guide.len() as u64) >> 32) as usize
    }

    /// [`Self::value`] of `u`, whose guide slice is `slice`.
    #[inline(always)]
    fn value_at(&self, slice: usize, u: u32) -> i64 {
        let g = self.guide[slice];
        let mut i = (g & !SETTLED) as usize;
        if g & SETTLED == 0 {
            let last = self.cdf.len() - 1;
            while i < last && self.cdf[i] <= u {
                i += 1;
            }
        }
        self.min_q + i as i64
    }
}

/// The tables for one σ and one oversampling count (shared by clones of the ADC model).
#[derive(Clone, Debug)]
pub struct SumTable {
    sigma_lsb: f64,
    oversample: u32,
    grid: Arc<Vec<Grid>>,
}

/// The standard normal CDF.
fn phi(x: f64) -> f64 {
    0.5 * libm::erfc(-x / std::f64::consts::SQRT_2)
}

/// P(q = k) for q = ⌊f + n + ½⌋, n ~ N(0, σ), k from `min_k`.
fn conversion_pmf(f: f64, sigma: f64) -> (i64, Vec<f64>) {
    let reach = (TAIL_SIGMAS * sigma).ceil() as i64 + 1;
    let min_k = -reach;
    let pmf = (min_k..=reach + 1)
        .map(|k| {
            let k = k as f64;
            phi((k + 0.5 - f) / sigma) - phi((k - 0.5 - f) / sigma)
        })
        .collect();
    (min_k, pmf)
}

/// The distribution of the sum of two independent variables given as (offset, pmf).
fn convolve(a: &(i64, Vec<f64>), b: &(i64, Vec<f64>)) -> (i64, Vec<f64>) {
    let mut out = vec![0.0; a.1.len() + b.1.len() - 1];
    for (i, &x) in a.1.iter().enumerate() {
        if x == 0.0 {
            continue;
        }
        for (j, &y) in b.1.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    trim((a.0 + b.0, out))
}

/// Drops the negligible ends of a pmf.
fn trim((mut min, mut pmf): (i64, Vec<f64>)) -> (i64, Vec<f64>) {
    let first = pmf.iter().position(|&p| p > NEGLIGIBLE).unwrap_or(0);
    let last = pmf.iter().rposition(|&p| p > NEGLIGIBLE).unwrap_or(0);
    pmf.truncate(last + 1);
    pmf.drain(..first);
    min += first as i64;
    (min, pmf)
}

/// The distribution of the sum of `n` independent copies of `one` (binary powers).
fn sum_of(one: (i64, Vec<f64>), mut n: u32) -> (i64, Vec<f64>) {
    let mut acc: Option<(i64, Vec<f64>)> = None;
    let mut power = one;
    while n > 0 {
        if n & 1 == 1 {
            acc = Some(match acc {
                None => power.clone(),
                Some(a) => convolve(&a, &power),
            });
        }
        n >>= 1;
        if n > 0 {
            power = convolve(&power, &power);
        }
    }
    acc.unwrap_or((0, vec![1.0]))
}

impl SumTable {
    /// The tables for noise `sigma_lsb` over `oversample` conversions, or None outside the
    /// range they serve (see the module docs).
    pub fn new(sigma_lsb: f64, oversample: u32) -> Option<Self> {
        if !(MIN_SIGMA_LSB..=MAX_SIGMA_LSB).contains(&sigma_lsb) || oversample == 0 {
            return None;
        }
        let grid = (0..=BINS)
            .map(|j| {
                let f = j as f64 / BINS as f64;
                let (min_q, pmf) = sum_of(trim(conversion_pmf(f, sigma_lsb)), oversample);
                Grid::new(min_q, &pmf)
            })
            .collect::<Option<Vec<_>>>()?;
        Some(Self {
            sigma_lsb,
            oversample,
            grid: Arc::new(grid),
        })
    }

    /// The noise this table was built for, LSB RMS.
    pub fn sigma_lsb(&self) -> f64 {
        self.sigma_lsb
    }

    /// True when every conversion of a sample with ideal value `v_lsb` stays inside
    /// `0 ..= max_code` but for the cut tails: only then is the table's sum the clamped sum.
    pub fn serves(&self, v_lsb: f64, max_code: u32) -> bool {
        let reach = TAIL_SIGMAS * self.sigma_lsb + 1.0;
        v_lsb >= reach && v_lsb <= max_code as f64 - reach
    }

    /// One draw of Σ round(v + nᵢ) for ideal value `v_lsb` (callers check [`Self::serves`]).
    /// Always inlined (with [`Grid::value`]): the ADC model's block loop called it, and took
    /// 18.2-18.8 ns a sample inlined against 18.9-19.1 called.
    #[inline(always)]
    pub fn draw<R: RngCore + ?Sized>(&self, v_lsb: f64, rng: &mut R) -> u32 {
        self.finish(self.prepare(v_lsb, rng))
    }

    /// The first half of [`Self::draw`]: the generator's draw, the grid point and the guide
    /// slice it picks, and the sum's whole part, with the guide entry asked of the memory
    /// ahead of [`Self::finish`]. A block of samples prepares its draws in order, then
    /// finishes them: the guide reads, the loop's slowest loads (the guides of the 65 grid
    /// points, 73 kB at σ 2 LSB, do not fit the L1 cache), are then already on their way.
    #[inline(always)]
    pub fn prepare<R: RngCore + ?Sized>(&self, v_lsb: f64, rng: &mut R) -> Prepared {
        // v ≥ 0 where the table serves, so truncation is the floor (and avoids a libm call on
        // targets without SSE4.1's roundsd).
        let floor = v_lsb as i64 as f64;
        let x = (v_lsb - floor) * BINS as f64;
        let lower = (x as usize).min(BINS - 1);
        let r = rng.next_u64();
        // The high half picks the grid point above with probability x − lower.
        let above = ((r >> 32) as f64) < (x - lower as f64) * 4_294_967_296.0;
        let grid = lower + usize::from(above);
        let u = r as u32;
        let slice = self.grid[grid].slice(u);
        #[cfg(target_arch = "x86_64")]
        if let Some(g) = self.grid[grid].guide.get(slice) {
            // SAFETY: SSE, which `_mm_prefetch` needs, is in every x86_64 CPU; a prefetch is a
            // hint that reads nothing the program sees (and `g` is a live entry anyway).
            unsafe {
                std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                    (g as *const u16).cast(),
                )
            };
        }
        Prepared {
            whole: self.oversample as i64 * floor as i64,
            grid: grid as u32,
            slice: slice as u32,
            u,
        }
    }

    /// The second half of [`Self::draw`]: the sum `p` stands for.
    #[inline(always)]
    pub fn finish(&self, p: Prepared) -> u32 {
        let q = self.grid[p.grid as usize].value_at(p.slice as usize, p.u);
        (p.whole + q).max(0) as u32
    }
}

/// A draw of [`SumTable::draw`] between [`SumTable::prepare`] and [`SumTable::finish`].
#[derive(Clone, Copy, Debug, Default)]
pub struct Prepared {
    /// oversample × ⌊v⌋.
    whole: i64,
    /// The grid point drawn.
    grid: u32,
    /// Its guide's slice for `u`.
    slice: u32,
    /// The uniform that picks the value.
    u: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// The reference: each conversion drawn, rounded and summed, as the ADC model's slow path.
    fn per_conversion(v: f64, sigma: f64, n: u32, rng: &mut ChaCha8Rng) -> u32 {
        let d = Normal::new(0.0, sigma).unwrap();
        (0..n)
            .map(|_| (v + d.sample(rng)).round().clamp(0.0, 4095.0) as u32)
            .sum()
    }

    /// The table's draws and per-conversion draws of the same ideal values have the same
    /// distribution: a two-sample χ² over the sums' histogram, at fractions on and between the
    /// grid (including the half-LSB where rounding flips), for σ across the served range.
    #[test]
    fn same_distribution_as_drawing_each_conversion() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for &sigma in &[0.25, 0.5, 2.0, 8.0] {
            let t = SumTable::new(sigma, 16).unwrap();
            for &v in &[1000.0, 1000.5, 1000.013, 1000.37, 2047.9921875] {
                let n = 40_000;
                let mut a = std::collections::BTreeMap::<u32, [f64; 2]>::new();
                for _ in 0..n {
                    a.entry(t.draw(v, &mut rng)).or_default()[0] += 1.0;
                    a.entry(per_conversion(v, sigma, 16, &mut rng)).or_default()[1] += 1.0;
                }
                // Pool sparse cells (expected < 10) so χ² applies.
                let (mut chi2, mut dof, mut pool) = (0.0, 0usize, [0.0f64; 2]);
                for c in a.values() {
                    pool[0] += c[0];
                    pool[1] += c[1];
                    if pool[0] + pool[1] >= 20.0 {
                        let e = (pool[0] + pool[1]) / 2.0;
                        chi2 += (pool[0] - e).powi(2) / e + (pool[1] - e).powi(2) / e;
                        dof += 1;
                        pool = [0.0; 2];
                    }
                }
                let dof = dof.saturating_sub(1).max(1) as f64;
                // χ² with k dof: mean k, sd √(2k); 5 sd is a false alarm ~1e-6 per case.
                assert!(
                    chi2 < dof + 5.0 * (2.0 * dof).sqrt(),
                    "σ {sigma} v {v}: χ² {chi2:.1} over {dof} dof"
                );
            }
        }
    }

    /// A table that ignored the fraction (always the lower grid point) is caught: the mean
    /// of the sum drifts by up to 16 × 1/64 LSB, which 100 000 draws resolve.
    #[test]
    fn mean_follows_the_fraction_between_grid_points() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let t = SumTable::new(2.0, 16).unwrap();
        let v = 1000.0 + 0.5 / BINS as f64;
        let n = 200_000;
        let mean = (0..n).map(|_| t.draw(v, &mut rng) as f64).sum::<f64>() / n as f64;
        // σ of one sum ≈ 4 × √(4 + 1/12) = 8.08; the mean's standard error 0.018 codes.
        assert!((mean - 16.0 * v).abs() < 0.08, "{mean} vs {}", 16.0 * v);
    }

    /// The guide's settled slices give what the search from their entry gives, at both ends of
    /// every slice and at random draws, for every grid point of σ across the served range: the
    /// flag only skips reads, never changes a draw (the published figures rest on the draws).
    #[test]
    fn settled_slices_give_the_searched_value() {
        use rand::Rng;
        let search = |g: &Grid, u: u32| {
            let n = g.guide.len() as u64;
            let mut i = (g.guide[((u as u64 * n) >> 32) as usize] & !SETTLED) as usize;
            while i < g.cdf.len() - 1 && g.cdf[i] <= u {
                i += 1;
            }
            g.min_q + i as i64
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut settled = 0usize;
        for &sigma in &[0.25, 0.7, 2.0, 8.0] {
            let t = SumTable::new(sigma, 16).unwrap();
            for g in t.grid.iter() {
                let n = g.guide.len() as u64;
                for s in 0..n {
                    let first = ((s << 32) + n - 1) / n;
                    let last = (((s + 1) << 32) + n - 1) / n - 1;
                    for u in [first, first + 1, last.saturating_sub(1), last] {
                        let u = u.min(u32::MAX as u64) as u32;
                        assert_eq!(g.value(u), search(g, u), "σ {sigma} slice {s} u {u}");
                    }
                    settled += usize::from(g.guide[s as usize] & SETTLED != 0);
                }
                for _ in 0..2_000 {
                    let u: u32 = rng.random();
                    assert_eq!(g.value(u), search(g, u), "σ {sigma} u {u}");
                }
            }
        }
        // Most slices are settled (else the flag would buy nothing).
        assert!(settled > 1_000, "{settled}");
    }

    #[test]
    fn refuses_outside_its_range() {
        assert!(SumTable::new(0.1, 16).is_none());
        assert!(SumTable::new(9.0, 16).is_none());
        assert!(SumTable::new(f64::NAN, 16).is_none());
        let t = SumTable::new(2.0, 16).unwrap();
        assert!(!t.serves(10.0, 4095));
        assert!(t.serves(16.0, 4095));
        assert!(!t.serves(4085.0, 4095));
    }
}
