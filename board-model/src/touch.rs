//! The 4-wire resistive overlay on the 2D image's four pins (issue #36): PC2 = X+, PC3 = X−,
//! PB0 = Y+, PB1 = Y− on both boards (`saw_boards::touch`), each a GPIO the firmware drives high
//! or low (MODER 01, the level from ODR) or leaves in analog mode (MODER 11: floating, the
//! Schmitt trigger off, the ADC switch connects it; RM0390 §7.3.12, RM0440 §9.3.12), and each an
//! ADC1 input.
//!
//! The analog side is host-sim's overlay model (`host_sim::touch::TouchModel::targets`: each
//! terminal's DC voltage and time constant for a drive pattern, from the plate and driver
//! resistances, the contact the finger's force makes and the node capacitance), run in
//! continuous virtual time: every GPIO write that changes the drive relaxes the four nodes to
//! that instant under the drive before it, and every conversion reads its node at its own
//! sampling instant (the ADC models call `convert` at the end of the sampling phase), so a
//! conversion started before the node settled reads the step's remainder (the RC's
//! e^(−t/τ)). A node with no path (a floating plate without contact) keeps its charge.
//!
//! Drive patterns the overlay method uses: X (X+ high, X− low), Y (Y+ high, Y− low), Z (Y+
//! high, X− low; Z1 and Z2 differ only in the channel). Any other pattern (a switch's
//! intermediate steps: one pin released or driven before the others) has its driven pins take
//! their level and the others keep their charge; one that drives both plates other than as Z
//! (current across the contact no phase asks for) is also recorded in `Trace::odd`.

use crate::machine::PinMode;
use crate::periph::{seconds, Time};
use host_sim::touch::{Finger, Overlay, TouchModel};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use saw_core::touch::plates::{Phase, Terminal};
use std::rc::Rc;

/// Where the finger is at a virtual time (s since reset): None = lifted.
pub type FingerAt = Rc<dyn Fn(f64) -> Option<Finger>>;

/// A terminal's drive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drive {
    High,
    Low,
    Float,
}

/// One change of the four terminals' drive (X+, X−, Y+, Y−).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DriveChange {
    pub at: Time,
    pub drive: [Drive; 4],
}

/// One conversion of an overlay channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conversion {
    /// End of its sampling phase (where the ADC models hold the input).
    pub at: Time,
    pub terminal: Terminal,
    /// The node's voltage then, fraction of VDD, before noise.
    pub v: f64,
    pub code: u16,
}

/// What the overlay saw.
#[derive(Clone, Debug, Default)]
pub struct Trace {
    pub drives: Vec<DriveChange>,
    pub conversions: Vec<Conversion>,
    /// Drive patterns outside the method's three (with their times).
    pub odd: Vec<DriveChange>,
}

/// The overlay wired to a board.
pub struct Panel {
    model: TouchModel,
    finger: FingerAt,
    /// X+, X−, Y+, Y− node voltages, fraction of VDD.
    v: [f64; 4],
    drive: [Drive; 4],
    at: Time,
    /// ADC channel → terminal.
    channels: [(u8, Terminal); 4],
    rng: ChaCha8Rng,
    noise: Option<Normal<f64>>,
    pub trace: Trace,
}

fn index(t: Terminal) -> usize {
    match t {
        Terminal::XPlus => 0,
        Terminal::XMinus => 1,
        Terminal::YPlus => 2,
        Terminal::YMinus => 3,
    }
}

impl Panel {
    /// The overlay on `board`'s pins, the finger where `finger` says.
    pub fn new(
        board: &saw_boards::BoardDef,
        overlay: Overlay,
        seed: u64,
        finger: FingerAt,
    ) -> Self {
        let p = saw_boards::touch::touch_pins(board).expect("the board has overlay pins");
        Self {
            model: TouchModel::new(overlay, seed),
            finger,
            v: [0.0; 4],
            drive: [Drive::Float; 4],
            at: 0,
            channels: [
                (p.x_plus.channel, Terminal::XPlus),
                (p.x_minus.channel, Terminal::XMinus),
                (p.y_plus.channel, Terminal::YPlus),
                (p.y_minus.channel, Terminal::YMinus),
            ],
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5A5A),
            noise: (overlay.noise_lsb > 0.0)
                .then(|| Normal::new(0.0, overlay.noise_lsb).ok())
                .flatten(),
            trace: Trace::default(),
        }
    }

    /// The overlay's pins on `board`: (port letter, pin) for X+, X−, Y+, Y−.
    pub fn pins(board: &saw_boards::BoardDef) -> [(char, u8); 4] {
        let p = saw_boards::touch::touch_pins(board).expect("the board has overlay pins");
        [p.x_plus, p.x_minus, p.y_plus, p.y_minus].map(|t| (t.pin.port, t.pin.pin))
    }

    /// The method's phase for this drive (Z for Z1 and Z2), or None.
    fn phase(d: &[Drive; 4]) -> Option<Phase> {
        use Drive::*;
        match d {
            [High, Low, Float, Float] => Some(Phase::X),
            [Float, Float, High, Low] => Some(Phase::Y),
            [Float, Low, High, Float] => Some(Phase::Z1),
            _ => None,
        }
    }

    /// Lets the nodes relax from `self.at` to `t` under the drive in force, the finger where it
    /// is at `t` (it moves little within one phase).
    fn relax_to(&mut self, t: Time) {
        if t <= self.at {
            return;
        }
        let dt = seconds(t - self.at);
        let finger = (self.finger)(seconds(t));
        match Self::phase(&self.drive) {
            Some(phase) => {
                let targets = self.model.targets(phase, finger.as_ref());
                for (v, (v_ss, tau)) in self.v.iter_mut().zip(targets) {
                    match tau {
                        Some(tau) if tau <= 0.0 => *v = v_ss,
                        Some(tau) => *v = v_ss + (*v - v_ss) * (-dt / tau).exp(),
                        None => {}
                    }
                }
            }
            None => {
                for (v, d) in self.v.iter_mut().zip(self.drive) {
                    match d {
                        Drive::High => *v = 1.0,
                        Drive::Low => *v = 0.0,
                        Drive::Float => {}
                    }
                }
            }
        }
        self.at = t;
    }

    /// The pins' modes changed (a GPIO write): X+, X−, Y+, Y−.
    pub fn set_pins(&mut self, t: Time, modes: [PinMode; 4]) {
        let drive = modes.map(|m| match m {
            PinMode::Output { high: true } => Drive::High,
            PinMode::Output { high: false } => Drive::Low,
            // An alternate function on these pins would be a firmware defect; floating here.
            PinMode::Input | PinMode::Analog | PinMode::Alternate(_) => Drive::Float,
        });
        if drive == self.drive {
            return;
        }
        self.relax_to(t);
        self.drive = drive;
        let change = DriveChange { at: t, drive };
        let x_driven = drive[0] != Drive::Float || drive[1] != Drive::Float;
        let y_driven = drive[2] != Drive::Float || drive[3] != Drive::Float;
        if x_driven && y_driven && Self::phase(&drive) != Some(Phase::Z1) {
            self.trace.odd.push(change);
        }
        self.trace.drives.push(change);
        // Driven pins take their level at once (50 Ω into 2.5 nF: 0.1 µs).
        self.relax_to(t + 1);
    }

    /// The ADC converts channel `ch` with its sampling ending at `t`: None if it is not an
    /// overlay channel.
    pub fn convert(&mut self, t: Time, ch: u8) -> Option<u16> {
        let terminal = self.channels.iter().find(|(c, _)| *c == ch)?.1;
        self.relax_to(t);
        let v = self.v[index(terminal)];
        let n = match &self.noise {
            Some(d) => d.sample(&mut self.rng),
            None => 0.0,
        };
        let code = (v * 4096.0 + n).round().clamp(0.0, 4095.0) as u16;
        self.trace.conversions.push(Conversion {
            at: t,
            terminal,
            v,
            code,
        });
        Some(code)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periph::TICKS_PER_S;

    fn panel(f: Option<Finger>) -> Panel {
        let overlay = Overlay {
            noise_lsb: 0.0,
            ..Overlay::default()
        };
        Panel::new(&saw_boards::NUCLEO_F446RE, overlay, 1, Rc::new(move |_| f))
    }

    const US: Time = TICKS_PER_S / 1_000_000;
    const HI: PinMode = PinMode::Output { high: true };
    const LO: PinMode = PinMode::Output { high: false };
    const AN: PinMode = PinMode::Analog;

    /// X drive, finger at x = 0.25 pressed at 1 N (300 Ω): settled, Y+ reads the X plate's
    /// divider (50 + 600·0.25) / 700 = 0.2857 of VDD, 1170 codes; worked by hand.
    #[test]
    fn x_phase_settles_to_the_divider() {
        let mut p = panel(Some(Finger {
            x: 0.25,
            y: 0.6,
            force_n: 1.0,
        }));
        p.set_pins(0, [HI, LO, AN, AN]);
        // F446 channel 8 = Y+.
        let code = p.convert(200 * US, 8).unwrap();
        assert_eq!(code, (4096.0_f64 * 200.0 / 700.0).round() as u16);
    }

    /// An early conversion reads wrong: from Y+ at 0 V (nothing before), τ = (R_th + 300 + 400)
    /// · 2.454 nF; at one τ the node is 1 − 1/e of the way (63.2 %).
    #[test]
    fn a_conversion_one_time_constant_in_reads_the_rc_step() {
        let f = Finger {
            x: 0.25,
            y: 0.6,
            force_n: 1.0,
        };
        let mut p = panel(Some(f));
        p.set_pins(0, [HI, LO, AN, AN]);
        let r_th = (50.0 + 150.0) * (50.0 + 450.0) / 700.0;
        let tau_s = (r_th + 300.0 + 400.0) * 2_454e-12;
        let t = (tau_s * TICKS_PER_S as f64).round() as Time;
        let code = p.convert(t, 8).unwrap() as f64;
        let settled = 4096.0 * 200.0 / 700.0;
        assert!(
            (code - settled * (1.0 - (-1.0f64).exp())).abs() <= 1.0,
            "{code}"
        );
    }

    /// Floating without contact: the node keeps its charge through a phase change.
    #[test]
    fn a_floating_plate_without_contact_keeps_its_charge() {
        let mut p = panel(None);
        // Z drive, no contact: Y− (channel 9) goes to VDD through the Y plate.
        p.set_pins(0, [AN, LO, HI, AN]);
        assert_eq!(p.convert(100 * US, 9), Some(4095));
        // X drive: Y− has no path; it holds VDD.
        p.set_pins(100 * US, [HI, LO, AN, AN]);
        assert_eq!(p.convert(200 * US, 9), Some(4095));
        assert!(p.trace.odd.is_empty());
        assert_eq!(p.trace.drives.len(), 2);
    }
}
