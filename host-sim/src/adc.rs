//! Rheostat + ADC model: true position → oversampled 16-bit code, as the core's sample stage
//! expects it.
//!
//! Each control sample is the sum of [`OVERSAMPLE`] 12-bit conversions. One conversion is the
//! ideal code of the position (the calibration's `code_at_um`, divided by 16 to get 12-bit LSBs),
//! plus a fixed offset and Gaussian noise (σ in 12-bit LSB RMS, independent per conversion),
//! rounded and clamped to 0..=4095. Rail faults replace every conversion of the window by 0
//! (open wiper, pulled down) or 4095 (short to the supply); a dropout delivers no sample at all.
//!
//! The sum is drawn in one step from its exact distribution ([`crate::noise::SumTable`]) where
//! that is valid, and conversion by conversion elsewhere (near the rails, tiny or huge σ, or
//! when [`AdcParams::per_conversion`] asks for it).
//!
//! Silicon effects for the conversion budget (`docs/conversion-budget.md`), each off by default
//! so the published figures do not move, and used only through [`AdcModel::sample_moving`]:
//! - [`Settling`]: the sample-and-hold capacitor charging through the rheostat's Thevenin
//!   resistance R·u(1 − u) for the programmed sampling time (a deterministic, position-dependent
//!   error: the fraction exp(−t_s/τ) of the step from the charge the capacitor kept from its
//!   previous conversion; interleaved ADCs each keep their own), and an optional capacitor at
//!   the pin (an RC low-pass, i.e. lag);
//! - a noise floor common to every conversion of a sample ([`AdcParams::floor_lsb_rms`]):
//!   reference, supply and wiper noise below the sample rate, which oversampling cannot average;
//! - the conversion window ([`AdcParams::conversion_window_us`]): the conversions are spread over
//!   time before the sample's stamp, so the sample is the mean position over that window;
//! - any number of conversions per sample, scaled back to the core's 16-conversion code (the
//!   G474 oversampler's right shift, or the F446's software sum shifted).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use saw_core::position::{Calibration, PositionMapper};
use saw_core::sample::{Sample, CONVERSION_FULL_SCALE, OVERSAMPLE};
use serde::Deserialize;

use crate::noise::{Prepared, SumTable};
use crate::trajectory::State;

/// What goes wrong with the sensor during a fault window.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FaultKind {
    /// Open wiper: the pull-down reads 0 on every conversion.
    Open,
    /// Wiper shorted to the supply: 4095 on every conversion.
    Short,
    /// No samples arrive (DMA stalled, ADC stopped): exercises the stale watchdog.
    Dropout,
    /// Every conversion off by `offset_lsb` 12-bit LSB (clamped to the converter's range):
    /// interference or a bouncing wiper. A window of one sample period is a single-sample spike.
    Spike {
        /// Added to every conversion, 12-bit LSB.
        offset_lsb: i16,
    },
    /// An offset that grows from 0 at the window's start by `lsb_per_s` (a warming reference, a
    /// wearing track), added to every conversion and clamped like a spike.
    Drift {
        /// Growth of the offset, 12-bit LSB per second.
        lsb_per_s: i32,
    },
}

impl FaultKind {
    /// The offset this kind adds to each conversion `since_start_us` into its window, 12-bit
    /// LSB (0 for the kinds that replace the reading instead).
    pub fn offset_lsb_at(&self, since_start_us: u64) -> f64 {
        match *self {
            FaultKind::Spike { offset_lsb } => offset_lsb as f64,
            FaultKind::Drift { lsb_per_s } => lsb_per_s as f64 * since_start_us as f64 * 1e-6,
            FaultKind::Open | FaultKind::Short | FaultKind::Dropout => 0.0,
        }
    }
}

/// A fault over `[start_us, end_us)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
pub struct FaultWindow {
    /// What happens.
    pub kind: FaultKind,
    /// Start, µs of simulation time.
    pub start_us: u64,
    /// End (exclusive), µs.
    pub end_us: u64,
}

impl FaultWindow {
    /// True when `t_us` lies inside the window.
    pub fn contains(&self, t_us: u64) -> bool {
        (self.start_us..self.end_us).contains(&t_us)
    }
}

/// ADC parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct AdcParams {
    /// Offset added to every conversion, 12-bit LSB.
    pub offset_lsb: f64,
    /// Gaussian noise per conversion, 12-bit LSB RMS.
    pub noise_lsb_rms: f64,
    /// Conversions summed per sample (the core expects 16).
    pub oversample: u32,
    /// PRNG seed.
    pub seed: u64,
    /// Fault windows.
    pub faults: Vec<FaultWindow>,
    /// Draw every conversion instead of the sum's tabulated distribution (the reference the
    /// fast path is measured against; about 10× slower).
    pub per_conversion: bool,
    /// Sampling-time settling through the rheostat; None: every conversion sees the pin's
    /// voltage exactly (the model of every published figure).
    pub settling: Option<Settling>,
    /// Noise common to every conversion of one sample (it does not average down with
    /// oversampling), 12-bit LSB RMS; 0: none.
    pub floor_lsb_rms: f64,
    /// Corner of that noise's first-order spectrum, Hz: consecutive samples Δt apart are
    /// correlated by exp(−2π·f_c·Δt).
    pub floor_corner_hz: f64,
    /// Span of one sample's conversions, ending at its timestamp, µs (evenly spaced; the
    /// sample's effective time is the span's centre); 0: all at the timestamp.
    pub conversion_window_us: f64,
}

/// The sample-and-hold capacitor against the rheostat (STM32 ADC input model: the source
/// resistance in series with the sampling switch R_ADC charging C_ADC for t_s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settling {
    /// Programmed sampling time, ns.
    pub sampling_time_ns: f64,
    /// End-to-end resistance of the rheostat wired as a divider, Ω: its Thevenin resistance at
    /// wiper fraction u is R·u(1 − u) (R/4 at mid travel).
    pub pot_ohm: f64,
    /// The ADC's sampling switch resistance R_ADC, Ω.
    pub switch_ohm: f64,
    /// The ADC's hold capacitor C_ADC, pF.
    pub hold_pf: f64,
    /// A capacitor from the pin to ground, nF (0: none fitted). It low-passes the pin with
    /// τ = R_s·C (lag) and, being charged, hands the hold capacitor the pin's voltage at once.
    pub pin_nf: f64,
    /// Interleaved ADCs sampling the pin in turn, each with its own hold capacitor.
    pub adcs: u32,
}

impl Settling {
    /// Thevenin resistance of the rheostat at a conversion value of `v_lsb` (12-bit), Ω.
    pub fn source_ohm(&self, v_lsb: f64) -> f64 {
        let u = (v_lsb / CONVERSION_FULL_SCALE as f64).clamp(0.0, 1.0);
        self.pot_ohm * u * (1.0 - u)
    }

    /// The fraction of the step from the held voltage that is left after the sampling time at
    /// `v_lsb`: exp(−t_s / ((R_s + R_ADC)·C_ADC)). With a pin capacitor the hold capacitor
    /// charges from it through R_ADC alone (C_pin ≫ C_ADC, so the charge it gives is ignored).
    pub fn residual_fraction(&self, v_lsb: f64) -> f64 {
        let r_ohm = if self.pin_nf > 0.0 {
            self.switch_ohm
        } else {
            self.source_ohm(v_lsb) + self.switch_ohm
        };
        // Ω × pF = ps: τ in ns is R·C / 1000.
        let tau_ns = r_ohm * self.hold_pf * 1e-3;
        if tau_ns <= 0.0 {
            0.0
        } else {
            (-self.sampling_time_ns / tau_ns).exp()
        }
    }

    /// Sampling time needed for a full-scale step to settle within `lsb` (12-bit) at the worst
    /// source resistance (mid travel), ns: τ·ln(4096 / lsb).
    pub fn needed_ns(pot_ohm: f64, switch_ohm: f64, hold_pf: f64, lsb: f64) -> f64 {
        (pot_ohm / 4.0 + switch_ohm) * hold_pf * 1e-3 * (CONVERSION_FULL_SCALE as f64 / lsb).ln()
    }
}

impl Default for AdcParams {
    fn default() -> Self {
        Self {
            offset_lsb: 0.0,
            noise_lsb_rms: 2.0,
            oversample: OVERSAMPLE,
            seed: 1,
            faults: Vec::new(),
            per_conversion: false,
            settling: None,
            floor_lsb_rms: 0.0,
            floor_corner_hz: 1_000.0,
            conversion_window_us: 0.0,
        }
    }
}

impl AdcParams {
    /// The closed loop's model of `board`'s acquisition: the default (2 LSB RMS of white noise
    /// per conversion, no silicon effect) converting the board's conversions per sample
    /// (`saw_boards::Oversampling::conversions`: 16 on the F446, 32 on the G474), the sum
    /// scaled to the core's 16-conversion code as the board's shift does. On the F446 this is
    /// exactly [`AdcParams::default`].
    pub fn for_board(board: &saw_boards::BoardDef) -> Self {
        Self {
            oversample: board.adc.oversampling.conversions(),
            ..Self::default()
        }
    }

    /// The same model with `noise_lsb_rms` of noise per conversion, drawn from `seed`.
    pub fn with_noise(mut self, noise_lsb_rms: f64, seed: u64) -> Self {
        self.noise_lsb_rms = noise_lsb_rms;
        self.seed = seed;
        self
    }

    /// True when a silicon effect of the conversion budget is on (or the conversions per sample
    /// are not the core's 16): [`AdcModel::sample_moving`] then draws conversion by conversion.
    pub fn silicon_effects(&self) -> bool {
        self.settling.is_some()
            || self.floor_lsb_rms > 0.0
            || self.conversion_window_us > 0.0
            || self.oversample != OVERSAMPLE
    }
}

/// Table draws [`AdcModel::samples_into`] prepares before it finishes them: enough to cover
/// the guide reads' latency, few enough that their guide entries are still in the L1 cache.
const PREPARED: usize = 64;

/// What the silicon effects remember between conversions.
#[derive(Clone, Debug, Default)]
struct Held {
    /// Each interleaved ADC's hold capacitor, 12-bit LSB (None before its first conversion).
    caps_lsb: Vec<Option<f64>>,
    /// The ADC that converts next.
    next_adc: usize,
    /// The pin capacitor's voltage, 12-bit LSB, and when it was last brought up to date, s.
    pin: Option<(f64, f64)>,
    /// The noise floor's value, 12-bit LSB, and the time of the sample it was drawn for, µs.
    floor: Option<(f64, u64)>,
}

/// The rheostat and ADC.
#[derive(Clone, Debug)]
pub struct AdcModel {
    mapper: PositionMapper,
    params: AdcParams,
    rng: ChaCha8Rng,
    noise: Option<Normal<f64>>,
    table: Option<SumTable>,
    held: Held,
}

/// Why an ADC model could not be built.
#[derive(Clone, Debug, PartialEq)]
pub enum AdcError {
    /// The calibration is invalid.
    Calibration(saw_core::position::CalibrationError),
    /// Negative or non-finite noise.
    BadNoise {
        /// The noise asked for, LSB RMS.
        noise_lsb_rms: f64,
    },
    /// A silicon-effect parameter that is negative, non-finite or zero where it must count.
    BadSilicon {
        /// Which parameter.
        what: &'static str,
        /// Its value.
        value: f64,
    },
}

impl std::fmt::Display for AdcError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AdcError::Calibration(e) => e.fmt(f),
            AdcError::BadNoise { noise_lsb_rms } => write!(
                f,
                "ADC noise {noise_lsb_rms} LSB RMS must be finite and at least 0 LSB"
            ),
            AdcError::BadSilicon { what, value } => write!(
                f,
                "ADC {what} {value} must be finite and at least 0 (and a count at least 1)"
            ),
        }
    }
}

impl std::error::Error for AdcError {}

impl AdcModel {
    /// A model of the rheostat calibrated as `cal`.
    pub fn new(cal: Calibration, params: AdcParams) -> Result<Self, AdcError> {
        let mapper = PositionMapper::new(cal).map_err(AdcError::Calibration)?;
        let noise = if params.noise_lsb_rms > 0.0 {
            Some(
                Normal::new(0.0, params.noise_lsb_rms).map_err(|_| AdcError::BadNoise {
                    noise_lsb_rms: params.noise_lsb_rms,
                })?,
            )
        } else if params.noise_lsb_rms == 0.0 {
            None
        } else {
            return Err(AdcError::BadNoise {
                noise_lsb_rms: params.noise_lsb_rms,
            });
        };
        let rng = ChaCha8Rng::seed_from_u64(params.seed);
        let table = if params.per_conversion {
            None
        } else {
            SumTable::new(params.noise_lsb_rms, params.oversample)
        };
        for (what, v) in [
            ("noise floor", params.floor_lsb_rms),
            ("noise floor corner", params.floor_corner_hz),
            ("conversion window", params.conversion_window_us),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(AdcError::BadSilicon { what, value: v });
            }
        }
        if let Some(s) = &params.settling {
            for (what, v) in [
                ("sampling time", s.sampling_time_ns),
                ("rheostat resistance", s.pot_ohm),
                ("switch resistance", s.switch_ohm),
                ("hold capacitor", s.hold_pf),
                ("pin capacitor", s.pin_nf),
            ] {
                if !v.is_finite() || v < 0.0 {
                    return Err(AdcError::BadSilicon { what, value: v });
                }
            }
            if s.adcs == 0 {
                return Err(AdcError::BadSilicon {
                    what: "interleaved ADC count",
                    value: 0.0,
                });
            }
        }
        if params.oversample == 0 {
            return Err(AdcError::BadSilicon {
                what: "conversions per sample",
                value: 0.0,
            });
        }
        Ok(Self {
            mapper,
            params,
            rng,
            noise,
            table,
            held: Held::default(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &AdcParams {
        &self.params
    }

    /// The active fault at `t_us`, if any (the first listed wins).
    pub fn fault_at(&self, t_us: u64) -> Option<FaultKind> {
        self.params
            .faults
            .iter()
            .find(|f| f.contains(t_us))
            .map(|f| f.kind)
    }

    /// Ideal (noise-free, unquantized) 12-bit conversion value at `position_um`.
    pub fn ideal_conversion(&self, position_um: f64) -> f64 {
        self.mapper.code_at_um(position_um as f32) as f64 / OVERSAMPLE as f64
    }

    /// One conversion at `position_um` (noise, offset, quantization, clamping).
    pub fn convert(&mut self, position_um: f64) -> u32 {
        let mut v = self.ideal_conversion(position_um) + self.params.offset_lsb;
        if let Some(n) = &self.noise {
            v += n.sample(&mut self.rng);
        }
        v.round().clamp(0.0, (CONVERSION_FULL_SCALE - 1) as f64) as u32
    }

    /// The sum of one sample's conversions at `position_um`: from the table where it serves,
    /// else conversion by conversion.
    fn sum_of_conversions(&mut self, position_um: f64) -> u32 {
        if let Some(t) = &self.table {
            let v = self.ideal_conversion(position_um) + self.params.offset_lsb;
            if t.serves(v, CONVERSION_FULL_SCALE - 1) {
                return t.draw(v, &mut self.rng);
            }
        }
        (0..self.params.oversample)
            .map(|_| self.convert(position_um))
            .sum()
    }

    /// The control sample at `t_us` for a finger at `position_um`, or None during a dropout.
    /// `t_us` is simulation time; the sample carries it truncated to the core's wrapping u32.
    pub fn sample(&mut self, position_um: f64, t_us: u64) -> Option<Sample> {
        // The window is looked up once: a spike or drift needs its start as well as its kind.
        let window = self
            .params
            .faults
            .iter()
            .find(|f| f.contains(t_us))
            .copied();
        let sum = match window.map(|f| f.kind) {
            Some(FaultKind::Dropout) => return None,
            Some(FaultKind::Open) => 0,
            Some(FaultKind::Short) => (CONVERSION_FULL_SCALE - 1) * self.params.oversample,
            Some(kind @ (FaultKind::Spike { .. } | FaultKind::Drift { .. })) => {
                let since_us = t_us - window.map_or(t_us, |f| f.start_us);
                self.shifted_sum(position_um, kind.offset_lsb_at(since_us))
            }
            None => self.sum_of_conversions(position_um),
        };
        Some(Sample::from_sum(self.code_of_sum(sum as f64), t_us as u32))
    }

    /// The core's 16-conversion code of a sum of [`AdcParams::oversample`] conversions: the sum
    /// itself at 16, else scaled with rounding (the G474 oversampler's right shift rounds; the
    /// F446's software sum is shifted the same way). One rule for [`Self::sample`] and
    /// [`Self::sample_moving`].
    fn code_of_sum(&self, sum: f64) -> u32 {
        let m = self.params.oversample;
        if m == OVERSAMPLE {
            sum as u32
        } else {
            (sum * OVERSAMPLE as f64 / m as f64).round() as u32
        }
    }

    /// The control samples of a block: for each of `states`, at (`k0` + i) × `period_us` µs,
    /// what [`Self::sample`] gives (the same draws in the same order), into `out` (cleared
    /// first). Drawn in a loop of their own, the table lookups of consecutive samples overlap
    /// their cache misses instead of waiting for the core between them.
    pub fn samples_into(
        &mut self,
        states: &[State],
        k0: u64,
        period_us: u32,
        out: &mut Vec<Option<Sample>>,
    ) {
        out.clear();
        let t_us = |i: usize| (k0 + i as u64) * period_us as u64;
        let (first_us, last_us) = (t_us(0), t_us(states.len().saturating_sub(1)));
        let faultless = self
            .params
            .faults
            .iter()
            .all(|f| f.end_us <= first_us || f.start_us > last_us);
        match self.table.clone() {
            // The common block (no fault window in it, the table built, the core's 16
            // conversions): the table draws in a loop of their own, which leaves the CPU free to
            // overlap each draw's table reads with the next ones'. Per sample it is what
            // `sample` does there, in the same order.
            Some(table) if faultless && self.params.oversample == OVERSAMPLE => {
                let top = CONVERSION_FULL_SCALE - 1;
                let offset_lsb = self.params.offset_lsb;
                out.reserve(states.len());
                let mut prepared = [Prepared::default(); PREPARED];
                let mut i = 0;
                while i < states.len() {
                    // The next run of samples the table serves, at most PREPARED, drawn in
                    // order and finished after: each draw's guide read overlaps the next
                    // ones' work.
                    let end = (i + PREPARED).min(states.len());
                    let mut j = i;
                    while j < end {
                        let v = self.ideal_conversion(states[j].position_um) + offset_lsb;
                        if !table.serves(v, top) {
                            break;
                        }
                        prepared[j - i] = table.prepare(v, &mut self.rng);
                        j += 1;
                    }
                    // One reservation for the run (an iterator of known length), not a
                    // capacity check a sample.
                    out.extend(prepared[..j - i].iter().enumerate().map(|(m, p)| {
                        Some(Sample::from_sum(table.finish(*p), t_us(i + m) as u32))
                    }));
                    if j < end {
                        // Near a rail (or σ outside the table's range): every conversion drawn,
                        // after the draws before it, as `sample` does.
                        let sum = (0..OVERSAMPLE)
                            .map(|_| self.convert(states[j].position_um))
                            .sum();
                        out.push(Some(Sample::from_sum(sum, t_us(j) as u32)));
                        j += 1;
                    }
                    i = j;
                }
            }
            _ => out.extend(
                states
                    .iter()
                    .enumerate()
                    .map(|(i, s)| self.sample(s.position_um, t_us(i))),
            ),
        }
    }

    /// The control sample at `t_us` for a finger whose position at time t (s) is
    /// `position_at(t)`, with the silicon effects of [`AdcParams`]: each conversion of the
    /// window at its own time and through the hold capacitor, the noise floor common to the
    /// sample, the sum scaled to the core's 16-conversion code. With every effect off this is
    /// exactly [`Self::sample`] at the stamp's position (same draws, same codes), and so it is
    /// during a fault window.
    pub fn sample_moving(&mut self, position_at: &dyn Fn(f64) -> f64, t_us: u64) -> Option<Sample> {
        let t_s = t_us as f64 * 1e-6;
        if !self.params.silicon_effects() || self.fault_at(t_us).is_some() {
            return self.sample(position_at(t_s), t_us);
        }
        let m = self.params.oversample;
        let window_s = self.params.conversion_window_us * 1e-6;
        let floor = self.floor_at(t_us);
        let top = (CONVERSION_FULL_SCALE - 1) as f64;
        let mut sum = 0.0f64;
        for i in 0..m {
            // Evenly spread, the last ending at the stamp: the window's centre is the sample's
            // effective time.
            let t_conv_s = t_s - window_s + (i as f64 + 0.5) * window_s / m as f64;
            let ideal = self.ideal_conversion(position_at(t_conv_s)) + self.params.offset_lsb;
            let held = self.settle(ideal, t_conv_s);
            let mut v = held + floor;
            if let Some(n) = &self.noise {
                v += n.sample(&mut self.rng);
            }
            sum += v.round().clamp(0.0, top);
        }
        // The core's code is the sum of 16 conversions (scaled when there are more or fewer).
        Some(Sample::from_sum(self.code_of_sum(sum), t_us as u32))
    }

    /// The noise floor for the sample at `t_us`: a first-order (Ornstein–Uhlenbeck) process of
    /// σ = `floor_lsb_rms`, drawn exactly from its value at the previous sample.
    fn floor_at(&mut self, t_us: u64) -> f64 {
        let sigma = self.params.floor_lsb_rms;
        if sigma <= 0.0 {
            return 0.0;
        }
        let z: f64 = rand_distr::StandardNormal.sample(&mut self.rng);
        let v = match self.held.floor {
            Some((prev, t_prev)) if t_us > t_prev => {
                let dt_s = (t_us - t_prev) as f64 * 1e-6;
                let a = (-2.0 * std::f64::consts::PI * self.params.floor_corner_hz * dt_s).exp();
                a * prev + sigma * (1.0 - a * a).sqrt() * z
            }
            Some((prev, _)) => prev,
            None => sigma * z,
        };
        self.held.floor = Some((v, t_us));
        v
    }

    /// The voltage one conversion holds when the pin's ideal value is `ideal_lsb` at `t_s`:
    /// the pin capacitor (if fitted) low-passes the source, then the converting ADC's hold
    /// capacitor closes the fraction 1 − exp(−t_s/τ) of the gap from the charge it kept.
    fn settle(&mut self, ideal_lsb: f64, t_s: f64) -> f64 {
        let Some(s) = self.params.settling else {
            return ideal_lsb;
        };
        let pin = if s.pin_nf > 0.0 {
            let tau_s = s.source_ohm(ideal_lsb) * s.pin_nf * 1e-9;
            let v = match self.held.pin {
                Some((v, t_prev)) if tau_s > 0.0 => {
                    let a = (-(t_s - t_prev).max(0.0) / tau_s).exp();
                    ideal_lsb + (v - ideal_lsb) * a
                }
                _ => ideal_lsb,
            };
            self.held.pin = Some((v, t_s));
            v
        } else {
            ideal_lsb
        };
        if self.held.caps_lsb.len() != s.adcs as usize {
            self.held.caps_lsb = vec![None; s.adcs as usize];
        }
        let k = self.held.next_adc % s.adcs as usize;
        self.held.next_adc = (k + 1) % s.adcs as usize;
        let held = match self.held.caps_lsb[k] {
            Some(prev) => pin + (prev - pin) * s.residual_fraction(pin),
            None => pin,
        };
        self.held.caps_lsb[k] = Some(held);
        held
    }

    /// The summed conversions inside a spike or drift window, whose offset is `extra_lsb` now:
    /// each conversion as usual, then the offset added and the result clamped to the
    /// converter's range (a spike near an end can reach a rail, as a real one would). Kept out
    /// of [`Self::sample`] so the fault-free path stays as it is.
    fn shifted_sum(&mut self, position_um: f64, extra_lsb: f64) -> u32 {
        let top = (CONVERSION_FULL_SCALE - 1) as f64;
        (0..self.params.oversample)
            .map(|_| {
                (self.convert(position_um) as f64 + extra_lsb)
                    .round()
                    .clamp(0.0, top) as u32
            })
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block of samples (`samples_into`) is what `sample` gives period by period, with the
    /// generator left in the same state: blocks with no fault (the table's own loop, its draws
    /// prepared in runs and finished after) whose finger runs past both rails (where the
    /// table does not serve and each conversion is drawn, between prepared runs), and blocks
    /// with a spike and a dropout in them; blocks of several lengths, so runs end everywhere.
    #[test]
    fn blocks_are_single_samples() {
        use rand::RngCore;
        for sigma in [0.0, 2.0, 8.0, 12.0] {
            let params = AdcParams {
                faults: vec![
                    FaultWindow {
                        kind: FaultKind::Spike { offset_lsb: 40 },
                        start_us: 120_000,
                        end_us: 120_500,
                    },
                    FaultWindow {
                        kind: FaultKind::Dropout,
                        start_us: 150_000,
                        end_us: 151_000,
                    },
                ],
                ..AdcParams::default().with_noise(sigma, 3)
            };
            // −4 mm … 67 mm and back, 5 µm a period: past both ends of the 63 mm travel.
            let states: Vec<State> = (0..3_000u64)
                .map(|k| {
                    let x = (k as f64 * 5.0) % 14_200.0;
                    let x = if x < 7_100.0 { x } else { 14_200.0 - x };
                    State {
                        position_um: -4_000.0 + x * 10.0,
                        velocity_um_s: 0.0,
                    }
                })
                .collect();
            let mut single = AdcModel::new(Calibration::default(), params.clone()).unwrap();
            let want: Vec<Option<Sample>> = states
                .iter()
                .enumerate()
                .map(|(k, s)| single.sample(s.position_um, k as u64 * 100))
                .collect();
            // Blocks of the pipeline's size and of sizes that are not multiples of the
            // prepared run (PREPARED), down to one sample.
            for len in [512, PREPARED + 33, PREPARED, 7, 1] {
                let mut blocks = AdcModel::new(Calibration::default(), params.clone()).unwrap();
                let (mut got, mut block) = (Vec::new(), Vec::new());
                for (b, chunk) in states.chunks(len).enumerate() {
                    let k0 = (b * len) as u64;
                    blocks.samples_into(chunk, k0, 100, &mut block);
                    got.extend_from_slice(&block);
                }
                assert_eq!(got, want, "σ {sigma}, blocks of {len}");
                let mut next = single.clone();
                assert_eq!(
                    blocks.rng.next_u64(),
                    next.rng.next_u64(),
                    "σ {sigma}, blocks of {len}"
                );
            }
            assert!(want.iter().any(|s| s.is_none()), "σ {sigma}: no dropout");
        }
    }

    #[test]
    fn noiseless_code_matches_calibration() {
        let cal = Calibration::default();
        let mut adc = AdcModel::new(
            cal,
            AdcParams {
                noise_lsb_rms: 0.0,
                ..AdcParams::default()
            },
        )
        .unwrap();
        let s = adc.sample(0.0, 0).unwrap();
        // 2 % of full scale = 1310.72 codes → 81.92 LSB per conversion → 82 × 16.
        assert_eq!(s.code, 82 * 16);
        let m = PositionMapper::new(cal).unwrap();
        let s = adc.sample(30_000.0, 100).unwrap();
        let back = m.position_um(&s).unwrap();
        // Quantized to one 12-bit LSB (16 codes ≈ 16 µm).
        assert!((back - 30_000).abs() <= 16, "{back}");
    }

    #[test]
    fn rails_and_dropouts() {
        let mut adc = AdcModel::new(
            Calibration::default(),
            AdcParams {
                faults: vec![
                    FaultWindow {
                        kind: FaultKind::Open,
                        start_us: 100,
                        end_us: 200,
                    },
                    FaultWindow {
                        kind: FaultKind::Short,
                        start_us: 200,
                        end_us: 300,
                    },
                    FaultWindow {
                        kind: FaultKind::Dropout,
                        start_us: 300,
                        end_us: 400,
                    },
                ],
                ..AdcParams::default()
            },
        )
        .unwrap();
        assert_eq!(adc.sample(10_000.0, 100).unwrap().code, 0);
        assert_eq!(adc.sample(10_000.0, 200).unwrap().code, 65_520);
        assert_eq!(adc.sample(10_000.0, 300), None);
        assert!(adc.sample(10_000.0, 400).unwrap().code > 1_000);
    }

    #[test]
    fn noise_is_seeded_and_averaged() {
        let p = AdcParams {
            noise_lsb_rms: 3.0,
            seed: 42,
            ..AdcParams::default()
        };
        let mut a = AdcModel::new(Calibration::default(), p.clone()).unwrap();
        let mut b = AdcModel::new(Calibration::default(), p).unwrap();
        let xs: Vec<f64> = (0..4000)
            .map(|i| a.sample(31_500.0, i).unwrap().code as f64)
            .collect();
        let ys: Vec<f64> = (0..4000)
            .map(|i| b.sample(31_500.0, i).unwrap().code as f64)
            .collect();
        assert_eq!(xs, ys);
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64).sqrt();
        // 16 conversions of σ = 3 LSB summed: σ = 3 × √16 = 12 codes.
        assert!((sd - 12.0).abs() < 1.0, "{sd}");
    }

    /// A spike adds its offset to every conversion of its window and clamps at the rail; a
    /// drift's offset grows from 0 at its start.
    #[test]
    fn spikes_and_drift_shift_the_reading() {
        let faults = vec![
            FaultWindow {
                kind: FaultKind::Spike { offset_lsb: 100 },
                start_us: 100,
                end_us: 200,
            },
            FaultWindow {
                kind: FaultKind::Spike {
                    offset_lsb: -i16::MAX,
                },
                start_us: 200,
                end_us: 300,
            },
            FaultWindow {
                kind: FaultKind::Drift { lsb_per_s: 1_000 },
                start_us: 1_000_000,
                end_us: 2_000_000,
            },
        ];
        let mut adc = AdcModel::new(
            Calibration::default(),
            AdcParams {
                noise_lsb_rms: 0.0,
                faults,
                ..AdcParams::default()
            },
        )
        .unwrap();
        let clean = adc.sample(30_000.0, 0).unwrap().code;
        assert_eq!(adc.sample(30_000.0, 100).unwrap().code, clean + 100 * 16);
        assert_eq!(adc.sample(30_000.0, 200).unwrap().code, 0);
        assert_eq!(adc.sample(30_000.0, 1_000_000).unwrap().code, clean);
        // Half a second in: 500 LSB on each of the 16 conversions.
        assert_eq!(
            adc.sample(30_000.0, 1_500_000).unwrap().code,
            clean + 500 * 16
        );
        assert_eq!(adc.sample(30_000.0, 2_000_000).unwrap().code, clean);
    }

    /// A sample of other than 16 conversions is scaled to the core's 16-conversion code with
    /// rounding, on the tabulated and the per-conversion paths and through rails and spikes:
    /// the same code for the same voltage at 8, 16 or 32 conversions, and the noise of m
    /// conversions (σ·√m in the sum, σ·16/√m in the code: σ = 3 LSB gives 12 codes at 16,
    /// 8.49 at 32, 16.97 at 8).
    #[test]
    fn other_conversion_counts_are_scaled_to_the_core_code() {
        let model = |oversample: u32, noise: f64, per_conversion: bool, faults| {
            AdcModel::new(
                Calibration::default(),
                AdcParams {
                    noise_lsb_rms: noise,
                    oversample,
                    seed: 5,
                    per_conversion,
                    faults,
                    ..AdcParams::default()
                },
            )
            .unwrap()
        };
        let faults = vec![
            FaultWindow {
                kind: FaultKind::Short,
                start_us: 100,
                end_us: 200,
            },
            FaultWindow {
                kind: FaultKind::Spike { offset_lsb: 100 },
                start_us: 200,
                end_us: 300,
            },
        ];
        for m in [8, 16, 32] {
            let mut adc = model(m, 0.0, false, faults.clone());
            assert_eq!(adc.sample(0.0, 0).unwrap().code, 82 * 16, "{m}");
            let clean = adc.sample(30_000.0, 0).unwrap().code;
            assert_eq!(adc.sample(30_000.0, 100).unwrap().code, 65_520, "{m}");
            assert_eq!(
                adc.sample(30_000.0, 200).unwrap().code,
                clean + 100 * 16,
                "{m}"
            );
            for per_conversion in [false, true] {
                let mut adc = model(m, 3.0, per_conversion, Vec::new());
                let xs: Vec<f64> = (0..4000)
                    .map(|i| adc.sample(31_500.0, i).unwrap().code as f64)
                    .collect();
                let n = xs.len() as f64;
                let mean = xs.iter().sum::<f64>() / n;
                let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
                let want = 3.0 * 16.0 / (m as f64).sqrt();
                assert!(
                    (sd - want).abs() < 0.06 * want,
                    "{m} {per_conversion}: {sd}"
                );
                let ideal = adc.ideal_conversion(31_500.0) * 16.0;
                assert!((mean - ideal).abs() < 1.0, "{m} {per_conversion}: {mean}");
            }
        }
    }

    /// The ADC model's refusals read as sentences (the calibration's is the core's own).
    #[test]
    fn errors_read_as_sentences() {
        let e = AdcModel::new(
            Calibration::default(),
            AdcParams {
                noise_lsb_rms: -1.0,
                ..AdcParams::default()
            },
        )
        .err()
        .unwrap();
        assert_eq!(
            e.to_string(),
            "ADC noise -1 LSB RMS must be finite and at least 0 LSB"
        );
        let cal = Calibration {
            length_um: 0,
            ..Calibration::default()
        };
        let e = AdcModel::new(cal, AdcParams::default()).err().unwrap();
        assert_eq!(
            e.to_string(),
            "length 0 mm must be above 0 mm and at most 1000 mm"
        );
    }
}
