//! Tangible lines (fig. 12 of the SAW display paper): crossing a line fires one carrier pulse.
//!
//! The paper found a long rectangular pulse is felt as two strings (the friction changes at both
//! its edges) and a triangle-modulated pulse as one, so the envelope is selectable. A line fires
//! once per crossing in either direction: after firing it is disarmed until the finger has moved
//! `hysteresis_um` clear of it on either side, so a finger resting on a line never re-fires.

use heapless::Vec;

use crate::burst::{BurstTimer, SafetyLimits, TimerSettings};

use super::compiled::CompileError;
use super::{LineFault, TextureError, MAX_LINE_REARM_UM};

/// Most lines a scene may draw.
pub const MAX_LINES: usize = 16;

/// Amplitude envelope of a line pulse.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Envelope {
    /// Full amplitude for the whole pulse (felt as two strings when long).
    Rectangular,
    /// Rising then falling linearly (felt as one string).
    Triangular,
}

/// The lines of a scene.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Lines {
    /// Line positions, µm, strictly increasing.
    pub positions_um: Vec<u32, MAX_LINES>,
    /// Pulse length, µs.
    pub pulse_us: u32,
    /// Pulse envelope.
    pub envelope: Envelope,
    /// Peak amplitude, ‰.
    pub amplitude_permille: u16,
    /// Distance the finger must move clear of a line to re-arm it, µm.
    pub hysteresis_um: u32,
}

impl Default for Lines {
    /// No lines; 10 ms triangular pulses at full drive, 200 µm re-arm distance once some are added.
    fn default() -> Self {
        Self {
            positions_um: Vec::new(),
            pulse_us: 10_000,
            envelope: Envelope::Triangular,
            amplitude_permille: 1000,
            hysteresis_um: 200,
        }
    }
}

impl Lines {
    /// Checks positions against a substrate of `length_um` and the pulse against the on-time cap.
    pub fn validate(&self, length_um: u32, max_on_time_us: u32) -> Result<(), TextureError> {
        let mut prev: Option<u32> = None;
        for (i, &p) in self.positions_um.iter().enumerate() {
            let index = i as u8;
            if p == 0 || p >= length_um {
                return Err(TextureError::BadLines(LineFault::OutOfRange {
                    index,
                    at_um: p,
                    length_um,
                }));
            }
            if let Some(q) = prev.filter(|&q| p <= q) {
                return Err(TextureError::BadLines(LineFault::Unsorted {
                    index,
                    at_um: p,
                    previous_um: q,
                }));
            }
            prev = Some(p);
        }
        if self.positions_um.is_empty() {
            return Ok(());
        }
        if self.pulse_us == 0 || self.pulse_us > max_on_time_us {
            return Err(TextureError::BadPulse {
                pulse_us: self.pulse_us,
                max_on_time_us,
            });
        }
        if self.amplitude_permille == 0 || self.amplitude_permille > 1000 {
            return Err(TextureError::BadLines(LineFault::Amplitude {
                permille: self.amplitude_permille,
            }));
        }
        if self.hysteresis_um > MAX_LINE_REARM_UM {
            return Err(TextureError::BadLines(LineFault::Rearm {
                rearm_um: self.hysteresis_um,
            }));
        }
        Ok(())
    }
}

/// Which side of a line the finger was last seen clear of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    Below,
    Above,
}

/// Farthest ahead of a line a pulse may fire, µm: 400 mm/s with a 10 ms triangle. A faster
/// velocity estimate (a glitch the median did not catch) must not fire a line millimetres early.
pub const MAX_LINE_LEAD_UM: i64 = 2_000;

/// A scene's lines, compiled: the pulse's one-pulse settings and the rest after it.
#[derive(Clone, Debug)]
pub(crate) struct LinePulses {
    lines: Lines,
    pulse: TimerSettings,
    /// How far ahead a triangle fires, in µs of travel: half the pulse, so the peak (felt as the
    /// line) falls on it, plus half a sample period, so firing on the sample grid lands the peak
    /// within ± half a sample of travel instead of 0 … 1 sample late. 0 for rectangles: their
    /// first edge marks the line, as before. Kept as s × 2^32 (µm of lead per µm/s of speed),
    /// so the per-sample lead is one 32 × 32 → 64-bit multiply and a shift: a 64-bit division
    /// is a library call on the Cortex-M4.
    lead_s_q32: i64,
    /// Pulse plus the rest after it, µs: the line owns the gate this long after it fires, so
    /// pulse / (pulse + rest) keeps the duty cap.
    window_us: u32,
}

impl LinePulses {
    /// The pulses' envelope.
    pub(crate) fn envelope(&self) -> Envelope {
        self.lines.envelope
    }

    /// Validates `lines` on a substrate of `length_um` and prepares their pulse; None when the
    /// scene draws no lines.
    pub(crate) fn compile(
        lines: &Lines,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        length_um: u32,
        sample_period_us: u32,
    ) -> Result<Option<Self>, CompileError> {
        lines.validate(length_um, limits.max_on_time_us)?;
        if !lines.positions_um.is_empty() && lines.amplitude_permille > limits.max_level_permille {
            return Err(TextureError::LevelAboveCap {
                permille: lines.amplitude_permille,
                max_level_permille: limits.max_level_permille,
            }
            .into());
        }
        if lines.positions_um.is_empty() {
            return Ok(None);
        }
        // High for the whole count, one tick low at the end.
        let clocks = lines.pulse_us as u64 * timer.clock_hz as u64 / 1_000_000;
        let pulse = timer.one_pulse(clocks)?;
        let lead_us = match lines.envelope {
            Envelope::Triangular => lines.pulse_us / 2 + sample_period_us / 2,
            Envelope::Rectangular => 0,
        };
        // Rounded to nearest: 5 050 µs at 200 mm/s is 1 010 µm, not 1 009.
        let lead_s_q32 = (((lead_us as i64) << 32) + 500_000) / 1_000_000;
        Ok(Some(Self {
            lines: lines.clone(),
            pulse,
            lead_s_q32,
            window_us: lines.pulse_us + refractory_us(lines, limits),
        }))
    }
}

/// Rest after a line pulse so that pulse / (pulse + rest) ≤ the duty cap.
pub(crate) fn refractory_us(lines: &Lines, limits: &SafetyLimits) -> u32 {
    let cap = limits.max_duty_permille as u64;
    (lines.pulse_us as u64 * (1000 - cap)).div_ceil(cap) as u32
}

/// What the lines do on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LineStep {
    /// No line pulse owns the gate: the region's texture does.
    Free,
    /// Inside a pulse or its rest: the line owns the gate (the port plays the pulse's
    /// envelope). `skipped`: a line was crossed now and gets no pulse, to keep the duty cap.
    Window { skipped: bool },
    /// Line `line` was crossed: fire `pulse` at `amplitude_permille`, and call
    /// [`LineTracker::started`] if the gate takes it.
    Fire {
        line: u8,
        pulse: TimerSettings,
        amplitude_permille: u16,
    },
}

/// Per-line arming state, and the window of the running line pulse.
#[derive(Clone, Debug, Default)]
pub(crate) struct LineTracker {
    armed: [Option<Side>; MAX_LINES],
    /// Where each line last fired, relative to the line, µm (a triangle fires ahead of it:
    /// re-arming counts the hysteresis from there as well as from the line); 0 once re-armed.
    ahead_um: [i32; MAX_LINES],
    /// Start of the running line pulse, while in its pulse + rest window.
    pulse_start_us: Option<u32>,
    /// Bit i: line i is armed from below with no fired offset (`armed = Below`, `ahead = 0`).
    /// A sample with the finger (and its lead) more than the hysteresis below such a line
    /// changes nothing for it, so [`Self::update_ahead`] skips it.
    settled_below: u32,
    /// Bit i: line i is armed from above with no fired offset; skipped likewise while the
    /// finger is clear above it.
    settled_above: u32,
    /// Window of the last sample, as indices into the (sorted) lines: lines `..lo` lay below
    /// it, lines `hi..` above it. Carried from sample to sample so finding the next window is
    /// a step or two, not a scan.
    lo: u8,
    hi: u8,
    /// Set when the last sample visited no line and its window lay between two neighbouring
    /// lines (exclusive bounds; `i32::MIN` / `i32::MAX` past the ends): every line was
    /// settled on the side the finger is clear of. A window still inside that gap changes
    /// nothing, so the sample returns at once (a finger resting or moving between lines).
    gap: Option<(i32, i32)>,
    /// Lines visited by [`Self::update_ahead`] (tests: the visit is the optimisation, and only
    /// a count can tell a visit of more lines, which changes no result, from the right one).
    #[cfg(test)]
    visits: u32,
}

impl LineTracker {
    /// Forgets which side the finger was on (after a fault or a scene load). A running pulse's
    /// window is kept: the gate may still be in its rest.
    pub(crate) fn reset(&mut self) {
        self.armed = [None; MAX_LINES];
        self.ahead_um = [0; MAX_LINES];
        self.settled_below = 0;
        self.settled_above = 0;
        self.gap = None;
    }

    /// Forgets everything, the running pulse's window too (a fault has cut the line).
    pub(crate) fn cut(&mut self) {
        self.reset();
        self.pulse_start_us = None;
    }

    /// The gate took the pulse of [`LineStep::Fire`] at `t_us`: its window starts.
    pub(crate) fn started(&mut self, t_us: u32) {
        self.pulse_start_us = Some(t_us);
    }

    /// One sample of the lines at `position_um`, `t_us`. Out of line: inlined into the
    /// sample loop it cost scenes without lines ~9 instructions per sample on the M4 (register
    /// pressure in `on_sample`), for a call that saves a scene with lines about as much.
    #[inline(never)]
    pub(crate) fn step(
        &mut self,
        lines: &LinePulses,
        position_um: i32,
        velocity_um_s: Option<i32>,
        t_us: u32,
    ) -> LineStep {
        // On the speed's magnitude, so both directions round alike (an arithmetic shift floors
        // a negative product towards −∞).
        let lead_um = velocity_um_s.map_or(0, |v| {
            let ahead = ((v.unsigned_abs() as i64 * lines.lead_s_q32) >> 32).min(MAX_LINE_LEAD_UM);
            (if v.is_negative() { -ahead } else { ahead }) as i32
        });
        let fired = self.update_ahead(&lines.lines, position_um, lead_um);
        if let Some(start) = self.pulse_start_us {
            let dt = t_us.wrapping_sub(start);
            if dt < lines.window_us {
                return LineStep::Window {
                    skipped: fired.is_some(),
                };
            }
            self.pulse_start_us = None;
        }
        match fired {
            Some(line) => LineStep::Fire {
                line,
                pulse: lines.pulse,
                amplitude_permille: lines.lines.amplitude_permille,
            },
            None => LineStep::Free,
        }
    }

    /// Updates with a new position; returns the index of a line crossed, if any.
    #[cfg(test)]
    pub(crate) fn update(&mut self, lines: &Lines, position_um: i32) -> Option<u8> {
        self.update_ahead(lines, position_um, 0)
    }

    /// Updates with a new position, firing a line `lead_um` of travel before the finger reaches
    /// it (signed: the direction of motion; only a lead towards the line counts). Returns the
    /// index of a line fired, if any. A line re-arms once the finger is `hysteresis_um` clear
    /// of both the line and where it fired.
    ///
    /// Only the lines this sample can change are visited: those inside the window
    /// [min(p + lead⁻, p − h), max(p + lead⁺, p + h)] around the position p, and those outside
    /// it that are not settled on the side the finger is clear of (just fired, not re-armed,
    /// or armed from the other side: a jump across a line still fires it). For every other
    /// line the full update is a no-op (see [`Self::update_line`]), so the result is the same
    /// as visiting all of them, in the same (ascending) order. Needs the lines sorted, which
    /// [`Lines::validate`] enforces.
    pub(crate) fn update_ahead(
        &mut self,
        lines: &Lines,
        position_um: i32,
        lead_um: i32,
    ) -> Option<u8> {
        // Positions are within the substrate (≤ 1 m), the lead within ±2 mm and the hysteresis
        // within 5 mm: plain i32 sums cannot overflow.
        let h = lines.hysteresis_um as i32;
        let (up, down) = (position_um + lead_um.max(0), position_um + lead_um.min(0));
        let (floor, ceil) = (down.min(position_um - h), up.max(position_um + h));
        if let Some((below, above)) = self.gap {
            if below < floor && ceil < above {
                return None;
            }
        }
        let at = |i: usize| lines.positions_um.get(i).map(|&l| l as i32);
        let n = lines.positions_um.len();
        // lo: lines strictly below `floor`; hi: lines at or below `ceil`.
        let mut lo = (self.lo as usize).min(n);
        while lo > 0 && at(lo - 1).is_some_and(|l| l >= floor) {
            lo -= 1;
        }
        while at(lo).is_some_and(|l| l < floor) {
            lo += 1;
        }
        let mut hi = (self.hi as usize).min(n).max(lo);
        while hi > lo && at(hi - 1).is_some_and(|l| l > ceil) {
            hi -= 1;
        }
        while at(hi).is_some_and(|l| l <= ceil) {
            hi += 1;
        }
        (self.lo, self.hi) = (lo as u8, hi as u8);
        let below_window = 1u32.wrapping_shl(lo as u32).wrapping_sub(1);
        let to_hi = 1u32.wrapping_shl(hi as u32).wrapping_sub(1);
        let all = 1u32.wrapping_shl(n as u32).wrapping_sub(1);
        let above_window = all & !to_hi;
        let mut todo = (to_hi & !below_window)
            | (below_window & !self.settled_above)
            | (above_window & !self.settled_below);
        self.gap = (todo == 0).then(|| {
            let below = lo.checked_sub(1).and_then(at).unwrap_or(i32::MIN);
            (below, at(lo).unwrap_or(i32::MAX))
        });
        let mut fired = None;
        while todo != 0 {
            let i = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            #[cfg(test)]
            {
                self.visits += 1;
            }
            if self.update_line(i, at(i), position_um, up, down, h) {
                fired = Some(i as u8);
            }
        }
        fired
    }

    /// One line's update: fires it (true) when crossed from the side it was armed on, and
    /// re-arms it once the finger is `h` clear of both the line and where it fired.
    #[inline(always)]
    fn update_line(
        &mut self,
        i: usize,
        line: Option<i32>,
        position_um: i32,
        up: i32,
        down: i32,
        h: i32,
    ) -> bool {
        let (Some(line), Some(armed), Some(ahead)) =
            (line, self.armed.get_mut(i), self.ahead_um.get_mut(i))
        else {
            return false;
        };
        let crossed = match *armed {
            Some(Side::Below) => up >= line,
            Some(Side::Above) => down <= line,
            None => false,
        };
        if crossed {
            *armed = None;
            *ahead = position_um - line;
        }
        if position_um < line + (*ahead).min(0) - h {
            *armed = Some(Side::Below);
            *ahead = 0;
        } else if position_um > line + (*ahead).max(0) + h {
            *armed = Some(Side::Above);
            *ahead = 0;
        }
        let bit = 1u32.wrapping_shl(i as u32);
        let settled = *ahead == 0;
        if settled && *armed == Some(Side::Below) {
            self.settled_below |= bit;
        } else {
            self.settled_below &= !bit;
        }
        if settled && *armed == Some(Side::Above) {
            self.settled_above |= bit;
        } else {
            self.settled_above &= !bit;
        }
        crossed
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The visit-every-line update (the code before the window), as the reference.
    fn reference(
        armed: &mut [Option<Side>; MAX_LINES],
        ahead_um: &mut [i32; MAX_LINES],
        lines: &Lines,
        position_um: i32,
        lead_um: i32,
    ) -> Option<u8> {
        let h = lines.hysteresis_um as i32;
        let (up, down) = (position_um + lead_um.max(0), position_um + lead_um.min(0));
        let mut fired = None;
        for (i, ((&line, armed), ahead)) in lines
            .positions_um
            .iter()
            .zip(armed.iter_mut())
            .zip(ahead_um.iter_mut())
            .enumerate()
        {
            let line = line as i32;
            let crossed = match *armed {
                Some(Side::Below) => up >= line,
                Some(Side::Above) => down <= line,
                None => false,
            };
            if crossed {
                *armed = None;
                *ahead = position_um - line;
                fired = Some(i as u8);
            }
            if position_um < line + (*ahead).min(0) - h {
                *armed = Some(Side::Below);
                *ahead = 0;
            } else if position_um > line + (*ahead).max(0) + h {
                *armed = Some(Side::Above);
                *ahead = 0;
            }
        }
        fired
    }

    /// The windowed update fires and re-arms exactly as visiting every line does: random
    /// walks with leads both ways, dither on lines, jumps across several lines (a fault's
    /// recovery), resets, and scenes of 0 to 16 lines with lines closer than the hysteresis.
    #[test]
    fn the_window_changes_nothing() {
        let mut lcg = 0x2545_f491u32;
        let mut rnd = |m: u32| {
            lcg = lcg.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (lcg >> 8) % m.max(1)
        };
        let mut fires = 0;
        for scene in 0..300 {
            let mut l = Lines {
                hysteresis_um: 50 + rnd(1_000),
                ..Lines::default()
            };
            let count = scene % (MAX_LINES + 1);
            let mut at = 0;
            for _ in 0..count {
                at += 1 + rnd(4_000);
                let _ = l.positions_um.push(at);
            }
            let mut t = LineTracker::default();
            let (mut armed, mut ahead) = ([None; MAX_LINES], [0; MAX_LINES]);
            let mut p = rnd(at + 2_000) as i32;
            for step in 0..3_000 {
                p += match rnd(100) {
                    0 => rnd(60_000) as i32 - 30_000,
                    1..=30 => rnd(41) as i32 - 20,
                    _ => rnd(401) as i32 - 150,
                };
                if step % 997 == 0 {
                    t.reset();
                    (armed, ahead) = ([None; MAX_LINES], [0; MAX_LINES]);
                }
                let lead = rnd(4_001) as i32 - 2_000;
                let want = reference(&mut armed, &mut ahead, &l, p, lead);
                assert_eq!(
                    t.update_ahead(&l, p, lead),
                    want,
                    "scene {scene} step {step}"
                );
                assert_eq!((t.armed, t.ahead_um), (armed, ahead));
                fires += want.is_some() as u32;
            }
        }
        assert!(fires > 1_000, "{fires}");
    }

    fn lines() -> Lines {
        let mut l = Lines::default();
        let _ = l.positions_um.push(10_000);
        let _ = l.positions_um.push(20_000);
        l
    }

    /// Only the lines a sample can change are visited (the M4F cost of `update_ahead`, issue
    /// #17): with the finger resting or moving between two lines, clear of both by more than
    /// the hysteresis, none once they have settled; inside one line's hysteresis, that line
    /// alone. Visiting more would change no result, so only this count catches it.
    #[test]
    fn only_the_lines_a_sample_can_change_are_visited() {
        let mut l = lines();
        let _ = l.positions_um.push(31_500);
        let h = l.hysteresis_um as i32;
        let mut t = LineTracker::default();
        for _ in 0..3 {
            assert_eq!(t.update_ahead(&l, 15_000, 0), None);
        }
        t.visits = 0;
        for p in (15_000..16_000).step_by(10) {
            assert_eq!(t.update_ahead(&l, p, 0), None);
        }
        assert_eq!(t.visits, 0, "between the lines");
        // Up to half the hysteresis below the line at 20 mm, and resting there.
        for p in (16_000..20_000 - h / 2).step_by(10) {
            assert_eq!(t.update_ahead(&l, p, 0), None);
        }
        t.visits = 0;
        for _ in 0..10 {
            assert_eq!(t.update_ahead(&l, 20_000 - h / 2, 0), None);
        }
        assert_eq!(t.visits, 10, "the line at 20 mm alone");
        // Back down between the lines: none again once clear.
        for p in (15_000..20_000 - h / 2).rev().step_by(10) {
            assert_eq!(t.update_ahead(&l, p, 0), None);
        }
        t.visits = 0;
        for _ in 0..10 {
            assert_eq!(t.update_ahead(&l, 15_000, 0), None);
        }
        assert_eq!(t.visits, 0, "between the lines, coming back");
    }

    #[test]
    fn fires_once_per_crossing_either_way() {
        let l = lines();
        let mut t = LineTracker::default();
        let mut fires = 0;
        // Sweep up and back at 10 µm per sample.
        for p in (5_000..25_000)
            .step_by(10)
            .chain((5_000..25_000).rev().step_by(10))
        {
            fires += t.update(&l, p).is_some() as u32;
        }
        assert_eq!(fires, 4);
    }

    #[test]
    fn resting_on_a_line_never_refires() {
        let l = lines();
        let mut t = LineTracker::default();
        assert_eq!(t.update(&l, 9_000), None);
        assert_eq!(t.update(&l, 10_000), Some(0));
        let mut fires = 0;
        for i in 0..10_000 {
            // ±150 µm of dither, inside the 200 µm re-arm distance.
            let p = 10_000 + ((i * 37) % 301) - 150;
            fires += t.update(&l, p).is_some() as u32;
        }
        assert_eq!(fires, 0);
    }

    #[test]
    fn bad_lines_rejected() {
        let mut l = lines();
        assert!(l.validate(63_000, 50_000).is_ok());
        l.positions_um[1] = 5_000;
        assert!(matches!(
            l.validate(63_000, 50_000),
            Err(TextureError::BadLines(LineFault::Unsorted { index: 1, .. }))
        ));
        let l = Lines {
            pulse_us: 60_000,
            ..lines()
        };
        assert_eq!(
            l.validate(63_000, 50_000),
            Err(TextureError::BadPulse {
                pulse_us: 60_000,
                max_on_time_us: 50_000
            })
        );
    }

    /// Each rule alone, at its limit and one past it.
    #[test]
    fn validation_limits() {
        let check = |l: Lines| l.validate(63_000, 50_000);
        let at = |positions: &[u32]| {
            let mut l = lines();
            l.positions_um.clear();
            for &p in positions {
                let _ = l.positions_um.push(p);
            }
            check(l)
        };
        assert_eq!(at(&[1, 62_999]), Ok(()));
        let outside = |index, at_um| {
            Err(TextureError::BadLines(LineFault::OutOfRange {
                index,
                at_um,
                length_um: 63_000,
            }))
        };
        assert_eq!(at(&[0, 20_000]), outside(0, 0));
        assert_eq!(at(&[10_000, 63_000]), outside(1, 63_000));
        assert_eq!(
            at(&[10_000, 10_000]),
            Err(TextureError::BadLines(LineFault::Unsorted {
                index: 1,
                at_um: 10_000,
                previous_um: 10_000
            }))
        );
        let pulse = |pulse_us| {
            check(Lines {
                pulse_us,
                ..lines()
            })
        };
        assert_eq!(pulse(50_000), Ok(()));
        let bad_pulse = |pulse_us| {
            Err(TextureError::BadPulse {
                pulse_us,
                max_on_time_us: 50_000,
            })
        };
        assert_eq!(pulse(50_001), bad_pulse(50_001));
        assert_eq!(pulse(0), bad_pulse(0));
        let amp = |amplitude_permille| {
            check(Lines {
                amplitude_permille,
                ..lines()
            })
        };
        assert_eq!(amp(1), Ok(()));
        assert_eq!(amp(1_000), Ok(()));
        let bad_amp = |permille| Err(TextureError::BadLines(LineFault::Amplitude { permille }));
        assert_eq!(amp(0), bad_amp(0));
        assert_eq!(amp(1_001), bad_amp(1_001));
        let hyst = |hysteresis_um| {
            check(Lines {
                hysteresis_um,
                ..lines()
            })
        };
        assert_eq!(hyst(5_000), Ok(()));
        assert_eq!(
            hyst(5_001),
            Err(TextureError::BadLines(LineFault::Rearm { rearm_um: 5_001 }))
        );
        // No lines: nothing else is checked (the defaults of an unused section never refuse).
        let mut none = Lines {
            pulse_us: 0,
            ..lines()
        };
        none.positions_um.clear();
        assert_eq!(check(none), Ok(()));
    }

    /// A line arms once the finger is more than the re-arm distance (200 µm) clear of it, on
    /// either side: from exactly 200 µm away arriving on the line is not a crossing, from
    /// 201 µm it is.
    #[test]
    fn arming_distance_to_the_um() {
        for (from, fires) in [
            (9_800, false),
            (9_799, true),
            (10_200, false),
            (10_201, true),
        ] {
            let mut t = LineTracker::default();
            assert_eq!(t.update(&lines(), from), None);
            assert_eq!(
                t.update(&lines(), 10_000).is_some(),
                fires,
                "from {from} um"
            );
        }
    }

    /// After a reset (a fault, a new scene) the tracker has no side for any line: arriving
    /// beyond a line is not a crossing of it.
    #[test]
    fn reset_forgets_the_side() {
        let l = lines();
        let mut t = LineTracker::default();
        assert_eq!(t.update(&l, 9_000), None);
        t.reset();
        assert_eq!(t.update(&l, 10_500), None);
        // Armed again from the new side: going back down over the line fires it.
        assert_eq!(t.update(&l, 10_000), Some(0));
    }

    /// A triangle fires ahead of its line by the lead, once; it re-arms only when the finger is
    /// the hysteresis clear of both the line and the point where it fired — so a finger still
    /// short of the line after firing (it fired 500 µm early) does not fire it again.
    #[test]
    fn a_lead_fires_ahead_once_and_rearms_clear_of_the_firing_point() {
        let l = lines();
        let mut t = LineTracker::default();
        let mut fired_at = std::vec::Vec::new();
        for p in (8_000..12_000).step_by(10) {
            if t.update_ahead(&l, p, 500).is_some() {
                fired_at.push(p);
            }
        }
        assert_eq!(fired_at, [9_500]);
        // Back down: the line re-arms above (past 10 200) and fires when the finger, moving
        // down with a lead of −500 µm, is 500 µm above it.
        let mut down = std::vec::Vec::new();
        for p in (8_000..=12_000).rev().step_by(10) {
            if t.update_ahead(&l, p, -500).is_some() {
                down.push(p);
            }
        }
        assert_eq!(down, [10_500]);
        // Fired ahead, then the finger turns back before the line: re-armed only once it is
        // 200 µm below where it fired, so wobbling near the firing point fires nothing.
        let mut t = LineTracker::default();
        assert_eq!(t.update_ahead(&l, 9_000, 0), None);
        assert_eq!(t.update_ahead(&l, 9_500, 500), Some(0));
        for p in [9_400, 9_350, 9_450, 9_310] {
            assert_eq!(t.update_ahead(&l, p, 500), None, "{p}");
        }
        assert_eq!(t.update_ahead(&l, 9_290, -100), None);
        assert_eq!(t.update_ahead(&l, 9_600, 500), Some(0));
        // A lead away from the line does not delay or advance anything.
        let mut t = LineTracker::default();
        assert_eq!(t.update_ahead(&l, 9_000, -400), None);
        assert_eq!(t.update_ahead(&l, 9_999, -400), None);
        assert_eq!(t.update_ahead(&l, 10_000, -400), Some(0));
    }

    /// The lead a compiled triangle fires with: velocity × (half the pulse + half a sample
    /// period), to the µm — 10 ms pulses sampled every 100 µs lead by 5.05 ms of travel: 1 010 µm
    /// at 200 mm/s, 101 µm at 20 mm/s, the other way when moving down — and none for rectangles
    /// or without a velocity.
    #[test]
    fn a_triangle_leads_by_half_the_pulse_and_half_a_sample() {
        let timer = crate::burst::TEST_TIMER;
        let limits = SafetyLimits::default();
        let fire_from = |envelope, v: Option<i32>, up: bool| -> i32 {
            let mut l = lines();
            l.envelope = envelope;
            let c = LinePulses::compile(&l, &timer, &limits, 100_000, 100)
                .unwrap()
                .unwrap();
            // Approach line 0 (10 mm) one µm at a time; where does it fire?
            let mut t = LineTracker::default();
            let path: std::vec::Vec<i32> = if up {
                (7_000..=10_000).collect()
            } else {
                (10_000..=13_000).rev().collect()
            };
            for p in path {
                if let LineStep::Fire { line: 0, .. } = t.step(&c, p, v, 0) {
                    return p;
                }
            }
            panic!("never fired");
        };
        assert_eq!(
            fire_from(Envelope::Triangular, Some(200_000), true),
            10_000 - 1_010
        );
        assert_eq!(
            fire_from(Envelope::Triangular, Some(20_000), true),
            10_000 - 101
        );
        assert_eq!(
            fire_from(Envelope::Triangular, Some(-200_000), false),
            10_000 + 1_010
        );
        assert_eq!(fire_from(Envelope::Triangular, None, true), 10_000);
        assert_eq!(
            fire_from(Envelope::Rectangular, Some(200_000), true),
            10_000
        );
        // A glitch of 10 m/s leads by the 2 mm cap, not 50 mm.
        assert_eq!(
            fire_from(Envelope::Triangular, Some(10_000_000), true),
            10_000 - 2_000
        );
    }
}
