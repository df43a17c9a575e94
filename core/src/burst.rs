//! Burst stage: a burst command (f_b, duty) → the burst timer's PSC / ARR / CCR.
//!
//! The burst timer runs PWM mode 1 on the RF enable line: the line is high while CNT < CCR, so
//! each period starts with its on-time. Settings are written to preloaded registers and take
//! effect at the next update event, i.e. only ever between two whole periods.
//!
//! Rounding, documented because it sets the f_b error:
//! - the prescaler is the smallest that fits the period in the counter, so the period keeps the
//!   most ticks: `psc = ⌈ticks / 2^bits⌉ − 1`;
//! - the period is rounded to the nearest tick: `arr + 1 = round(clk / ((psc+1) f_b))`, so the
//!   relative f_b error is at most 0.5 / (arr + 1): ≤ 15 ppm on a 16-bit timer (arr + 1 ≥ 32 768
//!   whenever the prescaler is in use) and ≤ 0.5 / 45 000 = 11 ppm at 2 kHz on a 90 MHz 32-bit timer;
//! - the on-time is rounded to the nearest tick, then floored to both caps (duty and on-time), so
//!   a cap is never exceeded by rounding.

/// The board's burst timer, as the core needs to know it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BurstTimer {
    /// Timer kernel clock, Hz.
    pub clock_hz: u32,
    /// Counter width: 16 or 32.
    pub counter_bits: u8,
    /// Highest burst frequency the board renders, Hz (the RF chain's on/off time limits it).
    pub max_burst_hz: u32,
}

impl BurstTimer {
    /// `clocks` kernel clocks in µs, rounded up (so rests computed from it are never short).
    pub fn clocks_to_us_ceil(&self, clocks: u64) -> u64 {
        (clocks * 1_000_000).div_ceil(self.clock_hz.max(1) as u64)
    }

    /// Rejects an impossible timer description (zero clock, width not 16 or 32).
    fn validate(&self) -> Result<(), BurstError> {
        if self.clock_hz == 0 || !(self.counter_bits == 16 || self.counter_bits == 32) {
            return Err(self.bad());
        }
        Ok(())
    }

    /// This timer refused as impossible, its description in the error.
    pub(crate) fn bad(&self) -> BurstError {
        BurstError::BadTimer {
            clock_hz: self.clock_hz,
            counter_bits: self.counter_bits,
            max_burst_hz: self.max_burst_hz,
        }
    }

    /// The longest period the timer counts, clocks: a full counter at the last value of the
    /// 16-bit prescaler, 2^bits · 65 536.
    fn longest_period_clocks(&self) -> u64 {
        (1u64 << self.counter_bits.min(32)) * 65_536
    }

    /// Lowest f_b the timer reaches, mHz, rounded up.
    fn min_millihz(&self) -> u32 {
        (self.clock_hz as u64 * 1000).div_ceil(self.longest_period_clocks()) as u32
    }

    /// One-pulse settings with the line high for `on_clocks` kernel clocks (rounded down to a
    /// whole tick, at least one), starting one tick after the counter (see
    /// [`GateAction::Pulse`](crate::gate::GateAction::Pulse)): `arr = ccr = ticks`.
    pub fn one_pulse(&self, on_clocks: u64) -> Result<TimerSettings, BurstError> {
        // A zero delay is rounded up to the one tick PWM mode 2 needs.
        self.delayed_pulse(0, on_clocks)
    }

    /// One-pulse settings whose line rises `delay_clocks` after the counter starts (rounded
    /// down to whole ticks, at least one) and stays high for `on_clocks` (rounded down, at
    /// least one tick): the counter runs 0..=arr and the line is high for its last `ccr` ticks,
    /// `arr = delay_ticks + ccr − 1`. The hybrid renderer starts a ridge's burst inside the
    /// sample period this way. Err when delay and pulse together do not fit the counter at one
    /// prescaler value.
    pub fn delayed_pulse(
        &self,
        delay_clocks: u64,
        on_clocks: u64,
    ) -> Result<TimerSettings, BurstError> {
        let span = 1u64 << self.counter_bits.min(32);
        let total = delay_clocks.saturating_add(on_clocks);
        let psc = total / span;
        if psc > u16::MAX as u64 {
            let to_us =
                |clocks: u64| clocks.saturating_mul(1_000_000) / self.clock_hz.max(1) as u64;
            return Err(BurstError::PulseTooLong {
                pulse_us: to_us(total),
                max_us: to_us(self.longest_period_clocks() - 1),
            });
        }
        let tick = psc + 1;
        let on_ticks = (on_clocks / tick).max(1);
        let delay_ticks = (delay_clocks / tick).max(1);
        // It fits: total < tick · span, so ⌊delay/tick⌋ + ⌊on/tick⌋ ≤ span − 1, and the two
        // one-tick floors add at most one tick between them (a zero delay with a pulse shorter
        // than a tick cannot happen at psc > 0), so arr ≤ span − 1.
        Ok(TimerSettings {
            psc: psc as u16,
            arr: (delay_ticks + on_ticks - 1) as u32,
            ccr: on_ticks as u32,
        })
    }
}

/// Register values for one burst waveform.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimerSettings {
    /// Prescaler: the counter ticks at clock / (psc + 1).
    pub psc: u16,
    /// Auto-reload: the period is arr + 1 ticks.
    pub arr: u32,
    /// Compare: the enable line is high for the first ccr ticks of each period (periodic
    /// bursts), or for the last ccr ticks of the count (one-pulses, see
    /// [`GateAction::Pulse`](crate::gate::GateAction::Pulse)).
    pub ccr: u32,
}

impl TimerSettings {
    /// Period in kernel-clock cycles.
    pub fn period_clocks(&self) -> u64 {
        (self.psc as u64 + 1) * (self.arr as u64 + 1)
    }

    /// On-time in kernel-clock cycles.
    pub fn on_clocks(&self) -> u64 {
        (self.psc as u64 + 1) * self.ccr as u64
    }

    /// As a one-pulse: kernel clocks from the counter's start to the line's rise, (arr + 1 −
    /// ccr) ticks (one tick for [`BurstTimer::one_pulse`]).
    pub fn pulse_delay_clocks(&self) -> u64 {
        (self.psc as u64 + 1) * (self.arr as u64 + 1).saturating_sub(self.ccr as u64)
    }

    /// The burst frequency these settings produce, mHz.
    pub fn produced_millihz(&self, clock_hz: u32) -> u64 {
        (clock_hz as u64 * 1000 + self.period_clocks() / 2) / self.period_clocks()
    }
}

/// A burst as a texture asks for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BurstCommand {
    /// Burst frequency f_b, mHz.
    pub burst_millihz: u32,
    /// Fraction of each period with the carrier on, ‰ (the seed uses 400).
    pub duty_permille: u16,
}

/// Caps the carrier must never exceed, whatever a scene asks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SafetyLimits {
    /// Highest duty, ‰.
    pub max_duty_permille: u16,
    /// Longest single on-time, µs (heat in the IDTs and the amplifier).
    pub max_on_time_us: u32,
    /// Highest RF level, ‰ of full drive: no region, line or pulse drives above it (textures
    /// without an amplitude of their own, "full drive", play at it).
    pub max_level_permille: u16,
}

impl Default for SafetyLimits {
    /// 50 % duty, 50 ms on-time: the seed's 40 % at 20 Hz (20 ms) passes untouched; a 1 Hz burst
    /// is shortened to 50 ms rather than holding 2–3 W on the IDTs for 0.4 s.
    fn default() -> Self {
        Self {
            max_duty_permille: 500,
            max_on_time_us: 50_000,
            max_level_permille: 1000,
        }
    }
}

/// Why a burst command cannot be rendered. Each variant carries the value and the limit its
/// sentence (`Display`) names, so a refusal reads without the code at hand.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum BurstError {
    /// f_b is zero.
    ZeroFrequency,
    /// f_b above the board's limit.
    AboveBoardLimit {
        /// The f_b asked for, mHz.
        burst_millihz: u32,
        /// The highest f_b the board renders, mHz.
        max_millihz: u32,
    },
    /// f_b so low the prescaler overflows.
    BelowTimerRange {
        /// The f_b asked for, mHz.
        burst_millihz: u32,
        /// The lowest f_b the burst timer reaches, mHz (rounded up).
        min_millihz: u32,
    },
    /// Duty is zero or above 1000 ‰.
    BadDuty {
        /// The duty asked for, ‰.
        duty_permille: u16,
    },
    /// Duty above the configured cap.
    DutyAboveCap {
        /// The duty asked for, ‰.
        duty_permille: u16,
        /// The duty cap, ‰.
        cap_permille: u16,
    },
    /// The caps leave no on-time at all.
    NoOnTime {
        /// The f_b whose period holds no on-time, mHz; 0 when the on-time cap itself is zero.
        burst_millihz: u32,
        /// The duty cap, ‰.
        max_duty_permille: u16,
        /// The on-time cap, µs.
        max_on_time_us: u32,
    },
    /// The timer description itself is impossible (zero clock, width not 16 or 32, or no top
    /// f_b).
    BadTimer {
        /// Timer kernel clock, Hz.
        clock_hz: u32,
        /// Counter width.
        counter_bits: u8,
        /// Highest burst frequency, Hz.
        max_burst_hz: u32,
    },
    /// A single pulse longer than the burst timer can count (prescaler overflow).
    PulseTooLong {
        /// The pulse asked for, µs.
        pulse_us: u64,
        /// The longest pulse the timer counts, µs.
        max_us: u64,
    },
}

impl core::fmt::Display for BurstError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::{Deci, Milli};
        match *self {
            BurstError::ZeroFrequency => {
                write!(f, "f_b is 0 Hz, and a burst needs a frequency above 0 Hz")
            }
            BurstError::AboveBoardLimit {
                burst_millihz,
                max_millihz,
            } => write!(
                f,
                "f_b {} Hz is above this board's limit of {} Hz",
                Milli(burst_millihz as u64),
                Milli(max_millihz as u64)
            ),
            BurstError::BelowTimerRange {
                burst_millihz,
                min_millihz,
            } => write!(
                f,
                "f_b {} Hz is below the lowest the burst timer reaches, {} Hz",
                Milli(burst_millihz as u64),
                Milli(min_millihz as u64)
            ),
            BurstError::BadDuty { duty_permille } => write!(
                f,
                "duty {} % must be above 0 % and at most 100 %",
                Deci(duty_permille as u64)
            ),
            BurstError::DutyAboveCap {
                duty_permille,
                cap_permille,
            } => write!(
                f,
                "duty {} % is above the carrier's cap of {} %",
                Deci(duty_permille as u64),
                Deci(cap_permille as u64)
            ),
            // Zero f_b marks the caps' own check: no burst is involved, only the cap.
            BurstError::NoOnTime {
                burst_millihz: 0,
                max_on_time_us,
                ..
            } => write!(
                f,
                "on-time cap {} ms must be above 0 ms",
                Milli(max_on_time_us as u64)
            ),
            BurstError::NoOnTime {
                burst_millihz,
                max_duty_permille,
                max_on_time_us,
            } => write!(
                f,
                "at f_b {} Hz the carrier's caps (duty {} %, on-time {} ms) leave less than one \
                 timer tick of on-time",
                Milli(burst_millihz as u64),
                Deci(max_duty_permille as u64),
                Milli(max_on_time_us as u64)
            ),
            BurstError::BadTimer {
                clock_hz,
                counter_bits,
                max_burst_hz,
            } => write!(
                f,
                "the burst timer (clock {clock_hz} Hz, {counter_bits}-bit counter, top f_b \
                 {max_burst_hz} Hz) is impossible: it needs a clock above 0 Hz, a 16- or 32-bit \
                 counter and a top f_b above 0 Hz"
            ),
            BurstError::PulseTooLong { pulse_us, max_us } => write!(
                f,
                "a pulse of {} ms is longer than the burst timer's longest, {} ms",
                Milli(pulse_us),
                Milli(max_us)
            ),
        }
    }
}

impl SafetyLimits {
    /// Rejects caps that are zero or above 100 %.
    pub fn validate(&self) -> Result<(), BurstError> {
        if self.max_duty_permille == 0 || self.max_duty_permille > 1000 {
            return Err(BurstError::BadDuty {
                duty_permille: self.max_duty_permille,
            });
        }
        if self.max_on_time_us == 0 {
            return Err(self.no_on_time(0));
        }
        Ok(())
    }

    /// Largest compare value allowed for a period of `arr + 1` ticks at prescaler `psc`: at
    /// most `arr`, so the line falls for at least one tick every period. (In PWM mode 1 the
    /// output is high while CNT < CCR, RM0390 §18.3.9 / RM0440 §29.3.16; CNT runs 0 … ARR, so a
    /// CCR above ARR never lets it fall and a 100 % duty cap would make the carrier continuous,
    /// past any on-time cap — the soak found 4.4 ms against a 1.36 ms cap.)
    pub fn max_ccr(&self, timer: &BurstTimer, psc: u16, arr: u32) -> u32 {
        let period = arr as u64 + 1;
        let by_duty = period * self.max_duty_permille as u64 / 1000;
        let by_time = self.max_on_time_clocks(timer) / (psc as u64 + 1);
        by_duty.min(by_time).min(arr as u64) as u32
    }

    /// Rejects a burst duty that is zero, above 100 % or above the duty cap.
    pub fn check_duty(&self, duty_permille: u16) -> Result<(), BurstError> {
        if duty_permille == 0 || duty_permille > 1000 {
            return Err(BurstError::BadDuty { duty_permille });
        }
        if duty_permille > self.max_duty_permille {
            return Err(BurstError::DutyAboveCap {
                duty_permille,
                cap_permille: self.max_duty_permille,
            });
        }
        Ok(())
    }

    /// The caps leave no on-time for bursts at `burst_millihz` (0: the on-time cap is zero).
    fn no_on_time(&self, burst_millihz: u32) -> BurstError {
        BurstError::NoOnTime {
            burst_millihz,
            max_duty_permille: self.max_duty_permille,
            max_on_time_us: self.max_on_time_us,
        }
    }

    /// The on-time cap in kernel-clock cycles, ⌊µs · clock / 10^6⌋ (a gate pulse checks it).
    pub fn max_on_time_clocks(&self, timer: &BurstTimer) -> u64 {
        div_by_million(self.max_on_time_us as u64 * timer.clock_hz as u64)
    }

    /// True when periodic bursts `s` stay inside both caps (multiplies only: it runs on every
    /// gate change). The line must fall every period (`ccr ≤ arr`, see [`Self::max_ccr`]), or
    /// its on-time is the whole run however short each period is.
    pub fn allows(&self, timer: &BurstTimer, s: &TimerSettings) -> bool {
        s.ccr <= s.arr
            && s.ccr as u64 * 1000 <= (s.arr as u64 + 1) * self.max_duty_permille as u64
            && self.on_clocks_within_cap(timer, s.on_clocks())
    }

    /// `on_clocks ≤ max_on_time_clocks(timer)` without its u64 division (a library call of
    /// ~200 instructions on the M4F, and `allows` runs on every changed burst): for integers,
    /// n ≤ ⌊x / 10^6⌋ ⟺ n · 10^6 ≤ x. An `on_clocks` whose product would overflow u64 is
    /// above every cap (x < 2^64).
    fn on_clocks_within_cap(&self, timer: &BurstTimer, on_clocks: u64) -> bool {
        on_clocks <= u64::MAX / 1_000_000
            && on_clocks * 1_000_000 <= self.max_on_time_us as u64 * timer.clock_hz as u64
    }
}

/// ⌊x / 10^6⌋ without a u64 division (a ~200-instruction library call on the M4F): ⌊x / 10^6⌋
/// = ⌊⌊x / 2^6⌋ / 15 625⌋, and the second division is done as long division in 32- and 16-bit
/// digits, each remainder below 15 625 < 2^16 so every partial dividend fits 32 bits: three
/// hardware divides.
fn div_by_million(x: u64) -> u64 {
    const D: u32 = 15_625;
    let y = x >> 6;
    let hi = (y >> 32) as u32;
    let (q_hi, r) = (hi / D, hi % D);
    let mid = (r << 16) | ((y >> 16) as u32 & 0xffff);
    let (q_mid, r) = (mid / D, mid % D);
    let lo = (r << 16) | (y as u32 & 0xffff);
    ((q_hi as u64) << 32) | ((q_mid as u64) << 16) | (lo / D) as u64
}

/// Per-sample planner for textures whose f_b changes with motion: the divisions and cap
/// arithmetic of [`plan`] are done once at scene load, leaving a float divide, a float → u32
/// conversion (one instruction on the FPv4-SP) and, only when the prescaler is in use, one
/// 32-bit integer divide per call. Periods of 2^32 clocks or more (below 0.021 Hz at 90 MHz)
/// take a u64 path with the same rounding.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastPlanner {
    clock_hz: f32,
    counter_bits: u8,
    /// Shortest period the board renders, kernel clocks.
    min_period_clocks: u32,
    /// Longest period before the prescaler overflows, kernel clocks, as an f32 (converted once
    /// here, not per call).
    max_period_f: f32,
    /// Requested duty as a Q16 fraction (≤ 65 536).
    duty_q16: u32,
    /// The duty cap as a Q16 fraction, floored so it never rounds above the cap (≤ 65 536).
    cap_duty_q16: u32,
    max_on_clocks: u64,
    /// `max_on_clocks` saturated to u32 (the 32-bit path: a cap above `u32::MAX` clocks is
    /// above every period that path plans, so it never binds there).
    max_on_clocks_u32: u32,
}

impl FastPlanner {
    /// Prepares a planner for bursts of `duty_permille` on `timer` under `limits`.
    pub fn new(
        timer: &BurstTimer,
        limits: &SafetyLimits,
        duty_permille: u16,
    ) -> Result<Self, BurstError> {
        timer.validate()?;
        limits.check_duty(duty_permille)?;
        let min_period = (timer.clock_hz as u64)
            .div_ceil(timer.max_burst_hz.max(1) as u64)
            .max(2);
        let max_on_clocks = limits.max_on_time_clocks(timer);
        Ok(Self {
            clock_hz: timer.clock_hz as f32,
            counter_bits: timer.counter_bits,
            min_period_clocks: min_period.min(u32::MAX as u64) as u32,
            max_period_f: timer.longest_period_clocks() as f32,
            duty_q16: ((duty_permille as u64 * 65_536) / 1000) as u32,
            cap_duty_q16: ((limits.max_duty_permille as u64 * 65_536) / 1000) as u32,
            max_on_clocks,
            max_on_clocks_u32: max_on_clocks.min(u32::MAX as u64) as u32,
        })
    }

    /// Settings for bursts at `hz`, or None below the timer's range. Frequencies above the board
    /// limit are clamped to it; the flag says so, so the caller can log it (never alias silently).
    // Negated comparisons on purpose: a NaN fails them and is refused like zero.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    #[inline]
    pub fn plan_hz(&self, hz: f32) -> Option<(TimerSettings, bool)> {
        if !(hz > 0.0) {
            return None;
        }
        let period_f = self.clock_hz / hz;
        // The longest period, psc = 65 535 with a full counter, is itself representable.
        if !(period_f <= self.max_period_f) {
            return None;
        }
        if period_f < 4_294_967_296.0 {
            self.plan_u32(period_f as u32)
        } else {
            self.plan_u64(period_f)
        }
    }

    /// `plan_hz` for a period below 2^32 clocks: the same arithmetic in 32 bits (products in
    /// 64), no division at all when the period fits the counter unprescaled.
    #[inline]
    fn plan_u32(&self, period: u32) -> Option<(TimerSettings, bool)> {
        let clamped = period < self.min_period_clocks;
        let period = if clamped {
            self.min_period_clocks
        } else {
            period
        };
        // A 32-bit counter holds every such period at psc = 0 (the shift by 32 is None).
        let psc = (period - 1)
            .checked_shr(self.counter_bits as u32)
            .unwrap_or(0);
        let (ticks, max_on) = if psc == 0 {
            (period, self.max_on_clocks_u32)
        } else {
            // ≥ 2: psc < 2^16 here; saturating only so no overflow check is compiled in.
            let psc_div = psc.saturating_add(1);
            (period / psc_div, self.max_on_clocks_u32 / psc_div)
        };
        let ticks = ticks as u64;
        let wanted = ((ticks * self.duty_q16 as u64) >> 16).max(1);
        // At most ticks − 1: the line falls every period (see `SafetyLimits::max_ccr`).
        let cap = ((ticks * self.cap_duty_q16 as u64) >> 16)
            .min(max_on as u64)
            .min(ticks - 1);
        if cap == 0 {
            return None;
        }
        let settings = TimerSettings {
            psc: psc as u16,
            arr: (ticks - 1) as u32,
            ccr: wanted.min(cap) as u32,
        };
        Some((settings, clamped))
    }

    /// `plan_hz` for periods of 2^32 clocks and more (a prescaled 32-bit counter, or the
    /// 16-bit counter's single longest period): u64 arithmetic, as before the 32-bit path.
    #[inline(never)]
    fn plan_u64(&self, period_f: f32) -> Option<(TimerSettings, bool)> {
        let mut period = period_f as u64;
        let clamped = period < self.min_period_clocks as u64;
        if clamped {
            period = self.min_period_clocks as u64;
        }
        let psc = (period - 1) >> self.counter_bits;
        // ≥ 1 even if psc were u64::MAX: no division-by-zero check on the per-sample path.
        let psc_div = psc.saturating_add(1);
        let ticks = period / psc_div;
        let wanted = ((ticks * self.duty_q16 as u64) >> 16).max(1);
        // At most ticks − 1: the line falls every period (see `SafetyLimits::max_ccr`).
        let cap = ((ticks * self.cap_duty_q16 as u64) >> 16)
            .min(self.max_on_clocks / psc_div)
            .min(ticks - 1);
        if cap == 0 {
            return None;
        }
        let settings = TimerSettings {
            psc: psc as u16,
            arr: (ticks - 1) as u32,
            ccr: wanted.min(cap) as u32,
        };
        Some((settings, clamped))
    }
}

/// Plans the timer settings of a command; the result stays inside `limits` (an on-time cap
/// shortens the pulse, never stretches the period). Returns whether a cap cut the on-time.
pub fn plan(
    timer: &BurstTimer,
    limits: &SafetyLimits,
    cmd: &BurstCommand,
) -> Result<(TimerSettings, bool), BurstError> {
    timer.validate()?;
    if cmd.burst_millihz == 0 {
        return Err(BurstError::ZeroFrequency);
    }
    // The board's top f_b in mHz, or the timer's own (a two-tick period) if that is lower.
    let above = || BurstError::AboveBoardLimit {
        burst_millihz: cmd.burst_millihz,
        max_millihz: (timer.max_burst_hz as u64 * 1000)
            .min(timer.clock_hz as u64 * 1000 / 2)
            .min(u32::MAX as u64) as u32,
    };
    if cmd.burst_millihz as u64 > timer.max_burst_hz as u64 * 1000 {
        return Err(above());
    }
    limits.check_duty(cmd.duty_permille)?;
    let clock_millihz = timer.clock_hz as u64 * 1000;
    let f = cmd.burst_millihz as u64;
    let counter_span = 1u64 << timer.counter_bits;
    let ticks = (clock_millihz + f / 2) / f;
    let psc = ticks.saturating_sub(1) / counter_span;
    if psc > u16::MAX as u64 {
        return Err(BurstError::BelowTimerRange {
            burst_millihz: cmd.burst_millihz,
            min_millihz: timer.min_millihz(),
        });
    }
    let step = f * (psc + 1);
    let period = (clock_millihz + step / 2) / step;
    if period < 2 {
        return Err(above());
    }
    let arr = (period - 1) as u32;
    let wanted = ((period * cmd.duty_permille as u64 + 500) / 1000).max(1) as u32;
    let cap = limits.max_ccr(timer, psc as u16, arr);
    if cap == 0 {
        return Err(limits.no_on_time(cmd.burst_millihz));
    }
    let ccr = wanted.min(cap);
    Ok((
        TimerSettings {
            psc: psc as u16,
            arr,
            ccr,
        },
        ccr < wanted,
    ))
}

/// The unit tests' burst timer: 90 MHz, 32 bits (the F446's), a 5 kHz f_b limit.
#[cfg(test)]
pub(crate) const TEST_TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 5_000,
};

#[cfg(test)]
mod tests {
    /// The delay and the pulse share one prescaler; both stay whole ticks, and a one-pulse is
    /// the delayed pulse with a delay of one tick.
    #[test]
    fn delayed_pulses_rise_after_their_delay() {
        let t32 = BurstTimer {
            clock_hz: 90_000_000,
            counter_bits: 32,
            max_burst_hz: 5_000,
        };
        let s = t32.delayed_pulse(4_500, 36_000).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr), (0, 40_499, 36_000));
        assert_eq!((s.pulse_delay_clocks(), s.on_clocks()), (4_500, 36_000));
        let one = t32.one_pulse(36_000).unwrap();
        assert_eq!(t32.delayed_pulse(1, 36_000).unwrap(), one);
        assert_eq!(one.pulse_delay_clocks(), 1);
        // A zero delay still rises one tick in: CCR = 0 would be high from CNT = 0, which PWM
        // mode 2 cannot do after UG from a stopped counter.
        assert_eq!(t32.delayed_pulse(0, 36_000).unwrap(), one);
        let t16 = BurstTimer {
            counter_bits: 16,
            ..t32
        };
        // 90 000 clocks do not fit 2^16 ticks: prescaler 2, so 15 000 + 30 000 ticks.
        let s = t16.delayed_pulse(30_000, 60_000).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr), (1, 44_999, 30_000));
        assert_eq!((s.pulse_delay_clocks(), s.on_clocks()), (30_000, 60_000));
        // Odd clocks round down to whole ticks, never up: the on-time cannot grow.
        let s = t16.delayed_pulse(30_001, 60_001).unwrap();
        assert_eq!((s.pulse_delay_clocks(), s.on_clocks()), (30_000, 60_000));
        // Past the last prescaler value: refused, naming the length.
        let long = (1u64 << 16) * 65_536;
        assert!(matches!(
            t16.delayed_pulse(long / 2, long / 2),
            Err(BurstError::PulseTooLong { .. })
        ));
        // The one-tick delay floor at the top of the counter: the count still fits.
        let s = t16.delayed_pulse(0, 65_535).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr), (0, 65_535, 65_535));
        let s = t16.delayed_pulse(0, 65_536).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr), (1, 32_768, 32_768));
    }

    use super::*;

    const T32: BurstTimer = BurstTimer {
        clock_hz: 90_000_000,
        counter_bits: 32,
        max_burst_hz: 5_000,
    };
    const T16: BurstTimer = BurstTimer {
        clock_hz: 180_000_000,
        counter_bits: 16,
        max_burst_hz: 5_000,
    };

    fn cmd(hz: u32) -> BurstCommand {
        BurstCommand {
            burst_millihz: hz * 1000,
            duty_permille: 400,
        }
    }

    /// A timer description a board crate could get wrong is refused before any planning: a
    /// zero clock, or a counter width that is neither 16 nor 32 (each alone).
    #[test]
    fn impossible_timers_are_refused() {
        for (clock_hz, counter_bits) in [(0, 32), (0, 16), (90_000_000, 24), (90_000_000, 0)] {
            let t = BurstTimer {
                clock_hz,
                counter_bits,
                max_burst_hz: 5_000,
            };
            let l = SafetyLimits::default();
            let bad = BurstError::BadTimer {
                clock_hz,
                counter_bits,
                max_burst_hz: 5_000,
            };
            assert_eq!(plan(&t, &l, &cmd(80)), Err(bad), "{t:?}");
            assert_eq!(FastPlanner::new(&t, &l, 400).err(), Some(bad), "{t:?}");
        }
    }

    /// Caps: 100 % duty is a valid cap (a scene may lift the duty limit entirely), 100.1 % and
    /// zero are not, nor is a zero on-time.
    #[test]
    fn cap_validation_edges() {
        let l = |max_duty_permille, max_on_time_us| SafetyLimits {
            max_duty_permille,
            max_on_time_us,
            ..SafetyLimits::default()
        };
        assert_eq!(l(1000, 1).validate(), Ok(()));
        assert_eq!(l(1, 1).validate(), Ok(()));
        let bad_duty = |duty_permille| Err(BurstError::BadDuty { duty_permille });
        assert_eq!(l(1001, 1).validate(), bad_duty(1001));
        assert_eq!(l(0, 1).validate(), bad_duty(0));
        assert_eq!(
            l(500, 0).validate(),
            Err(BurstError::NoOnTime {
                burst_millihz: 0,
                max_duty_permille: 500,
                max_on_time_us: 0
            })
        );
    }

    /// One-pulse settings up to the prescaler's last value (65 535) and refused past it.
    #[test]
    fn one_pulse_prescaler_range() {
        let span = 1u64 << 16;
        let last = 65_535 * span + (span - 1);
        let p = T16.one_pulse(last).unwrap();
        assert_eq!(p.psc, 65_535);
        assert_eq!(p.on_clocks(), (last / 65_536) * 65_536);
        assert!(matches!(
            T16.one_pulse(65_536 * span),
            Err(BurstError::PulseTooLong { .. })
        ));
        assert!(matches!(
            T16.one_pulse(u64::MAX >> 8),
            Err(BurstError::PulseTooLong { .. })
        ));
        // The refusal names the pulse and the longest count, 2^32 − 1 clocks: on a 1 MHz
        // timer, µs for clock.
        let slow = BurstTimer {
            clock_hz: 1_000_000,
            ..T16
        };
        assert_eq!(
            slow.one_pulse(5_000_000_000),
            Err(BurstError::PulseTooLong {
                pulse_us: 5_000_000_000,
                max_us: 4_294_967_295
            })
        );
        // The smallest pulse is one tick.
        let one = T16.one_pulse(0).unwrap();
        assert_eq!((one.psc, one.arr, one.ccr), (0, 1, 1));
    }

    /// The 32-bit path of `plan_hz` gives what the u64 arithmetic (`plan_u64`, the planner's
    /// code before #17) gives, on a 32-bit and two 16-bit timers, under loose and tight caps,
    /// from below the timer's range to above the board's limit; and every plan keeps the line
    /// falling each period and stays inside both caps (`allows`).
    #[test]
    fn the_32_bit_path_plans_as_the_u64_one() {
        let slow16 = BurstTimer {
            clock_hz: 1_000_000,
            counter_bits: 16,
            max_burst_hz: 5_000,
        };
        let caps = [
            SafetyLimits::default(),
            SafetyLimits {
                max_duty_permille: 1000,
                max_on_time_us: 5_000,
                ..SafetyLimits::default()
            },
            SafetyLimits {
                max_duty_permille: 30,
                max_on_time_us: 37,
                ..SafetyLimits::default()
            },
        ];
        let mut planned = 0;
        for timer in [T32, T16, slow16] {
            for limits in caps {
                for duty in [1, 30, 400, limits.max_duty_permille] {
                    let Ok(fast) = FastPlanner::new(&timer, &limits, duty) else {
                        continue; // a duty above the cap is refused at load
                    };
                    let mut hz = 1e-3f32;
                    while hz < 2e4 {
                        let period_f = fast.clock_hz / hz;
                        let want = (period_f <= fast.max_period_f)
                            .then(|| fast.plan_u64(period_f))
                            .flatten();
                        let got = fast.plan_hz(hz);
                        assert_eq!(got, want, "{timer:?} {limits:?} duty {duty} at {hz} Hz");
                        if let Some((s, _)) = got {
                            assert!(s.ccr <= s.arr && limits.allows(&timer, &s), "{s:?}");
                            planned += 1;
                        }
                        hz *= 1.0137;
                    }
                }
            }
        }
        assert!(planned > 10_000, "{planned}");
    }

    /// The division-free ⌊x / 10^6⌋ against the u64 division: edges of every digit and
    /// pseudo-random values over the whole u64 range.
    #[test]
    fn divides_by_a_million_exactly() {
        let mut lcg = 0x9e37_79b9_7f4a_7c15u64;
        let mut xs = std::vec![0, 1, 999_999, 1_000_000, 1_000_001, u64::MAX, u64::MAX - 1];
        for shift in 0..64 {
            let p = 1u64 << shift;
            xs.extend([p - 1, p, p + 1, p.wrapping_mul(1_000_000)]);
        }
        for _ in 0..100_000 {
            lcg = lcg
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            xs.push(lcg >> (lcg % 64));
        }
        for x in xs {
            assert_eq!(div_by_million(x), x / 1_000_000, "{x}");
        }
    }

    /// A 100 % duty under a 100 % cap still lets the line fall for a tick every period (CCR ≤
    /// ARR in PWM mode 1): otherwise the carrier is continuous, past any on-time cap. Both
    /// planners, and `allows` refuses a compare value past the period.
    #[test]
    fn the_line_falls_every_period_even_at_full_duty() {
        let limits = SafetyLimits {
            max_duty_permille: 1000,
            max_on_time_us: 5_000,
            ..SafetyLimits::default()
        };
        let full = BurstCommand {
            burst_millihz: 1_000_000,
            duty_permille: 1000,
        };
        let (s, capped) = plan(&TEST_TIMER, &limits, &full).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr, capped), (0, 89_999, 89_999, true));
        let fast = FastPlanner::new(&TEST_TIMER, &limits, 1000).unwrap();
        let (f, _) = fast.plan_hz(1000.0).unwrap();
        assert_eq!((f.psc, f.arr, f.ccr), (0, 89_999, 89_999));
        assert!(limits.allows(&TEST_TIMER, &s));
        let never_falls = TimerSettings { ccr: 90_000, ..s };
        assert!(!limits.allows(&TEST_TIMER, &never_falls));
        assert_eq!(limits.max_ccr(&TEST_TIMER, 0, 89_999), 89_999);
    }

    /// A duty exactly at the cap is rendered exactly: the cap is taken over the whole period
    /// (arr + 1 ticks), not cut a tick short and reported as capped.
    #[test]
    fn duty_at_the_cap_is_not_cut() {
        let t = BurstTimer {
            clock_hz: 1_000_000,
            counter_bits: 32,
            max_burst_hz: 5_000,
        };
        let at_cap = BurstCommand {
            burst_millihz: 1_000_000,
            duty_permille: 500,
        };
        let (s, capped) = plan(&t, &SafetyLimits::default(), &at_cap).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr, capped), (0, 999, 500, false));
        assert_eq!(SafetyLimits::default().max_ccr(&t, 0, 999), 500);
    }

    /// The prescaler is chosen on the period rounded the same way as the period itself: at
    /// clock / f_b = 65 536.5 ticks the period rounds to 65 537, which a 16-bit counter cannot
    /// hold at prescaler 0. A planner that truncated here would write ARR = 65 536 (a counter
    /// that never reaches it: no update events, the line stuck high).
    #[test]
    fn period_half_a_tick_past_the_counter_takes_the_prescaler() {
        let t = BurstTimer {
            clock_hz: 131_073,
            counter_bits: 16,
            max_burst_hz: 5_000,
        };
        let (s, _) = plan(&t, &SafetyLimits::default(), &cmd(2)).unwrap();
        assert_eq!((s.psc, s.arr), (1, 32_767));
        // Round to nearest below the edge: 65 535.5 ticks → 65 536, prescaler 0.
        let t = BurstTimer {
            clock_hz: 131_071,
            ..t
        };
        let (s, _) = plan(&t, &SafetyLimits::default(), &cmd(2)).unwrap();
        assert_eq!((s.psc, s.arr), (0, 65_535));
    }

    /// The lowest f_b a 16-bit counter at 180 MHz reaches: 2^32 clocks = 41.91 mHz. 42 mHz is
    /// planned (4 285 714 286 clocks: prescaler 65 394), 41 mHz refused rather than wrapping the prescaler.
    #[test]
    fn lowest_frequency_on_a_16_bit_counter() {
        let at = |burst_millihz| BurstCommand {
            burst_millihz,
            duty_permille: 400,
        };
        let (s, _) = plan(&T16, &SafetyLimits::default(), &at(42)).unwrap();
        assert_eq!(s.psc, 65_394);
        assert_eq!(
            plan(&T16, &SafetyLimits::default(), &at(41)),
            Err(BurstError::BelowTimerRange {
                burst_millihz: 41,
                min_millihz: 42
            })
        );
        // The last prescaler value itself: 1 Hz on a 65 535 × 65 536 + 1 Hz clock.
        let t = BurstTimer {
            clock_hz: 65_535 * 65_536 + 1,
            ..T16
        };
        let (s, _) = plan(&t, &SafetyLimits::default(), &at(1_000)).unwrap();
        assert_eq!((s.psc, s.arr), (65_535, 65_534));
    }

    /// The shortest period is two ticks (one on, one off); a board whose burst limit reaches
    /// its timer clock gets AboveBoardLimit for one-tick periods, not a malformed setting.
    #[test]
    fn two_tick_period_is_the_shortest() {
        let t = BurstTimer {
            clock_hz: 10_000,
            counter_bits: 16,
            max_burst_hz: 10_000,
        };
        let (s, capped) = plan(&t, &SafetyLimits::default(), &cmd(5_000)).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr, capped), (0, 1, 1, false));
        assert_eq!(
            plan(&t, &SafetyLimits::default(), &cmd(10_000)),
            Err(BurstError::AboveBoardLimit {
                burst_millihz: 10_000_000,
                max_millihz: 5_000_000
            })
        );
    }

    /// The frequency a setting produces, rounded to the nearest mHz (hand-worked).
    #[test]
    fn produced_frequency_rounds_to_the_nearest_millihertz() {
        let s = |psc, arr| TimerSettings { psc, arr, ccr: 1 };
        // 90 MHz / 90 000 = 1 kHz exactly.
        assert_eq!(s(1, 44_999).produced_millihz(90_000_000), 1_000_000);
        // 1 kHz / 3 = 333.333 Hz → 333 333 mHz; 1 kHz / 6 = 166.667 Hz → 166 667 mHz.
        assert_eq!(s(0, 2).produced_millihz(1_000), 333_333);
        assert_eq!(s(1, 2).produced_millihz(1_000), 166_667);
        // 20 Hz on the F446's 90 MHz timer: 4 500 000 clocks.
        assert_eq!(s(0, 4_499_999).produced_millihz(90_000_000), 20_000);
    }

    #[test]
    fn forty_percent_at_80_hz() {
        let (s, capped) = plan(&T32, &SafetyLimits::default(), &cmd(80)).unwrap();
        assert_eq!(s.psc, 0);
        assert_eq!(s.arr + 1, 90_000_000 / 80);
        assert_eq!(s.ccr, (s.arr + 1) * 2 / 5);
        assert!(!capped);
    }

    #[test]
    fn sixteen_bit_uses_prescaler_and_keeps_resolution() {
        let (s, _) = plan(&T16, &SafetyLimits::default(), &cmd(1)).unwrap();
        assert!(s.psc > 0);
        assert!(s.arr + 1 >= 32_768, "{s:?}");
        let produced = s.produced_millihz(T16.clock_hz) as f64;
        assert!((produced - 1000.0).abs() / 1000.0 < 1e-4);
    }

    #[test]
    fn on_time_cap_shortens_pulse_not_period() {
        let limits = SafetyLimits {
            max_duty_permille: 500,
            max_on_time_us: 10_000,
            ..SafetyLimits::default()
        };
        let (s, capped) = plan(&T32, &limits, &cmd(20)).unwrap();
        assert!(capped);
        assert_eq!(s.arr + 1, 90_000_000 / 20);
        assert_eq!(s.ccr, 900_000); // 10 ms at 90 MHz
    }

    #[test]
    fn bad_commands_rejected() {
        let l = SafetyLimits::default();
        assert_eq!(
            plan(&T32, &l, &cmd(0)).err(),
            Some(BurstError::ZeroFrequency)
        );
        assert_eq!(
            plan(&T32, &l, &cmd(5_001)).err(),
            Some(BurstError::AboveBoardLimit {
                burst_millihz: 5_001_000,
                max_millihz: 5_000_000
            })
        );
        let c = BurstCommand {
            burst_millihz: 80_000,
            duty_permille: 0,
        };
        assert_eq!(
            plan(&T32, &l, &c).err(),
            Some(BurstError::BadDuty { duty_permille: 0 })
        );
        let c = BurstCommand {
            burst_millihz: 80_000,
            duty_permille: 600,
        };
        assert_eq!(
            plan(&T32, &l, &c).err(),
            Some(BurstError::DutyAboveCap {
                duty_permille: 600,
                cap_permille: 500
            })
        );
    }

    /// The fast planner agrees with the exact one to the rounding of one tick, on both widths.
    #[test]
    fn agrees_with_exact_planner() {
        let limits = SafetyLimits::default();
        for timer in [T32, T16] {
            let fast = FastPlanner::new(&timer, &limits, 400).unwrap();
            for hz in [1u32, 3, 20, 80, 333, 1000, 2000, 4999] {
                let (exact, _) = plan(
                    &timer,
                    &limits,
                    &BurstCommand {
                        burst_millihz: hz * 1000,
                        duty_permille: 400,
                    },
                )
                .unwrap();
                let (s, clamped) = fast.plan_hz(hz as f32).unwrap();
                assert!(!clamped);
                assert_eq!(s.psc, exact.psc, "{hz} Hz");
                assert!(
                    s.arr.abs_diff(exact.arr) <= 1,
                    "{hz} Hz: {s:?} vs {exact:?}"
                );
                // The duty is a Q16 fraction floored (never above the request): the on-time
                // is short by at most one 65 536th of the period and a tick.
                assert!(
                    s.ccr <= exact.ccr + 1
                        && exact.ccr - s.ccr.min(exact.ccr) <= s.arr / 65_536 + 1,
                    "{hz} Hz: on-time {s:?} vs {exact:?}"
                );
                assert!(limits.allows(&timer, &s), "{hz} Hz: {s:?}");
            }
        }
    }

    /// The fast planner's edges, each hand-worked: the board limit itself is not clamped, the
    /// longest representable period is planned and one past it refused, a period of exactly
    /// 2^16 ticks needs no prescaler, −0 Hz is refused like 0.
    #[test]
    fn fast_planner_edges() {
        let l = SafetyLimits::default();
        // 5 kHz on 90 MHz: 18 000 clocks, the board's shortest period, not a clamped one.
        let fast = FastPlanner::new(&T32, &l, 400).unwrap();
        let (s, clamped) = fast.plan_hz(5_000.0).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr, clamped), (0, 17_999, 7_199, false));
        assert_eq!(fast.plan_hz(-0.0), None);
        // 16-bit at 180 MHz: 180e6 / 2^32 Hz is exactly 2^32 clocks = 65 536 × 65 536.
        let slow = FastPlanner::new(
            &T16,
            &SafetyLimits {
                max_on_time_us: 100_000_000,
                ..l
            },
            400,
        )
        .unwrap();
        let lowest = 180e6f32 / 4_294_967_296.0;
        let (s, _) = slow.plan_hz(lowest).unwrap();
        // The u64 path's duty: 40 % of 65 536 ticks, ⌊26 214.4⌋ (under the cap's 32 768).
        assert_eq!((s.psc, s.arr, s.ccr), (65_535, 65_535, 26_214));
        assert_eq!(slow.plan_hz(lowest * 0.999), None);
        // 180e6 / 65 536 Hz: exactly 65 536 clocks, the whole counter at prescaler 0.
        let fast16 = FastPlanner::new(&T16, &l, 400).unwrap();
        let (s, _) = fast16.plan_hz(180e6 / 65_536.0).unwrap();
        assert_eq!((s.psc, s.arr, s.ccr), (0, 65_535, 26_214));
    }

    /// Duty exactly at the cap passes; one ‰ over it, or over 100 %, is refused.
    #[test]
    fn duty_check_edges() {
        let l = SafetyLimits::default();
        assert_eq!(l.check_duty(500), Ok(()));
        assert_eq!(
            l.check_duty(501),
            Err(BurstError::DutyAboveCap {
                duty_permille: 501,
                cap_permille: 500
            })
        );
        assert_eq!(l.check_duty(1), Ok(()));
        let open = SafetyLimits {
            max_duty_permille: 1000,
            ..l
        };
        assert_eq!(open.check_duty(1000), Ok(()));
        assert_eq!(
            open.check_duty(1001),
            Err(BurstError::BadDuty {
                duty_permille: 1001
            })
        );
    }

    /// A period too short to hold any on-time under the duty cap is refused rather than given
    /// the one-tick minimum: at a 1 ‰ cap a 2-tick period would otherwise run at 50 %.
    #[test]
    fn unresolvable_duty_is_refused_not_rounded_up() {
        let tiny = BurstTimer {
            clock_hz: 1_000,
            counter_bits: 16,
            max_burst_hz: 500,
        };
        let l = SafetyLimits {
            max_duty_permille: 1,
            max_on_time_us: 50_000,
            ..SafetyLimits::default()
        };
        let fast = FastPlanner::new(&tiny, &l, 1).unwrap();
        assert_eq!(fast.plan_hz(500.0), None);
        let exact = BurstCommand {
            burst_millihz: 500_000,
            duty_permille: 1,
        };
        assert_eq!(
            plan(&tiny, &l, &exact),
            Err(BurstError::NoOnTime {
                burst_millihz: 500_000,
                max_duty_permille: 1,
                max_on_time_us: 50_000
            })
        );
        // At a 2 000-tick period the same cap holds one tick (the planner's Q16 cap, floored,
        // is 65/65 536 of a period: 1 000 ticks hold 0.99 of a tick, so 2 000 are needed).
        let (s, _) = fast.plan_hz(0.5).unwrap();
        assert_eq!((s.arr, s.ccr), (1_999, 1));
    }

    #[test]
    fn clamps_above_board_limit_and_refuses_nonsense() {
        let fast = FastPlanner::new(&T32, &SafetyLimits::default(), 400).unwrap();
        let (s, clamped) = fast.plan_hz(50_000.0).unwrap();
        assert!(clamped);
        assert_eq!(s.produced_millihz(T32.clock_hz), 5_000_000);
        assert_eq!(fast.plan_hz(0.0), None);
        assert_eq!(fast.plan_hz(f32::NAN), None);
        assert_eq!(fast.plan_hz(-3.0), None);
    }

    /// Each refusal reads as one sentence in the units a scene file uses (Hz, %, ms).
    #[test]
    fn errors_read_as_sentences() {
        let cases = [
            (
                BurstError::ZeroFrequency,
                "f_b is 0 Hz, and a burst needs a frequency above 0 Hz",
            ),
            (
                BurstError::AboveBoardLimit {
                    burst_millihz: 9_000_000,
                    max_millihz: 5_000_000,
                },
                "f_b 9000 Hz is above this board's limit of 5000 Hz",
            ),
            (
                BurstError::BelowTimerRange {
                    burst_millihz: 41,
                    min_millihz: 42,
                },
                "f_b 0.041 Hz is below the lowest the burst timer reaches, 0.042 Hz",
            ),
            (
                BurstError::BadDuty { duty_permille: 0 },
                "duty 0 % must be above 0 % and at most 100 %",
            ),
            (
                BurstError::BadDuty {
                    duty_permille: 1001,
                },
                "duty 100.1 % must be above 0 % and at most 100 %",
            ),
            (
                BurstError::DutyAboveCap {
                    duty_permille: 1000,
                    cap_permille: 500,
                },
                "duty 100 % is above the carrier's cap of 50 %",
            ),
            (
                BurstError::NoOnTime {
                    burst_millihz: 0,
                    max_duty_permille: 500,
                    max_on_time_us: 0,
                },
                "on-time cap 0 ms must be above 0 ms",
            ),
            (
                BurstError::NoOnTime {
                    burst_millihz: 500_000,
                    max_duty_permille: 1,
                    max_on_time_us: 50_000,
                },
                "at f_b 500 Hz the carrier's caps (duty 0.1 %, on-time 50 ms) leave less than \
                 one timer tick of on-time",
            ),
            (
                BurstError::BadTimer {
                    clock_hz: 90_000_000,
                    counter_bits: 24,
                    max_burst_hz: 5_000,
                },
                "the burst timer (clock 90000000 Hz, 24-bit counter, top f_b 5000 Hz) is \
                 impossible: it needs a clock above 0 Hz, a 16- or 32-bit counter and a top f_b \
                 above 0 Hz",
            ),
            (
                BurstError::PulseTooLong {
                    pulse_us: 30_000_000,
                    max_us: 23_860_929,
                },
                "a pulse of 30000 ms is longer than the burst timer's longest, 23860.929 ms",
            ),
        ];
        for (e, sentence) in cases {
            assert_eq!(std::format!("{e}"), sentence, "{e:?}");
        }
    }

    /// The limits in the sentences are the timer's own: the lowest f_b of a 16-bit counter at
    /// 180 MHz (42 mHz, rounded up) and the longest pulse it counts.
    #[test]
    fn error_limits_are_the_timers() {
        let at = BurstCommand {
            burst_millihz: 41,
            duty_permille: 400,
        };
        let e = plan(&T16, &SafetyLimits::default(), &at).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "f_b 0.041 Hz is below the lowest the burst timer reaches, 0.042 Hz"
        );
        let e = T16.one_pulse(180_000_000 * 30).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "a pulse of 30000 ms is longer than the burst timer's longest, 23860.929 ms"
        );
    }
}
