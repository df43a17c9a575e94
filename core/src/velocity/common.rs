//! Shared by the estimators of this directory: sample-slot bookkeeping, configuration checks, the
//! α-β gain formulas (f32 and I16F16 filters) and the f32 → µm/s conversion.
//!
//! The ADC is timer-triggered, so samples are taken on a fixed grid even when their timestamps
//! are read late (interrupt latency) or a sample is lost (DMA overrun). The estimators therefore
//! count *slots*: the time since the previous sample's place on the sampling grid, rounded to
//! whole sample periods. The grid follows the timestamps through a first-order loop (each step
//! moves it by 1/16 of the timestamp's offset), so a clock running a little fast or slow is
//! tracked while the jitter of single timestamps is not: jitter below half a period around the
//! grid is rounded away. A dropped sample shows as a step of two slots and is bridged exactly
//! (the estimators use the true slot spacing); a silence longer than [`MAX_BRIDGED_SLOTS`]
//! restarts the estimator.
//!
//! Every estimator holds its clock in a [`Sampler`], with the last estimate: `update` starts with
//! [`Sampler::step`] (a duplicate answers the last estimate, a first sample or a gap starts the
//! estimator over) and ends with [`Sampler::answer`]; what happens in between is the estimator's.
//! [`super::LsqSlope`] alone ticks the clock itself, for its own restart on a gap (see there).

use super::EstimatorError;

/// Longest step between two samples that is bridged (1 = no sample lost, 4 = three lost).
pub const MAX_BRIDGED_SLOTS: u32 = 4;

/// Why an estimator with gains or thresholds could not be configured. Each variant carries the
/// value its sentence (`Display`) names.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum TuningError {
    /// Window or sample period (shared with the baseline).
    Estimator(EstimatorError),
    /// The α-β double pole outside 0 < pole < 1.
    BadPole {
        /// The pole asked for.
        pole: f32,
    },
    /// α-β gains outside the stability triangle 0 < α < 2, 0 < β < 4 − 2α.
    UnstableGains {
        /// α asked for.
        alpha: f32,
        /// β asked for.
        beta: f32,
    },
    /// The fixed-point α-β's β below its I16F16 resolution ([`MIN_FIXED_BETA`]).
    BetaBelowResolution {
        /// β asked for.
        beta: f32,
    },
    /// FOAW's noise band not finite or negative.
    BadBand {
        /// The band asked for, µm.
        band_um: f32,
    },
    /// The super-twisting Lipschitz constant not finite or not above 0.
    BadLipschitz {
        /// The constant asked for, µm/s².
        lipschitz_um_s2: f32,
    },
}

/// Smallest β the fixed-point α-β takes: below it β rounds to a handful of I16F16 steps.
pub const MIN_FIXED_BETA: f32 = 1.0 / 8_192.0;

impl core::fmt::Display for TuningError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            TuningError::Estimator(e) => e.fmt(f),
            TuningError::BadPole { pole } => {
                write!(f, "pole {pole} must be between 0 and 1, both excluded")
            }
            TuningError::UnstableGains { alpha, beta } => write!(
                f,
                "gains α = {alpha}, β = {beta} are outside the stability triangle \
                 0 < α < 2, 0 < β < 4 − 2α"
            ),
            TuningError::BetaBelowResolution { beta } => write!(
                f,
                "gain β = {beta} is below the fixed-point filter's resolution of 1/8192"
            ),
            TuningError::BadBand { band_um } => {
                write!(
                    f,
                    "noise band {band_um} µm must be a finite number of at least 0 µm"
                )
            }
            TuningError::BadLipschitz { lipschitz_um_s2 } => write!(
                f,
                "Lipschitz constant {lipschitz_um_s2} µm/s² must be a finite number above 0"
            ),
        }
    }
}

impl From<EstimatorError> for TuningError {
    fn from(e: EstimatorError) -> Self {
        TuningError::Estimator(e)
    }
}

/// The sample periods every estimator accepts, [`super::LsqSlope`] included: 10 µs ..= 100 ms.
pub(crate) fn check_period(sample_period_us: u32) -> Result<(), EstimatorError> {
    if (10..=100_000).contains(&sample_period_us) {
        Ok(())
    } else {
        Err(EstimatorError::BadSamplePeriod { sample_period_us })
    }
}

/// (α, β) of the critically damped α-β filter with its double pole at `pole` (0 < pole < 1):
/// α = 1 − p², β = (1 − p)².
pub(crate) fn critically_damped_gains(pole: f32) -> Result<(f32, f32), TuningError> {
    if !(pole > 0.0 && pole < 1.0) {
        return Err(TuningError::BadPole { pole });
    }
    Ok((1.0 - pole * pole, (1.0 - pole) * (1.0 - pole)))
}

/// α-β gains inside the stability triangle 0 < α < 2, 0 < β < 4 − 2α (false for NaN).
pub(crate) fn alpha_beta_stable(alpha: f32, beta: f32) -> bool {
    alpha > 0.0 && alpha < 2.0 && beta > 0.0 && beta < 4.0 - 2.0 * alpha
}

/// Group delay of an α-β filter at constant acceleration, in samples: α/β − ½.
fn alpha_beta_delay_samples(alpha: f32, beta: f32) -> f32 {
    alpha / beta - 0.5
}

/// Samples without output after a (re)start, while the transient from v̂ = 0 settles: about two
/// group delays, 1 ..= 10 000.
pub(crate) fn alpha_beta_warmup(alpha: f32, beta: f32) -> u32 {
    libm::roundf(2.0 * alpha_beta_delay_samples(alpha, beta)).clamp(1.0, 10_000.0) as u32
}

/// Group delay of an α-β filter, µs, rounded.
pub(crate) fn alpha_beta_group_delay_us(alpha: f32, beta: f32, sample_period_us: u32) -> u32 {
    libm::roundf(alpha_beta_delay_samples(alpha, beta) * sample_period_us as f32) as u32
}

/// What the time since the previous sample means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tick {
    /// No previous sample: start.
    First,
    /// This many whole periods since the previous sample (1 normally, 2..=MAX with drops).
    Slots(u32),
    /// Less than half a period since the previous sample: a repeated reading, ignored.
    Duplicate,
    /// Longer than [`MAX_BRIDGED_SLOTS`] periods, or time ran backwards: restart.
    Gap,
}

/// Turns timestamps into slot steps (see the module doc).
///
/// No 64-bit arithmetic and, on the common path (one slot, or a duplicate), no division: the
/// offset from the grid, plus half a period, is compared against thresholds computed in `new`.
/// Only a step of 2..=[`MAX_BRIDGED_SLOTS`] slots (a lost sample) divides, in u32 (one `udiv`
/// on a Cortex-M3/M4).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlotClock {
    period_us: u32,
    /// max(period, 1), non-zero by type: the per-sample division needs no zero check and the
    /// tick no `max` (the estimators' constructors refuse periods below 10 µs anyway).
    step_us: core::num::NonZeroU32,
    /// ⌊period/2⌋: added to the offset from the grid so that whole periods round to nearest.
    half_us: u32,
    /// 2 periods: a rounded offset below this (and not below one period) is one slot.
    two_periods_us: u32,
    /// (MAX_BRIDGED_SLOTS + 1) periods: a rounded offset from here on is a gap.
    gap_us: u32,
    /// Where the previous sample sits on the sampling grid, µs (wrapping).
    grid_us: Option<u32>,
    /// Sub-µs part of the grid, 1/256 µs.
    grid_frac: i32,
}

impl SlotClock {
    /// For periods up to 100 ms ([`check_period`]); the thresholds saturate far above that.
    pub(crate) const fn new(period_us: u32) -> Self {
        Self {
            period_us,
            step_us: match core::num::NonZeroU32::new(period_us) {
                Some(p) => p,
                None => core::num::NonZeroU32::MIN,
            },
            half_us: period_us / 2,
            two_periods_us: period_us.saturating_mul(2),
            gap_us: period_us.saturating_mul(MAX_BRIDGED_SLOTS + 1),
            grid_us: None,
            grid_frac: 0,
        }
    }

    pub(crate) fn period_us(&self) -> u32 {
        self.period_us
    }

    #[inline(always)]
    pub(crate) fn tick(&mut self, t_us: u32) -> Tick {
        let Some(grid) = self.grid_us else {
            self.grid_us = Some(t_us);
            return Tick::First;
        };
        // Offset from the previous grid point plus half a period: its whole periods are the
        // slot count, rounded to nearest. Read as u32, a timestamp more than half a period
        // *before* the grid (signed offset < −⌊p/2⌋) lands at ≥ 2³¹, past `gap_us`: time that
        // ran backwards is a gap (restart) like a long silence, not a duplicate.
        let rounded = t_us.wrapping_sub(grid).wrapping_add(self.half_us);
        // ≥ 10 already (every estimator's constructor runs `check_period`); non-zero by type,
        // so the division has no zero check on the per-sample path (scripts/panic-check.sh).
        let step = self.step_us;
        let p = step.get();
        // A timestamp exactly one period on (the firmware stamps its samples so): one slot and
        // no offset to follow, the general path's result without its arithmetic. `grid_frac`
        // stays in 0..256, so a zero offset moves the grid by nothing there either.
        if rounded == p.wrapping_add(self.half_us) {
            self.grid_us = Some(t_us);
            return Tick::Slots(1);
        }
        let (slots, on_grid) = if rounded < p {
            return Tick::Duplicate;
        } else if rounded < self.two_periods_us {
            (1, grid.wrapping_add(p))
        } else if rounded < self.gap_us {
            let slots = rounded / step;
            (slots, grid.wrapping_add(slots * p))
        } else {
            self.grid_us = Some(t_us);
            return Tick::Gap;
        };
        // Move the grid by 1/16 of the offset, in 1/256 µs so small offsets still count. The
        // offset is (rounded mod p) − ⌊p/2⌋, within ±p/2, so 16× it cannot overflow.
        let offset = t_us.wrapping_sub(on_grid) as i32;
        self.grid_frac += offset * 16;
        let whole = self.grid_frac >> 8;
        self.grid_frac -= whole << 8;
        self.grid_us = Some(on_grid.wrapping_add(whole as u32));
        Tick::Slots(slots)
    }

    pub(crate) fn reset(&mut self) {
        self.grid_us = None;
        self.grid_frac = 0;
    }

    /// True when a sample at `t_us` is exactly one period past the grid: [`Self::tick`] would
    /// take its fast path there (one slot, the grid moved to `t_us`, the fraction untouched).
    #[inline(always)]
    pub(crate) fn one_period_on(&self, t_us: u32) -> bool {
        matches!(self.grid_us, Some(grid) if t_us.wrapping_sub(grid) == self.step_us.get())
    }

    /// [`Self::tick`]'s fast path at `t_us`, for a caller that tested [`Self::one_period_on`]
    /// (a deferred rest: the grid moves as the tick would move it).
    #[inline(always)]
    pub(crate) fn step_on_grid(&mut self, t_us: u32) {
        self.grid_us = Some(t_us);
    }
}

/// What a sample is to an estimator once [`Sampler::step`] has placed it on the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Step {
    /// A repeated reading: the estimator returns its previous estimate ([`Sampler::last_out`])
    /// and changes nothing.
    Repeat,
    /// The first sample since a (re)start — the first ever, the first after a reset, or one after
    /// a gap (the clock then restarts from scratch on it): the estimator forgets its history and
    /// starts on this sample. The previous estimate is already `None`.
    Start,
    /// This many whole periods since the previous sample (1 normally, 2..=MAX with drops).
    Slots(u32),
}

/// The slot clock and the last estimate: the bookkeeping every estimator does around its own
/// arithmetic. [`Self::step`] places a sample (a repeat, a (re)start or whole slots, the clock
/// restarted after a gap), [`Self::answer`] keeps the estimate a duplicate repeats.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sampler {
    clock: SlotClock,
    last_out: Option<i32>,
}

impl Sampler {
    /// For periods up to 100 ms ([`check_period`]).
    pub(crate) const fn new(period_us: u32) -> Self {
        Self {
            clock: SlotClock::new(period_us),
            last_out: None,
        }
    }

    pub(crate) fn period_us(&self) -> u32 {
        self.clock.period_us()
    }

    /// The sample at `t_us`: a repeat, a (re)start or a step of whole slots.
    #[inline(always)]
    pub(crate) fn step(&mut self, t_us: u32) -> Step {
        match self.clock.tick(t_us) {
            Tick::Duplicate => Step::Repeat,
            Tick::Slots(m) => Step::Slots(m),
            Tick::First | Tick::Gap => {
                // From scratch: after a gap the clock has restarted on this sample but kept its
                // sub-µs phase. On a first sample this changes nothing, but one arm for both keeps
                // the estimators' hot path as short as it was (M4F instruction counts).
                self.reset();
                self.clock.tick(t_us);
                Step::Start
            }
        }
    }

    /// The clock's own tick, for an estimator that handles a gap itself ([`super::LsqSlope`]).
    #[inline(always)]
    pub(crate) fn tick(&mut self, t_us: u32) -> Tick {
        self.clock.tick(t_us)
    }

    /// The previous estimate.
    pub(crate) fn last_out(&self) -> Option<i32> {
        self.last_out
    }

    /// Keeps `out` for a duplicate to repeat, and returns it.
    #[inline(always)]
    pub(crate) fn answer(&mut self, out: Option<i32>) -> Option<i32> {
        self.last_out = out;
        out
    }

    pub(crate) fn reset(&mut self) {
        self.clock.reset();
        self.last_out = None;
    }
}

/// µm/s from a float, rounded to nearest, saturating (NaN → 0, which cannot happen with finite
/// inputs but keeps the output bounded whatever arrives).
pub(crate) fn to_um_s(v: f32) -> i32 {
    libm::roundf(v) as i32
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The slot clock as it was before the on-grid fast path (issue #35): the fast path must
    /// change no tick and no grid, over on-grid runs, jitter, drops, duplicates, gaps and time
    /// running backwards.
    #[derive(Clone, Copy)]
    struct ReferenceClock {
        p: u32,
        grid: Option<u32>,
        frac: i32,
    }

    impl ReferenceClock {
        fn tick(&mut self, t: u32) -> Tick {
            let Some(grid) = self.grid else {
                self.grid = Some(t);
                return Tick::First;
            };
            let p = self.p;
            let rounded = t.wrapping_sub(grid).wrapping_add(p / 2);
            let (slots, on_grid) = if rounded < p {
                return Tick::Duplicate;
            } else if rounded < 2 * p {
                (1, grid.wrapping_add(p))
            } else if rounded < p * (MAX_BRIDGED_SLOTS + 1) {
                (rounded / p, grid.wrapping_add(rounded / p * p))
            } else {
                self.grid = Some(t);
                return Tick::Gap;
            };
            self.frac += t.wrapping_sub(on_grid) as i32 * 16;
            let whole = self.frac >> 8;
            self.frac -= whole << 8;
            self.grid = Some(on_grid.wrapping_add(whole as u32));
            Tick::Slots(slots)
        }
    }

    proptest! {
        #[test]
        fn the_on_grid_path_is_the_general_path(
            period in prop_oneof![Just(100u32), 10u32..2_000],
            steps in proptest::collection::vec(
                prop_oneof![
                    6 => Just(0i64),
                    2 => -60i64..60,
                    1 => Just(100_000i64),
                    1 => -3_000i64..3_000,
                    1 => Just(-1i64 << 31),
                ],
                1..300,
            ),
        ) {
            let mut fast = SlotClock::new(period);
            let mut reference = ReferenceClock { p: period, grid: None, frac: 0 };
            let mut t = u32::MAX - 50_000;
            for (i, &d) in steps.iter().enumerate() {
                // Mostly exactly one period on (the fast path), else off by `d` µs.
                let step = period as i64 + if d == 100_000 { period as i64 } else { d };
                t = t.wrapping_add(step as u32);
                prop_assert_eq!(fast.tick(t), reference.tick(t), "tick {}", i);
                prop_assert_eq!((fast.grid_us, fast.grid_frac), (reference.grid, reference.frac), "grid {}", i);
            }
        }
    }

    #[test]
    fn slots_round_jitter_and_count_drops() {
        let mut c = SlotClock::new(100);
        assert_eq!(c.tick(1_000), Tick::First);
        assert_eq!(c.tick(1_140), Tick::Slots(1)); // 40 µs late
        assert_eq!(c.tick(1_160), Tick::Slots(1)); // 40 µs early: only 20 µs after the last
        assert_eq!(c.tick(1_400), Tick::Slots(2)); // one sample lost
        assert_eq!(c.tick(1_420), Tick::Duplicate);
        assert_eq!(c.tick(1_900), Tick::Gap); // five slots: restart
        assert_eq!(c.tick(1_000), Tick::Gap); // ran backwards
    }

    #[test]
    fn grid_follows_a_slow_clock_and_ignores_jitter() {
        // Period really 100.01 µs (100 ppm slow) with ±30 µs jitter: never a wrong slot count
        // (the grid itself wanders by σ ≈ 3 µs, so the margin is not the full ±50 µs).
        let mut c = SlotClock::new(100);
        c.tick(0);
        let mut lcg = 12_345u32;
        for k in 1..20_000u32 {
            lcg = lcg.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let jitter = (lcg >> 16) % 61;
            let t = (k as f64 * 100.01) as u32 + jitter;
            assert_eq!(c.tick(t.wrapping_sub(30)), Tick::Slots(1), "sample {k}");
        }
    }

    #[test]
    fn sampler_repeats_the_last_answer_and_starts_over_after_a_gap() {
        let mut s = Sampler::new(100);
        assert_eq!(s.step(1_000), Step::Start);
        assert_eq!(s.answer(None), None);
        assert_eq!(s.step(1_100), Step::Slots(1));
        assert_eq!(s.answer(Some(7)), Some(7));
        assert_eq!(s.step(1_120), Step::Repeat);
        assert_eq!(s.last_out(), Some(7));
        assert_eq!(s.step(1_300), Step::Slots(2));
        assert_eq!(s.step(2_000), Step::Start); // seven slots: a gap
        assert_eq!(s.last_out(), None);
        assert_eq!(s.step(2_100), Step::Slots(1));
    }

    #[test]
    fn rounding_saturates() {
        assert_eq!(to_um_s(2.5), 3);
        assert_eq!(to_um_s(-2.5), -3);
        assert_eq!(to_um_s(1e12), i32::MAX);
        assert_eq!(to_um_s(f32::NAN), 0);
    }

    /// [`SlotClock::tick`] against the implementation it replaced (an i64 `div_euclid` per
    /// sample), kept here verbatim: the same ticks and the same grid state, step by step.
    mod equivalence {
        use super::*;

        /// The i64 implementation, as it was.
        struct OldSlotClock {
            period_us: u32,
            grid_us: Option<u32>,
            grid_frac: i32,
        }

        impl OldSlotClock {
            fn new(period_us: u32) -> Self {
                Self {
                    period_us,
                    grid_us: None,
                    grid_frac: 0,
                }
            }

            fn tick(&mut self, t_us: u32) -> Tick {
                let Some(grid) = self.grid_us else {
                    self.grid_us = Some(t_us);
                    return Tick::First;
                };
                let dt = t_us.wrapping_sub(grid) as i32 as i64;
                let p = self.period_us as i64;
                if dt < -p / 2 {
                    self.grid_us = Some(t_us);
                    return Tick::Gap;
                }
                let slots = (dt + p / 2).div_euclid(p);
                if slots <= 0 {
                    return Tick::Duplicate;
                }
                if slots > MAX_BRIDGED_SLOTS as i64 {
                    self.grid_us = Some(t_us);
                    return Tick::Gap;
                }
                let on_grid = grid.wrapping_add((slots * p) as u32);
                let offset = t_us.wrapping_sub(on_grid) as i32;
                self.grid_frac += offset.clamp(-1 << 20, 1 << 20) * 16;
                let whole = self.grid_frac >> 8;
                self.grid_frac -= whole << 8;
                self.grid_us = Some(on_grid.wrapping_add(whole as u32));
                Tick::Slots(slots as u32)
            }

            fn reset(&mut self) {
                self.grid_us = None;
                self.grid_frac = 0;
            }
        }

        /// One step of a timestamp sequence, made concrete against the period and the grid.
        #[derive(Clone, Debug)]
        enum Step {
            /// One period later, ± up to a whole period of jitter.
            Next(i32),
            /// k periods later (k = 2..=6: one to five samples lost), ± jitter.
            Drop(u32, i32),
            /// Up to a period later: a repeated or early reading.
            Soon(u32),
            /// Anywhere (long silences, the u32 clock's wrap, half the clock away).
            Jump(u32),
            /// Up to three periods back.
            Back(u32),
            /// Within ±2 µs of a rounding threshold: k·p + p/2 from the grid (k = −2..=6).
            Edge(i32, i32),
            /// Forget the grid.
            Reset,
        }

        fn step() -> impl Strategy<Value = Step> {
            prop_oneof![
                8 => any::<i32>().prop_map(Step::Next),
                2 => (2u32..=6, any::<i32>()).prop_map(|(k, j)| Step::Drop(k, j)),
                1 => any::<u32>().prop_map(Step::Soon),
                1 => any::<u32>().prop_map(Step::Jump),
                1 => any::<u32>().prop_map(Step::Back),
                2 => (-2i32..=6, -2i32..=2).prop_map(|(k, d)| Step::Edge(k, d)),
                1 => Just(Step::Reset),
            ]
        }

        fn period() -> impl Strategy<Value = u32> {
            // The accepted range is 10..=100 000 (`check_period`); the clock itself is checked
            // beyond it, both ways, and at the odd/even halves.
            prop_oneof![
                Just(100u32),
                Just(10),
                Just(100_000),
                Just(101),
                1u32..=200_000
            ]
        }

        fn start() -> impl Strategy<Value = u32> {
            prop_oneof![any::<u32>(), (u32::MAX - 2_000_000)..=u32::MAX]
        }

        /// The next timestamp for `s`, from the last one and the old clock's grid.
        fn next_t(s: &Step, t: u32, p: u32, grid: Option<u32>) -> u32 {
            let jitter = |j: i32| (j % p as i32) as u32;
            match *s {
                Step::Next(j) => t.wrapping_add(p).wrapping_add(jitter(j)),
                Step::Drop(k, j) => t.wrapping_add(k * p).wrapping_add(jitter(j)),
                Step::Soon(d) => t.wrapping_add(d % (p + 1)),
                Step::Jump(d) => t.wrapping_add(d),
                Step::Back(d) => t.wrapping_sub(d % (3 * p + 1)),
                Step::Edge(k, d) => grid
                    .unwrap_or(t)
                    .wrapping_add((k * p as i32) as u32)
                    .wrapping_add(p / 2)
                    .wrapping_add(d as u32),
                Step::Reset => t,
            }
        }

        proptest! {
            #![proptest_config(ProptestConfig { cases: 500, ..ProptestConfig::default() })]

            #[test]
            fn slot_clock_tick_matches_the_old_i64_division(
                p in period(),
                t0 in start(),
                steps in prop::collection::vec(step(), 1..300),
            ) {
                let mut old = OldSlotClock::new(p);
                let mut new = SlotClock::new(p);
                prop_assert_eq!(new.tick(t0), old.tick(t0));
                let mut t = t0;
                for (i, s) in steps.iter().enumerate() {
                    t = next_t(s, t, p, old.grid_us);
                    if let Step::Reset = s {
                        old.reset();
                        new.reset();
                    } else {
                        prop_assert_eq!(new.tick(t), old.tick(t), "step {} {:?} t={}", i, s, t);
                    }
                    prop_assert_eq!(new.grid_us, old.grid_us, "step {}", i);
                    prop_assert_eq!(new.grid_frac, old.grid_frac, "step {}", i);
                }
            }
        }

        /// Every offset from −3 to +7 periods around the grid (and the extremes of the signed
        /// 32-bit offset), from grids near 0 and near the wrap, with sub-µs parts across their
        /// range: one tick each, from the same state.
        #[test]
        fn slot_clock_tick_matches_the_old_i64_division_at_every_offset() {
            for p in [1u32, 2, 3, 10, 11, 99, 100, 101, 1_000, 4_097, 100_000] {
                let pi = p as i64;
                let offsets = (-3 * pi..=7 * pi)
                    .chain([i32::MIN as i64, i32::MIN as i64 + 1, i32::MAX as i64 - 1])
                    .chain([i32::MAX as i64]);
                for dt in offsets {
                    for grid in [0u32, 12_345, u32::MAX - 150_000, u32::MAX] {
                        for frac in [0i32, 1, 8, 128, 255] {
                            let t = grid.wrapping_add(dt as i32 as u32);
                            let mut old = OldSlotClock::new(p);
                            old.grid_us = Some(grid);
                            old.grid_frac = frac;
                            let mut new = SlotClock::new(p);
                            new.grid_us = Some(grid);
                            new.grid_frac = frac;
                            let what = (p, dt, grid, frac);
                            assert_eq!(new.tick(t), old.tick(t), "{what:?}");
                            assert_eq!(new.grid_us, old.grid_us, "{what:?}");
                            assert_eq!(new.grid_frac, old.grid_frac, "{what:?}");
                        }
                    }
                }
            }
        }
    }

    /// A tuning refusal reads as one sentence naming the value and the rule; a window or
    /// period one reads as the estimator's.
    #[test]
    fn tuning_errors_read_as_sentences() {
        let cases = [
            (
                TuningError::BadPole { pole: 1.0 },
                "pole 1 must be between 0 and 1, both excluded",
            ),
            (
                TuningError::UnstableGains {
                    alpha: 1.5,
                    beta: 1.1,
                },
                "gains α = 1.5, β = 1.1 are outside the stability triangle 0 < α < 2, \
                 0 < β < 4 − 2α",
            ),
            (
                TuningError::BetaBelowResolution { beta: 0.0001 },
                "gain β = 0.0001 is below the fixed-point filter's resolution of 1/8192",
            ),
            (
                TuningError::BadBand { band_um: f32::NAN },
                "noise band NaN µm must be a finite number of at least 0 µm",
            ),
            (
                TuningError::BadLipschitz {
                    lipschitz_um_s2: 0.0,
                },
                "Lipschitz constant 0 µm/s² must be a finite number above 0",
            ),
            (
                TuningError::from(check_period(5).unwrap_err()),
                "sample period 5 µs is outside the estimators' 10 µs to 100000 µs",
            ),
        ];
        for (e, sentence) in cases {
            assert_eq!(std::format!("{e}"), sentence);
        }
    }

    /// α = 1 − p², β = (1 − p)², by hand at p = 0.5: (0.75, 0.25); the open interval's ends
    /// are refused.
    #[test]
    fn critically_damped_gains_and_their_edges() {
        assert_eq!(critically_damped_gains(0.5), Ok((0.75, 0.25)));
        for pole in [0.0, 1.0, -0.1, f32::INFINITY] {
            assert_eq!(
                critically_damped_gains(pole),
                Err(TuningError::BadPole { pole })
            );
        }
        assert!(critically_damped_gains(f32::NAN).is_err());
    }

    /// Every estimator's `reset` makes it a new one, and so does a silence longer than the
    /// bridged slots: fed the same samples afterwards, it answers exactly what a freshly made
    /// estimator answers (nothing of the 1 s ramp before, nor of the clock's phase, survives).
    #[test]
    fn reset_and_gaps_make_every_estimator_new() {
        use crate::velocity::*;
        fn check<E: VelocityEstimator>(name: &str, make: impl Fn() -> E) {
            for (how, t0) in [("reset", 1_000_000), ("gap", 2_000_000)] {
                let mut e = make();
                for i in 0..10_000u32 {
                    e.update(i as i32 * 10, i * 100);
                }
                if how == "reset" {
                    e.reset();
                }
                let mut fresh = make();
                for i in 0..300u32 {
                    let t = t0 + i * 100;
                    let x = 100_000 - i as i32 * 5;
                    assert_eq!(
                        e.update(x, t),
                        fresh.update(x, t),
                        "{name} after a {how}, sample {i}"
                    );
                }
            }
        }
        check("lsq32", || LsqSlope::<32>::new(100).unwrap());
        check("med3+lsq32", || {
            Median3::new(LsqSlope::<32>::new(100).unwrap(), 100)
        });
        check("diff4", || BackwardDifference::<4>::new(100).unwrap());
        check("foaw", || {
            Foaw::<32>::new(FoawFit::EndFit, 24.0, 100).unwrap()
        });
        check("ab", || AlphaBeta::critically_damped(100, 0.9).unwrap());
        check("abq16", || {
            AlphaBetaFixed::critically_damped(100, 0.9).unwrap()
        });
        check("std", || SuperTwisting::new(100, 1e6).unwrap());
    }
}
