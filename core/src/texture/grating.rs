//! Grating texture: a virtual grating of spatial period λ (Konyo et al.: f = V/λ, so the felt
//! spatial period does not depend on hand speed), rendered one of two ways.
//!
//! - [`GratingRender::PositionPhase`] (the default): one burst per ridge crossing, taken from the
//!   position itself. A ridge sits at every multiple of λ; crossing it fires one pulse lasting
//!   duty·λ/|V| (the time the finger needs to cover the ridge's share of the period). Velocity
//!   only sizes the pulse, so bursts land where the ridges are whatever the estimator's lag:
//!   measured 7–15 µm RMS at 20–200 mm/s against 63–344 µm for velocity synthesis
//!   (docs/estimators.md). A ridge that fired is disarmed until the finger is `rearm_um` clear
//!   of it, so noise on a ridge fires nothing and a real back-and-forth fires once per crossing.
//! - [`GratingRender::Hybrid`]: position phase, but on a steady stroke each crossing is
//!   predicted inside the coming sample period from a line through the last 64 positions
//!   (checked against its newer 32-sample half, which takes over when the two disagree)
//!   (texture::predict) and the burst is started there by a delayed one-pulse
//!   ([`BurstTimer::delayed_pulse`]) instead of on the first sample past the ridge, which is up
//!   to one sample of travel late (20 µm at 200 mm/s and 10 kHz). Below the trust speed, after
//!   a gap, a glitch or a reversal (the line is emptied) it is position phase.
//! - [`GratingRender::VelocitySynthesis`]: periodic bursts at f = |V|/λ on the burst timer. Its
//!   frequency is right but its phase is free, and the estimator's lag puts the bursts
//!   v × 3.3 ms behind the ridges. Below `min_speed_um_s` no bursts are made (at rest the
//!   velocity estimate is noise); the threshold has hysteresis (off below half of it).

use crate::burst::{BurstError, BurstTimer, FastPlanner, SafetyLimits, TimerSettings};

use super::compiled::{Moment, Render, Request, Want};
use super::motion::MotionGate;
use super::predict::{Line, LineFit, INNOVATION_GATE_UM, TRUST_SPEED_UM_S};
use super::{SpreadParam, TextureError};

/// How a grating turns motion into bursts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum GratingRender {
    /// One pulse per ridge crossing, placed by position (see the module doc).
    #[default]
    PositionPhase,
    /// Periodic bursts at f = |V|/λ (see the module doc).
    VelocitySynthesis,
    /// Position phase with each crossing predicted inside the sample period and the burst
    /// started there by a delayed one-pulse (see the module doc); position phase itself when
    /// the prediction is not trusted.
    Hybrid,
}

/// Default re-arm distance of a ridge, µm: 8.7 σ of the position noise at 3 LSB with 16×
/// oversampling (11.5 µm), so a finger resting on a ridge never re-fires it.
pub const DEFAULT_REARM_UM: u32 = 100;

/// A grating region's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Grating {
    /// Spatial period λ, µm (grooved tile: ridge width + groove width).
    pub wavelength_um: u32,
    /// Duty of each burst, ‰ (the ridge's share of the period).
    pub duty_permille: u16,
    /// Velocity synthesis only: bursts start above this speed, µm/s, and stop below half of it.
    pub min_speed_um_s: u32,
    /// Drive amplitude, ‰ (tile-to-scene sets it from the skin model's A).
    pub amplitude_permille: u16,
    /// How bursts are made.
    pub render: GratingRender,
    /// Position phase only: distance the finger must move clear of a fired ridge before it can
    /// fire again, µm; below λ/2 so every ridge re-arms on the way to the next.
    pub rearm_um: u32,
}

impl Grating {
    /// A grating of period `wavelength_um`: position phase, 40 % duty, full drive, re-arm at
    /// 100 µm (or λ/4 for gratings finer than 0.4 mm); 15 mm/s start threshold should velocity
    /// synthesis be chosen (below it, noise at rest fires bursts: docs/estimators.md).
    pub const fn new(wavelength_um: u32) -> Self {
        let quarter = wavelength_um / 4;
        Self {
            wavelength_um,
            duty_permille: 400,
            min_speed_um_s: 15_000,
            amplitude_permille: 1000,
            render: GratingRender::PositionPhase,
            rearm_um: if quarter < DEFAULT_REARM_UM {
                quarter
            } else {
                DEFAULT_REARM_UM
            },
        }
    }

    /// Checks the parameters against a substrate of `length_um`.
    pub fn validate(&self, length_um: u32) -> Result<(), TextureError> {
        if self.wavelength_um == 0 || self.wavelength_um > length_um {
            return Err(TextureError::BadWavelength {
                wavelength_um: self.wavelength_um,
                length_um,
            });
        }
        if self.min_speed_um_s > 1_000_000 {
            return Err(TextureError::BadSpeedThreshold {
                min_speed_um_s: self.min_speed_um_s,
            });
        }
        if self.amplitude_permille == 0 || self.amplitude_permille > 1000 {
            return Err(TextureError::BadSpread {
                param: SpreadParam::Amplitude,
                permille: self.amplitude_permille,
            });
        }
        if self.render != GratingRender::VelocitySynthesis
            && self.rearm_um.saturating_mul(2) >= self.wavelength_um
        {
            return Err(TextureError::BadRearm {
                rearm_um: self.rearm_um,
                wavelength_um: self.wavelength_um,
            });
        }
        Ok(())
    }
}

/// Position-phase ridge tracking: which cell of the grating the finger is in and which ridge
/// is disarmed. Integer only: one division per sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct RidgeTracker {
    /// Cell index k of the last sample, position in [kλ, (k+1)λ).
    cell: Option<i32>,
    /// The ridge (index k, at kλ) that fired last and is not yet re-armed.
    disarmed: Option<i32>,
    /// Start of `cell`, kλ µm: a sample inside the same cell needs no division.
    cell_lo_um: i32,
}

/// A ridge crossing seen on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Crossing {
    /// Ridge index k (the ridge at kλ).
    pub ridge: i32,
    /// Further ridges passed within the same sample (too fast for one pulse each).
    pub skipped: u32,
    /// Crossed moving towards +x.
    pub up: bool,
}

impl RidgeTracker {
    /// Forgets the finger's place (region change, fault).
    pub(crate) fn reset(&mut self) {
        *self = Self::default();
    }

    /// Updates with a position; returns the armed ridge crossed since the last sample, if any.
    /// On the first sample the nearest ridge, if within `rearm_um`, starts disarmed: arriving
    /// at rest on a ridge is not a crossing.
    #[inline(always)]
    pub(crate) fn update(
        &mut self,
        position_um: i32,
        wavelength_um: i32,
        rearm_um: i32,
    ) -> Option<Crossing> {
        // Most samples stay in the cell of the last: no division then (the M4F's per-sample
        // cost). `wrapping_sub`: positions are 0..=1 m, the difference cannot overflow.
        let same = self.cell.filter(|_| {
            let offset = position_um.wrapping_sub(self.cell_lo_um);
            offset >= 0 && offset < wavelength_um
        });
        if same.is_some() && self.disarmed.is_none() {
            return None;
        }
        let cell = match same {
            Some(c) => c,
            // Checked: div_euclid panics on a zero divisor (and on i32::MIN / -1). `validate`
            // refuses a wavelength of 0, so None never happens; it would read as no crossing.
            None => {
                let c = position_um.checked_div_euclid(wavelength_um)?;
                self.cell_lo_um = c.wrapping_mul(wavelength_um);
                c
            }
        };
        let offset = position_um.wrapping_sub(self.cell_lo_um);
        // The nearest ridge and the distance to it.
        let (near, dist) = if offset * 2 < wavelength_um {
            (cell, offset)
        } else {
            (cell + 1, wavelength_um - offset)
        };
        let mut crossing = None;
        match self.cell {
            None => {
                if dist <= rearm_um {
                    self.disarmed = Some(near);
                }
            }
            // Same cell: no ridge passed.
            Some(prev) if prev == cell => {}
            Some(prev) => {
                // Moving up the last ridge passed is `cell`'s lower edge; moving down, `prev`'s:
                // the higher cell's either way.
                let (ridge, passed) = (cell.max(prev), cell.abs_diff(prev));
                if self.disarmed != Some(ridge) || passed > 1 {
                    crossing = Some(Crossing {
                        ridge,
                        skipped: passed - 1,
                        // The cells differ here, so the higher one being `cell` means up.
                        up: ridge == cell,
                    });
                    self.disarmed = Some(ridge);
                }
            }
        }
        self.cell = Some(cell);
        if let Some(r) = self.disarmed {
            if r != near || dist > rearm_um {
                self.disarmed = None;
            }
        }
        crossing
    }
}

/// A position-phase grating, compiled: one pulse per ridge crossing (texture::grating).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ridges {
    wavelength_um: i32,
    rearm_um: i32,
    /// The ridge's share of the period, duty · λ, µm.
    ridge_um: i32,
    /// duty · λ · timer clock: the pulse's on-time in clocks is this over |V| in µm/s.
    on_clock_um_s: u64,
    /// Shortest pulse: the on-time of a burst at the board's top f_b.
    min_on_clocks: u64,
    /// Longest pulse: the on-time cap.
    max_on_clocks: u64,
    /// Pulses start at least this far apart, µs (the board's top f_b).
    min_spacing_us: u32,
    /// A pulse is not cut before it has been on this long, µs (the shortest pulse).
    min_on_us: u32,
    amplitude: u16,
    tracker: RidgeTracker,
    last_pulse_us: Option<u32>,
    /// While a pulse may be on: the span of positions it stays on over, µm (lo ..hi).
    on_span_um: Option<(i32, i32)>,
    /// Largest step between two samples the slider can make, µm; a larger one is a glitch
    /// until the next sample confirms it.
    max_step_um: i32,
    /// The last position accepted, and how far the next may step from it, µm: `max_step_um`,
    /// or `u32::MAX` before any (a first position is always plausible). A reach, not an
    /// Option: one load pair and one compare per sample.
    last_um: i32,
    last_reach_um: u32,
    /// A jump waiting for confirmation.
    jump_um: Option<i32>,
    /// The hybrid renderer's prediction, when the grating is rendered that way.
    hybrid: Option<Predictor>,
}

/// The hybrid renderer's state (see [`GratingRender::Hybrid`]).
#[derive(Clone, Copy, Debug)]
struct Predictor {
    fit: LineFit,
    sample_period_us: u32,
    /// One sample period in timer clocks, as f32 for the delay.
    period_clocks: f32,
    /// |slope| from which the line is trusted, µm per sample.
    trust_um: f32,
    /// Sample periods per second, to turn the slope into a speed.
    samples_per_s: f32,
    /// λ, µm, as f32 (the reach test's).
    wavelength_um: f32,
    /// The ridge fired last (by prediction or by position), until the finger is `rearm_um`
    /// clear of it: neither path fires it again before.
    last_fired: Option<i32>,
    /// The trusted line's end at the previous sample, µm: where this sample's window starts;
    /// NaN for none (no trusted line then): a NaN test, not an Option's tag.
    prev_end_um: f32,
}

/// The fastest the slider is taken to move, µm/s: a step between two samples that would need
/// more (over up to four sample periods, to bridge dropped samples) is a sensor glitch.
pub const MAX_SLIDER_SPEED_UM_S: u32 = 2_000_000;

impl Ridges {
    pub(crate) fn new(
        g: &Grating,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        sample_period_us: u32,
    ) -> Result<Self, BurstError> {
        if timer.max_burst_hz == 0 {
            return Err(timer.bad());
        }
        limits.check_duty(g.duty_permille)?;
        let duty = g.duty_permille as u64;
        let clock = timer.clock_hz as u64;
        let max_on_clocks = limits.max_on_time_clocks(timer);
        let min_on_clocks =
            (clock * duty / (1000 * timer.max_burst_hz as u64)).clamp(1, max_on_clocks.max(1));
        // Both extremes must be renderable, so no crossing is ever refused by the timer.
        timer.one_pulse(max_on_clocks)?;
        timer.one_pulse(min_on_clocks)?;
        if g.render == GratingRender::Hybrid {
            // The longest pulse delayed by a whole period: every prediction renders too.
            let period_clocks = sample_period_us as u64 * clock / 1_000_000;
            timer.delayed_pulse(period_clocks, max_on_clocks)?;
        }
        Ok(Self {
            wavelength_um: g.wavelength_um as i32,
            rearm_um: g.rearm_um as i32,
            ridge_um: (g.wavelength_um as u64 * duty / 1000) as i32,
            on_clock_um_s: duty * g.wavelength_um as u64 * clock / 1000,
            min_on_clocks,
            max_on_clocks,
            min_spacing_us: 1_000_000u32.div_ceil(timer.max_burst_hz),
            min_on_us: timer.clocks_to_us_ceil(min_on_clocks) as u32,
            amplitude: g.amplitude_permille,
            tracker: RidgeTracker::default(),
            last_pulse_us: None,
            on_span_um: None,
            max_step_um: (4 * MAX_SLIDER_SPEED_UM_S as u64 * sample_period_us as u64 / 1_000_000)
                .min(i32::MAX as u64) as i32,
            last_um: 0,
            last_reach_um: u32::MAX,
            jump_um: None,
            hybrid: (g.render == GratingRender::Hybrid).then(|| Predictor {
                fit: LineFit::default(),
                sample_period_us,
                // Via u32 (a period is far below 2^32 clocks): u64 → f32 is a soft-float
                // helper on the M4F, which the firmware keeps off its paths (scripts/emu.sh).
                period_clocks: (sample_period_us as u64 * clock / 1_000_000).min(u32::MAX as u64)
                    as u32 as f32,
                // In f32 from u32s: u64 → f32 is a soft-float helper on the M4F.
                trust_um: TRUST_SPEED_UM_S as f32 * sample_period_us as f32 / 1e6,
                samples_per_s: 1e6 / sample_period_us.max(1) as f32,
                wavelength_um: g.wavelength_um as f32,
                last_fired: None,
                prev_end_um: f32::NAN,
            }),
        })
    }

    /// False for a single-sample glitch: a step the slider cannot make, not (yet) confirmed by
    /// a second sample near it. A real jump (after a gap) costs one sample.
    #[inline(always)]
    fn plausible(&mut self, position_um: i32) -> bool {
        let near = |a: i32, b: i32| a.abs_diff(b) <= self.max_step_um as u32;
        let ok = self.last_um.abs_diff(position_um) <= self.last_reach_um
            || self.jump_um.is_some_and(|j| near(j, position_um));
        if ok {
            self.last_um = position_um;
            self.last_reach_um = self.max_step_um as u32;
            self.jump_um = None;
        } else {
            self.jump_um = Some(position_um);
        }
        ok
    }

    /// Rendered by the hybrid (its own line fit), not by position phase alone.
    pub(crate) fn is_hybrid(&self) -> bool {
        self.hybrid.is_some()
    }

    /// The hybrid's velocity, µm/s: its line's slope, as its pulses are sized (None without a
    /// full window, or for a position-phase grating).
    pub(crate) fn own_velocity_um_s(&self) -> Option<i32> {
        let h = self.hybrid.as_ref()?;
        h.fit.line().map(|l| (l.slope_um * h.samples_per_s) as i32)
    }

    /// The hybrid's newest `k` positions and their times, oldest first (none for a
    /// position-phase grating): what a velocity estimator is seeded from on leaving its region.
    pub(crate) fn own_history(&self, k: usize) -> impl Iterator<Item = (i32, u32)> + '_ {
        self.hybrid
            .as_ref()
            .into_iter()
            .flat_map(move |h| h.fit.history(k, h.sample_period_us))
    }

    /// [`Self::step_as`] for this grating's renderer (tests; the controller asks through
    /// [`Render::request`]).
    #[cfg(test)]
    pub(crate) fn step(
        &mut self,
        position_um: i32,
        velocity_um_s: Option<i32>,
        t_us: u32,
        timer: &BurstTimer,
    ) -> (Want, Option<TimerSettings>, u32) {
        let r = if self.hybrid.is_some() {
            self.step_hybrid(position_um, t_us, timer)
        } else {
            self.step_as::<false>(position_um, velocity_um_s, t_us, timer)
        };
        (r.want, r.settings, r.skipped)
    }

    /// The hybrid's copy, a call of its own: inlined into the controller it spills the
    /// sample path's registers (M4F: +30 instructions per sample, `scripts/emu.sh`). It
    /// returns the whole request, written once into the caller's (a tuple copied into a
    /// request after the call cost the M4F ~14 instructions a sample), and takes no velocity:
    /// its own line is its velocity (the estimator sleeps in its region).
    #[inline(never)]
    fn step_hybrid(&mut self, position_um: i32, t_us: u32, timer: &BurstTimer) -> Request {
        self.step_as::<true>(position_um, None, t_us, timer)
    }

    /// A step's outcome as the controller's request (this grating's amplitude). Every path
    /// builds its request where it ends, `fire`'s and `predict`'s in the caller's: a tuple
    /// merged on the stack and copied into the request cost the M4F ~10 instructions a sample.
    #[inline(always)]
    fn request_of(&self, want: Want, settings: Option<TimerSettings>, skipped: u32) -> Request {
        Request {
            settings,
            skipped,
            amplitude: self.amplitude,
            want,
            clamped: false,
        }
    }

    /// What to do on this sample, the pulse's settings, and the ridges passed without a pulse.
    ///
    /// A pulse's length is set from the speed, duty·λ/|V|, so at a steady speed the timer ends
    /// it on time to the clock. It is also ended by position: once the finger leaves the
    /// ridge's share of the period (forward past it, or back beyond the re-arm distance) the
    /// pulse is cut, so an estimate that lags an acceleration or a reversal cannot stretch it
    /// (and its duty rest) over the next ridge. With the speed unknown (the estimator's first
    /// window after a start or a fault) the timer is set to the on-time cap and position alone
    /// ends the pulse.
    ///
    /// `HYBRID` says whether the grating is rendered by prediction (it must match
    /// `self.hybrid`): two copies, so the position-phase one carries none of the prediction's
    /// code and registers on the M4F.
    #[inline(always)]
    fn step_as<const HYBRID: bool>(
        &mut self,
        position_um: i32,
        velocity_um_s: Option<i32>,
        t_us: u32,
        timer: &BurstTimer,
    ) -> Request {
        let mut want = Want::Periodic;
        if !self.plausible(position_um) {
            if let Some(h) = self.hybrid.as_mut().filter(|_| HYBRID) {
                h.fit.reset();
            }
            return self.request_of(want, None, 0);
        }
        // The hybrid's line first: its sums are the step's largest piece, and made before the
        // span test and the tracker they share no registers with those (M4F: the crossing and
        // the span held across the fit spilled to the stack). Independent state: same result.
        let line = match self.hybrid.as_mut().filter(|_| HYBRID) {
            Some(h) => h.fit.push(position_um, t_us, h.sample_period_us),
            None => None,
        };
        if let Some((lo, hi)) = self.on_span_um {
            // Signed: a predicted pulse starts after the sample that fired it.
            let long_enough = self
                .last_pulse_us
                .is_some_and(|t0| t_us.wrapping_sub(t0) as i32 >= self.min_on_us as i32);
            if (position_um < lo || position_um > hi) && long_enough {
                self.on_span_um = None;
                want = Want::EndPulse;
            }
        }
        let crossing = self
            .tracker
            .update(position_um, self.wavelength_um, self.rearm_um);
        let mut crossing = crossing;
        // Its own fit is the hybrid's velocity (the sample path's contract, `Need::OwnFit`: the
        // shared estimator rests in its region): the line's slope sizes the pulses of position
        // phase too; without a line yet, position alone ends them. Made only where a pulse is
        // sized (most samples fire nothing).
        let mut own: Option<(Line, f32)> = None;
        if let Some(h) = self.hybrid.as_mut().filter(|_| HYBRID) {
            own = line.map(|l| (l, h.samples_per_s));
            // The last ridge fired re-arms once the finger is `rearm_um` clear of it.
            let here_um = line.map_or(position_um as f32, |l| l.end_um);
            if let Some(k) = h.last_fired {
                let dist_um = (here_um - (k * self.wavelength_um) as f32).abs();
                if dist_um > self.rearm_um as f32 {
                    h.last_fired = None;
                }
            }
            let trusted = line.filter(|l| l.slope_um.abs() >= h.trust_um);
            let from_um = match trusted {
                // The line's window joins the last one's: (previous end, end + slope].
                Some(l) if h.prev_end_um.is_nan() => l.end_um - l.slope_um,
                Some(_) => h.prev_end_um,
                None => 0.0,
            };
            h.prev_end_um = trusted.map_or(f32::NAN, |l| l.end_um);
            if let Some(line) = trusted {
                // On a trusted line a raw crossing is only noise's opinion, unless it is of a
                // ridge behind the line's window that nothing fired (the line was not yet
                // trusted when the finger passed it): that one fires now, as position phase.
                let behind = crossing.filter(|c| {
                    let r_um = (c.ridge * self.wavelength_um) as f32;
                    let passed = if line.slope_um > 0.0 {
                        r_um <= from_um
                    } else {
                        r_um >= from_um
                    };
                    passed && c.skipped == 0 && h.last_fired != Some(c.ridge)
                });
                if let Some(c) = behind {
                    let velocity_um_s = Some((line.slope_um * h.samples_per_s) as i32);
                    let out = self.fire(c, velocity_um_s, 0, want, t_us, timer);
                    if out.settings.is_some() {
                        if let Some(h) = self.hybrid.as_mut().filter(|_| HYBRID) {
                            h.last_fired = Some(c.ridge);
                        }
                    }
                    return out;
                }
                // The ridges nearest the raw position bound every candidate: one within reach of
                // the line (two periods of travel, plus how far the raw sample may sit from the
                // line) is its cell's edge above or below. Far from both, nothing to predict.
                // A line end outside the raw cell is never called far: `predict` decides then.
                // (`update` has just set the cell: its edge is the raw position's.)
                let reach_um = 2.0 * line.slope_um.abs() + (INNOVATION_GATE_UM + 8.0);
                let above_lo_um = line.end_um - self.tracker.cell_lo_um as f32;
                let far = above_lo_um > reach_um && h.wavelength_um - above_lo_um > reach_um;
                if far {
                    return self.request_of(want, None, 0);
                }
                return self.predict(line, from_um, want, t_us, timer);
            }
            // Position phase, but not a ridge the prediction already fired.
            if crossing.is_some_and(|c| h.last_fired == Some(c.ridge) && c.skipped == 0) {
                crossing = None;
            }
        }
        let Some(c) = crossing else {
            return self.request_of(want, None, 0);
        };
        let velocity_um_s = if HYBRID {
            own.map(|(l, samples_per_s)| (l.slope_um * samples_per_s) as i32)
        } else {
            velocity_um_s
        };
        let out = self.fire(c, velocity_um_s, 0, want, t_us, timer);
        if out.settings.is_some() {
            if let Some(h) = self.hybrid.as_mut().filter(|_| HYBRID) {
                h.last_fired = Some(c.ridge);
            }
        }
        out
    }

    /// The hybrid's step on a trusted line: the first ridge at or past where the line was one
    /// period ago (so a ridge the line passed since is still fired, now), fired if the line
    /// reaches it within the coming period, the burst delayed to the crossing.
    fn predict(
        &mut self,
        line: Line,
        from_um: f32,
        want: Want,
        t_us: u32,
        timer: &BurstTimer,
    ) -> Request {
        let Some(h) = self.hybrid.as_ref() else {
            return self.request_of(want, None, 0);
        };
        let up = line.slope_um > 0.0;
        // The first ridge past `from_um` in the direction of motion. Positions are 0..=1 m:
        // the cast truncates towards 0, which is the floor there.
        let from_floor_um = from_um as i32;
        let Some(cell) = from_floor_um.checked_div_euclid(self.wavelength_um) else {
            return self.request_of(want, None, 0);
        };
        let ridge = if up { cell + 1 } else { cell };
        let already = h.last_fired == Some(ridge);
        let fraction = ((ridge * self.wavelength_um) as f32 - line.end_um) / line.slope_um;
        if already || fraction > 1.0 {
            return self.request_of(want, None, 0);
        }
        // Rounded to the nearest clock and µs (the cast truncates; a fraction of 0.7 in f32
        // is 0.699999988).
        // f32 → u32 is one FPU instruction; → u64 a soft-float helper.
        let delay_clocks = (fraction.max(0.0) * h.period_clocks + 0.5) as u32 as u64;
        let delay_us = (fraction.max(0.0) * h.sample_period_us as f32 + 0.5) as u32;
        let speed_um_s = (line.slope_um.abs() * h.samples_per_s) as i32;
        let c = Crossing {
            ridge,
            skipped: 0,
            up,
        };
        let out = self.fire(
            c,
            Some(speed_um_s),
            delay_clocks,
            want,
            t_us.wrapping_add(delay_us),
            timer,
        );
        // Fired, or skipped (too soon after the last pulse): either way this ridge is done,
        // so a skip is counted once and never fired late on a later sample.
        if let Some(h) = self.hybrid.as_mut() {
            h.last_fired = Some(ridge);
        }
        out
    }

    /// Fires crossing `c` with a pulse starting `delay_clocks` after now, at `start_us`.
    fn fire(
        &mut self,
        c: Crossing,
        velocity_um_s: Option<i32>,
        delay_clocks: u64,
        want: Want,
        start_us: u32,
        timer: &BurstTimer,
    ) -> Request {
        let t_us = start_us;
        let too_soon = self
            .last_pulse_us
            .is_some_and(|last| t_us.wrapping_sub(last) < self.min_spacing_us);
        let on = match velocity_um_s {
            Some(v) => self
                .on_clock_um_s
                .checked_div(v.unsigned_abs() as u64)
                .unwrap_or(u64::MAX),
            None => u64::MAX,
        }
        // max/min, not clamp (which panics if the bounds cross; `new` checked they do not).
        .max(self.min_on_clocks)
        .min(self.max_on_clocks);
        // `new` checked that both ends of the clamp render, so one_pulse cannot fail here; if it
        // did, the ridge would be skipped like one that comes too soon.
        let settings = if too_soon {
            None
        } else {
            timer.delayed_pulse(delay_clocks, on).ok()
        };
        let Some(settings) = settings else {
            return self.request_of(want, None, c.skipped + 1);
        };
        let ridge = c.ridge * self.wavelength_um;
        self.on_span_um = Some(if c.up {
            (ridge - self.rearm_um, ridge + self.ridge_um)
        } else {
            (ridge - self.ridge_um, ridge + self.rearm_um)
        });
        self.last_pulse_us = Some(t_us);
        self.request_of(Want::Pulse, Some(settings), c.skipped)
    }
}

impl Render for Ridges {
    /// Forgets the finger's place and the pulse's span (region change, fault): the first
    /// sample after is an arrival, not a crossing.
    fn reset(&mut self) {
        self.tracker.reset();
        self.on_span_um = None;
        self.last_reach_um = u32::MAX;
        self.jump_um = None;
        if let Some(h) = self.hybrid.as_mut() {
            h.fit.reset();
            h.last_fired = None;
            h.prev_end_um = f32::NAN;
        }
    }

    // Every sample from the controller's one call site (`Compiled::request`): inlined, so the
    // sample's fields stay in registers.
    #[inline(always)]
    fn request(&mut self, now: &Moment<'_>) -> Request {
        if self.hybrid.is_some() {
            return self.step_hybrid(now.position_um, now.t_us, now.timer);
        }
        self.step_as::<false>(now.position_um, now.velocity_um_s, now.t_us, now.timer)
    }
}

/// A velocity-synthesis grating, compiled: periodic bursts at f = |V|/λ above the speed
/// threshold.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Synthesis {
    inv_wavelength_per_um: f32,
    motion: MotionGate,
    planner: FastPlanner,
    amplitude: u16,
}

impl Synthesis {
    pub(crate) fn new(
        g: &Grating,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Result<Self, BurstError> {
        Ok(Self {
            inv_wavelength_per_um: 1.0 / g.wavelength_um as f32,
            motion: MotionGate::new(g.min_speed_um_s),
            planner: FastPlanner::new(timer, limits, g.duty_permille)?,
            amplitude: g.amplitude_permille,
        })
    }
}

impl Render for Synthesis {
    fn reset(&mut self) {
        self.motion.reset();
    }

    // Every sample from the controller's one call site (`Compiled::request`): inlined, so the
    // sample's fields stay in registers.
    #[inline(always)]
    fn request(&mut self, now: &Moment<'_>) -> Request {
        let inv_wavelength_per_um = self.inv_wavelength_per_um;
        self.motion
            .request(now.velocity_um_s, &self.planner, self.amplitude, |speed| {
                speed * inv_wavelength_per_um
            })
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec;
    use std::vec::Vec;

    fn crossings(t: &mut RidgeTracker, path: impl Iterator<Item = i32>) -> (u32, u32) {
        let (mut fired, mut skipped) = (0, 0);
        for p in path {
            if let Some(c) = t.update(p, 1_000, 100) {
                fired += 1;
                skipped += c.skipped;
            }
        }
        (fired, skipped)
    }

    #[test]
    fn one_crossing_per_ridge_each_way() {
        let mut t = RidgeTracker::default();
        // Up from 0.5 mm to 10.5 mm at 7 µm per sample, then back down: 10 ridges each way.
        let up = (500..10_500).step_by(7);
        let down = (500..10_500).rev().step_by(7);
        assert_eq!(crossings(&mut t, up.chain(down)), (20, 0));
    }

    #[test]
    fn the_crossing_fires_on_the_sample_past_the_ridge() {
        let mut t = RidgeTracker::default();
        assert_eq!(t.update(850, 1_000, 100), None);
        assert_eq!(t.update(999, 1_000, 100), None);
        let c = t.update(1_000, 1_000, 100).map(|c| c.ridge);
        assert_eq!(c, Some(1));
        // Downwards the same ridge fires on the first sample below it, once re-armed.
        assert_eq!(t.update(1_200, 1_000, 100), None);
        assert_eq!(t.update(1_000, 1_000, 100), None);
        assert_eq!(t.update(999, 1_000, 100).map(|c| c.ridge), Some(1));
        // Negative positions (below the substrate's zero) use floor, not truncation.
        let mut t = RidgeTracker::default();
        t.update(-500, 1_000, 100);
        assert_eq!(t.update(-1_001, 1_000, 100).map(|c| c.ridge), Some(-1));
    }

    #[test]
    fn dither_on_a_ridge_fires_once_and_resting_there_never() {
        let dither = |i: i32| ((i * 37) % 181) - 90; // ±90 µm, inside the 100 µm re-arm
                                                     // Arriving from below: one crossing, then silence however long the dither lasts.
        let mut t = RidgeTracker::default();
        let path = (4_500..5_000)
            .step_by(10)
            .chain((0..20_000).map(|i| 5_000 + dither(i)));
        assert_eq!(crossings(&mut t, path), (1, 0));
        // Starting at rest on the ridge: nothing at all.
        let mut t = RidgeTracker::default();
        assert_eq!(
            crossings(&mut t, (0..20_000).map(|i| 5_000 + dither(i))),
            (0, 0)
        );
        // Beyond the re-arm distance and back is a real second crossing.
        let mut t = RidgeTracker::default();
        let path = [4_800, 5_010, 5_150, 4_990, 4_850, 5_020];
        assert_eq!(crossings(&mut t, path.into_iter()), (3, 0));
    }

    #[test]
    fn several_ridges_in_one_sample_fire_once_and_count_the_rest() {
        let mut t = RidgeTracker::default();
        // 3.5 mm per sample: three ridges per step.
        let (fired, skipped) = crossings(&mut t, (0..10).map(|i| 500 + i * 3_500));
        assert_eq!(fired, 9);
        // From 0.5 mm to 32 mm the finger passed ridges 1..=32: every one fired or was counted.
        assert_eq!(fired + skipped, 32);
    }

    /// Re-arming to the µm: a ridge that fired stays disarmed while the finger is within
    /// `rearm` (100 µm) of it, inclusive, and re-arms one µm further. Crossings say their
    /// direction, and a jump over two ridges fires even when the nearer one is disarmed.
    #[test]
    fn rearm_edge_direction_and_jumps() {
        for (away, fires_back) in [(1_100, false), (1_101, true)] {
            let mut t = RidgeTracker::default();
            assert_eq!(t.update(500, 1_000, 100), None);
            let up = t.update(1_000, 1_000, 100).unwrap();
            assert_eq!((up.ridge, up.up, up.skipped), (1, true, 0));
            assert_eq!(t.update(away, 1_000, 100), None);
            let back = t.update(999, 1_000, 100);
            assert_eq!(back.is_some(), fires_back, "away to {away} um");
            if let Some(c) = back {
                assert_eq!((c.ridge, c.up), (1, false));
            }
        }
        let mut t = RidgeTracker::default();
        t.update(500, 1_000, 100);
        t.update(1_000, 1_000, 100);
        // Ridge 1 is disarmed; one sample later the finger is at -0.5 mm: ridges 1 and 0.
        let c = t.update(-500, 1_000, 100).unwrap();
        assert_eq!((c.ridge, c.skipped, c.up), (1, 1, false));
    }

    #[test]
    fn validation() {
        let g = Grating::new(1_000);
        assert_eq!(g.rearm_um, 100);
        assert!(g.validate(63_000).is_ok());
        assert_eq!(Grating::new(200).rearm_um, 50);
        let bad = Grating { rearm_um: 500, ..g };
        assert_eq!(
            bad.validate(63_000),
            Err(TextureError::BadRearm {
                rearm_um: 500,
                wavelength_um: 1_000
            })
        );
        let synth = Grating {
            render: GratingRender::VelocitySynthesis,
            ..bad
        };
        assert!(synth.validate(63_000).is_ok());
        assert_eq!(
            Grating::new(0).validate(63_000),
            Err(TextureError::BadWavelength {
                wavelength_um: 0,
                length_um: 63_000
            })
        );
        // Each limit from both sides: a wavelength up to the substrate's length, a start
        // threshold up to 1 m/s, amplitude 1–1000 ‰, rearm below half a wavelength.
        assert!(Grating::new(63_000).validate(63_000).is_ok());
        assert_eq!(
            Grating::new(63_001).validate(63_000),
            Err(TextureError::BadWavelength {
                wavelength_um: 63_001,
                length_um: 63_000
            })
        );
        let speed = |min_speed_um_s| {
            Grating {
                min_speed_um_s,
                ..g
            }
            .validate(63_000)
        };
        assert_eq!(speed(1_000_000), Ok(()));
        assert_eq!(
            speed(1_000_001),
            Err(TextureError::BadSpeedThreshold {
                min_speed_um_s: 1_000_001
            })
        );
        let amp = |amplitude_permille| {
            Grating {
                amplitude_permille,
                ..g
            }
            .validate(63_000)
        };
        assert_eq!(amp(1), Ok(()));
        assert_eq!(amp(1_000), Ok(()));
        let bad_amp = |permille| {
            Err(TextureError::BadSpread {
                param: SpreadParam::Amplitude,
                permille,
            })
        };
        assert_eq!(amp(0), bad_amp(0));
        assert_eq!(amp(1_001), bad_amp(1_001));
        let rearm = |rearm_um| Grating { rearm_um, ..g }.validate(63_000);
        assert_eq!(rearm(499), Ok(()));
        assert_eq!(
            rearm(500),
            Err(TextureError::BadRearm {
                rearm_um: 500,
                wavelength_um: 1_000
            })
        );
    }

    const TIMER: BurstTimer = crate::burst::TEST_TIMER;

    fn hybrid(wavelength_um: u32) -> Ridges {
        let g = Grating {
            render: GratingRender::Hybrid,
            ..Grating::new(wavelength_um)
        };
        Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap()
    }

    /// The hybrid's own velocity is its line's slope in µm/s (none until the line has its 64
    /// samples); a position-phase grating has none, nor a history.
    #[test]
    fn the_hybrids_own_velocity_is_its_lines_slope() {
        let mut r = hybrid(1_000);
        for k in 0..200u32 {
            r.step(5_000 + 7 * k as i32, None, k * 100, &TIMER);
            let v = r.own_velocity_um_s();
            // 7 µm a 100 µs sample: 70 mm/s.
            assert_eq!(v, (k >= 63).then_some(70_000), "{k}");
        }
        assert_eq!(
            r.own_history(3).map(|(p, _)| p).collect::<Vec<_>>(),
            [5_000 + 7 * 197, 5_000 + 7 * 198, 5_000 + 7 * 199]
        );
        let mut p =
            Ridges::new(&Grating::new(1_000), &TIMER, &SafetyLimits::default(), 100).unwrap();
        for k in 0..200u32 {
            p.step(5_000 + 7 * k as i32, Some(70_000), k * 100, &TIMER);
        }
        assert_eq!(p.own_velocity_um_s(), None);
        assert_eq!(p.own_history(3).count(), 0);
    }

    /// Every pulse of a run of positions sampled every 100 µs (None: a dropped sample): (sample
    /// index, settings). The velocity handed in is the true one; the hybrid uses its line.
    fn pulses(
        r: &mut Ridges,
        path: impl Iterator<Item = Option<i32>>,
        v_um_s: i32,
    ) -> Vec<(u32, TimerSettings)> {
        let mut out = Vec::new();
        for (k, p) in path.enumerate() {
            let Some(um) = p else { continue };
            let (want, s, skipped) = r.step(um, Some(v_um_s), k as u32 * 100, &TIMER);
            assert_eq!(skipped, 0, "sample {k}");
            if want == Want::Pulse {
                out.push((k as u32, s.unwrap()));
            }
        }
        out
    }

    /// Hand-worked: a noiseless 100 mm/s ramp, x = 303 + 10·k µm at sample k. The ridge at
    /// 1 mm is crossed at k = 69.7, after the line's 64-sample window has filled (k = 63); the
    /// line is exact, so the sample at k = 69 fires it delayed by 0.7 of a period, 70 µs =
    /// 6 300 clocks at 90 MHz, and the pulse lasts duty·λ/V = 0.4 · 1 mm / 100 mm/s = 4 ms =
    /// 360 000 clocks. Ridge 2 mm: k = 169.7, the same.
    #[test]
    fn the_hybrid_fires_at_the_predicted_crossing() {
        let mut r = hybrid(1_000);
        let got = pulses(&mut r, (0..220).map(|k| Some(303 + 10 * k)), 100_000);
        let expected = TIMER.delayed_pulse(6_300, 360_000).unwrap();
        assert_eq!((expected.arr, expected.ccr), (366_299, 360_000));
        assert_eq!(got, vec![(69, expected), (169, expected)]);
        // The last pulse is booked at its delayed start, 169.7 periods: 16 970 µs (the
        // spacing rule and the end-by-position check read it).
        assert_eq!(r.last_pulse_us, Some(16_970));
        // Going down: x = 2 697 − 10·k crosses 2 mm at k = 69.7 and 1 mm at k = 169.7.
        let mut r = hybrid(1_000);
        let got = pulses(&mut r, (0..220).map(|k| Some(2_697 - 10 * k)), -100_000);
        assert_eq!(got, vec![(69, expected), (169, expected)]);
        // Position phase on the same ramp: the first sample past the ridge, undelayed.
        let g = Grating::new(1_000);
        let mut r = Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap();
        let got = pulses(&mut r, (0..220).map(|k| Some(303 + 10 * k)), 100_000);
        let one = TIMER.one_pulse(360_000).unwrap();
        assert_eq!(got, vec![(70, one), (170, one)]);
    }

    /// On the line's first trusted sample its window starts one period back, at end − slope.
    /// Hand-worked: x = 365 + 10·k µm is full at k = 63 (x = 995) and crosses 1 mm at
    /// k = 63.5, so that sample fires it delayed by half a period, 50 µs = 4 500 clocks (not
    /// the next sample, undelayed); 2 mm at k = 163.5 the same.
    #[test]
    fn the_first_trusted_sample_predicts_within_its_period() {
        let mut r = hybrid(1_000);
        let got = pulses(&mut r, (0..200).map(|k| Some(365 + 10 * k)), 100_000);
        let expected = TIMER.delayed_pulse(4_500, 360_000).unwrap();
        assert_eq!(got, vec![(63, expected), (163, expected)]);
    }

    /// A ridge the prediction fired is not fired again by position phase when the line drops
    /// on the next sample. Hand-worked on the ramp x = 303 + 10·k: 1 mm is predicted at k = 69;
    /// at k = 70 the sample comes 80 µm off the line (over the 72 µm gate: the line empties)
    /// and past the ridge, so the tracker reports the crossing, which is the one already fired.
    /// The ramp goes on; the line refills and 2 mm is predicted at k = 169 as on a clean ramp.
    #[test]
    fn a_ridge_the_prediction_fired_is_not_fired_again() {
        let mut r = hybrid(1_000);
        let path = (0..220).map(|k| Some(303 + 10 * k + if k == 70 { 80 } else { 0 }));
        let got = pulses(&mut r, path, 100_000);
        let expected = TIMER.delayed_pulse(6_300, 360_000).unwrap();
        assert_eq!(got, vec![(69, expected), (169, expected)]);
    }

    /// A ridge the raw samples cross on the line's first trusted sample, but which lies behind
    /// the line's window, fires at once as position phase (nothing fired it: the line was not
    /// full when the finger reached it). Hand-worked: the ramp x = 385 + 10·k with the sample at
    /// k = 62 20 µm low (985, not 1 005). The window fills at k = 63 (x = 1 015): the raw
    /// samples cross 1 mm there (985 → 1 015). The line's end weights sample i by
    /// (6i − 124)/4 160 and its slope by (12i − 378)/262 080, so the low sample puts the end
    /// at 1 015 − 20 · 0.0596 = 1 013.8 and the slope at 10 − 20 · 0.0014 = 9.97: the window
    /// starts at 1 003.8, past the ridge. So the ridge fires undelayed at k = 63; prediction
    /// alone would look only ahead, to 2 mm, and never fire it. 2 mm: k = 161.5, predicted
    /// at k = 161 half a period late (the window is a clean ramp by then).
    /// The pulse at k = 63 is sized by the hybrid's own line (its velocity since issue #35,
    /// not the estimator's): 10 − 20·366/262 080 = 9.97207 µm a sample, 99 720 µm/s once
    /// truncated, so duty·λ·clock / V = 0.4 · 1 000 µm · 90 MHz / 99 720 µm/s = 361 010 clocks
    /// (floor), where the true 100 mm/s the test hands in would give 360 000.
    #[test]
    fn a_ridge_behind_the_first_trusted_window_fires_at_once() {
        let mut r = hybrid(1_000);
        let path = (0..200).map(|k| Some(385 + 10 * k - if k == 62 { 20 } else { 0 }));
        let got = pulses(&mut r, path, 100_000);
        let now = TIMER.delayed_pulse(0, 361_010).unwrap();
        let half = TIMER.delayed_pulse(4_500, 360_000).unwrap();
        assert_eq!(got, vec![(63, now), (161, half)]);
    }

    /// The line is trusted from 10 mm/s (1 µm per sample at 10 kHz): at 9 mm/s the ridge is
    /// fired by position phase on the first sample past it, at 11 mm/s predicted.
    #[test]
    fn below_the_trust_speed_the_hybrid_is_position_phase() {
        // 9 µm/sample ... 0.9 µm/sample: x = 700 + 0.9·k crosses 1 mm at k = 333.3.
        let mut r = hybrid(1_000);
        let path = (0..400).map(|k| Some(700 + (9 * k) / 10));
        let got = pulses(&mut r, path, 9_000);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, 334, "{got:?}");
        assert_eq!(got[0].1.pulse_delay_clocks(), 1, "undelayed: {got:?}");
        // 1.1 µm/sample: x = 700 + ⌊1.1·k⌋ µm. The staircase sits 0.45 µm below 700 + 1.1·k on
        // average, so the line reaches 1 mm at k ≈ 273.1 (the raw sample reads 1 000 at
        // k = 273): predicted at k = 273, a tenth of a period ahead.
        let mut r = hybrid(1_000);
        let path = (0..400).map(|k| Some(700 + (11 * k) / 10));
        let got = pulses(&mut r, path, 11_000);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].0, 273, "{got:?}");
        assert!(got[0].1.pulse_delay_clocks() > 1, "predicted: {got:?}");
    }

    /// A dropped sample empties the line: the next ridge within 64 samples is position phase,
    /// the one after is predicted again. A glitch the position guard rejects does the same.
    #[test]
    fn a_gap_or_a_glitch_empties_the_line() {
        // Unbroken, this ramp's ridges at k = 69.7 and 169.7 are both predicted (above).
        let ramp = |k: i32| 303 + 10 * k;
        // Sample 66 missing: the ridge at k = 69.7 is fired by position phase at k = 70.
        let mut r = hybrid(1_000);
        let path = (0..220).map(|k| (k != 66).then_some(ramp(k)));
        let got = pulses(&mut r, path, 100_000);
        assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![70, 169]);
        assert_eq!(got[0].1.pulse_delay_clocks(), 1);
        assert_eq!(got[1].1.pulse_delay_clocks(), 6_300);
        // A 3 mm spike at sample 66: rejected by the guard, and the line starts over.
        let mut r = hybrid(1_000);
        let path = (0..220).map(|k| Some(if k == 66 { ramp(k) + 3_000 } else { ramp(k) }));
        let got = pulses(&mut r, path, 100_000);
        assert_eq!(got.iter().map(|g| g.0).collect::<Vec<_>>(), vec![70, 169]);
        assert_eq!(got[0].1.pulse_delay_clocks(), 1);
        assert_eq!(got[1].1.pulse_delay_clocks(), 6_300);
    }

    /// A reversal: up at 100 mm/s to 1.2 mm, then straight back down. The ridge at 1 mm is
    /// crossed twice and fired twice (predicted going up; going down the line, bent away by
    /// the turn, is emptied and position phase fires it), never a third time.
    #[test]
    fn a_reversal_empties_the_line_and_fires_each_crossing_once() {
        let x = |k: i32| {
            if k <= 90 {
                303 + 10 * k
            } else {
                1_203 - 10 * (k - 90)
            }
        };
        let mut r = hybrid(1_000);
        let got = pulses(&mut r, (0..130).map(|k| Some(x(k))), 100_000);
        let ks: Vec<u32> = got.iter().map(|g| g.0).collect();
        assert_eq!(ks.len(), 2, "{got:?}");
        assert_eq!(ks[0], 69);
        // Down through 1 mm at k = 110.3: 21 samples after the turn, inside the line's refill.
        assert_eq!(ks[1], 111, "{got:?}");
        assert_eq!(
            got[1].1.pulse_delay_clocks(),
            1,
            "position phase after the turn"
        );
    }

    /// The span a ridge pulse stays on over, to the µm: going up over the ridge at 6 mm it is
    /// [6 mm − rearm, 6 mm + duty·λ]; the pulse is cut one µm outside either end, not on it.
    #[test]
    fn ridge_pulse_span_edges() {
        let g = Grating::new(1_000);
        let rearm = g.rearm_um as i32;
        // (speed, approach: the last sample fires, a sample on the ridge, the span).
        let up: (i32, &[i32], i32, (i32, i32)) = (
            20_000,
            &[5_500, 5_800, 6_000],
            6_010,
            (6_000 - rearm, 6_000 + 400),
        );
        // Going down over the same ridge the span is mirrored: [6 mm − duty·λ, 6 mm + rearm].
        let down: (i32, &[i32], i32, (i32, i32)) = (
            -20_000,
            &[6_500, 6_200, 6_000, 5_999],
            5_990,
            (6_000 - 400, 6_000 + rearm),
        );
        for (v, approach, on_ridge, (lo, hi)) in [up, down] {
            for (edge, outside) in [(lo, lo - 1), (hi, hi + 1)] {
                let mut r = Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap();
                let mut t = 0;
                let mut step = |r: &mut Ridges, um: i32| {
                    t += 100;
                    r.step(um, Some(v), t, &TIMER).0
                };
                let (&last, before) = approach.split_last().unwrap();
                for &um in before {
                    assert_eq!(step(&mut r, um), Want::Periodic, "{v} um/s at {um} um");
                }
                assert_eq!(step(&mut r, last), Want::Pulse, "{v} um/s at {last} um");
                // Past the shortest pulse, still on the ridge.
                for _ in 0..10 {
                    assert_eq!(step(&mut r, on_ridge), Want::Periodic);
                }
                assert_eq!(step(&mut r, edge), Want::Periodic, "{v} um/s at {edge} um");
                assert_eq!(
                    step(&mut r, outside),
                    Want::EndPulse,
                    "{v} um/s at {outside} um"
                );
            }
        }
    }

    /// Ridge pulses may start as close as the board's shortest burst period (200 µs at 5 kHz),
    /// not closer: two ridges crossed 200 µs apart both fire; 150 µs apart, the second is
    /// counted as skipped.
    #[test]
    fn ridge_pulses_as_close_as_the_board_allows() {
        let g = Grating::new(1_000);
        let mut r = Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap();
        let fired: std::vec::Vec<_> = [(100, 5_500), (200, 6_000), (300, 6_500), (400, 7_000)]
            .into_iter()
            .map(|(t, um)| {
                let (want, _, skipped) = r.step(um, Some(5_000_000), t, &TIMER);
                (want, skipped)
            })
            .collect();
        assert_eq!(
            fired,
            [
                (Want::Periodic, 0),
                (Want::Pulse, 0),
                // Past the ridge's 400 µm share: the first pulse is cut by position.
                (Want::EndPulse, 0),
                (Want::Pulse, 0)
            ]
        );
        let mut r = Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap();
        r.step(5_500, Some(5_000_000), 100, &TIMER);
        r.step(6_000, Some(5_000_000), 200, &TIMER);
        r.step(6_600, Some(5_000_000), 275, &TIMER);
        let (want, _, skipped) = r.step(7_000, Some(5_000_000), 350, &TIMER);
        // The first pulse is cut here too (past its share, and on for its 80 µs minimum).
        assert_eq!((want, skipped), (Want::EndPulse, 1));
    }
}
