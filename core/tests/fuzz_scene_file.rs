//! Property tests (fuzzing in CI's budget): scene files and sample streams from an adversary.
//! Whatever comes in, nothing panics, a file either reads into a configuration that loads or is
//! refused with a located error, and the carrier caps hold on every gate action.
//!
//! Needs the `scene-file` feature, which core/Cargo.toml's self dev-dependency turns on for every
//! test build: no `cfg` gate here, so a build without it fails to compile rather than passing
//! with nothing run.

use proptest::prelude::*;
use saw_core::burst::{BurstTimer, SafetyLimits};
use saw_core::gate::GateAction;
use saw_core::sample::Sample;
use saw_core::scene_file::load_for_board;
use saw_core::Controller;

const TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 5_000,
};
const DEFAULT: &str = include_str!("../../scenes/default.toml");
const LINES: &str = include_str!("../../scenes/lines.toml");
const RANDOM: &str = include_str!("../../scenes/random.toml");

/// A shipped file with one byte range replaced by fuzz.
fn mutated() -> impl Strategy<Value = String> {
    (
        prop::sample::select(vec![DEFAULT, LINES, RANDOM]),
        any::<prop::sample::Index>(),
        "[ -~\n]{0,12}",
    )
        .prop_map(|(base, at, junk)| {
            let i = at.index(base.len());
            let i = (0..=i)
                .rev()
                .find(|&k| base.is_char_boundary(k))
                .unwrap_or(0);
            format!("{}{}{}", &base[..i], junk, &base[i..])
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn any_text_reads_or_is_located(text in prop_oneof![mutated(), "[ -~\n]{0,200}"]) {
        match load_for_board("fuzz.toml", &text, TIMER, 100) {
            Ok(cfg) => {
                let mut c = Controller::new(TIMER, 100).unwrap();
                prop_assert!(c.load(&cfg).is_ok());
            }
            Err(e) => {
                prop_assert!(e.line >= 1 && e.line <= text.lines().count().max(1) + 1, "{}", e);
                prop_assert!(!e.message.is_empty());
            }
        }
    }

    #[test]
    fn any_sample_stream_keeps_the_caps(
        scene in prop::sample::select(vec![DEFAULT, LINES, RANDOM, include_str!("../../scenes/grating.toml")]),
        codes in prop::collection::vec(any::<u16>(), 1..400),
        steps in prop::collection::vec(0u32..400, 1..400),
    ) {
        let cfg = load_for_board("scene.toml", scene, TIMER, 100).unwrap();
        let limits: SafetyLimits = cfg.limits;
        let mut c = Controller::new(TIMER, 100).unwrap();
        c.load(&cfg).unwrap();
        let mut t = 0u32;
        for (i, &code) in codes.iter().enumerate() {
            t = t.wrapping_add(steps[i % steps.len()]);
            let out = c.on_sample(Sample { code, t_us: t });
            match out.action {
                Some(GateAction::Start(s) | GateAction::Update(s)) => prop_assert!(limits.allows(&TIMER, &s), "{:?}", s),
                Some(GateAction::Pulse(s)) => prop_assert!(s.on_clocks() <= limits.max_on_time_clocks(&TIMER)),
                _ => {}
            }
            if out.fault.is_some() {
                prop_assert!(out.action.is_none() || out.action == Some(GateAction::Off));
            }
        }
    }
}
