//! 4-wire touch overlay model (issue #36): the plates as resistors, each terminal's node
//! settling exponentially from the voltage the previous phase left on it, ADC noise and
//! rounding, and the contact's resistance from the finger's force — the codes each phase of
//! `saw_core::touch::plates` would read, at the times its schedule reads them.
//!
//! Per phase: the driven terminals take their drive at once (the driver's 50 Ω into the 1 nF
//! filter is 50 ns); every other terminal relaxes toward its DC voltage with one time constant,
//! τ = R·C, C = 2·C_filter + C_interlayer and R the source behind it — for a sensed plate in
//! contact, the driven plate's Thevenin resistance at the touch point, the contact and the
//! sensed plate (the core's bound with the finger's own figures); for a plate not in contact,
//! the plate and the driver that holds it (Z phases), or no path at all (position phases: the
//! node keeps its charge). Conversions read the sensed node at the schedule's trigger and every
//! conversion time after it, each rounded to 12 bits with Gaussian noise; the phase's code is
//! their sum scaled to 16 conversions, the core's scale.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use saw_core::sample::CONVERSION_FULL_SCALE;
use saw_core::touch::frame::Frame;
use saw_core::touch::plates::{
    AdcTiming, Phase, PinRole, PlateRc, Schedule, Terminal, SEQUENCE, TERMINALS,
};

/// The overlay: its plates and the contact's law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Overlay {
    /// Plate resistances, drivers and capacitances (`r_touch_max_ohm` is not used: the finger
    /// sets the contact).
    pub rc: PlateRc,
    /// Contact resistance × force, Ω·N: R_touch = this / F. 300 Ω·N puts the core's default
    /// touch-down (1.5 kΩ) at 0.2 N and its lift-off (3 kΩ) at 0.1 N.
    pub contact_ohm_n: f64,
    /// Force below which the spacer dots keep the plates apart, N.
    pub actuation_force_n: f64,
    /// White noise per conversion, 12-bit LSB RMS (the 1D model's default is 2).
    pub noise_lsb: f64,
}

impl Default for Overlay {
    /// The core's default plates; contact 300 Ω·N; actuation at 0.05 N (5 gf, the light end of
    /// 4-wire panels' actuation forces — a figure to measure); 2 LSB of noise.
    fn default() -> Self {
        Self {
            rc: PlateRc::DEFAULT,
            contact_ohm_n: 300.0,
            actuation_force_n: 0.05,
            noise_lsb: 2.0,
        }
    }
}

/// A finger on the overlay.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Finger {
    /// Position along X, 0 at X− to 1 at X+.
    pub x: f64,
    /// Position along Y, 0 at Y− to 1 at Y+.
    pub y: f64,
    /// Press force, N.
    pub force_n: f64,
}

/// The model's state: the voltage on each terminal's node (fraction of VDD) and the noise.
#[derive(Clone, Debug)]
pub struct TouchModel {
    overlay: Overlay,
    /// X+, X−, Y+, Y−, as [`TERMINALS`].
    node_v: [f64; 4],
    rng: ChaCha8Rng,
    noise: Option<Normal<f64>>,
}

fn index(t: Terminal) -> usize {
    match t {
        Terminal::XPlus => 0,
        Terminal::XMinus => 1,
        Terminal::YPlus => 2,
        Terminal::YMinus => 3,
    }
}

impl TouchModel {
    /// A model with every node at 0 V.
    pub fn new(overlay: Overlay, seed: u64) -> Self {
        let noise = (overlay.noise_lsb > 0.0)
            .then(|| Normal::new(0.0, overlay.noise_lsb).ok())
            .flatten();
        Self {
            overlay,
            node_v: [0.0; 4],
            rng: ChaCha8Rng::seed_from_u64(seed),
            noise,
        }
    }

    /// The voltage on terminal `t`'s node now, fraction of VDD.
    pub fn node_v(&self, t: Terminal) -> f64 {
        self.node_v[index(t)]
    }

    /// The contact's resistance under `finger`, Ω; `None` without contact.
    pub fn contact_ohm(&self, finger: Option<&Finger>) -> Option<f64> {
        let f = finger?;
        (f.force_n >= self.overlay.actuation_force_n && f.force_n > 0.0)
            .then(|| self.overlay.contact_ohm_n / f.force_n)
    }

    /// Each terminal's DC voltage in `phase` and the time constant it approaches it with, s
    /// (`None`: no path, the node keeps its charge). Driven terminals: τ = 0.
    pub fn targets(&self, phase: Phase, finger: Option<&Finger>) -> [(f64, Option<f64>); 4] {
        let rc = &self.overlay.rc;
        let (rx, ry) = (rc.r_x_plate_ohm as f64, rc.r_y_plate_ohm as f64);
        let rd = rc.r_drive_ohm as f64;
        let c_f = rc.c_node_pf() as f64 * 1e-12;
        let contact = self.contact_ohm(finger);
        let (x, y) = finger.map_or((0.5, 0.5), |f| (f.x, f.y));
        let mut out = [(0.0, None); 4];
        match phase {
            Phase::X | Phase::Y => {
                // The driven plate (rp) as a divider between two drivers; u is the touch point.
                let (rp, rs, u, hi, lo, s1, s2) = if phase == Phase::X {
                    (
                        rx,
                        ry,
                        x,
                        Terminal::XPlus,
                        Terminal::XMinus,
                        Terminal::YPlus,
                        Terminal::YMinus,
                    )
                } else {
                    (
                        ry,
                        rx,
                        y,
                        Terminal::YPlus,
                        Terminal::YMinus,
                        Terminal::XPlus,
                        Terminal::XMinus,
                    )
                };
                let total = rp + 2.0 * rd;
                out[index(hi)] = ((rd + rp) / total, Some(0.0));
                out[index(lo)] = (rd / total, Some(0.0));
                let v_touch = (rd + rp * u) / total;
                let r_th = (rd + rp * u) * (rd + rp * (1.0 - u)) / total;
                for s in [s1, s2] {
                    out[index(s)] = match contact {
                        Some(rt) => (v_touch, Some((r_th + rt + rs) * c_f)),
                        None => (self.node_v(s), None),
                    };
                }
            }
            Phase::Z1 | Phase::Z2 => {
                // Y+ high, X− low; the current path Y+ → Y plate → contact → X plate → X−.
                match contact {
                    Some(rt) => {
                        let total = 2.0 * rd + ry * (1.0 - y) + rt + rx * x;
                        let i = 1.0 / total;
                        let tau = Some((2.0 * rd + rx + ry + rt) * c_f);
                        out[index(Terminal::YPlus)] = (1.0 - i * rd, Some(0.0));
                        out[index(Terminal::XMinus)] = (i * rd, Some(0.0));
                        out[index(Terminal::XPlus)] = (i * (rd + rx * x), tau);
                        out[index(Terminal::YMinus)] = (i * (rd + rx * x + rt), tau);
                    }
                    None => {
                        out[index(Terminal::YPlus)] = (1.0, Some(0.0));
                        out[index(Terminal::XMinus)] = (0.0, Some(0.0));
                        // X+ reaches X−'s 0 V through the X plate, Y− Y+'s VDD through Y.
                        out[index(Terminal::XPlus)] = (0.0, Some((rd + rx) * c_f));
                        out[index(Terminal::YMinus)] = (1.0, Some((rd + ry) * c_f));
                    }
                }
            }
        }
        out
    }

    /// Lets every node relax toward `targets` for `dt_s` seconds.
    fn relax(&mut self, targets: &[(f64, Option<f64>); 4], dt_s: f64) {
        for (v, (v_ss, tau)) in self.node_v.iter_mut().zip(targets) {
            match tau {
                Some(t) if *t <= 0.0 => *v = *v_ss,
                Some(t) => *v = v_ss + (*v - v_ss) * (-dt_s / t).exp(),
                None => {}
            }
        }
    }

    /// One conversion of `t`'s node: 12 bits, rounded, with noise, clamped.
    fn convert(&mut self, t: Terminal) -> u32 {
        let fs = CONVERSION_FULL_SCALE as f64;
        let n = match &self.noise {
            Some(d) => d.sample(&mut self.rng),
            None => 0.0,
        };
        (self.node_v(t) * fs + n).round().clamp(0.0, fs - 1.0) as u32
    }

    /// Runs `phase`: switches the pins, waits `settle_ns`, then converts the sensed node
    /// `conversions` times `conversion_ns` apart (the nodes keep relaxing between them), and
    /// returns the sum scaled to 16 conversions (rounded).
    pub fn read_phase(
        &mut self,
        phase: Phase,
        finger: Option<&Finger>,
        settle_ns: f64,
        conversions: u32,
        conversion_ns: f64,
    ) -> u16 {
        let targets = self.targets(phase, finger);
        // Driven pins first (τ = 0), then the settling.
        self.relax(&targets, 0.0);
        self.relax(&targets, settle_ns * 1e-9);
        let sensed = phase.sensed();
        let mut sum = 0u64;
        for _ in 0..conversions.max(1) {
            sum += self.convert(sensed) as u64;
            self.relax(&targets, conversion_ns * 1e-9);
        }
        let scaled = (sum * 16 + conversions.max(1) as u64 / 2) / conversions.max(1) as u64;
        scaled.min(u16::MAX as u64) as u16
    }

    /// One frame on `schedule`'s designed times (the finger held for the frame), stamped
    /// `t_us` at its end.
    pub fn frame(
        &mut self,
        schedule: &Schedule,
        adc: &AdcTiming,
        finger: Option<&Finger>,
        t_us: u32,
    ) -> Frame {
        let mut codes = [0u16; 4];
        for (slot, code) in schedule.slots.iter().zip(codes.iter_mut()) {
            let n = if slot.phase.is_position() {
                adc.conversions_position
            } else {
                adc.conversions_pressure
            };
            // The model has no hold capacitor (the board model's has: its charge sharing is
            // what the discard is for), so a discarded conversion is only time: the summed ones
            // start `discard` conversions after the settling.
            let discard_ns = adc.discard as f64 * adc.conversion_ns as f64;
            *code = self.read_phase(
                slot.phase,
                finger,
                slot.settle_ns as f64 + discard_ns,
                n,
                adc.conversion_ns as f64,
            );
        }
        debug_assert_eq!(
            SEQUENCE.map(|p| p as u8),
            schedule.slots.map(|s| s.phase as u8)
        );
        let [x_code, y_code, z1_code, z2_code] = codes;
        Frame {
            x_code,
            y_code,
            z1_code,
            z2_code,
            t_us,
        }
    }
}

/// Which terminals `phase` drives (for checking a model against the core's pin table).
pub fn driven(phase: Phase) -> impl Iterator<Item = Terminal> {
    TERMINALS
        .into_iter()
        .filter(move |t| matches!(phase.role(*t), PinRole::High | PinRole::Low))
}

#[cfg(test)]
mod tests {
    use super::*;
    use saw_core::touch::calibration::{Affine, CalPoint};
    use saw_core::touch::fault::RailBands;
    use saw_core::touch::frame::{Reading, TouchSensor};
    use saw_core::touch::pressure::{touch_resistance_ohm, PressureConfig};

    fn quiet(rc: PlateRc) -> TouchModel {
        TouchModel::new(
            Overlay {
                rc,
                noise_lsb: 0.0,
                ..Overlay::default()
            },
            1,
        )
    }

    const F446: AdcTiming = AdcTiming {
        conversion_ns: 3_023,
        conversions_position: 16,
        conversions_pressure: 16,
        discard: 0,
    };

    /// Ideal drivers (0 Ω) so the X phase's DC voltage is x itself: x = ¼ reads
    /// ¼ · 65 536 = 16 384 after a long wait (each conversion rounds 1 024.0 exactly).
    #[test]
    fn a_settled_position_reads_the_touch_point() {
        let rc = PlateRc {
            r_drive_ohm: 0,
            ..PlateRc::DEFAULT
        };
        let mut m = quiet(rc);
        let f = Finger {
            x: 0.25,
            y: 0.6,
            force_n: 1.0,
        };
        assert_eq!(m.read_phase(Phase::X, Some(&f), 1e6, 16, 3_023.0), 16_384);
        // Y: 0.6 · 4096 = 2 457.6 → 2 458 a conversion, 39 328 in 16.
        assert_eq!(m.read_phase(Phase::Y, Some(&f), 1e6, 16, 3_023.0), 39_328);
    }

    /// The X phase after a frame with no finger: Z2 left Y+ driven at VDD, and the finger at
    /// x = ½ (0.2 N: 1.5 kΩ, the touch-down threshold) pulls it to ½ — a step of half the
    /// supply, 2 048 LSB. Ideal drivers: τ = (600/4 + 1 500 + 400) Ω · 2 454 pF = 5.0307 µs.
    /// - Read one conversion at the derived settling time (the core's `settle_ns`, τ·ln 2^13):
    ///   the error is 2 048 · 2^−13 = 0.25 LSB, so the conversion rounds to 2 048 exactly.
    /// - Read it at half that time: the error is 2 048 · e^(−ln(2^13)/2) = 2 048 · 2^−6.5 =
    ///   22.63 LSB, so 2 070 or 2 071 a conversion (22.6 LSB high: the node comes down from
    ///   VDD), 16 × that on the 16-conversion scale.
    #[test]
    fn a_phase_read_too_early_is_off_by_the_derived_settling_error() {
        let rc = PlateRc {
            r_drive_ohm: 0,
            ..PlateRc::DEFAULT
        };
        let settle_ns = rc.settle_ns(Phase::X) as f64;
        assert_eq!(settle_ns, 45_332.0);
        let finger = Finger {
            x: 0.5,
            y: 0.5,
            force_n: 0.2,
        };
        let after_lifted_frame = |read_at_ns: f64| {
            let mut m = quiet(rc);
            let s = Schedule::new(&rc, &F446).unwrap();
            m.frame(&s, &F446, None, 0);
            assert_eq!(m.node_v(Terminal::YPlus), 1.0, "Z2 drove Y+ to VDD");
            // One conversion, scaled to the 16-conversion code.
            m.read_phase(Phase::X, Some(&finger), read_at_ns, 1, 3_023.0)
        };
        assert_eq!(after_lifted_frame(settle_ns), 2_048 * 16);
        let early = after_lifted_frame(settle_ns / 2.0) as f64 / 16.0;
        assert!((2_070.0..=2_071.0).contains(&early), "{early}");
        // On the full 16-conversion reading the later conversions have settled more (each
        // 3 023 ns is e^(−3023/5030.7) = 0.548 of the error before): 22.63 · (1 − 0.548^16) /
        // (1 − 0.548) = 50.1 codes over the settled 32 768.
        let mut m = quiet(rc);
        let s = Schedule::new(&rc, &F446).unwrap();
        m.frame(&s, &F446, None, 0);
        let code = m.read_phase(Phase::X, Some(&finger), settle_ns / 2.0, 16, 3_023.0) as f64;
        assert!((code - 32_768.0 - 50.1).abs() <= 8.0, "{code}");
    }

    /// For every finger the core's settle bound covers (contact up to its 1.5 kΩ, anywhere on
    /// the plate, the default 50 Ω drivers and caps), every phase read at the schedule's
    /// trigger is within ½ LSB of its settled value, whatever the previous phase left.
    #[test]
    fn the_schedule_settles_every_finger_within_half_an_lsb() {
        let rc = PlateRc::DEFAULT;
        let s = Schedule::new(&rc, &F446).unwrap();
        for &force_n in &[0.2, 0.5, 2.0] {
            for i in 0..=10 {
                for j in 0..=10 {
                    let f = Finger {
                        x: i as f64 / 10.0,
                        y: j as f64 / 10.0,
                        force_n,
                    };
                    let mut m = quiet(rc);
                    m.frame(&s, &F446, None, 0);
                    for slot in s.slots {
                        let before = m.clone();
                        let targets = m.targets(slot.phase, Some(&f));
                        let v_ss = targets[index(slot.phase.sensed())].0;
                        let mut probe = before;
                        probe.relax(&targets, 0.0);
                        probe.relax(&targets, slot.settle_ns as f64 * 1e-9);
                        let err_lsb = (probe.node_v(slot.phase.sensed()) - v_ss).abs() * 4096.0;
                        assert!(err_lsb <= 0.5, "{f:?} {:?}: {err_lsb} LSB", slot.phase);
                        m.read_phase(slot.phase, Some(&f), slot.settle_ns as f64, 16, 3_023.0);
                    }
                }
            }
        }
    }

    /// The model's Z codes give back the contact through the core's formula with R_x + 2 R_drive
    /// (700 Ω), within 1 %; with the bare plate (600 Ω) they read it low by 600/700.
    #[test]
    fn pressure_from_the_model_through_the_core_formula() {
        let mut m = quiet(PlateRc::DEFAULT);
        let s = Schedule::new(&PlateRc::DEFAULT, &F446).unwrap();
        for (force_n, r_ohm) in [(0.5, 600.0), (0.2, 1_500.0), (1.0, 300.0)] {
            for (x, y) in [(0.3, 0.7), (0.8, 0.2)] {
                let f = Finger { x, y, force_n };
                m.frame(&s, &F446, Some(&f), 0);
                let fr = m.frame(&s, &F446, Some(&f), 0);
                let r = touch_resistance_ohm(700, fr.x_code, fr.z1_code, fr.z2_code, 655).unwrap()
                    as f64;
                assert!(
                    (r / r_ohm - 1.0).abs() < 0.01,
                    "{force_n} N at {x},{y}: {r} Ω"
                );
                let bare = touch_resistance_ohm(600, fr.x_code, fr.z1_code, fr.z2_code, 655)
                    .unwrap() as f64;
                assert!(
                    (bare / (r_ohm * 600.0 / 700.0) - 1.0).abs() < 0.01,
                    "{bare}"
                );
            }
        }
    }

    /// The model drives exactly the terminals the core's pin table drives, with the same
    /// levels (driven nodes take τ = 0). A driven end sits one driver drop from its rail: on
    /// the 400 Ω Y plate with 50 Ω drivers, 50/500 = 10 % (so 0.9 and 0.1), less on X.
    #[test]
    fn the_model_follows_the_core_pin_table() {
        let m = quiet(PlateRc::DEFAULT);
        let f = Finger {
            x: 0.4,
            y: 0.4,
            force_n: 1.0,
        };
        for phase in SEQUENCE {
            let t = m.targets(phase, Some(&f));
            for term in TERMINALS {
                let (v, tau) = t[index(term)];
                match phase.role(term) {
                    PinRole::High => {
                        assert!(tau == Some(0.0) && v >= 0.9 - 1e-12, "{phase:?} {term:?}")
                    }
                    PinRole::Low => {
                        assert!(tau == Some(0.0) && v <= 0.1 + 1e-12, "{phase:?} {term:?}")
                    }
                    _ => assert!(tau != Some(0.0), "{phase:?} {term:?}"),
                }
            }
            assert_eq!(driven(phase).count(), 2);
        }
    }

    /// Must-show of issue #36: lift-off turns the carrier off within one sample, with the
    /// plates switching at their designed times. Frames of the model on the F446 schedule go
    /// through the core's `TouchSensor`; the finger lifts between two frames, and the first
    /// frame after reads `Lifted` (carrier off, no fault). Touch-down, by contrast, waits the
    /// recovery run: 16 frames. With noise (2 LSB), over 20 lifts at random points. On each
    /// board's 2D acquisition (`sim2d::adc_timing`: 4 pressure conversions, one discarded
    /// after each switch): the Z pair's precision still gives no false lift-off or landing.
    #[test]
    fn lift_off_reads_lifted_on_the_next_frame() {
        for b in saw_boards::ALL {
            lift_off_on(crate::sim2d::adc_timing(b));
        }
    }

    fn lift_off_on(adc: AdcTiming) {
        let rc = PlateRc::DEFAULT;
        let s = Schedule::new(&rc, &adc).unwrap();
        let frame_us = (s.frame_ns() / 1_000) as u32;
        // Calibrate on the model itself: three targets on a 95 × 54 mm screen.
        let mut m = TouchModel::new(Overlay::default(), 7);
        let touch = |m: &mut TouchModel, x: f64, y: f64| {
            let f = Finger { x, y, force_n: 1.0 };
            m.frame(&s, &adc, Some(&f), 0);
            m.frame(&s, &adc, Some(&f), 0)
        };
        let pts = [
            (0.1, 0.1, 9_500, 5_400),
            (0.9, 0.5, 85_500, 27_000),
            (0.5, 0.9, 47_500, 48_600),
        ];
        let cal = pts.map(|(x, y, x_um, y_um)| {
            let fr = touch(&mut m, x, y);
            CalPoint {
                x_code: fr.x_code,
                y_code: fr.y_code,
                x_um,
                y_um,
            }
        });
        let map = Affine::from_points(cal, &RailBands::default()).unwrap();
        let mut sensor =
            TouchSensor::new(PressureConfig::DEFAULT, RailBands::default(), map).unwrap();
        let mut t_us = 0u32;
        for k in 0..20 {
            let f = Finger {
                x: 0.1 + 0.04 * k as f64,
                y: 0.85 - 0.035 * k as f64,
                force_n: 0.6,
            };
            let mut downs = 0;
            for i in 0..30 {
                t_us = t_us.wrapping_add(frame_us);
                let r = sensor.on_frame(&m.frame(&s, &adc, Some(&f), t_us));
                match r {
                    Reading::Down { x_um, y_um, .. } => {
                        downs += 1;
                        assert!(i >= 15, "down after {i} frames");
                        // The targets put x = 0.1, 0.5, 0.9 at 9.5, 47.5, 85.5 mm: 95 mm per unit
                        // of x, 54 mm per unit of y. Within 0.2 mm (noise: 2 LSB a conversion,
                        // about 2 µm a code).
                        assert!((x_um as f64 - f.x * 95_000.0).abs() < 200.0, "{x_um}");
                        assert!((y_um as f64 - f.y * 54_000.0).abs() < 200.0, "{y_um}");
                    }
                    Reading::Landing { .. } => assert!(i < 15, "landing at {i}"),
                    other => panic!("{other:?} at {i}"),
                }
            }
            assert_eq!(downs, 15);
            t_us = t_us.wrapping_add(frame_us);
            assert_eq!(
                sensor.on_frame(&m.frame(&s, &adc, None, t_us)),
                Reading::Lifted,
                "lift {k}"
            );
        }
    }
}
