//! No runt and no doubled pulse when f_b changes, through the real gate: `saw_core::Controller`
//! is driven sample by sample (10 kHz) and each gate action it emits goes to host-sim's timer
//! model at the sample's time. Every pulse on the recorded line must be whole: its on-time and
//! its period exactly the settings latched at its rise.
//!
//! - Scene reloads: one constant region whose f_b (log-uniform 10 Hz – 2 kHz) and duty change by
//!   reloading the scene, 400 times per run at random gaps, on both boards' timers and the 16-bit
//!   one, over several seeds.
//! - A velocity-synthesis grating under a finger whose speed swings 20 – 100 mm/s: f_b = |V|/λ
//!   changes on nearly every sample, several updates per burst period.
//! - Negative control: the same reloads on the 16-bit timer without preload must produce at
//!   least a computed minimum of malformed pulses (see `isolated_changes`), so the check is shown
//!   to see what preload prevents, on every seed.

use host_sim::timer::{TimerModel, Waveform};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_core::burst::{BurstCommand, BurstTimer, TimerSettings};
use saw_core::gate::GateAction;
use saw_core::sample::Sample;
use saw_core::texture::{Grating, GratingRender, Texture};
use saw_core::{default_config, Config, Controller};
use saw_tests::{timers, TIMER_16BIT_180MHZ};

/// Both boards sample at 10 kHz.
const PERIOD_US: u64 = 100;
/// About mid-substrate on the default calibration.
const MID_CODE: u16 = 32_768;
const SEEDS: [u64; 4] = [0x5a5_0001, 0x5a5_0002, 0x5a5_0003, 0x5a5_0004];
const CHANGES: usize = 400;

/// The controller and the timer model, in lock step.
struct Rig {
    c: Controller,
    tm: TimerModel,
    clock_hz: u64,
    t_us: u64,
    /// Every gate action the controller emitted, at its kernel-clock time.
    writes: Vec<(u64, GateAction)>,
}

impl Rig {
    fn new(timer: BurstTimer, preload: bool, config: &Config) -> Self {
        let mut c = Controller::new(timer, PERIOD_US as u32).unwrap();
        c.load(config).unwrap();
        Self {
            c,
            tm: TimerModel::new(timer.clock_hz, timer.counter_bits, preload),
            clock_hz: timer.clock_hz as u64,
            t_us: 0,
            writes: Vec::new(),
        }
    }

    /// One sample: the controller's action (if any) reaches the timer at the sample's time.
    fn sample(&mut self, code: u16) {
        let out = self.c.on_sample(Sample {
            code,
            t_us: self.t_us as u32,
        });
        if let Some(a) = out.action {
            let t = self.t_us * self.clock_hz / 1_000_000;
            self.tm.apply(t, a);
            self.writes.push((t, a));
        }
        self.t_us += PERIOD_US;
    }

    fn finish(self) -> (Waveform, Vec<(u64, GateAction)>, u32) {
        let end = self.t_us * self.clock_hz / 1_000_000;
        let errors = self.tm.protocol_errors;
        (self.tm.finish(end), self.writes, errors)
    }
}

/// The default configuration with one region, `texture`, over the whole substrate.
fn one_region(texture: Texture) -> Config {
    let mut cfg = default_config();
    cfg.scene.boundaries_um.clear();
    cfg.scene.textures.clear();
    cfg.scene.textures.push(texture).unwrap();
    cfg
}

/// The settings in force at a rise at `rise`: a Start latches at once (the rise is its UG), an
/// Update only at the next update event, so only one strictly before the rise counts. None when
/// the line was last switched off.
fn latched(writes: &[(u64, GateAction)], rise: u64) -> Option<TimerSettings> {
    let upto = writes.partition_point(|(t, _)| *t <= rise);
    writes[..upto].iter().rev().find_map(|(t, a)| match a {
        GateAction::Start(s) | GateAction::Pulse(s) => Some(Some(*s)),
        GateAction::Update(s) if *t < rise => Some(Some(*s)),
        GateAction::Update(_) => None,
        GateAction::Off => Some(None),
    })?
}

/// Pulses of a run against the settings latched at their rise.
#[derive(Debug)]
struct Malformed {
    /// Pulses that are not whole: on-time or period other than the latched settings (or a rise
    /// with the line switched off).
    bad: usize,
    /// Of those, the ones whose period (rise to next rise) is wrong.
    bad_period: usize,
    /// Of those, the ones whose on-time is wrong.
    bad_on: usize,
    /// All complete pulses.
    pulses: usize,
}

/// Checks every pulse: on-time and period (rise to next rise) exactly the settings latched at
/// the rise. The runs here emit no Off after the start (asserted), so every period is checked.
fn malformed(w: &Waveform, writes: &[(u64, GateAction)]) -> Malformed {
    assert!(
        !writes.iter().any(|(_, a)| *a == GateAction::Off),
        "an Off would cut a period; these runs have none"
    );
    let pulses = w.pulses();
    let mut m = Malformed {
        bad: 0,
        bad_period: 0,
        bad_on: 0,
        pulses: pulses.len(),
    };
    for p in &pulses {
        let Some(s) = latched(writes, p.rise) else {
            m.bad += 1;
            continue;
        };
        let bad_period = p.period().is_some_and(|per| per != s.period_clocks());
        let bad_on = p.on() != s.on_clocks();
        m.bad_period += bad_period as usize;
        m.bad_on += bad_on as usize;
        m.bad += (bad_period || bad_on) as usize;
    }
    m
}

/// Reloads at random gaps: half short (0.1 – 30 ms, often several per burst period), half long
/// (101 – 130 ms, longer than any period the 16-bit timer can run, see `isolated_changes`).
/// Returns the waveform, the controller's writes, the timer's protocol errors.
fn reloads(timer: BurstTimer, preload: bool, seed: u64) -> (Waveform, Vec<(u64, GateAction)>, u32) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cmd = |rng: &mut ChaCha8Rng| BurstCommand {
        burst_millihz: (10_000.0 * 200f64.powf(rng.random::<f64>())) as u32,
        duty_permille: rng.random_range(100..=500),
    };
    let first = cmd(&mut rng);
    let mut rig = Rig::new(timer, preload, &one_region(Texture::Constant(first)));
    for _ in 0..10 {
        rig.sample(MID_CODE);
    }
    for _ in 0..CHANGES {
        rig.c
            .load(&one_region(Texture::Constant(cmd(&mut rng))))
            .unwrap();
        let gap = if rng.random_bool(0.5) {
            rng.random_range(1..=300)
        } else {
            rng.random_range(1_010..=1_300)
        };
        for _ in 0..gap {
            rig.sample(MID_CODE);
        }
    }
    // 200 ms more: the last period ends and the next one rises.
    for _ in 0..2_000 {
        rig.sample(MID_CODE);
    }
    rig.finish()
}

/// Checks one run with preload: at least `min_pulses` pulses, every one whole, the timer
/// understood every action, and the controller started once and then only updated.
fn assert_whole(
    name: &str,
    w: &Waveform,
    writes: &[(u64, GateAction)],
    errors: u32,
    min_pulses: usize,
) -> usize {
    assert_eq!(errors, 0, "{name}: timer protocol errors");
    let Malformed { bad, pulses: n, .. } = malformed(w, writes);
    assert_eq!(bad, 0, "{name}: {bad} of {n} pulses malformed with preload");
    assert!(n >= min_pulses, "{name}: only {n} pulses");
    assert!(
        matches!(writes.first(), Some((_, GateAction::Start(_)))),
        "{name}: {:?}",
        writes.first()
    );
    let updates = writes
        .iter()
        .filter(|(_, a)| matches!(a, GateAction::Update(_)))
        .count();
    assert_eq!(updates + 1, writes.len(), "{name}: one Start, then Updates");
    // Every pulse equals one of the commanded settings (not merely "close").
    let set: std::collections::HashSet<(u64, u64)> = writes
        .iter()
        .filter_map(|(_, a)| match a {
            GateAction::Start(s) | GateAction::Update(s) => {
                Some((s.on_clocks(), s.period_clocks()))
            }
            _ => None,
        })
        .collect();
    for p in w.pulses().iter().filter(|p| p.next_rise.is_some()) {
        assert!(
            set.contains(&(p.on(), p.period().unwrap())),
            "{name}: {p:?}"
        );
    }
    eprintln!("{name}: {n} pulses, {updates} updates, 0 malformed with preload");
    updates
}

#[test]
fn preload_keeps_every_pulse_whole_across_scene_reloads() {
    for (name, timer) in timers() {
        for seed in SEEDS {
            let (w, writes, errors) = reloads(timer, true, seed);
            let name = format!("{name}, seed {seed:#x}");
            let updates = assert_whole(&name, &w, &writes, errors, CHANGES);
            // A reload whose plan equals the running one is no change; random f_b almost never.
            assert!(updates >= CHANGES - 4, "{name}: {updates} updates");
        }
    }
}

/// A velocity-synthesis grating, λ = 0.5 mm, under a finger at 60 mm/s ± 40 mm/s (2 Hz swing),
/// 6 → 60 mm in 0.9 s, ±3 LSB of noise per sample: f_b = |V|/λ swings 40 – 200 Hz. The
/// texture keeps its plan while the speed stays within 2^-5 of the one it was planned at
/// (`texture::motion::PLAN_HOLD`), so the gate updates on every 3 % of speed change: about
/// twice per burst period here (it was ten times and more when every sample re-planned), so
/// many periods still take an update mid-period. The speed never drops below the grating's
/// 7.5 mm/s stop threshold: one Start, then Updates.
#[test]
fn preload_keeps_every_pulse_whole_under_a_velocity_grating() {
    let grating = Grating {
        render: GratingRender::VelocitySynthesis,
        ..Grating::new(500)
    };
    let cfg = one_region(Texture::Grating(grating));
    for (name, timer) in timers() {
        for seed in SEEDS {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut rig = Rig::new(timer, true, &cfg);
            let mapper = *rig.c.mapper().unwrap();
            let w = 2.0 * std::f64::consts::PI * 2.0;
            for k in 0..9_000 {
                let t = k as f64 * PERIOD_US as f64 * 1e-6;
                let um = 6_000.0 + 60_000.0 * t + 40_000.0 / w * (w * t).sin();
                let noise = rng.random_range(-3..=3) as f32;
                let code = (mapper.code_at_um(um as f32) + noise).round() as u16;
                rig.sample(code);
            }
            let (wave, writes, errors) = rig.finish();
            let name = format!("{name} grating, seed {seed:#x}");
            // ≈ 0.87 s at 40 – 200 Hz: over 80 bursts, and more updates than periods.
            let updates = assert_whole(&name, &wave, &writes, errors, 80);
            let n = wave.pulses().len();
            assert!(updates >= 2 * n, "{name}: {updates} updates for {n} pulses");
        }
    }
}

/// The least numbers of malformed pulses the timer must produce without preload, from the
/// reloads that are alone in their burst period: (wrong periods, wrong on-times, `p_max`).
///
/// Without preload an Update writes ARR and CCR at once (PSC stays buffered until the update
/// event). In the period it lands in, with `a0`, `c0` running and the count at `cnt` ticks:
/// - the period ends at `a1 + 1` ticks, or — `a1` below the count — runs on to 2^16 ticks; a
///   CCR above the count while the line is low re-raises it (a doubled pulse), cutting the
///   period short at the write. So if `a1 ≠ a0` the period is not `a0`'s length (unless `a0` is
///   already 65 535, where the run-on happens to be the same length);
/// - while the line is high (`cnt < c0`) it falls at `c1` ticks, or at once if `c1 ≤ cnt`: if
///   `c1 ≠ c0` the on-time is not `c0`'s.
///
/// That holds for an update with no other write within `p_max` on either side, `p_max` being
/// the longest period the timer can run, 2^16 ticks at the largest prescaler written (10 Hz on
/// 180 MHz: PSC 274, 65 536 × 275 clocks = 100.12 ms): the previous write's own period has ended
/// before this one begins, so this period runs exactly the previous settings (which is also what
/// the check expects at its rise), and the next write comes after it ends, so no two such
/// updates share a period. Whether the line was high is read from the last rise strictly before
/// the write (the write's own edges, a doubled pulse's rise, are at its time; a period starting
/// exactly at the write is then not counted, which only lowers the minimum). On a 32-bit timer the run-on is 2^32 ticks —
/// 47.7 s at 90 MHz, longer than the whole run — so one early run-on would swallow every later
/// change into one period and the count could collapse to a single pulse: hence the 16-bit timer.
fn isolated_changes(
    w: &Waveform,
    writes: &[(u64, GateAction)],
    counter_bits: u8,
) -> (usize, usize, u64) {
    let settings = |a: &GateAction| match a {
        GateAction::Start(s) | GateAction::Update(s) => *s,
        other => panic!("{other:?}"),
    };
    let p_max = writes
        .iter()
        .map(|(_, a)| (settings(a).psc as u64 + 1) << counter_bits)
        .max()
        .unwrap();
    let (mut period, mut on) = (0, 0);
    for i in 1..writes.len() {
        let (t, a) = &writes[i];
        let (t_prev, prev) = &writes[i - 1];
        let t_next = writes.get(i + 1).map_or(w.end, |w| w.0);
        if t - t_prev <= p_max || t_next - t <= p_max {
            continue;
        }
        let (s, s0) = (settings(a), settings(prev));
        period += (s.arr != s0.arr && s0.arr != 65_535) as usize;
        let rise = *w.rises_in(0, *t).last().unwrap();
        on += (t - rise < s0.on_clocks() && s.ccr != s0.ccr) as usize;
    }
    (period, on, p_max)
}

#[test]
fn without_preload_the_same_reloads_make_at_least_one_runt_per_isolated_change() {
    let timer = TIMER_16BIT_180MHZ;
    for seed in SEEDS {
        let (w, writes, errors) = reloads(timer, false, seed);
        assert_eq!(errors, 0);
        let (min_period, min_on, p_max) = isolated_changes(&w, &writes, timer.counter_bits);
        // The long gaps (≥ 101 ms) exceed every period, so about a quarter of the changes
        // (a long gap on both sides) are isolated, and about 30 % of those land while the line
        // is high (duty 10 – 50 %).
        assert!(
            p_max < 101 * timer.clock_hz as u64 / 1_000,
            "p_max {p_max} clocks"
        );
        assert!(
            min_period >= CHANGES / 8 && min_on >= CHANGES / 40,
            "seed {seed:#x}: only {min_period} / {min_on} isolated changes"
        );
        let m = malformed(&w, &writes);
        eprintln!(
            "16-bit, seed {seed:#x}: without preload {} of {} pulses malformed ({} with a wrong \
             period, {} with a wrong on-time), minimum {min_period} and {min_on}",
            m.bad, m.pulses, m.bad_period, m.bad_on
        );
        assert!(
            m.bad_period >= min_period && m.bad_on >= min_on,
            "seed {seed:#x}: {m:?} without preload, fewer than the {min_period} wrong periods and \
             {min_on} wrong on-times the isolated changes must leave — the check is partly blind"
        );
    }
}
