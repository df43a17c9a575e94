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
//! **The ADC's hold capacitor** (the datasheets' ADC input model: the pin, the sampling switch
//! R_ADC and the sample-and-hold capacitor C_ADC; DS10693 / DS12288 "ADC characteristics",
//! `saw_boards::AdcDef::{switch_ohm, hold_ff}`: 6 kΩ / 7 pF F446, 11.5 kΩ / 5 pF G474): C_ADC
//! keeps the voltage of the last conversion, whatever channel it was. When a sampling phase
//! starts (one sampling time, the board's plan, before the conversion's hold) the switch
//! connects it to the node, and the two share their charge: V = (C_node·V_node +
//! C_ADC·V_hold) / (C_node + C_ADC). R_ADC·C_ADC (42 / 58 ns) is far inside the sampling time,
//! so the sharing is taken as instant; the node then recovers through its own path for the
//! rest of the sampling (C_ADC's 0.3 % on the node's τ left out), and C_ADC holds the end
//! value. So the first conversion after a channel switch reads the node dipped toward the
//! previous channel's voltage by up to C_ADC / C_node of the step (7 / 2 461 of a full scale
//! step: 11.6 LSB on the F446), less what the node recovers within the sampling time, and the
//! dip decays into the next conversions with the node's τ.
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
    /// The node's voltage then, fraction of VDD, before noise (the hold capacitor's charge
    /// sharing included).
    pub v: f64,
    /// The hold capacitor's share in `v`, fraction of VDD: `v` less what the node would read
    /// without the sampling switch.
    pub shared: f64,
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
    /// C_ADC's voltage (the last conversion's), fraction of VDD.
    hold_v: f64,
    /// C_ADC and the node's capacitance, F.
    c_hold_f: f64,
    c_node_f: f64,
    /// One sampling phase, ticks (the board's plan: the firmware converts every overlay
    /// channel at it).
    sampling: Time,
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
            hold_v: 0.0,
            c_hold_f: board.adc.hold_ff as f64 * 1e-15,
            c_node_f: overlay.rc.c_node_pf() as f64 * 1e-12,
            sampling: sampling_ticks(board),
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
    /// overlay channel. The sampling phase began one sampling time earlier: the hold
    /// capacitor shares its charge with the node then (module doc).
    pub fn convert(&mut self, t: Time, ch: u8) -> Option<u16> {
        let terminal = self.channels.iter().find(|(c, _)| *c == ch)?.1;
        let i = index(terminal);
        self.relax_to(t.saturating_sub(self.sampling));
        let before = self.v[i];
        let (cn, ch_f) = (self.c_node_f, self.c_hold_f);
        let dip = (cn * before + ch_f * self.hold_v) / (cn + ch_f) - before;
        // Where the node would be at the hold without the switch: the same relaxation from
        // `before` (deterministic: no noise is drawn), then the state put back.
        let saved = (self.v, self.at);
        self.relax_to(t);
        let without = self.v[i];
        (self.v, self.at) = saved;
        self.v[i] = before + dip;
        self.relax_to(t);
        let shared = self.v[i] - without;
        let v = self.v[i];
        self.hold_v = v;
        let n = match &self.noise {
            Some(d) => d.sample(&mut self.rng),
            None => 0.0,
        };
        let code = (v * 4096.0 + n).round().clamp(0.0, 4095.0) as u16;
        self.trace.conversions.push(Conversion {
            at: t,
            terminal,
            v,
            shared,
            code,
        });
        Some(code)
    }
}

/// One sampling phase of `board`'s plan, master ticks: sampling half-cycles at its ADC clock.
fn sampling_ticks(board: &saw_boards::BoardDef) -> Time {
    let half_cycles = board.adc.sample_half_cycles as u128;
    let den = 2 * board.adc.clk_hz.max(1) as u128;
    (half_cycles * crate::periph::TICKS_PER_S as u128 / den) as Time
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
        // F446 channel 8 = Y+. The first conversion charges the hold capacitor (the test
        // below); the second, 10 µs (5 τ) later, reads the settled node.
        p.convert(200 * US, 8).unwrap();
        let code = p.convert(210 * US, 8).unwrap();
        assert_eq!(code, (4096.0_f64 * 200.0 / 700.0).round() as u16);
        assert!(p.trace.conversions[1].shared.abs() * 4096.0 < 0.01);
    }

    /// The hold capacitor's charge sharing, worked by hand from the ADC input model: X drive,
    /// finger at x = 0.25 at 1 N (300 Ω), Y+ settled at 200/700 of VDD = 1 170.29 LSB; C_ADC
    /// (7 pF, F446) holds 0 V. At the sampling's start (56 cycles at 22.5 MHz = 2.4889 µs
    /// before the hold) the node drops by 200/700 · 7/(2 454 + 7) of VDD = 3.329 LSB, then
    /// recovers with τ = (R_th + 300 + 400) Ω · 2.454 nF, R_th = 200 · 500 / 700 = 142.86 Ω:
    /// τ = 2.0684 µs; at the hold 3.329 · e^(−2.4889/2.0684) = 0.999 LSB remain: 1 169.29 LSB,
    /// code 1 169.
    #[test]
    fn the_first_conversion_shares_charge_with_the_hold_capacitor() {
        let mut p = panel(Some(Finger {
            x: 0.25,
            y: 0.6,
            force_n: 1.0,
        }));
        p.set_pins(0, [HI, LO, AN, AN]);
        assert_eq!(p.convert(200 * US, 8), Some(1_169));
        let tau_s = (200.0 * 500.0 / 700.0 + 700.0) * 2.454e-9;
        let dip_lsb = 4096.0 * (200.0 / 700.0) * 7.0 / 2_461.0;
        let want = -dip_lsb * (-(56.0_f64 / 22.5e6) / tau_s).exp();
        let got = p.trace.conversions[0].shared * 4096.0;
        assert!((got - want).abs() < 0.002, "{got} LSB vs {want}");
        assert!((want + 0.999).abs() < 0.001, "{want}");
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
