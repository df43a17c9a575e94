//! Touch plates: the 4-wire overlay's phase sequence as data — which terminal each phase drives
//! high or low, leaves floating or converts — each phase's settling time from the plates' RC,
//! and the frame (one reading of every phase) and per-axis rate that result for an ADC.
//!
//! A 4-wire overlay is two resistive plates, X (terminals X+ and X− on opposite edges) and Y,
//! that touch where the finger presses. Driving one plate end to end makes it a rheostat whose
//! wiper is the touch point; the other plate, left floating, carries the wiper's voltage to its
//! terminals, where the ADC reads it (TI SBAA155 §1; the CP3BT26's touchscreen interface §16.2,
//! the same method on a microcontroller's own pins). Pressure takes two more conversions with
//! the current forced through the contact: Y+ high, X− low, read X+ (Z1) and Y− (Z2) (TI
//! TSC2101/TSC2117 data sheets, "Measuring touch pressure"; Microchip SAM9 "4-wire pressure
//! measurement method"); [`super::pressure`] turns them into the contact's resistance.
//!
//! **Settling.** A phase switch steps the sensed node from the previous phase's voltage to the
//! new one through a resistance R (the driven plate's Thevenin resistance, the contact, the
//! sensed plate) into the node's capacitance C (the filter capacitor on each terminal of the
//! sensed plate and the capacitance between the plates). A first-order step is within ½ LSB of
//! 12 bits once e^(−t/τ) ≤ 2^−13: t = τ·ln 2^13 = 9.011·τ, τ = R·C. [`PlateRc::tau_ps`] takes
//! the worst R a used reading can see: the driven plate at mid-travel, the contact at the
//! touch-down threshold (readings with more resistance are lift-off, not positions) and the
//! whole sensed plate. Default figures and their sources are on [`PlateRc::DEFAULT`];
//! `docs/touch.md` works them through.

use core::fmt;

/// One terminal of the overlay: an edge electrode of the X or Y plate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Terminal {
    /// X plate, the edge driven high in the X phase (x = 1 there).
    XPlus,
    /// X plate, the edge driven low in the X phase (x = 0 there).
    XMinus,
    /// Y plate, the edge driven high in the Y phase (y = 1 there).
    YPlus,
    /// Y plate, the edge driven low in the Y phase (y = 0 there).
    YMinus,
}

/// The four terminals, in the order pin tables list them.
pub const TERMINALS: [Terminal; 4] = [
    Terminal::XPlus,
    Terminal::XMinus,
    Terminal::YPlus,
    Terminal::YMinus,
];

/// What a phase does with one terminal's pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PinRole {
    /// Push-pull output, high (VDD = VREF+ on both Nucleos, so readings are ratiometric).
    High,
    /// Push-pull output, low.
    Low,
    /// Not driven and not converted: analog mode, so the Schmitt trigger is off and a plate at
    /// mid-supply draws no shoot-through current (RM0390 and RM0440, GPIO chapter, "Analog
    /// configuration").
    Floating,
    /// Not driven; the ADC converts it (analog mode, its channel in the sequence).
    Sensed,
}

/// One step of the plate sequence.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Phase {
    /// X position: X+ high, X− low, Y+ converted, Y− floating.
    X,
    /// Y position: Y+ high, Y− low, X+ converted, X− floating.
    Y,
    /// First pressure reading: Y+ high, X− low, X+ converted, Y− floating.
    Z1,
    /// Second pressure reading: the same drive as Z1, Y− converted, X+ floating. Only the ADC
    /// channel changes from Z1, so the plates need no settling.
    Z2,
}

/// The phases of one frame, in order. Z1 follows Y and Z2 follows Z1 so the pressure pair
/// shares one drive; the frame then starts again at X.
pub const SEQUENCE: [Phase; 4] = [Phase::X, Phase::Y, Phase::Z1, Phase::Z2];

impl Phase {
    /// What this phase does with terminal `t`.
    pub const fn role(self, t: Terminal) -> PinRole {
        use PinRole::*;
        use Terminal::*;
        match (self, t) {
            (Phase::X, XPlus) => High,
            (Phase::X, XMinus) => Low,
            (Phase::X, YPlus) => Sensed,
            (Phase::X, YMinus) => Floating,
            (Phase::Y, YPlus) => High,
            (Phase::Y, YMinus) => Low,
            (Phase::Y, XPlus) => Sensed,
            (Phase::Y, XMinus) => Floating,
            (Phase::Z1, YPlus) => High,
            (Phase::Z1, XMinus) => Low,
            (Phase::Z1, XPlus) => Sensed,
            (Phase::Z1, YMinus) => Floating,
            (Phase::Z2, YPlus) => High,
            (Phase::Z2, XMinus) => Low,
            (Phase::Z2, YMinus) => Sensed,
            (Phase::Z2, XPlus) => Floating,
        }
    }

    /// The terminal the ADC converts in this phase.
    pub const fn sensed(self) -> Terminal {
        match self {
            Phase::X => Terminal::YPlus,
            Phase::Y | Phase::Z1 => Terminal::XPlus,
            Phase::Z2 => Terminal::YMinus,
        }
    }

    /// The phase after this one in [`SEQUENCE`] (Z2 wraps to X).
    pub const fn next(self) -> Phase {
        match self {
            Phase::X => Phase::Y,
            Phase::Y => Phase::Z1,
            Phase::Z1 => Phase::Z2,
            Phase::Z2 => Phase::X,
        }
    }

    /// The phase before this one in [`SEQUENCE`] (X wraps to Z2).
    pub const fn previous(self) -> Phase {
        match self {
            Phase::X => Phase::Z2,
            Phase::Y => Phase::X,
            Phase::Z1 => Phase::Y,
            Phase::Z2 => Phase::Z1,
        }
    }

    /// True when entering this phase from [`Phase::previous`] changes any driven pin, so the
    /// plates must settle before the first conversion. False only for Z2 (Z1's drive).
    pub const fn switches_drive(self) -> bool {
        let p = self.previous();
        !(same_drive(p.role(Terminal::XPlus), self.role(Terminal::XPlus))
            && same_drive(p.role(Terminal::XMinus), self.role(Terminal::XMinus))
            && same_drive(p.role(Terminal::YPlus), self.role(Terminal::YPlus))
            && same_drive(p.role(Terminal::YMinus), self.role(Terminal::YMinus)))
    }

    /// A position phase (X or Y) rather than a pressure phase.
    pub const fn is_position(self) -> bool {
        matches!(self, Phase::X | Phase::Y)
    }
}

/// Two roles put the same voltage on the pin: both drive it the same way, or neither drives it
/// (floating and sensed are both analog mode; only the ADC's channel differs).
const fn same_drive(a: PinRole, b: PinRole) -> bool {
    matches!(
        (a, b),
        (PinRole::High, PinRole::High)
            | (PinRole::Low, PinRole::Low)
            | (
                PinRole::Floating | PinRole::Sensed,
                PinRole::Floating | PinRole::Sensed
            )
    )
}

/// ln 2^13 = 13 · ln 2 = 9.010 913 347…, the number of time constants a first-order step takes
/// to come within ½ LSB of 12 bits (2^−13 of full scale), as the fraction 9 010 914 / 10^6,
/// rounded up so the settling time is never shorter than the formula's.
pub const LN_2_POW_13: (u64, u64) = (9_010_914, 1_000_000);

/// The electrical figures that set the plates' settling.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PlateRc {
    /// X plate resistance, X+ to X−, Ω.
    pub r_x_plate_ohm: u32,
    /// Y plate resistance, Y+ to Y−, Ω.
    pub r_y_plate_ohm: u32,
    /// Output resistance of a GPIO driving a terminal, Ω.
    pub r_drive_ohm: u32,
    /// The largest contact resistance whose reading is used, Ω: the touch-down threshold
    /// ([`super::pressure::PressureConfig::touch_ohm`]).
    pub r_touch_max_ohm: u32,
    /// Capacitance between the two plates, pF.
    pub c_interlayer_pf: u32,
    /// Filter capacitor from each terminal to ground, pF (0: none fitted).
    pub c_filter_pf: u32,
}

impl PlateRc {
    /// The figures `docs/touch.md` derives:
    /// - plates 600 Ω (X) and 400 Ω (Y): 4-wire plates are 100 to 2000 Ω end to end (TI
    ///   SBAA155 §1; 100 Ω to 1 kΩ in the CP3BT26 data sheet §16.2.3); the long axis has more;
    /// - drive 50 Ω: an STM32 output holds V_OL ≤ 0.4 V at 8 mA (DS10693 and DS12288, I/O
    ///   static characteristics), 50 Ω at most;
    /// - contact 1 500 Ω at the touch-down threshold ([`super::pressure::PressureConfig`]);
    /// - between the plates 454 pF: a parallel-plate capacitor ε0·A/d over a 4.3-inch panel's
    ///   95 × 54 mm at a 0.1 mm air gap (8.854 pF/m · 5.13·10^−3 m² / 10^−4 m) — an estimate
    ///   to replace with the panel's measured figure;
    /// - filter 1 nF on each terminal: TI SBAA155 §3 fits decoupling capacitors at the
    ///   controller's inputs against LCD and backlight pickup; 1 nF keeps the settling under
    ///   the conversion window (`docs/touch.md`).
    pub const DEFAULT: PlateRc = PlateRc {
        r_x_plate_ohm: 600,
        r_y_plate_ohm: 400,
        r_drive_ohm: 50,
        r_touch_max_ohm: 1_500,
        c_interlayer_pf: 454,
        c_filter_pf: 1_000,
    };

    /// Checks every figure against its range.
    pub fn validate(self) -> Result<Self, PlateError> {
        check("r_x_plate_ohm", self.r_x_plate_ohm, PLATE_OHM, "Ω")?;
        check("r_y_plate_ohm", self.r_y_plate_ohm, PLATE_OHM, "Ω")?;
        check("r_drive_ohm", self.r_drive_ohm, DRIVE_OHM, "Ω")?;
        check("r_touch_max_ohm", self.r_touch_max_ohm, TOUCH_OHM, "Ω")?;
        check("c_interlayer_pf", self.c_interlayer_pf, INTERLAYER_PF, "pF")?;
        check("c_filter_pf", self.c_filter_pf, FILTER_PF, "pF")?;
        Ok(self)
    }

    /// The capacitance on the sensed node, pF: the filter capacitors on both terminals of the
    /// floating plate (the far one reaches the node through that plate) and the plates'.
    pub const fn c_node_pf(&self) -> u64 {
        2 * self.c_filter_pf as u64 + self.c_interlayer_pf as u64
    }

    /// The worst source resistance behind the sensed node in `phase`, Ω.
    /// - X: the X plate as a divider between two drivers, (R_x + 2·R_drive)/4 at mid-travel
    ///   (R·u·(1 − u) peaks at u = ½), the contact, and the whole Y plate;
    /// - Y: the same with the plates swapped;
    /// - Z1, Z2: the current path Y+ → Y plate → contact → X plate → X−, both plates whole
    ///   and both drivers in series with the contact (the sensed terminal hangs off it).
    pub const fn r_source_ohm(&self, phase: Phase) -> u64 {
        let (rx, ry) = (self.r_x_plate_ohm as u64, self.r_y_plate_ohm as u64);
        let (rd, rt) = (self.r_drive_ohm as u64, self.r_touch_max_ohm as u64);
        match phase {
            Phase::X => (rx + 2 * rd) / 4 + rt + ry,
            Phase::Y => (ry + 2 * rd) / 4 + rt + rx,
            Phase::Z1 | Phase::Z2 => 2 * rd + rx + ry + rt,
        }
    }

    /// Time constant of `phase`'s sensed node, ps (Ω · pF = ps).
    /// Saturates at `u64::MAX` (only figures far outside [`PlateRc::validate`]'s ranges get
    /// near it).
    pub const fn tau_ps(&self, phase: Phase) -> u64 {
        self.r_source_ohm(phase).saturating_mul(self.c_node_pf())
    }

    /// Settling time of `phase` to ½ LSB of 12 bits, ns: τ · ln 2^13, rounded up; 0 for a
    /// phase that does not switch the drive (Z2).
    pub const fn settle_ns(&self, phase: Phase) -> u64 {
        if !phase.switches_drive() {
            return 0;
        }
        let (num, den) = LN_2_POW_13;
        // ps · ln → ns: divide by 1000 and by den, rounding up.
        let scaled = self.tau_ps(phase) as u128 * num as u128;
        let ns = scaled.div_ceil(den as u128 * 1_000);
        if ns > u64::MAX as u128 {
            u64::MAX
        } else {
            ns as u64
        }
    }
}

impl Default for PlateRc {
    fn default() -> Self {
        Self::DEFAULT
    }
}

const PLATE_OHM: (u32, u32) = (50, 10_000);
const DRIVE_OHM: (u32, u32) = (0, 1_000);
const TOUCH_OHM: (u32, u32) = (1, 100_000);
const INTERLAYER_PF: (u32, u32) = (0, 100_000);
const FILTER_PF: (u32, u32) = (0, 1_000_000);
const CONVERSION_NS: (u32, u32) = (1, 1_000_000);
const CONVERSIONS: (u32, u32) = (1, 256);
const DISCARD: (u32, u32) = (0, 16);

fn check(
    field: &'static str,
    value: u32,
    (min, max): (u32, u32),
    unit: &'static str,
) -> Result<(), PlateError> {
    if value < min || value > max {
        return Err(PlateError::OutOfRange {
            field,
            value,
            min,
            max,
            unit,
        });
    }
    Ok(())
}

/// Why plate figures or an ADC timing were refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum PlateError {
    /// A figure outside its range.
    OutOfRange {
        /// The field's name, as in [`PlateRc`] or [`AdcTiming`].
        field: &'static str,
        /// The value given.
        value: u32,
        /// The least accepted.
        min: u32,
        /// The most accepted.
        max: u32,
        /// Its unit.
        unit: &'static str,
    },
}

impl fmt::Display for PlateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            PlateError::OutOfRange {
                field,
                value,
                min,
                max,
                unit,
            } => write!(
                f,
                "{field} {value} {unit} is outside the accepted {min} to {max} {unit}"
            ),
        }
    }
}

/// How the ADC converts one phase.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdcTiming {
    /// One conversion, sampling included, ns (F446: (56 + 12) cycles at 22.5 MHz, RM0390
    /// §13.5; G474: (47.5 + 12.5) cycles at 37.5 MHz, RM0440 §21.4.16; `saw-boards`
    /// computes both).
    pub conversion_ns: u32,
    /// Conversions summed per position phase (16 gives the 1D stage's code scale).
    pub conversions_position: u32,
    /// Conversions per pressure phase. The codes are scaled to 16 conversions' sum; fewer
    /// convert faster at more noise, which only the touch thresholds see.
    pub conversions_pressure: u32,
    /// Conversions thrown away at the start of every phase, before the summed ones: the first
    /// conversion after a channel switch meets the ADC's hold capacitor still charged to the
    /// previous channel, and the charge it shares with the node dips the node by up to
    /// C_ADC / C_node of the step (`docs/touch.md`, "Why 1 nF"). They take their time in the
    /// phase's slot like the others.
    pub discard: u32,
}

/// One phase's slot in the frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PhaseSlot {
    /// The phase.
    pub phase: Phase,
    /// From the frame's start to this phase's pin switch, ns.
    pub start_ns: u64,
    /// From the pin switch to the ADC trigger, ns.
    pub settle_ns: u64,
    /// The conversions, the discarded ones first, ns.
    pub convert_ns: u64,
}

impl PhaseSlot {
    /// From the frame's start to the ADC trigger of this phase, ns.
    pub const fn trigger_ns(&self) -> u64 {
        self.start_ns + self.settle_ns
    }
    /// From the frame's start to the end of this phase's conversions, ns.
    pub const fn end_ns(&self) -> u64 {
        self.start_ns + self.settle_ns + self.convert_ns
    }
}

/// The designed times of one frame: where each phase switches the pins and triggers the ADC.
/// A timer runs it: one compare switches the pins at `start_ns`, the next triggers the
/// conversions at `trigger_ns`, and DMA takes the codes, as the 1D acquisition does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Schedule {
    /// The phases in [`SEQUENCE`] order.
    pub slots: [PhaseSlot; 4],
}

impl Schedule {
    /// Lays the phases back to back: each settles, then converts, then the next switches.
    pub fn new(rc: &PlateRc, adc: &AdcTiming) -> Result<Self, PlateError> {
        rc.validate()?;
        check("conversion_ns", adc.conversion_ns, CONVERSION_NS, "ns")?;
        check(
            "conversions_position",
            adc.conversions_position,
            CONVERSIONS,
            "conversions",
        )?;
        check(
            "conversions_pressure",
            adc.conversions_pressure,
            CONVERSIONS,
            "conversions",
        )?;
        check("discard", adc.discard, DISCARD, "conversions")?;
        let mut start_ns = 0;
        let slots = SEQUENCE.map(|phase| {
            let conversions = if phase.is_position() {
                adc.conversions_position
            } else {
                adc.conversions_pressure
            };
            let slot = PhaseSlot {
                phase,
                start_ns,
                settle_ns: rc.settle_ns(phase),
                convert_ns: (conversions + adc.discard) as u64 * adc.conversion_ns as u64,
            };
            start_ns = slot.end_ns();
            slot
        });
        Ok(Self { slots })
    }

    /// One frame, every phase once, ns.
    pub fn frame_ns(&self) -> u64 {
        self.slots.iter().map(|s| s.settle_ns + s.convert_ns).sum()
    }

    /// Readings of each axis per second (one per frame), rounded down.
    pub fn per_axis_rate_hz(&self) -> u32 {
        let frame = self.frame_ns().max(1);
        (1_000_000_000 / frame) as u32
    }

    /// Share of the frame spent waiting for the plates, ‰.
    pub fn settle_share_permille(&self) -> u32 {
        let settle: u64 = self.slots.iter().map(|s| s.settle_ns).sum();
        (settle * 1000 / self.frame_ns().max(1)) as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each phase drives exactly one terminal high and one low and converts exactly one; the
    /// table is written out here from the method's description (module docs), not read back.
    #[test]
    fn each_phase_drives_one_pair_and_converts_one_terminal() {
        use PinRole::*;
        let expected = [
            (Phase::X, [High, Low, Sensed, Floating]),
            (Phase::Y, [Sensed, Floating, High, Low]),
            (Phase::Z1, [Sensed, Low, High, Floating]),
            (Phase::Z2, [Floating, Low, High, Sensed]),
        ];
        for (phase, roles) in expected {
            for (t, role) in TERMINALS.iter().zip(roles) {
                assert_eq!(phase.role(*t), role, "{phase:?} {t:?}");
            }
            assert_eq!(phase.role(phase.sensed()), Sensed, "{phase:?}");
        }
    }

    /// A position phase never drives the plate it reads: the sensed terminal is on the other
    /// plate from both driven ones, so it carries the touch point's voltage.
    #[test]
    fn position_phases_read_the_other_plate() {
        let plate = |t: Terminal| matches!(t, Terminal::XPlus | Terminal::XMinus);
        for phase in [Phase::X, Phase::Y] {
            for t in TERMINALS {
                if matches!(phase.role(t), PinRole::High | PinRole::Low) {
                    assert_ne!(plate(t), plate(phase.sensed()), "{phase:?}");
                }
            }
        }
    }

    #[test]
    fn sequence_cycles_and_only_z2_keeps_the_drive() {
        for (i, p) in SEQUENCE.iter().enumerate() {
            assert_eq!(p.next(), SEQUENCE[(i + 1) % 4]);
            assert_eq!(p.next().previous(), *p);
        }
        assert!(Phase::X.switches_drive());
        assert!(Phase::Y.switches_drive());
        assert!(Phase::Z1.switches_drive());
        assert!(!Phase::Z2.switches_drive());
    }

    /// The default figures worked by hand (docs/touch.md): C = 2 · 1000 + 454 = 2454 pF;
    /// X: R = (600 + 100)/4 + 1500 + 400 = 2075 Ω, τ = 2075 · 2454 = 5 092 050 ps,
    /// settle = 5 092 050 · 9.010 914 / 1000 = 45 884.0… → 45 885 ns (rounded up);
    /// Y: R = (400 + 100)/4 + 1500 + 600 = 2225 Ω, τ = 5 460 150 ps → 49 200.9… → 49 201 ns;
    /// Z1: R = 100 + 600 + 400 + 1500 = 2600 Ω, τ = 6 380 400 ps → 57 493.3… → 57 494 ns;
    /// Z2: 0 (same drive as Z1).
    #[test]
    fn default_settling_times_by_hand() {
        let rc = PlateRc::DEFAULT;
        assert_eq!(rc.c_node_pf(), 2_454);
        assert_eq!(rc.tau_ps(Phase::X), 5_092_050);
        assert_eq!(rc.settle_ns(Phase::X), 45_885);
        assert_eq!(rc.tau_ps(Phase::Y), 5_460_150);
        assert_eq!(rc.settle_ns(Phase::Y), 49_201);
        assert_eq!(rc.tau_ps(Phase::Z1), 6_380_400);
        assert_eq!(rc.settle_ns(Phase::Z1), 57_494);
        assert_eq!(rc.settle_ns(Phase::Z2), 0);
    }

    /// ln 2^13 as a fraction is within 10^−6 of 13 · ln 2 and never below it.
    #[test]
    fn ln_fraction_is_rounded_up() {
        let exact = 13.0 * core::f64::consts::LN_2;
        let frac = LN_2_POW_13.0 as f64 / LN_2_POW_13.1 as f64;
        assert!(frac >= exact && frac - exact < 1e-6, "{frac} vs {exact}");
    }

    /// F446 default acquisition, 16 conversions of 68 cycles at 22.5 MHz = 3 022.2 ns, taken
    /// as 3 023 ns: 48 368 ns per phase. Frame = 45 885 + 48 368 + 49 201 + 48 368 + 57 494 +
    /// 48 368 + 0 + 48 368 = 346 052 ns, so 1e9 / 346 052 = 2 889 readings of each axis a second.
    #[test]
    fn f446_frame_by_hand() {
        let adc = AdcTiming {
            conversion_ns: 3_023,
            conversions_position: 16,
            conversions_pressure: 16,
            discard: 0,
        };
        let s = Schedule::new(&PlateRc::DEFAULT, &adc).unwrap();
        assert_eq!(s.frame_ns(), 346_052);
        assert_eq!(s.per_axis_rate_hz(), 2_889);
        // Phases back to back: each starts where the previous ended; the ADC fires after the
        // settling.
        assert_eq!(s.slots[0].start_ns, 0);
        assert_eq!(s.slots[0].trigger_ns(), 45_885);
        assert_eq!(s.slots[1].start_ns, 45_885 + 48_368);
        assert_eq!(s.slots[3].trigger_ns(), s.slots[2].end_ns());
        assert_eq!(s.slots[3].end_ns(), 346_052);
        // Settling: 152 580 of 346 052 ns = 440 ‰.
        assert_eq!(s.settle_share_permille(), 440);
    }

    /// G474 default sampling, (47.5 + 12.5) cycles at 37.5 MHz = 1 600 ns a conversion, 16
    /// a phase: 25 600 ns; frame = 152 580 + 4 · 25 600 = 254 980 ns, 3 921 per second.
    #[test]
    fn g474_frame_by_hand() {
        let adc = AdcTiming {
            conversion_ns: 1_600,
            conversions_position: 16,
            conversions_pressure: 16,
            discard: 0,
        };
        let s = Schedule::new(&PlateRc::DEFAULT, &adc).unwrap();
        assert_eq!(s.frame_ns(), 254_980);
        assert_eq!(s.per_axis_rate_hz(), 3_921);
    }

    /// The boards' 2D acquisition (`saw_boards::touch::touch_adc`): one conversion discarded
    /// after each switch, then 15 summed a position phase and 4 a pressure phase. F446, 3 023 ns
    /// a conversion: X and Y convert 16 × 3 023 = 48 368 ns, Z1 and Z2 5 × 3 023 = 15 115 ns;
    /// frame = 152 580 + 2 · 48 368 + 2 · 15 115 = 279 546 ns, 1e9 / 279 546 = 3 577 a second;
    /// settling 152 580 / 279 546 = 545 ‰. G474, 1 600 ns: 152 580 + 2 · 25 600 + 2 · 8 000 =
    /// 219 780 ns, 4 550 a second.
    #[test]
    fn discarded_conversions_take_their_time_in_the_slot() {
        let adc = AdcTiming {
            conversion_ns: 3_023,
            conversions_position: 15,
            conversions_pressure: 4,
            discard: 1,
        };
        let s = Schedule::new(&PlateRc::DEFAULT, &adc).unwrap();
        assert_eq!(s.slots[0].convert_ns, 48_368);
        assert_eq!(s.slots[2].convert_ns, 15_115);
        assert_eq!(s.slots[3].convert_ns, 15_115);
        assert_eq!(s.frame_ns(), 279_546);
        assert_eq!(s.per_axis_rate_hz(), 3_577);
        assert_eq!(s.settle_share_permille(), 545);
        let g474 = AdcTiming {
            conversion_ns: 1_600,
            ..adc
        };
        let s = Schedule::new(&PlateRc::DEFAULT, &g474).unwrap();
        assert_eq!(s.frame_ns(), 219_780);
        assert_eq!(s.per_axis_rate_hz(), 4_550);
        // More than 16 discarded is refused with a sentence.
        let e = Schedule::new(&PlateRc::DEFAULT, &AdcTiming { discard: 17, ..adc }).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "discard 17 conversions is outside the accepted 0 to 16 conversions"
        );
    }

    /// No filter capacitor: C = 454 pF, τ_X = 2075 · 454 = 942 050 ps → 8 488.7… → 8 489 ns.
    #[test]
    fn settle_scales_with_the_capacitance() {
        let rc = PlateRc {
            c_filter_pf: 0,
            ..PlateRc::DEFAULT
        };
        assert_eq!(rc.settle_ns(Phase::X), 8_489);
    }

    /// Figures no validation would pass still give an answer, not an overflow panic.
    #[test]
    fn absurd_figures_saturate() {
        let rc = PlateRc {
            r_x_plate_ohm: u32::MAX,
            r_y_plate_ohm: u32::MAX,
            r_drive_ohm: u32::MAX,
            r_touch_max_ohm: u32::MAX,
            c_interlayer_pf: u32::MAX,
            c_filter_pf: u32::MAX,
        };
        for phase in SEQUENCE {
            assert_eq!(rc.tau_ps(phase), u64::MAX, "{phase:?}");
            // u64::MAX ps · 9 010 914 / 10^9, rounded up: 1.66 · 10^17 ns.
            let expected = if phase == Phase::Z2 {
                0
            } else {
                166_222_024_428_206_431
            };
            let got = rc.settle_ns(phase);
            assert_eq!(got, expected, "{phase:?}");
        }
    }

    #[test]
    fn out_of_range_figures_are_refused_with_a_sentence() {
        let rc = PlateRc {
            r_x_plate_ohm: 20,
            ..PlateRc::DEFAULT
        };
        let e = rc.validate().unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "r_x_plate_ohm 20 Ω is outside the accepted 50 to 10000 Ω"
        );
        let adc = AdcTiming {
            conversion_ns: 3_023,
            conversions_position: 0,
            conversions_pressure: 16,
            discard: 0,
        };
        let e = Schedule::new(&PlateRc::DEFAULT, &adc).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "conversions_position 0 conversions is outside the accepted 1 to 256 conversions"
        );
        // The largest figures accepted do not overflow: 122 kΩ · 2.1 µF.
        let big = PlateRc {
            r_x_plate_ohm: 10_000,
            r_y_plate_ohm: 10_000,
            r_drive_ohm: 1_000,
            r_touch_max_ohm: 100_000,
            c_interlayer_pf: 100_000,
            c_filter_pf: 1_000_000,
        };
        let adc = AdcTiming {
            conversion_ns: 1_000_000,
            conversions_position: 256,
            conversions_pressure: 256,
            discard: 16,
        };
        let s = Schedule::new(&big, &adc).unwrap();
        assert!(s.per_axis_rate_hz() < 1);
    }
}
