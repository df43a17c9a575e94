//! The sample path's contract (docs/sample-contract.md): per sample the controller computes only
//! what the region in force needs. In a region whose texture reads only the position the
//! velocity estimator rests (its window kept, its sums not) and the first sample of a region
//! that reads the velocity wakes it whole. Checked here end to end, on the rheostat/ADC model's
//! samples:
//! - resting changes no burst, no amplitude, no region switch, no fault: a controller that rests
//!   and one that updates on every sample give the same outputs but for the velocity field,
//!   and the velocity the resting one works out when asked is the other's, sample by sample;
//! - entry into a velocity-driven region: the first burst's f_b and time with the estimator
//!   rested and woken ("seed from the last positions") are those of the estimator run in the
//!   background (today's), at 20–200 mm/s both ways; restarting it on entry instead costs the
//!   window's warm-up before the first burst.

use host_sim::adc::{AdcModel, AdcParams, FaultKind, FaultWindow};
use host_sim::sim::{burst_timer, sample_period_us};
use host_sim::trajectory::Trajectory;
use saw_boards::NUCLEO_F446RE;
use saw_core::controller::{Controller, Output, WindowEstimator};
use saw_core::gate::GateAction;
use saw_core::sample::Sample;
use saw_core::scene::Config;
use saw_core::velocity::{LsqSlope, Median3, VelocityEstimator};

/// Every texture kind side by side, 8 mm each on the 63 mm substrate, no lines: four regions
/// rest the estimator (constant, random, off, constant), three read it, and in the last (the
/// hybrid, [`HYBRID_REGION`]) it sleeps: the hybrid's own line is the velocity.
const MIXED: &str = r#"
[[region]]
kind = "constant"
until_mm = 8
f_b_hz = 20
duty_percent = 40

[[region]]
kind = "grating"
until_mm = 16
wavelength_mm = 1.0
render = "velocity"

[[region]]
kind = "random"
until_mm = 24
f_b_hz = 60
spread_percent = 30
seed = 3

[[region]]
kind = "material"
until_mm = 32
delta_mu = 0.3
normal_force_n = 1.0
mass_g = 1.0
stiffness_n_per_m = 500

[[region]]
kind = "off"
until_mm = 40

[[region]]
kind = "grating"
until_mm = 48
wavelength_mm = 1.0

[[region]]
kind = "constant"
until_mm = 56
f_b_hz = 300
duty_percent = 30

[[region]]
kind = "grating"
wavelength_mm = 0.5
render = "hybrid"
"#;

/// The index of MIXED's hybrid region.
const HYBRID_REGION: u8 = 7;

fn config(text: &str) -> Config {
    let b = &NUCLEO_F446RE;
    saw_core::scene_file::load_for_board("t.toml", text, burst_timer(b), sample_period_us(b))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn controller<E: VelocityEstimator>(cfg: &Config, estimator: E) -> Controller<E> {
    let b = &NUCLEO_F446RE;
    let mut c = Controller::with_estimator(burst_timer(b), sample_period_us(b), estimator);
    c.load(cfg).unwrap();
    c
}

fn default_estimator() -> Median3<LsqSlope<32>> {
    let period = sample_period_us(&NUCLEO_F446RE);
    Median3::new(LsqSlope::new(period).unwrap(), period)
}

/// The ADC model's samples along `trajectory` for `duration_s`, 2 LSB, with `faults`.
fn samples(
    cfg: &Config,
    trajectory: &Trajectory,
    duration_s: f64,
    seed: u64,
    faults: Vec<FaultWindow>,
) -> Vec<Sample> {
    let params = AdcParams {
        faults,
        ..AdcParams::default().with_noise(2.0, seed)
    };
    let mut adc = AdcModel::new(cfg.calibration, params).unwrap();
    let period = sample_period_us(&NUCLEO_F446RE) as u64;
    let n = (duration_s * 1e6) as u64 / period;
    (0..n)
        .filter_map(|k| {
            let t_us = k * period;
            adc.sample(trajectory.state(t_us as f64 * 1e-6).position_um, t_us)
        })
        .collect()
}

/// Resting changes nothing but the velocity field, which the resting controller still answers
/// when asked: strokes over all eight regions at 20–300 mm/s, with a rail fault and a glitch,
/// on three noise seeds.
#[test]
fn resting_changes_no_burst_and_the_velocity_is_there_when_asked() {
    let cfg = config(MIXED);
    let mut rested_samples = 0usize;
    let mut woken = 0usize;
    let mut asleep_answered = 0usize;
    for (speed, seed) in [(20_000.0, 1), (120_000.0, 2), (300_000.0, 3)] {
        let stroke = Trajectory::Triangle {
            a_um: 2_000.0,
            b_um: 61_000.0,
            speed_um_s: speed,
        };
        let faults = vec![
            FaultWindow {
                start_us: 400_000,
                end_us: 403_000,
                kind: FaultKind::Open,
            },
            FaultWindow {
                start_us: 700_000,
                end_us: 700_100,
                kind: FaultKind::Spike { offset_lsb: 900 },
            },
        ];
        let input = samples(&cfg, &stroke, 2.0 * 59_000.0 / speed * 1.5, seed, faults);
        let mut contract = controller(&cfg, default_estimator());
        let mut always = controller(&cfg, default_estimator());
        always.velocity_every_sample(true);
        let mut was_resting = false;
        for (i, &s) in input.iter().enumerate() {
            let a: Output = contract.on_sample(s);
            let b: Output = always.on_sample(s);
            let what = format!("{speed} µm/s, seed {seed}, sample {i}");
            assert_eq!(
                Output {
                    velocity_um_s: None,
                    ..a
                },
                Output {
                    velocity_um_s: None,
                    ..b
                },
                "{what}"
            );
            // Where the contract computed a velocity it is the same figure; where it rested,
            // asking gives it.
            if a.velocity_um_s.is_some() {
                assert_eq!(a.velocity_um_s, b.velocity_um_s, "{what}");
                woken += usize::from(was_resting);
                was_resting = false;
            } else if a.position_um.is_some() && b.velocity_um_s.is_some() {
                rested_samples += 1;
                was_resting = true;
            }
            if a.region == Some(HYBRID_REGION) {
                // The estimator sleeps there: asked, the hybrid's own line answers (its
                // 64-sample fit of the raw positions, not the estimator's figure; compared on
                // a steady stroke in the core's tests), once its window is full.
                asleep_answered += usize::from(contract.velocity_um_s().is_some());
            } else {
                assert_eq!(contract.velocity_um_s(), b.velocity_um_s, "{what}: asked");
            }
            // Telemetry's velocity is the one asked for (above), and a ridge rate reads 0
            // where that velocity is 0 or unknown: in the hybrid's region, while its line
            // refills after a turn (docs/sample-contract.md, "Sleep").
            let (mut ta, mut tb) = (contract.telemetry(), always.telemetry());
            if a.region == Some(HYBRID_REGION) {
                (ta.velocity_um_s, tb.velocity_um_s) = (0, 0);
                (ta.burst_millihz, tb.burst_millihz) = (0, 0);
            }
            assert_eq!(ta, tb, "{what}: telemetry");
        }
    }
    // Not vacuous: the estimator rested over many samples and was woken often.
    eprintln!("{rested_samples} samples rested, {woken} wakes");
    assert!(rested_samples > 10_000, "{rested_samples}");
    assert!(woken > 10, "{woken}");
    assert!(asleep_answered > 1_000, "{asleep_answered}");
}

/// "Restart it" (issue #35's second warm-up option): an estimator that forgets its window when
/// woken, as a region entry without a background window would. For the entry comparison only.
#[derive(Clone, Debug)]
struct RestartOnEntry<E>(E);

impl<E: VelocityEstimator> VelocityEstimator for RestartOnEntry<E> {
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        self.0.update(position_um, t_us)
    }
    fn reset(&mut self) {
        self.0.reset();
    }
    fn group_delay_us(&self) -> u32 {
        self.0.group_delay_us()
    }
    fn rests(&self) -> bool {
        true
    }
    fn rest(&mut self, _position_um: i32, _t_us: u32) {}
    fn wake(&mut self) {
        self.0.reset();
    }
    fn estimate(&self) -> Option<i32> {
        None
    }
}

/// A constant region, a velocity-synthesis grating of λ = 1 mm (f = |V|/λ) from 30 to 40 mm,
/// a constant region again.
const ENTRY: &str = r#"
[[region]]
kind = "constant"
until_mm = 30
f_b_hz = 20
duty_percent = 40

[[region]]
kind = "grating"
until_mm = 40
wavelength_mm = 1.0
render = "velocity"

[[region]]
kind = "constant"
f_b_hz = 20
duty_percent = 40
"#;

/// The grating's first burst after the finger enters it: (µs after the true crossing of the
/// boundary, f_b produced, Hz).
fn first_burst<E: VelocityEstimator>(
    mut c: Controller<E>,
    input: &[Sample],
    boundary_crossed_us: u32,
) -> Option<(u32, f64)> {
    let clock = burst_timer(&NUCLEO_F446RE).clock_hz;
    let mut inside = false;
    for &s in input {
        let out = c.on_sample(s);
        inside |= out.region == Some(1);
        if !inside {
            continue;
        }
        if let Some(GateAction::Start(t) | GateAction::Update(t)) = out.action {
            let hz = t.produced_millihz(clock) as f64 / 1e3;
            return Some((s.t_us.wrapping_sub(boundary_crossed_us), hz));
        }
    }
    None
}

/// The figures docs/sample-contract.md publishes: over [`ENTRY_SEEDS`] seeds at each of
/// 20, 50, 100, 200 mm/s both ways, the worst first-burst f_b error against |V|/λ, and the
/// restart's extra delay before the first burst, in sample periods (its window's warm-up: the
/// entry sample and 33 more fill the median's 3 and the slope's 32).
const ENTRY_SEEDS: std::ops::Range<u64> = 0..6;
const STATED_WORST_ENTRY_ERROR_PERCENT: f64 = 11.0;
/// The same for the restarted estimator's first burst (a later burst, from a fresh window).
const STATED_WORST_RESTART_ERROR_PERCENT: f64 = 20.0;
const STATED_RESTART_EXTRA_SAMPLES: u32 = 33;

/// The true crossing of the boundary in [`entry_strokes`]' strokes, µs.
const ENTRY_CROSSED_US: u32 = 60_000;

/// The strokes into the middle region (30–40 mm) of an entry scene: at 20, 50, 100, 200 mm/s,
/// both ways, [`ENTRY_SEEDS`] noise seeds each, warm before the boundary (60 ms of travel in the
/// region before it, crossed at [`ENTRY_CROSSED_US`]): (what, speed in mm/s, samples).
fn entry_strokes(cfg: &Config) -> impl Iterator<Item = (String, f64, Vec<Sample>)> + '_ {
    [20.0, 50.0, 100.0, 200.0]
        .into_iter()
        .flat_map(move |speed_mm_s| {
            [1.0, -1.0].into_iter().flat_map(move |dir| {
                ENTRY_SEEDS.map(move |seed| {
                    let speed = speed_mm_s * 1e3 * dir;
                    let boundary = if dir > 0.0 { 30_000.0 } else { 40_000.0 };
                    let stroke = Trajectory::Constant {
                        from_um: boundary - speed * ENTRY_CROSSED_US as f64 * 1e-6,
                        speed_um_s: speed,
                    };
                    let input = samples(cfg, &stroke, 0.075, seed, vec![]);
                    (
                        format!("{speed_mm_s} mm/s, dir {dir}, seed {seed}"),
                        speed_mm_s,
                        input,
                    )
                })
            })
        })
}

#[test]
fn entering_a_velocity_region_the_woken_estimator_bursts_as_the_background_one() {
    let cfg = config(ENTRY);
    let period = sample_period_us(&NUCLEO_F446RE);
    let (mut worst_percent, mut worst_restart_percent): (f64, f64) = (0.0, 0.0);
    for (what, speed_mm_s, input) in entry_strokes(&cfg) {
        let crossed_us = ENTRY_CROSSED_US;
        let mut background = controller(&cfg, default_estimator());
        background.velocity_every_sample(true);
        let today = first_burst(background, &input, crossed_us).expect(&what);
        let woken =
            first_burst(controller(&cfg, default_estimator()), &input, crossed_us).expect(&what);
        let restarted = first_burst(
            controller(&cfg, RestartOnEntry(default_estimator())),
            &input,
            crossed_us,
        )
        .expect(&what);
        // Seeded from the last positions = run in the background, exactly.
        assert_eq!(woken, today, "{what}");
        let want_hz = speed_mm_s; // |V| / λ with λ = 1 mm
        let err = (today.1 - want_hz).abs() / want_hz * 100.0;
        worst_percent = worst_percent.max(err);
        let restart_err = (restarted.1 - want_hz).abs() / want_hz * 100.0;
        worst_restart_percent = worst_restart_percent.max(restart_err);
        let extra = restarted.0 - today.0;
        eprintln!(
            "{what}: first burst {} µs after the crossing, {:.2} Hz ({err:.2} %); restart +{} µs",
            today.0, today.1, extra
        );
        assert!(
            extra >= STATED_RESTART_EXTRA_SAMPLES * period,
            "{what}: restart only {extra} µs later"
        );
    }
    eprintln!(
        "worst first-burst error {worst_percent:.2} % (restarted: {worst_restart_percent:.2} %)"
    );
    assert!(
        worst_percent <= STATED_WORST_ENTRY_ERROR_PERCENT,
        "{worst_percent}"
    );
    assert!(
        worst_restart_percent <= STATED_WORST_RESTART_ERROR_PERCENT,
        "{worst_restart_percent}"
    );
}

/// [`ENTRY`] with hybrid gratings (λ = 0.5 mm) either side: the finger comes from a region where
/// the estimator sleeps (the hybrid's own line is the velocity there).
const ENTRY_FROM_HYBRID: &str = r#"
[[region]]
kind = "grating"
until_mm = 30
wavelength_mm = 0.5
render = "hybrid"

[[region]]
kind = "grating"
until_mm = 40
wavelength_mm = 1.0
render = "velocity"

[[region]]
kind = "grating"
wavelength_mm = 0.5
render = "hybrid"
"#;

/// Leaving the hybrid's region, the sleeping estimator is seeded from the hybrid's line's newest
/// positions ("seed it from the last positions", issue #35): the first burst in the velocity
/// region that follows is the background estimator's, sample and f_b, on every entry at
/// 20–200 mm/s both ways over [`ENTRY_SEEDS`] (the line's window of 64 raw positions holds the
/// estimator's 34 whenever no glitch or turn emptied it in the last 3.4 ms).
#[test]
fn entering_a_velocity_region_from_the_hybrids_the_seeded_estimator_bursts_as_the_background_one() {
    let cfg = config(ENTRY_FROM_HYBRID);
    let mut entries = 0;
    for (what, _, input) in entry_strokes(&cfg) {
        let mut background = controller(&cfg, default_estimator());
        background.velocity_every_sample(true);
        let today = first_burst(background, &input, ENTRY_CROSSED_US).expect(&what);
        let seeded = first_burst(
            controller(&cfg, default_estimator()),
            &input,
            ENTRY_CROSSED_US,
        )
        .expect(&what);
        assert_eq!(seeded, today, "{what}");
        entries += 1;
    }
    assert_eq!(entries, 48);
}

/// Each board's controller has its plan's window: the first velocity comes on the window's
/// last sample (the median's three, then the slope's N), and the boards' range of windows ends
/// where saw-core's 32-bit sums do.
#[test]
fn each_board_estimates_over_its_own_window() {
    assert_eq!(
        *saw_boards::VELOCITY_WINDOWS.end(),
        saw_core::velocity::LSQ_NARROW_WINDOW
    );
    fn first_estimate_at<E: VelocityEstimator>(mut c: Controller<E>, input: &[Sample]) -> usize {
        input
            .iter()
            .position(|&s| c.on_sample(s).velocity_um_s.is_some())
            .expect("an estimate")
    }
    let cfg = config(ENTRY);
    let stroke = Trajectory::Constant {
        from_um: 32_000.0,
        speed_um_s: 20_000.0,
    };
    let input = samples(&cfg, &stroke, 0.05, 1, vec![]);
    for b in saw_boards::ALL {
        let (timer, period) = (burst_timer(b), sample_period_us(b));
        let at = match b.velocity_window {
            26 => first_estimate_at(
                {
                    let mut c =
                        Controller::<WindowEstimator<26>>::with_window(timer, period).unwrap();
                    c.load(&cfg).unwrap();
                    c
                },
                &input,
            ),
            32 => first_estimate_at(
                {
                    let mut c = Controller::new(timer, period).unwrap();
                    c.load(&cfg).unwrap();
                    c
                },
                &input,
            ),
            w => panic!("{}: window {w} has no controller type in this test", b.name),
        };
        // Sample index (from 0) of the first estimate: 2 for the median, then N − 1 more.
        assert_eq!(at, b.velocity_window + 1, "{}", b.name);
    }
}
