//! Sensor faults through the Controller, against the documented numbers as literals (README,
//! "Safety rules the core keeps"; core/src/position.rs): the rail bands end at codes 655 and
//! 64 880 of the 16-bit sum, an open wiper reading a few codes is a fault, and the carrier comes
//! back only after 16 good samples — the 16th renders, the 15th does not.

use saw_core::burst::BurstTimer;
use saw_core::gate::GateAction;
use saw_core::position::SensorFault;
use saw_core::sample::Sample;
use saw_core::{default_config, Controller, Output};

const TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 5_000,
};
/// About 5 mm on the default calibration (1 310 + 5/63 × 62 915): region 0, 20 Hz bursts.
const GOOD: u16 = 6_303;

struct Rig {
    c: Controller,
    t_us: u32,
}

impl Rig {
    /// The default scene, 40 healthy samples in: the 20 Hz burst is running.
    fn running() -> Self {
        let mut c = Controller::new(TIMER, 100).unwrap();
        c.load(&default_config()).unwrap();
        let mut rig = Self { c, t_us: 0 };
        let first = rig.feed(GOOD);
        assert!(
            matches!(first.action, Some(GateAction::Start(_))),
            "{first:?}"
        );
        for _ in 1..40 {
            assert_eq!(rig.feed(GOOD).fault, None);
        }
        rig
    }

    fn feed(&mut self, code: u16) -> Output {
        let out = self.c.on_sample(Sample {
            code,
            t_us: self.t_us,
        });
        self.t_us += 100;
        out
    }

    /// `n` good samples that must all still be faulted with `fault`, the line untouched.
    fn still_faulted(&mut self, n: usize, fault: SensorFault) {
        for k in 1..=n {
            let out = self.feed(GOOD);
            assert_eq!(out.fault, Some(fault), "good sample {k} of {n}");
            assert_eq!(out.action, None, "good sample {k} of {n}");
            assert_eq!(out.region, None, "good sample {k} of {n}");
        }
    }
}

/// Each rail threshold from both sides, on a running burst: just outside turns the line off on
/// that very sample, just inside is a position (the ends, 0 and 63 000 µm) and no fault.
#[test]
fn rail_thresholds_through_the_controller() {
    for (outside, inside, fault, end_um) in [
        (655, 656, SensorFault::RailLow, 0),
        (64_880, 64_879, SensorFault::RailHigh, 63_000),
    ] {
        let mut rig = Rig::running();
        let out = rig.feed(inside);
        assert_eq!(out.fault, None, "code {inside}");
        assert_eq!(out.position_um, Some(end_um), "code {inside}");
        let out = rig.feed(outside);
        assert_eq!(out.fault, Some(fault), "code {outside}");
        assert_eq!(out.action, Some(GateAction::Off), "code {outside}");
        assert_eq!(out.position_um, None, "code {outside}");
    }
}

/// An open wiper does not read exactly 0: the ADC's offset and noise leave a few LSB per
/// conversion, 3 – 40 codes of the sum. Each such reading turns a running line off.
#[test]
fn open_wiper_reading_a_few_codes_turns_the_line_off() {
    for code in [3, 9, 17, 40] {
        let mut rig = Rig::running();
        let out = rig.feed(code);
        assert_eq!(out.fault, Some(SensorFault::RailLow), "code {code}");
        assert_eq!(out.action, Some(GateAction::Off), "code {code}");
    }
}

/// 15 good samples after a fault keep it; the 16th ends it and renders (position and region).
/// README: "it comes back only after 16 good samples". The counts are literals on purpose, not
/// `controller::RECOVERY_SAMPLES`: a changed constant must fail here.
#[test]
fn recovery_takes_sixteen_good_samples() {
    for (rail, fault) in [(17, SensorFault::RailLow), (65_520, SensorFault::RailHigh)] {
        let mut rig = Rig::running();
        assert_eq!(rig.feed(rail).action, Some(GateAction::Off));
        rig.still_faulted(15, fault);
        let out = rig.feed(GOOD);
        assert_eq!(out.fault, None, "16th good sample after {fault:?}");
        assert_eq!(out.region, Some(0), "16th good sample after {fault:?}");
        assert!(out.position_um.is_some());
        assert_eq!(rig.c.telemetry().faults, 1);
    }
}

/// A wiper bouncing on a worn track: a rail reading inside the good run starts the count again,
/// so 15 good, 1 rail, 15 good is still a fault; the 16th good sample after the bounce recovers.
#[test]
fn a_bounce_restarts_the_recovery_count() {
    let mut rig = Rig::running();
    assert_eq!(rig.feed(0).fault, Some(SensorFault::RailLow));
    rig.still_faulted(15, SensorFault::RailLow);
    let out = rig.feed(655);
    assert_eq!(out.fault, Some(SensorFault::RailLow));
    rig.still_faulted(15, SensorFault::RailLow);
    assert_eq!(rig.feed(GOOD).fault, None);
}
