//! One episode of the plane soak (`host-sim soak --plane`, docs/soak.md "The plane"): a random
//! 2D scene, a finger that strokes, circles, rests on and trembles across edges, jumps, lifts
//! off and lands, touch faults, and mid-stroke reloads, window moves and refused scenes, drawn
//! from (seed, episode) alone, run frame by frame through the core's `TouchSensor` and
//! `Controller2d` into the burst-timer model, and checked online: the 1D soak's line rules
//! ([`LineCheck`]: on-time and duty caps, runts, doubled pulses, a refusal keeps the scene, the
//! line off during a fault and while the core reports one) plus the plane's own: the line off
//! while the finger is lifted or landing, and no edge pulsing twice for one crossing.
//!
//! The sensor: frames are built from the finger as a 4-wire overlay reads it (X and Y codes
//! linear across the 95 × 54 mm screen, 16-conversion sums with noise; Z1/Z2 from the contact
//! resistance by the TSC2101 formula the core inverts; no contact when lifted) and go through
//! the core's [`TouchSensor`] (pressure thresholds, rail bands, three-point calibration), so
//! landing runs, lift-offs and per-axis rail faults are the sensor's own.
//!
//! Time: each episode runs on the board's frame period `P` (the touch schedule's, about 346 µs
//! on the F446 and 255 µs on the G474); frame `i` of episode `e` is global sample
//! `k = e · EPISODE_SAMPLES + i`, stamped `(k · P) mod 2^32` µs for the core (its wrapping
//! clock), while the timer model counts from the episode's start.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_core::burst::TimerSettings;
use saw_core::controller::RECOVERY_SAMPLES;
use saw_core::gate::GateAction;
use saw_core::plane::{Config2d, Controller2d, Prepared2d};
use saw_core::sample::CODE_FULL_SCALE;
use saw_core::touch::calibration::{Affine, CalPoint};
use saw_core::touch::fault::RailBands;
use saw_core::touch::frame::{Frame, Reading, TouchSensor};
use saw_core::touch::pressure::PressureConfig;

use super::check::{LineCheck, Rule, Violation};
use super::episode::{episode_rng, EpisodeReport, Plant, CRC64, EPISODE_SAMPLES};
use super::gen2d::{self, Piece, TouchFaultWindow, FAULTS_2D, SCREEN_UM};
use crate::sim::burst_timer;
use crate::sim2d::{board_frame_period_us, scene_edges, EdgeGeom};
use crate::timer::{Edge, LevelEdge, TimerModel};

/// Readings after a refused load over which the controller must do exactly what a copy taken
/// before the refusal does.
const REFUSAL_WATCH: u64 = super::episode::REFUSAL_WATCH_SAMPLES;

/// The overlay's codes: X from `X_CODES.0` at the screen's left to `.1` at its right (the
/// drivers' drops keep the ends off the rails), Y likewise.
const X_CODES: (f64, f64) = (6_000.0, 59_000.0);
const Y_CODES: (f64, f64) = (7_000.0, 58_000.0);
/// The plate resistance the pressure formula uses (`PressureConfig::DEFAULT`), Ω.
const R_X_OHM: f64 = 700.0;
/// A code certainly in a rail band (1 % of full scale, 655 codes, at either end: docs/touch.md
/// "Faults"), with one code of margin so the reference never calls a frame faulty the sensor
/// may read as good.
const RAIL_LOW_SURE: u16 = 654;
const RAIL_HIGH_SURE: u16 = (CODE_FULL_SCALE - 1 - 655 + 2) as u16;

fn code(frac: f64, codes: (f64, f64)) -> f64 {
    codes.0 + frac.clamp(0.0, 1.0) * (codes.1 - codes.0)
}

/// The sensor as a panel's three-point calibration sets it up: touches at (0.1, 0.1),
/// (0.9, 0.5) and (0.5, 0.9) of the screen.
fn sensor() -> Result<TouchSensor, String> {
    let cal = [(0.1, 0.1), (0.9, 0.5), (0.5, 0.9)].map(|(x, y)| CalPoint {
        x_code: code(x, X_CODES).round() as u16,
        y_code: code(y, Y_CODES).round() as u16,
        x_um: (x * SCREEN_UM.0 as f64).round() as i32,
        y_um: (y * SCREEN_UM.1 as f64).round() as i32,
    });
    let map = Affine::from_points(cal, &RailBands::default()).map_err(|e| e.to_string())?;
    TouchSensor::new(PressureConfig::DEFAULT, RailBands::default(), map).map_err(|e| e.to_string())
}

/// What one frame is, by what was injected (not by what the core reads).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Truth {
    /// No frame came (a dropped frame or a stale gap).
    Missing,
    /// The finger is off the plate.
    Lifted,
    /// Pressed, with an axis certainly on a rail.
    Rail,
    /// Pressed, both axes off the rails.
    Good,
}

/// The reference for the line-off rules: off on a lifted or railed frame and until the 16th
/// pressed good frame after it (the landing run and the recovery run: `RECOVERY_SAMPLES`, the
/// 16th may run), and from the period after the watchdog's tick finds the silence longer than
/// the running scene's stale limit (the 1D soak's `FaultRef`, frames for samples).
#[derive(Clone, Copy, Debug)]
struct Ref2d {
    last_us: Option<u64>,
    owed: Option<u16>,
    why: Rule,
}

impl Ref2d {
    /// A sensor that has seen no finger yet: the first touch lands.
    fn new() -> Self {
        Self {
            last_us: None,
            owed: Some(RECOVERY_SAMPLES - 1),
            why: Rule::OnWhileLifted,
        }
    }

    fn off(&mut self, t_us: u64, period_us: u64, stale_us: u64, truth: Truth) -> Option<Rule> {
        match truth {
            Truth::Lifted | Truth::Rail => {
                self.last_us = Some(t_us);
                self.owed = Some(RECOVERY_SAMPLES - 1);
                self.why = if truth == Truth::Lifted {
                    Rule::OnWhileLifted
                } else {
                    Rule::OnDuringFault
                };
                Some(self.why)
            }
            Truth::Missing => {
                if self.owed.is_none()
                    && self
                        .last_us
                        .is_some_and(|l| t_us + period_us / 2 > l + stale_us)
                {
                    self.owed = Some(RECOVERY_SAMPLES - 1);
                    self.why = Rule::OnDuringFault;
                    return None;
                }
                self.owed.map(|_| self.why)
            }
            Truth::Good => {
                self.last_us = Some(t_us);
                match self.owed {
                    Some(0) | None => {
                        self.owed = None;
                        None
                    }
                    Some(m) => {
                        self.owed = Some(m - 1);
                        Some(self.why)
                    }
                }
            }
        }
    }
}

/// The edge rule, from docs/plane.md's statement of the edges ("disarmed after, until the
/// finger is `rearm_um` clear of both the line and where it fired"; an edge forgets on a lift,
/// a fault, a load or leaving its zone, and re-arms only `rearm_um` clear of its line): between
/// two pulses of one edge, some reading the core rendered puts the finger at least the re-arm
/// distance from that edge's line. Distances are host-sim's own (`sim2d::scene_edges`, f64).
#[derive(Clone, Debug, Default)]
pub struct EdgeRef {
    geoms: Vec<EdgeGeom>,
    rearm_mm: f64,
    /// Per edge: the global sample of its last pulse, and whether the finger was clear since.
    last: Vec<Option<(u64, bool)>>,
    uncleared: usize,
    /// The last rendered reading stopped the line with no edge: an edge crossing waits for its
    /// pulse on this reading (docs/plane.md: an edge preempts a running burst).
    stopped: bool,
}

impl EdgeRef {
    /// The edges of `cfg`, none fired yet.
    pub fn new(cfg: &Config2d) -> Self {
        let geoms = scene_edges(&cfg.scene);
        Self {
            last: vec![None; geoms.len()],
            geoms,
            rearm_mm: cfg.scene.rearm_um as f64 / 1e3,
            uncleared: 0,
            stopped: false,
        }
    }

    /// A reading the core rendered at `p` (µm), at global sample `k`, with the edge it fired
    /// and whether it turned the line off; Some(the previous pulse's sample) when `edge` fired
    /// again with no clearing in between.
    ///
    /// A pulse that follows a stop (the crossing was found on the reading before, which stopped
    /// the texture's burst) comes on a reading after its crossing: that reading may clear it.
    pub fn rendered(&mut self, k: u64, p: (i32, i32), edge: Option<u8>, off: bool) -> Option<u64> {
        let pm = (p.0 as f64 / 1e3, p.1 as f64 / 1e3);
        let mut repeat = None;
        let after_stop = std::mem::replace(&mut self.stopped, off && edge.is_none());
        let fired = edge.map(usize::from).filter(|_| !after_stop);
        if let Some(e) = edge.map(usize::from) {
            if let Some(slot) = self.last.get_mut(e) {
                match *slot {
                    Some((at, false)) => repeat = Some(at),
                    _ => self.uncleared += 1,
                }
                *slot = Some((k, false));
            }
        }
        if self.uncleared > 0 {
            // 1 µm below the distance: the core's f32 arithmetic may re-arm a hair early.
            let clear = self.rearm_mm - 1e-3 - 1e-9;
            for (i, slot) in self.last.iter_mut().enumerate() {
                if Some(i) == fired {
                    continue;
                }
                if let (Some((at, false)), Some(g)) = (*slot, self.geoms.get(i)) {
                    if g.signed_distance_mm(pm).abs() >= clear {
                        *slot = Some((at, true));
                        self.uncleared -= 1;
                    }
                }
            }
        }
        repeat
    }
}

/// What happened mid-episode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Event {
    Reload,
    MoveWindow,
    Refuse,
}

/// A 2D scene the core loads (the default scene after 16 refused draws).
fn loadable_config2d(
    rng: &mut ChaCha8Rng,
    timer: &saw_core::burst::BurstTimer,
    frame_us: u32,
) -> Config2d {
    for _ in 0..16 {
        let cfg = gen2d::random_config2d(rng, timer.max_burst_hz);
        if Prepared2d::compile(timer, frame_us, &cfg).is_ok() {
            return cfg;
        }
    }
    Config2d::default()
}

/// Triangular noise of half-width `n` codes.
fn noise(rng: &mut ChaCha8Rng, n: i32) -> i32 {
    if n == 0 {
        return 0;
    }
    (rng.random_range(-n..=n) + rng.random_range(-n..=n)) / 2
}

fn clamp_code(c: f64) -> u16 {
    c.round().clamp(0.0, CODE_FULL_SCALE as f64) as u16
}

/// The frame the overlay gives with the finger at `at` (µm) pressing through `r_touch_ohm`, or
/// lifted (`None`), under the faults in force; and what it truly is.
fn frame(
    rng: &mut ChaCha8Rng,
    at: Option<((f64, f64), f64)>,
    faults: &[TouchFaultWindow],
    i: u64,
    noise_codes: i32,
    t_us: u32,
) -> (Frame, Truth) {
    let Some(((x, y), r)) = at else {
        // The floating plate: anything on X and Y, Z1 below the no-contact floor.
        let f = Frame {
            x_code: rng.random_range(0..=CODE_FULL_SCALE as u16),
            y_code: rng.random_range(0..=CODE_FULL_SCALE as u16),
            z1_code: rng.random_range(0..=600),
            z2_code: rng.random_range(0..=CODE_FULL_SCALE as u16),
            t_us,
        };
        return (f, Truth::Lifted);
    };
    let xt = code(x / SCREEN_UM.0 as f64, X_CODES);
    let yt = code(y / SCREEN_UM.1 as f64, Y_CODES);
    let (mut xc, mut yc) = (
        xt + noise(rng, noise_codes) as f64,
        yt + noise(rng, noise_codes) as f64,
    );
    // Z2/Z1 − 1 = R · full scale / (R_x · X): Z1 as large as keeps Z2 in range.
    let ratio = r * CODE_FULL_SCALE as f64 / (R_X_OHM * xt);
    let z1 = (20_000.0f64).min(65_000.0 / (1.0 + ratio));
    let z2 = z1 * (1.0 + ratio);
    let zn = noise_codes / 4;
    let (z1, z2) = (z1 + noise(rng, zn) as f64, z2 + noise(rng, zn) as f64);
    for f in faults.iter().filter(|f| (f.start..f.end).contains(&i)) {
        let rail = |rng: &mut ChaCha8Rng| {
            if f.high {
                CODE_FULL_SCALE as f64 - rng.random_range(0.0..300.0)
            } else {
                rng.random_range(0.0..300.0)
            }
        };
        match f.tag {
            0 => xc = rail(rng),
            1 => yc = rail(rng),
            2 => (xc, yc) = (rail(rng), rail(rng)),
            5 | 6 => {
                xc += f.offset.0 as f64;
                yc += f.offset.1 as f64;
            }
            _ => {}
        }
    }
    let fr = Frame {
        x_code: clamp_code(xc),
        y_code: clamp_code(yc),
        z1_code: clamp_code(z1),
        z2_code: clamp_code(z2),
        t_us,
    };
    let railed = |c: u16| c <= RAIL_LOW_SURE || c >= RAIL_HIGH_SURE;
    let truth = if railed(fr.x_code) || railed(fr.y_code) {
        Truth::Rail
    } else {
        Truth::Good
    };
    (fr, truth)
}

/// The planted defect's tampering with the timer after the core's reading (a faulty port).
fn tamper(
    plant: Plant,
    tm: &mut TimerModel,
    at: u64,
    action: Option<GateAction>,
    reading: Option<Reading>,
    last: Option<TimerSettings>,
) {
    let stretched = |s: TimerSettings| TimerSettings {
        ccr: s.arr.max(s.ccr),
        ..s
    };
    match (plant, action) {
        (Plant::DutyCap, Some(GateAction::Start(s))) => {
            tm.apply(at, GateAction::Start(stretched(s)))
        }
        (Plant::DutyCap, Some(GateAction::Update(s))) => {
            tm.apply(at, GateAction::Update(stretched(s)))
        }
        (Plant::CarrierOnFault, Some(GateAction::Off))
            if matches!(reading, Some(Reading::Fault(_))) =>
        {
            if let Some(s) = last {
                tm.apply(at, GateAction::Start(s));
            }
        }
        (Plant::CarrierOnLift, Some(GateAction::Off)) if reading == Some(Reading::Lifted) => {
            if let Some(s) = last {
                tm.apply(at, GateAction::Start(s));
            }
        }
        (Plant::DoubledPulse, Some(GateAction::Update(s))) => tm.apply(at, GateAction::Start(s)),
        _ => {}
    }
}

/// Runs plane episode `episode` of seed `seed` for its first `samples` frames (at most
/// [`EPISODE_SAMPLES`]), with `plant` in the harness.
pub fn run_episode2d(seed: u64, episode: u64, samples: u64, plant: Plant) -> EpisodeReport {
    let samples = samples.min(EPISODE_SAMPLES);
    // The plane's episodes draw from their own streams: stream e + 2^63 (the 1D soak's is e).
    let mut rng = episode_rng(seed, episode | 1 << 63);
    let board = &saw_boards::ALL[rng.random_range(0..saw_boards::ALL.len())];
    let timer = burst_timer(board);
    let global0 = episode * EPISODE_SAMPLES;
    let mut report = EpisodeReport {
        episode,
        samples,
        ..EpisodeReport::default()
    };
    let (frame_us, mut sensor) = match (board_frame_period_us(board), sensor()) {
        (Some(p), Ok(s)) => (p, s),
        (p, s) => {
            return refused(
                report,
                global0,
                &format!("no frame period ({p:?}) or sensor ({:?})", s.err()),
            )
        }
    };
    let period_us = frame_us as u64;
    report.frame_us = frame_us;
    let clock_hz = timer.clock_hz as u64;
    let clk = |t_us: u64| t_us * clock_hz / 1_000_000;
    let stamp = |i: u64| ((global0 + i) * period_us) as u32;
    let g_t0 = global0 * period_us;
    report.wrapped = samples > 0 && (g_t0 + samples * period_us - 1) >> 32 != g_t0 >> 32;

    let mut cfg = loadable_config2d(&mut rng, &timer, frame_us);
    let edges_um: Vec<gen2d::EdgeUm> = scene_edges(&cfg.scene)
        .iter()
        .map(|g| ((g.a.0 * 1e3, g.a.1 * 1e3), (g.b.0 * 1e3, g.b.1 * 1e3)))
        .collect();
    let duration_s = (EPISODE_SAMPLES * period_us) as f64 * 1e-6;
    let (pieces, moves) = gen2d::soak_finger(&mut rng, duration_s, &edges_um);
    let faults = gen2d::soak_faults2d(&mut rng, EPISODE_SAMPLES, period_us);
    for f in &faults {
        if f.start < samples {
            report.faults[f.tag] += 1;
        }
    }
    let noise_codes = rng.random_range(0..=48);
    let frame_seed: u64 = rng.random();
    let mut events: Vec<(u64, Event)> = (0..rng.random_range(0..=3))
        .map(|_| {
            let at = rng.random_range(EPISODE_SAMPLES / 20..EPISODE_SAMPLES);
            let e = match rng.random_range(0..10) {
                0..=3 => Event::Reload,
                4..=6 => Event::MoveWindow,
                _ => Event::Refuse,
            };
            (at, e)
        })
        .collect();
    events.sort_by_key(|e| e.0);
    // Missing frames: a stale gap or dropped frames.
    let missing = |i: u64| {
        faults
            .iter()
            .any(|f| (f.tag == 3 || f.tag == 4) && (f.start..f.end).contains(&i))
    };

    let mut ctrl = match Controller2d::new(timer, frame_us) {
        Ok(c) => c,
        Err(e) => return refused(report, global0, &e.to_string()),
    };
    if let Err(e) = ctrl.load(&cfg) {
        return refused(report, global0, &e.to_string());
    }
    let mut tm = TimerModel::new(timer.clock_hz, timer.counter_bits, true);
    let mut check = LineCheck::new(timer, clk(period_us), global0, &cfg.limits);
    let mut fref = Ref2d::new();
    let mut eref = EdgeRef::new(&cfg);
    let mut frng = ChaCha8Rng::seed_from_u64(frame_seed);
    let mut digest = CRC64.digest();
    let mut edges: Vec<Edge> = Vec::new();
    let mut levels: Vec<LevelEdge> = Vec::new();
    let mut actions: Vec<(u64, GateAction)> = Vec::with_capacity(2);
    let mut next_event = 0;
    let mut shadow: Option<(Controller2d, u64)> = None;
    let mut last_settings: Option<TimerSettings> = None;
    let mut piece = 0usize;

    for i in 0..samples {
        let t_us = i * period_us;
        let global = global0 + i;
        while let Some(&(at, ev)) = events.get(next_event) {
            if at != i {
                break;
            }
            next_event += 1;
            shadow = None;
            let before = ctrl.clone();
            let (next, broken) = match ev {
                Event::Reload => (gen2d::random_config2d(&mut rng, timer.max_burst_hz), false),
                Event::MoveWindow => match gen2d::moved_window(&mut rng, &cfg) {
                    Some(c) => (c, false),
                    None => (gen2d::random_config2d(&mut rng, timer.max_burst_hz), false),
                },
                Event::Refuse => (gen2d::broken_config2d(&mut rng, &cfg).1, true),
            };
            match ctrl.load(&next) {
                Ok(()) => {
                    if broken {
                        check.violate(
                            Rule::BrokenSceneAccepted,
                            global,
                            "a 2D scene broken on purpose loaded".to_string(),
                        );
                    } else if ev == Event::MoveWindow {
                        report.boundary_moves += 1;
                    } else {
                        report.reloads += 1;
                    }
                    cfg = next;
                    eref = EdgeRef::new(&cfg);
                    check.scene(&cfg.limits, clk(t_us));
                }
                Err(_) => {
                    report.refusals += 1;
                    report.broken += u64::from(broken);
                    if plant == Plant::ResetOnRefusal {
                        let _ = ctrl.load(&Config2d::default());
                    }
                    let until = events
                        .get(next_event)
                        .map_or(u64::MAX, |e| e.0)
                        .min(i + REFUSAL_WATCH);
                    shadow = Some((before, until));
                }
            }
        }

        // The finger and the frame.
        let t_s = t_us as f64 * 1e-6;
        while pieces
            .get(piece + 1)
            .is_some_and(|p: &Piece| p.start_s <= t_s)
        {
            piece += 1;
        }
        let at = pieces
            .get(piece)
            .and_then(|p| p.at(t_s).map(|xy| (xy, p.r_touch_ohm)));
        let (fr, truth) = if missing(i) {
            (None, Truth::Missing)
        } else {
            let (f, t) = frame(&mut frng, at, &faults, i, noise_codes, stamp(i));
            (Some(f), t)
        };
        if let Some(rule) = fref.off(t_us, period_us, cfg.stale_after_us as u64, truth) {
            check.must_be_off_for(i, rule);
            report.off_samples += 1;
        }

        actions.clear();
        let mut reading = None;
        if let Some(f) = fr {
            let r = sensor.on_frame(&f);
            reading = Some(r);
            let out = ctrl.on_reading(stamp(i), r);
            if let Some(a) = out.action {
                tm.apply(clk(t_us), a);
                actions.push((clk(t_us), a));
                if let GateAction::Start(s) | GateAction::Update(s) = a {
                    last_settings = Some(s);
                }
            }
            tamper(
                plant,
                &mut tm,
                clk(t_us),
                out.action,
                reading,
                last_settings,
            );
            if out.edge.is_some() {
                report.edge_pulses += 1;
            }
            if let (Some(p), Some(_)) = (out.position, out.place) {
                let off = out.action == Some(GateAction::Off);
                if let Some(before) = eref.rendered(global, (p.x_um, p.y_um), out.edge, off) {
                    check.violate(
                        Rule::EdgeRepeat,
                        global,
                        format!(
                            "edge {:?} pulsed at sample {before} and again here with the finger \
                             never {} µm clear of its line in between",
                            out.edge, cfg.scene.rearm_um
                        ),
                    );
                }
            }
        }
        tm.advance_to(clk(t_us));
        let tick_us = t_us + period_us / 2;
        let tick = ctrl.on_tick((stamp(i) as u64 + period_us / 2) as u32);
        if let Some(a) = tick {
            tm.apply(clk(tick_us), a);
            actions.push((clk(tick_us), a));
        }

        if let Some((sh, until)) = shadow.as_mut() {
            let out = reading.map(|r| sh.on_reading(stamp(i), r));
            let t = sh.on_tick((stamp(i) as u64 + period_us / 2) as u32);
            report.refusal_samples += 1;
            let got = actions.last().map(|a| a.1);
            let expected = t.or(out.and_then(|o| o.action));
            if expected != got || sh.telemetry() != ctrl.telemetry() {
                check.violate(
                    Rule::RefusalChangedScene,
                    global,
                    format!(
                        "after a refused 2D load the controller acts {got:?}, the scene before \
                         it {expected:?}"
                    ),
                );
                shadow = None;
            } else if i + 1 >= *until {
                shadow = None;
            }
        }
        if ctrl.fault().is_some() && tm.is_high() {
            check.violate(
                Rule::OnWhileReportedFault,
                global,
                format!("the line high with the core reporting {:?}", ctrl.fault()),
            );
        }
        tm.take_settled(&mut edges, &mut levels);
        hash_edges(&mut digest, &edges);
        check.step_many(&actions, &edges, tm.now());
    }
    let end = clk(samples * period_us);
    tm.advance_to(end);
    tm.take_settled(&mut edges, &mut levels);
    hash_edges(&mut digest, &edges);
    check.step(None, &edges, end);
    check.finish(end);
    if tm.protocol_errors > 0 {
        check.violate(
            Rule::TimerProtocol,
            global0 + samples.saturating_sub(1),
            format!(
                "{} actions the timer model could not apply",
                tm.protocol_errors
            ),
        );
    }
    let telemetry = ctrl.telemetry();
    report.lifts = telemetry.lifts as u64;
    report.edges_skipped = telemetry.edges_skipped as u64;
    report.ridge_pulses = telemetry.ridge_pulses as u64;
    for (m, n) in report.moves.iter_mut().zip(moves) {
        *m = n;
    }
    report.checksum = digest.finalize();
    report.pulses = check.pulses;
    report.violations = check.count;
    report.by_rule = check.by_rule;
    report.kept = check.kept;
    report
}

fn hash_edges(digest: &mut crc::Digest<'_, u64>, edges: &[Edge]) {
    for e in edges {
        digest.update(&e.t.to_le_bytes());
        digest.update(&[u8::from(e.high)]);
    }
}

fn refused(mut report: EpisodeReport, global0: u64, why: &str) -> EpisodeReport {
    report.violations = 1;
    report.by_rule[Rule::TimerProtocol.index()] += 1;
    report.kept.push(Violation {
        rule: Rule::TimerProtocol,
        sample: global0,
        detail: format!("the 2D episode could not start: {why}"),
    });
    report
}

/// How many fault kinds the plane soak counts (the report's array holds the 1D soak's seven).
const _: () = assert!(FAULTS_2D.len() == super::gen::SOAK_FAULTS.len());

#[cfg(test)]
mod tests {
    use super::*;
    use saw_core::plane::{PointUm, SegmentUm};

    /// A free edge along x from (10, 20) to (30, 20) mm, re-arm 500 µm.
    fn one_edge() -> EdgeRef {
        let mut c = Config2d::default();
        c.scene.rearm_um = 500;
        let _ = c.scene.free_edges.push(SegmentUm {
            a: PointUm::new(10_000, 20_000),
            b: PointUm::new(30_000, 20_000),
        });
        EdgeRef::new(&c)
    }

    /// Worked by hand: a second pulse with the finger never 500 µm from y = 20 mm is a repeat;
    /// one after a reading 600 µm off is not; 498 µm off does not clear, 499 µm does (the 1 µm
    /// allowance); the line's extension past the segment counts; the pulse's own reading never
    /// clears, but a pulse that follows a stop (its crossing a reading earlier) may.
    #[test]
    fn an_edge_must_be_cleared_between_its_pulses() {
        let mut e = one_edge();
        assert_eq!(e.rendered(1, (15_000, 20_010), Some(0), false), None);
        assert_eq!(e.rendered(2, (15_000, 19_700), None, false), None);
        assert_eq!(e.rendered(3, (15_000, 20_000), Some(0), false), Some(1));
        // Far away on the pulse's own reading: does not count.
        assert_eq!(e.rendered(4, (15_000, 25_000), Some(0), false), Some(3));
        assert_eq!(e.rendered(5, (15_000, 20_600), None, false), None);
        assert_eq!(e.rendered(6, (15_000, 20_000), Some(0), false), None);
        assert_eq!(e.rendered(7, (15_000, 19_502), None, false), None);
        assert_eq!(e.rendered(8, (15_000, 20_000), Some(0), false), Some(6));
        assert_eq!(e.rendered(9, (15_000, 19_501), None, false), None);
        assert_eq!(e.rendered(10, (15_000, 20_000), Some(0), false), None);
        assert_eq!(e.rendered(11, (90_000, 21_000), None, false), None);
        assert_eq!(e.rendered(12, (15_000, 20_000), Some(0), false), None);
        // A stop (line off, no edge), then the pulse 600 µm off: a repeat of 12 (nothing clear
        // between), but its own reading clears it for the next.
        assert_eq!(e.rendered(13, (15_000, 20_000), None, true), None);
        assert_eq!(e.rendered(14, (15_000, 20_600), Some(0), false), Some(12));
        assert_eq!(e.rendered(15, (15_000, 20_000), Some(0), false), None);
    }

    /// The reference's counts, by hand: a lift holds the line off on its frame and the next 15
    /// pressed frames; a gap is off from the period after the watchdog's tick finds it stale.
    #[test]
    fn the_reference_counts_landings_and_stale_gaps() {
        let (p, stale) = (300, 1_000);
        let mut r = Ref2d::new();
        let offs: Vec<bool> = (0..20)
            .map(|i| r.off(i * p, p, stale, Truth::Good).is_some())
            .collect();
        assert_eq!(offs.iter().filter(|o| **o).count(), 15);
        assert!(!offs[15]);
        assert_eq!(
            r.off(20 * p, p, stale, Truth::Lifted),
            Some(Rule::OnWhileLifted)
        );
        for i in 21..36 {
            assert!(r.off(i * p, p, stale, Truth::Good).is_some());
        }
        assert_eq!(r.off(36 * p, p, stale, Truth::Good), None);
        // Silence from 37: the tick at t + 150 finds > 1000 µs at frame 40 (40·300+150−36·300 =
        // 1350), 39 finds 1050 > 1000 too: 39 is the first.
        assert_eq!(r.off(37 * p, p, stale, Truth::Missing), None);
        assert_eq!(r.off(38 * p, p, stale, Truth::Missing), None);
        assert_eq!(r.off(39 * p, p, stale, Truth::Missing), None);
        assert_eq!(
            r.off(40 * p, p, stale, Truth::Missing),
            Some(Rule::OnDuringFault)
        );
    }
}
