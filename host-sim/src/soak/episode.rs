//! One soak episode: a scene, a finger, sensor faults and mid-stroke scene events, drawn from
//! (seed, episode index) alone, run through [`ClosedLoop::step`] and checked sample by sample.
//!
//! Time: the soak's clocks are u64 (global sample index `k`, µs `k · P`). The closed loop runs
//! each episode on a local sample index `k mod M` with `M · P` a multiple of 2^32 µs, so the
//! u32 µs the ADC model stamps on each sample (`t_us as u32`) is exactly the board's wrapping
//! clock at global sample `k`, while the timer model's kernel clocks stay far from u64 overflow
//! (`M · P` ≤ 2^32 · P µs) however long the soak runs. An episode that holds a multiple of
//! 2^32 µs crosses the core's wrap with a running scene.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_core::burst::TimerSettings;
use saw_core::controller::RECOVERY_SAMPLES;
use saw_core::gate::GateAction;
use saw_core::sample::Sample;
use saw_core::{Config, Controller};

use super::check::{LineCheck, Rule, Violation};
use super::gen;
use crate::adc::{FaultKind, FaultWindow};
use crate::sim::{burst_timer, sample_period_us, ClosedLoop, SimParams};
use crate::timer::{Edge, LevelEdge};

/// Samples per episode: 1 s at the boards' 10 kHz. Episode `e` holds global samples
/// `e · EPISODE_SAMPLES ..` and is drawn from (seed, e) alone.
pub const EPISODE_SAMPLES: u64 = 10_000;
/// Samples after a refused load over which the controller must do exactly what a copy taken
/// before the refusal does (20 ms; cut short by the episode's next event).
pub const REFUSAL_WATCH_SAMPLES: u64 = 200;
/// The longest stale limit a random scene gets, µs (`gen::random_config`).
const MAX_STALE_US: u64 = 10_000;

/// A defect planted in the soak's own harness (never in the core), to show the checks catch
/// it: each tampers with what reaches the timer model after the core's step, as a faulty port
/// would.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Plant {
    /// Nothing planted: the real soak.
    #[default]
    None,
    /// The port ignores the duty cap: every periodic setting's on-time stretched to all but one
    /// tick of its period.
    DutyCap,
    /// The port keeps the carrier on when the core turns it off for a sensor fault.
    CarrierOnFault,
    /// The port restarts the counter on every update instead of preloading it (a doubled or
    /// stretched pulse each time).
    DoubledPulse,
    /// After a refused scene the harness loads the built-in default scene (a device that resets
    /// on a bad upload).
    ResetOnRefusal,
    /// `--plane` only: the port restarts the burst when the core turns it off for a lift-off.
    CarrierOnLift,
}

/// What happened mid-episode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Event {
    /// A new random scene.
    Reload,
    /// A boundary of the running scene moved.
    MoveBoundary,
    /// The running scene broken on purpose and sent: the core must refuse it.
    Refuse,
}

/// What one episode did and found.
#[derive(Clone, Debug, Default)]
pub struct EpisodeReport {
    /// Episode index.
    pub episode: u64,
    /// Samples run.
    pub samples: u64,
    /// CRC-64 of the enable line's edges (time from the episode's start, level).
    pub checksum: u64,
    /// Pulses judged.
    pub pulses: u64,
    /// Fault windows injected, by [`gen::SOAK_FAULTS`] kind (only those starting within the
    /// samples run).
    pub faults: [u64; gen::SOAK_FAULTS.len()],
    /// Scenes loaded mid-episode.
    pub reloads: u64,
    /// Boundary moves loaded.
    pub boundary_moves: u64,
    /// Loads refused (scenes broken on purpose and random scenes the core found bad).
    pub refusals: u64,
    /// Of those, scenes broken on purpose.
    pub broken: u64,
    /// Samples compared against the controller's copy after refusals.
    pub refusal_samples: u64,
    /// Samples whose sensor reading the injected faults hold off.
    pub off_samples: u64,
    /// Violations found.
    pub violations: u64,
    /// Violations found, by [`Rule::index`].
    pub by_rule: [u64; Rule::ALL.len()],
    /// The first few, with their global sample index.
    pub kept: Vec<Violation>,
    /// Whether the episode crossed the core's 2^32 µs wrap.
    pub wrapped: bool,
    /// `--plane`: the board's frame period, µs (what a sample lasts).
    pub frame_us: u32,
    /// `--plane`: edge pulses fired (the core's `Output2d::edge`).
    pub edge_pulses: u64,
    /// `--plane`: edge crossings the core skipped (`Telemetry2d::edges_skipped`).
    pub edges_skipped: u64,
    /// `--plane`: oriented-grating ridge pulses.
    pub ridge_pulses: u64,
    /// `--plane`: a rendering finger lifted (`Telemetry2d::lifts`).
    pub lifts: u64,
    /// `--plane`: the finger's pieces by [`super::gen2d::MOVES`] kind.
    pub moves: [u64; super::gen2d::MOVES.len()],
}

/// The reference for the fault rule (`tests/tests/safety_fuzz.rs` `must_be_off`, online): the
/// injected windows say when the line must be off, not the core's own fault report.
///
/// One refinement over the fuzz's allowance: the fuzz lets the stale watchdog fire up to a
/// sample period late, and so may start a fresh 16-sample recovery count where the core, already
/// stale from an earlier gap (a spike train inside a dropout: samples between gaps just over the
/// limit), goes on counting. Here the count starts where the core's watchdog fires (at the tick
/// half a period after the first sample period whose silence exceeds the running scene's
/// limit), and the line must be off from the next sample period on: the same allowance for the
/// line, and the core's own count.
#[derive(Clone, Copy, Debug, Default)]
struct FaultRef {
    last_sample_us: Option<u64>,
    /// Good samples still owed before the line may go on again; None when no fault is in force.
    recovering: Option<u16>,
}

impl FaultRef {
    /// Whether sample period `t_us` must be off, given the fault the ADC model has then and the
    /// running scene's stale limit.
    fn off(&mut self, t_us: u64, period_us: u64, stale_us: u64, fault: Option<FaultKind>) -> bool {
        match fault {
            Some(FaultKind::Open | FaultKind::Short) => {
                self.last_sample_us = Some(t_us);
                self.recovering = Some(RECOVERY_SAMPLES - 1);
                true
            }
            Some(FaultKind::Dropout) => {
                // A fault already in force is left alone (the core does not restart its count
                // when the sensor goes quiet again).
                if self.recovering.is_none()
                    && self
                        .last_sample_us
                        .is_some_and(|l| t_us + period_us / 2 > l + stale_us)
                {
                    // The watchdog fires at this period's tick: off from the next period.
                    self.recovering = Some(RECOVERY_SAMPLES - 1);
                    return false;
                }
                self.recovering.is_some()
            }
            // An offset is a good sample for the reference; one that reaches a rail is a
            // fault the core reports, checked by the core-report rule.
            None | Some(FaultKind::Spike { .. } | FaultKind::Drift { .. }) => {
                self.last_sample_us = Some(t_us);
                match self.recovering {
                    Some(0) | None => {
                        self.recovering = None;
                        false
                    }
                    Some(m) => {
                        self.recovering = Some(m - 1);
                        true
                    }
                }
            }
        }
    }
}

/// The CRC the checksums use (CRC-64/XZ).
pub static CRC64: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);

/// The episode's generator: (seed, episode) alone, so any episode runs by itself.
pub fn episode_rng(seed: u64, episode: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(episode);
    rng
}

/// The local index modulus: `M · period_us` is a multiple of 2^32, so local and global sample
/// times agree modulo 2^32 µs.
fn local_modulus(period_us: u64) -> u64 {
    1u64 << (32 - period_us.trailing_zeros().min(32))
}

/// A scene the core loads, drawn for `board_max_hz` (the default scene after 16 refused draws).
fn loadable_config(
    rng: &mut ChaCha8Rng,
    timer: &saw_core::burst::BurstTimer,
    period_us: u32,
) -> Config {
    for _ in 0..16 {
        let cfg = gen::random_config(rng, timer.max_burst_hz);
        if saw_core::controller::Prepared::compile(timer, period_us, &cfg).is_ok() {
            return cfg;
        }
    }
    saw_core::default_config()
}

/// Runs episode `episode` of seed `seed` for its first `samples` samples (at most
/// [`EPISODE_SAMPLES`]; fewer reproduces a prefix exactly), with `plant` in the harness.
pub fn run_episode(seed: u64, episode: u64, samples: u64, plant: Plant) -> EpisodeReport {
    let samples = samples.min(EPISODE_SAMPLES);
    let mut rng = episode_rng(seed, episode);
    let board = &saw_boards::ALL[rng.random_range(0..saw_boards::ALL.len())];
    let timer = burst_timer(board);
    let period_us = sample_period_us(board) as u64;
    let clock_hz = timer.clock_hz as u64;
    let clk = |t_us: u64| t_us * clock_hz / 1_000_000;
    let global0 = episode * EPISODE_SAMPLES;
    let local0 = global0 % local_modulus(period_us);
    let t0_us = local0 * period_us;
    let mut report = EpisodeReport {
        episode,
        samples,
        ..EpisodeReport::default()
    };
    let global_t0_us = global0 * period_us;
    report.wrapped =
        (global_t0_us + samples * period_us - 1) >> 32 != global_t0_us >> 32 && samples > 0;

    let mut cfg = loadable_config(&mut rng, &timer, period_us as u32);
    let duration_us = EPISODE_SAMPLES * period_us;
    let trajectory = gen::soak_trajectory(&mut rng, duration_us as f64 * 1e-6);
    let tagged = gen::soak_faults(&mut rng, duration_us, period_us, MAX_STALE_US);
    let faults: Vec<FaultWindow> = tagged
        .iter()
        .map(|(_, f)| FaultWindow {
            start_us: f.start_us + t0_us,
            end_us: f.end_us + t0_us,
            ..*f
        })
        .collect();
    for (tag, f) in &tagged {
        if f.start_us < samples * period_us {
            report.faults[*tag] += 1;
        }
    }
    let noise = rng.random_range(0.0..4.0);
    let noise_seed = rng.random();
    let mut events: Vec<(u64, Event)> = (0..rng.random_range(0..=3))
        .map(|_| {
            let at = rng.random_range(EPISODE_SAMPLES / 20..EPISODE_SAMPLES);
            let e = match rng.random_range(0..10) {
                0..=3 => Event::Reload,
                4..=6 => Event::MoveBoundary,
                _ => Event::Refuse,
            };
            (at, e)
        })
        .collect();
    events.sort_by_key(|e| e.0);

    let params = SimParams::new(
        board,
        crate::trajectory::Trajectory::Rest { at_um: 0.0 },
        0.0,
    )
    .with_config(cfg.clone())
    .with_faults(faults)
    .with_noise(noise, noise_seed);
    let ctrl = match crate::sim::board_controller(board) {
        Ok(c) => c,
        Err(e) => return refused_board(report, global0, &e.to_string()),
    };
    let mut lp = match ClosedLoop::new(&params, ctrl) {
        Ok(lp) => lp,
        Err(e) => return refused_board(report, global0, &e.to_string()),
    };
    let period_clocks = clk(period_us);
    let mut check = LineCheck::new(
        timer,
        period_clocks,
        global0.wrapping_sub(local0),
        &cfg.limits,
    );
    let mut fref = FaultRef::default();
    let mut digest = CRC64.digest();
    let mut edges: Vec<Edge> = Vec::new();
    // The DAC changes the timer hands over with the edges: no rule reads them.
    let mut levels: Vec<LevelEdge> = Vec::new();
    let base_clk = clk(t0_us);
    let mut next_event = 0;
    // The controller as it was before a refused load, and the last sample to compare it on.
    let mut shadow: Option<(Controller<crate::sim::BoardEstimator>, u64)> = None;
    // The last periodic settings the core issued (for the carrier-on-fault plant).
    let mut last_settings: Option<TimerSettings> = None;

    for i in 0..samples {
        let k = local0 + i;
        let t_us = k * period_us;
        let global = global0 + i;
        while let Some(&(at, ev)) = events.get(next_event) {
            if at != i {
                break;
            }
            next_event += 1;
            shadow = None;
            let before = lp.ctrl.clone();
            let (next, broken) = match ev {
                Event::Reload => (loadable_or_not(&mut rng, &timer), false),
                Event::MoveBoundary => match moved_boundary(&mut rng, &cfg) {
                    Some(c) => (c, false),
                    None => (loadable_or_not(&mut rng, &timer), false),
                },
                Event::Refuse => (gen::broken_config(&mut rng, &cfg).1, true),
            };
            match lp.ctrl.load(&next) {
                Ok(()) => {
                    if broken {
                        check.violate(
                            Rule::BrokenSceneAccepted,
                            global,
                            "a scene broken on purpose loaded".to_string(),
                        );
                    } else if ev == Event::MoveBoundary {
                        report.boundary_moves += 1;
                    } else {
                        report.reloads += 1;
                    }
                    cfg = next;
                    check.scene(&cfg.limits, clk(t_us));
                }
                Err(_) => {
                    report.refusals += 1;
                    report.broken += u64::from(broken);
                    if plant == Plant::ResetOnRefusal {
                        let _ = lp.ctrl.load(&saw_core::default_config());
                    }
                    let until = events
                        .get(next_event)
                        .map_or(u64::MAX, |e| e.0)
                        .min(i + REFUSAL_WATCH_SAMPLES);
                    shadow = Some((before, until));
                }
            }
        }

        let off = fref.off(
            t_us,
            period_us,
            cfg.stale_after_us as u64,
            lp.adc.fault_at(t_us),
        );
        if off {
            check.must_be_off(k);
            report.off_samples += 1;
        }
        let state = trajectory.state((i * period_us) as f64 * 1e-6);
        let point = lp.step(k, state);
        let tick_us = t_us + period_us / 2;
        let action_t = if point.sampled {
            clk(t_us)
        } else {
            clk(tick_us)
        };
        if let Some(GateAction::Start(s) | GateAction::Update(s)) = point.action {
            last_settings = Some(s);
        }
        tamper(plant, &mut lp, &point, last_settings);

        if let Some((sh, until)) = shadow.as_mut() {
            let out = point.code.map(|code| {
                sh.on_sample(Sample {
                    code,
                    t_us: t_us as u32,
                })
            });
            let tick = sh.on_tick(tick_us as u32);
            let expected = tick.or(out.and_then(|o| o.action));
            report.refusal_samples += 1;
            if expected != point.action || sh.telemetry() != lp.ctrl.telemetry() {
                check.violate(
                    Rule::RefusalChangedScene,
                    global,
                    format!(
                        "after a refused load the controller acts {:?} (region {:?}), the scene \
                         before it {:?} (region {:?})",
                        point.action,
                        lp.ctrl.telemetry().region,
                        expected,
                        sh.telemetry().region
                    ),
                );
                shadow = None;
            } else if i + 1 >= *until {
                shadow = None;
            }
        }
        if point.fault.is_some() && point.gate {
            check.violate(
                Rule::OnWhileReportedFault,
                global,
                format!("the line high with the core reporting {:?}", point.fault),
            );
        }
        lp.tm.take_settled(&mut edges, &mut levels);
        hash_edges(&mut digest, &edges, base_clk);
        check.step(point.action.map(|a| (action_t, a)), &edges, lp.tm.now());
    }
    // The timer runs on to the episode's end (the last step stopped at its tick), so a pulse
    // that rose late is judged whole.
    let end = clk((local0 + samples) * period_us);
    lp.tm.advance_to(end);
    lp.tm.take_settled(&mut edges, &mut levels);
    hash_edges(&mut digest, &edges, base_clk);
    check.step(None, &edges, end);
    check.finish(end);
    if lp.tm.protocol_errors > 0 {
        check.violate(
            Rule::TimerProtocol,
            global0 + samples.saturating_sub(1),
            format!(
                "{} actions the timer model could not apply",
                lp.tm.protocol_errors
            ),
        );
    }
    report.checksum = digest.finalize();
    report.pulses = check.pulses;
    report.violations = check.count;
    report.by_rule = check.by_rule;
    report.kept = check.kept;
    report
}

/// A random scene, loadable or not (about one in ten is refused: that is a refusal too).
/// Adds `edges` to the episode's checksum: each edge's time from the episode's start and its
/// level.
fn hash_edges(digest: &mut crc::Digest<'_, u64>, edges: &[Edge], base_clk: u64) {
    for e in edges {
        digest.update(&(e.t - base_clk).to_le_bytes());
        digest.update(&[u8::from(e.high)]);
    }
}

fn loadable_or_not(rng: &mut ChaCha8Rng, timer: &saw_core::burst::BurstTimer) -> Config {
    gen::random_config(rng, timer.max_burst_hz)
}

/// The running scene with one boundary moved strictly between its neighbours (None without
/// boundaries).
fn moved_boundary(rng: &mut ChaCha8Rng, cfg: &Config) -> Option<Config> {
    let b = &cfg.scene.boundaries_um;
    if b.is_empty() {
        return None;
    }
    let i = rng.random_range(0..b.len());
    let lo = if i == 0 { 0 } else { b[i - 1] } + 1;
    let hi = b.get(i + 1).copied().unwrap_or(cfg.calibration.length_um);
    if hi <= lo + 1 {
        return None;
    }
    cfg.with_boundary(i as u8, rng.random_range(lo..hi)).ok()
}

/// The planted defect's tampering with the timer after the core's step, at the time the
/// timer has reached (where the core's own action took effect).
fn tamper<E: saw_core::velocity::VelocityEstimator>(
    plant: Plant,
    lp: &mut ClosedLoop<E>,
    point: &crate::sim::TracePoint,
    last: Option<TimerSettings>,
) {
    let now = lp.tm.now();
    match (plant, point.action) {
        (Plant::DutyCap, Some(GateAction::Start(s))) => {
            lp.tm.apply(now, GateAction::Start(stretched(s)));
        }
        (Plant::DutyCap, Some(GateAction::Update(s))) => {
            lp.tm.apply(now, GateAction::Update(stretched(s)));
        }
        (Plant::CarrierOnFault, Some(GateAction::Off)) if point.fault.is_some() => {
            if let Some(s) = last {
                lp.tm.apply(now, GateAction::Start(s));
            }
        }
        (Plant::DoubledPulse, Some(GateAction::Update(s))) => {
            lp.tm.apply(now, GateAction::Start(s));
        }
        _ => {}
    }
}

/// `s` with its on-time stretched to all but one tick of its period.
fn stretched(s: TimerSettings) -> TimerSettings {
    TimerSettings {
        ccr: s.arr.max(s.ccr),
        ..s
    }
}

/// An episode that could not start (the board refused by the controller): reported as a
/// violation rather than a panic.
fn refused_board(mut report: EpisodeReport, global0: u64, why: &str) -> EpisodeReport {
    report.violations = 1;
    report.by_rule[Rule::TimerProtocol.index()] += 1;
    report.kept.push(Violation {
        rule: Rule::TimerProtocol,
        sample: global0,
        detail: format!("the episode could not start: {why}"),
    });
    report
}
