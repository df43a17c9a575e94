//! Bare Cortex-M4F image of the portable core for QEMU's mps2-an386 (no embassy, no HAL).
//!
//! 1. Replays every golden vector (ADC samples recorded on the host, `golden.bin` embedded at
//!    compile time from `$GOLDEN_DIR`) through `saw_core::Controller` built from the same
//!    `Config`, compares each output record with the host's, and reports per vector
//!    `EQUIV vector=… n=… crc=… diff=… beyond_tol=…` (plus the first differing records).
//! 2. Counts instructions (QEMU `-icount shift=0`: 1 instruction = 1 ns; SysTick at the AN386's
//!    25 MHz = 40 instructions per tick) per scene, per texture kind, per velocity estimator and
//!    per stage: `COST-… case=… n=… per_sample=…`.
//! 3. The core's own log lines (scene loaded, region, sensor fault/recovered) go out through
//!    defmt over semihosting with the rest; scripts/emu.sh decodes them with defmt-print.
//!
//! Exits QEMU through semihosting: success, or failure on a mismatch or a panic.
#![no_std]
#![no_main]

#[allow(dead_code)]
mod format;
#[allow(dead_code)]
mod plane2d;

use core::hint::black_box;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::debug;
use defmt_semihosting as _;
use format::{Buf, Reader};
use saw_core::burst::{BurstTimer, FastPlanner};
use saw_core::plane::{Controller2d, Output2d};
use saw_core::position::PositionMapper;
use saw_core::region::RegionMap;
use saw_core::sample::Sample;
use saw_core::texture::{Grating, GratingRender, Material, RandomBurst, Texture};
use saw_core::touch::frame::{Frame, Reading};
use saw_core::velocity::{
    AlphaBeta, AlphaBetaFixed, BackwardDifference, Foaw, FoawFit, InnovationGate, LsqSlope,
    Median3, OneSampleDifference, StepClamp, SuperTwisting, VelocityEstimator,
};
use saw_core::{Config, Controller, Output};

static GOLDEN: &[u8] = include_bytes!(concat!(env!("GOLDEN_DIR"), "/golden.bin"));
static GOLDEN2D: &[u8] = include_bytes!(concat!(env!("GOLDEN_DIR"), "/golden2d.bin"));

/// Instructions per SysTick tick: 25 MHz SysTick, 1 GHz virtual instruction clock.
const INSTR_PER_TICK: u64 = 40;
/// Longest vector.
const MAX_SAMPLES: usize = 5_000;

static mut SAMPLES: [Sample; MAX_SAMPLES] = [Sample { code: 0, t_us: 0 }; MAX_SAMPLES];
static mut POSITIONS: [(i32, u32); MAX_SAMPLES] = [(0, 0); MAX_SAMPLES];
static mut OUTPUTS: [Output; MAX_SAMPLES] = [Output {
    position_um: None,
    velocity_um_s: None,
    region: None,
    action: None,
    amplitude_permille: None,
    envelope: None,
    drive: None,
    line: None,
    fault: None,
}; MAX_SAMPLES];

/// SysTick wraps (every 2^24 ticks = 671 ms of virtual time).
static WRAPS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// Ticks since start (monotonic), wrap-safe.
fn ticks() -> u64 {
    loop {
        let w0 = WRAPS.load(Ordering::Relaxed);
        let cvr = cortex_m::peripheral::SYST::get_current();
        let w1 = WRAPS.load(Ordering::Relaxed);
        if w0 == w1 {
            return ((w0 as u64) << 24) + (0xFF_FFFF - cvr as u64);
        }
    }
}

/// Runs `f` and returns the instructions it took (±40: one tick).
fn measure(f: impl FnOnce()) -> u64 {
    let t0 = ticks();
    f();
    (ticks() - t0) * INSTR_PER_TICK
}

/// Per-sample cost ×10 of `total` over `n` samples, less the harness loop `overhead`.
fn per_sample_x10(total: u64, overhead: u64, n: usize) -> u32 {
    (total.saturating_sub(overhead) * 10 / n.max(1) as u64) as u32
}

fn report(tag: &str, case: &str, n: usize, x10: u32) {
    defmt::println!(
        "{=str} case={=str} n={=u32} per_sample={=u32}.{=u32}",
        tag,
        case,
        n as u32,
        x10 / 10,
        x10 % 10
    );
}

fn fail() -> ! {
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    fail()
}

struct Golden {
    timer: BurstTimer,
    period_us: u32,
    /// Offsets of the scene configs.
    scenes: [(usize, &'static str); 16],
    n_scenes: usize,
    /// Offset of the vector table.
    vectors: usize,
}

fn parse_golden() -> Golden {
    let mut r = Reader::new(GOLDEN);
    if r.take(4) != format::MAGIC || r.u32() != format::VERSION {
        defmt::error!("golden.bin: bad magic or version");
        fail();
    }
    let (timer, period_us) = format::decode_timer(&mut r);
    let n_scenes = r.u8() as usize;
    let mut scenes = [(0, ""); 16];
    for s in scenes.iter_mut().take(n_scenes) {
        let name = r.name();
        *s = (r.pos, name);
        let _ = format::decode_config(&mut r);
    }
    Golden {
        timer,
        period_us,
        scenes,
        n_scenes,
        vectors: r.pos,
    }
}

fn config_at(offset: usize) -> Config {
    let mut r = Reader::new(GOLDEN);
    r.pos = offset;
    format::decode_config(&mut r)
}

/// Loads the vector's inputs into SAMPLES; returns (name, scene, n, expected outputs, crc).
fn read_vector(r: &mut Reader<'static>) -> (&'static str, usize, usize, &'static [u8], u32) {
    let name = r.name();
    let scene = r.u8() as usize;
    let n = r.u32() as usize;
    if n > MAX_SAMPLES {
        defmt::error!("vector {=str}: {} samples > {}", name, n, MAX_SAMPLES);
        fail();
    }
    // SAFETY: single-threaded; no other reference to SAMPLES is alive.
    let samples = unsafe { &mut *core::ptr::addr_of_mut!(SAMPLES) };
    for s in samples.iter_mut().take(n) {
        *s = Sample {
            code: r.u16(),
            t_us: r.u32(),
        };
    }
    let len = r.u32() as usize;
    let expected = r.take(len);
    let crc = r.u32();
    (name, scene, n, expected, crc)
}

/// Instructions of the harness loop alone (read a sample, store an output).
fn loop_overhead(n: usize) -> u64 {
    let samples = unsafe { &*core::ptr::addr_of!(SAMPLES) };
    let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS) };
    measure(|| {
        for (s, o) in samples[..n].iter().zip(outputs[..n].iter_mut()) {
            black_box(s);
            *o = black_box(Output::default());
        }
    })
}

/// Runs the samples through `ctl` into OUTPUTS; returns the instructions taken.
fn replay<E: VelocityEstimator>(ctl: &mut Controller<E>, n: usize) -> u64 {
    let samples = unsafe { &*core::ptr::addr_of!(SAMPLES) };
    let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS) };
    measure(|| {
        for (s, o) in samples[..n].iter().zip(outputs[..n].iter_mut()) {
            *o = ctl.on_sample(*black_box(s));
        }
    })
}

/// Samples before the "steady" worst: the first sample (scene announcement, region lookup) and
/// the estimator's filling window (median of 3 + 32) cost once per scene or fault.
const WORST_FROM: usize = 64;

/// Runs the samples through `ctl` one at a time, each timed alone; returns the costliest
/// sample's instructions (less `empty`, an empty measurement's; ±40: one SysTick tick) and its
/// index, over all samples and over those from [`WORST_FROM`] on.
fn replay_worst<E: VelocityEstimator>(
    ctl: &mut Controller<E>,
    n: usize,
    empty: u64,
) -> ((u64, usize), (u64, usize)) {
    let samples = unsafe { &*core::ptr::addr_of!(SAMPLES) };
    let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS) };
    let (mut worst, mut steady) = ((0, 0), (0, 0));
    for (i, (s, o)) in samples[..n].iter().zip(outputs[..n].iter_mut()).enumerate() {
        let cost = measure(|| *o = ctl.on_sample(*black_box(s))).saturating_sub(empty);
        if cost > worst.0 {
            worst = (cost, i);
        }
        if i >= WORST_FROM && cost > steady.0 {
            steady = (cost, i);
        }
    }
    (worst, steady)
}

fn new_controller(g: &Golden, cfg: &Config) -> Controller {
    let mut ctl = Controller::new(g.timer, g.period_us).unwrap_or_else(|_| fail());
    if ctl.load(cfg).is_err() {
        defmt::error!("scene rejected on target");
        fail();
    }
    ctl
}

/// Compares OUTPUTS with the expected records; returns (crc, differing, beyond tolerance).
fn compare(name: &str, n: usize, expected: &[u8]) -> (u32, u32, u32) {
    let outputs = unsafe { &*core::ptr::addr_of!(OUTPUTS) };
    let mut r = Reader::new(expected);
    let mut crc = 0u32;
    let (mut diff, mut beyond) = (0u32, 0u32);
    for (i, o) in outputs[..n].iter().enumerate() {
        let mut b = Buf::new();
        format::encode_output(&mut b, o);
        crc = format::crc32_update(crc, b.as_slice());
        let start = r.pos;
        let want = format::decode_output(&mut r);
        if &r.data[start..r.pos] != b.as_slice() {
            diff += 1;
            let ok = format::within_tolerance(o, &want);
            if !ok {
                beyond += 1;
            }
            if diff <= 3 {
                // A one-pulse's delay (arr + 1 − ccr ticks, issue #17) spelled out in clocks.
                let delay = |o: &Output| match o.action {
                    Some(saw_core::gate::GateAction::Pulse(t)) => t.pulse_delay_clocks(),
                    _ => 0,
                };
                defmt::println!(
                    "DIFF vector={=str} sample={=u32} within_tol={=bool}\n  target: {} (pulse delay {=u64} clocks)\n  host:   {} (pulse delay {=u64} clocks)",
                    name,
                    i as u32,
                    ok,
                    o,
                    delay(o),
                    want,
                    delay(&want)
                );
            }
        }
    }
    (crc, diff, beyond)
}

fn equivalence_and_scene_costs(g: &Golden) -> bool {
    let mut r = Reader::new(GOLDEN);
    r.pos = g.vectors;
    let n_vectors = r.u8();
    let mut all_ok = true;
    for _ in 0..n_vectors {
        let (name, scene, n, expected, host_crc) = read_vector(&mut r);
        let cfg = config_at(g.scenes[scene].0);
        let mut ctl = new_controller(g, &cfg);
        // The harness loop first: it overwrites OUTPUTS, which the replay then fills.
        let overhead = loop_overhead(n);
        let cost = replay(&mut ctl, n);
        let (crc, diff, beyond) = compare(name, n, expected);
        defmt::println!(
            "EQUIV vector={=str} n={=u32} crc={=u32:08x} host_crc={=u32:08x} diff={=u32} beyond_tol={=u32}",
            name,
            n as u32,
            crc,
            host_crc,
            diff,
            beyond
        );
        all_ok &= beyond == 0 && (diff > 0 || crc == host_crc);
        report("COST-SCENE", name, n, per_sample_x10(cost, overhead, n));
    }
    all_ok
}

/// Loads the default scene's back-and-forth vector (the benchmarks' input).
fn load_bench_inputs(g: &Golden, want: &str) -> usize {
    let mut r = Reader::new(GOLDEN);
    r.pos = g.vectors;
    for _ in 0..r.u8() {
        let (name, _, n, _, _) = read_vector(&mut r);
        if name == want {
            return n;
        }
    }
    defmt::error!("no vector {=str}", want);
    fail()
}

/// One-region scene of `texture` (optionally with the lines scene's lines).
fn single(texture: Texture, lines: bool) -> Config {
    let mut cfg = saw_core::default_config();
    cfg.scene.boundaries_um.clear();
    cfg.scene.textures.clear();
    let _ = cfg.scene.textures.push(texture);
    if lines {
        for p in [10_000, 20_000, 31_500, 43_000, 53_000] {
            let _ = cfg.scene.lines.positions_um.push(p);
        }
    }
    cfg
}

/// The one-region scenes of the per-kind table: (kind, texture, with the lines scene's lines).
fn kind_cases() -> [(&'static str, Texture, bool); 8] {
    let random = RandomBurst {
        center_millihz: 40_000,
        spread_permille: 300,
        amplitude_permille: 800,
        amplitude_spread_permille: 200,
        duty_permille: 400,
        seed: 1,
    };
    let synth = Grating {
        render: GratingRender::VelocitySynthesis,
        ..Grating::new(1_000)
    };
    let hybrid = Grating {
        render: GratingRender::Hybrid,
        ..Grating::new(1_000)
    };
    [
        ("off", Texture::Off, false),
        ("constant", Texture::constant_hz(80), false),
        ("grating", Texture::Grating(Grating::new(1_000)), false),
        ("grating-velocity", Texture::Grating(synth), false),
        ("grating-hybrid", Texture::Grating(hybrid), false),
        ("material", Texture::Material(Material::fig5(0.3)), false),
        ("random", Texture::Random(random), false),
        ("lines+off", Texture::Off, true),
    ]
}

fn texture_costs(g: &Golden, traj: &str, n: usize) {
    let cases = kind_cases();
    let overhead = loop_overhead(n);
    for (kind, texture, lines) in cases {
        let mut ctl = new_controller(g, &single(texture, lines));
        let cost = replay(&mut ctl, n);
        let mut case = [0u8; 48];
        let case = join(&mut case, kind, traj);
        report("COST-TEXTURE", case, n, per_sample_x10(cost, overhead, n));
        let mut ctl = new_controller(g, &single(texture, lines));
        let ((worst, at), (steady, steady_at)) = replay_worst(&mut ctl, n, measure(|| {}));
        defmt::println!(
            "COST-WORST case={=str} n={=u32} worst={=u64} at={=u32} steady={=u64} steady_at={=u32}",
            case,
            n as u32,
            worst,
            at as u32,
            steady,
            steady_at as u32
        );
    }
}

fn join<'a>(buf: &'a mut [u8; 48], a: &str, b: &str) -> &'a str {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    buf[..a.len()].copy_from_slice(a);
    buf[a.len()] = b'/';
    buf[a.len() + 1..a.len() + 1 + b.len()].copy_from_slice(b);
    core::str::from_utf8(&buf[..a.len() + 1 + b.len()]).unwrap_or("?")
}

/// Fills POSITIONS from SAMPLES through the default mapper (faults skipped); returns the count.
fn positions(n: usize) -> usize {
    let mapper =
        PositionMapper::new(saw_core::default_config().calibration).unwrap_or_else(|_| fail());
    let samples = unsafe { &*core::ptr::addr_of!(SAMPLES) };
    let pos = unsafe { &mut *core::ptr::addr_of_mut!(POSITIONS) };
    let mut m = 0;
    for s in &samples[..n] {
        if let Ok(p) = mapper.position_um(s) {
            pos[m] = (p, s.t_us);
            m += 1;
        }
    }
    m
}

fn estimator<E: VelocityEstimator + Clone>(g: &Golden, name: &str, e: E, n: usize, m: usize) {
    let pos = unsafe { &*core::ptr::addr_of!(POSITIONS) };
    let mut est = e.clone();
    let update = measure(|| {
        for &(p, t) in &pos[..m] {
            black_box(est.update(black_box(p), t));
        }
    });
    let upd_overhead = measure(|| {
        for &(p, t) in &pos[..m] {
            black_box((black_box(p), t));
        }
    });
    let mut ctl = Controller::with_estimator(g.timer, g.period_us, e);
    if ctl.load(&saw_core::default_config()).is_err() {
        fail();
    }
    let overhead = loop_overhead(n);
    let cost = replay(&mut ctl, n);
    let u = per_sample_x10(update, upd_overhead, m);
    let o = per_sample_x10(cost, overhead, n);
    defmt::println!(
        "COST-ESTIMATOR case={=str} n={=u32} update={=u32}.{=u32} on_sample={=u32}.{=u32}",
        name,
        n as u32,
        u / 10,
        u % 10,
        o / 10,
        o % 10
    );
}

fn estimator_costs(g: &Golden, n: usize) {
    let p = g.period_us;
    let m = positions(n);
    let ok = |r: Result<(), ()>| r.unwrap_or_else(|_| fail());
    estimator(
        g,
        "diff1",
        OneSampleDifference::new(p).unwrap_or_else(|_| fail()),
        n,
        m,
    );
    estimator(
        g,
        "diff4",
        BackwardDifference::<4>::new(p).unwrap_or_else(|_| fail()),
        n,
        m,
    );
    estimator(
        g,
        "lsq16",
        LsqSlope::<16>::new(p).unwrap_or_else(|_| fail()),
        n,
        m,
    );
    estimator(
        g,
        "lsq32",
        LsqSlope::<32>::new(p).unwrap_or_else(|_| fail()),
        n,
        m,
    );
    estimator(
        g,
        "lsq64",
        LsqSlope::<64>::new(p).unwrap_or_else(|_| fail()),
        n,
        m,
    );
    let foaw = |fit| Foaw::<33>::new(fit, 24.0, p).unwrap_or_else(|_| fail());
    estimator(g, "foaw-end-d24-n32", foaw(FoawFit::EndFit), n, m);
    estimator(g, "foaw-best-d24-n32", foaw(FoawFit::BestFit), n, m);
    let ab = AlphaBeta::critically_damped(p, 0.9).unwrap_or_else(|_| fail());
    estimator(g, "ab-p0.9(f32)", ab.clone(), n, m);
    let abq = AlphaBetaFixed::critically_damped(p, 0.9).unwrap_or_else(|_| fail());
    estimator(g, "abq16-p0.9(I16F16)", abq, n, m);
    let st = SuperTwisting::new(p, 1e6).unwrap_or_else(|_| fail());
    estimator(g, "std-L1e6", st, n, m);
    // The outlier guards issue #35 measured against the median (docs/conversion-budget.md,
    // "Outlier guards"), at the gate and clamp settings the sweep picked.
    let lsq32 = || LsqSlope::<32>::new(p).unwrap_or_else(|_| fail());
    estimator(
        g,
        "gate100+lsq32",
        InnovationGate::new(lsq32(), p, 100, 2),
        n,
        m,
    );
    estimator(
        g,
        "clamp0.5m/s+lsq32",
        StepClamp::new(lsq32(), p, 500_000),
        n,
        m,
    );
    let med = Median3::new(LsqSlope::<32>::new(p).unwrap_or_else(|_| fail()), p);
    estimator(g, "med3+lsq32(default)", med, n, m);
    ok(Ok(()));
}

fn stage_costs(n: usize) {
    let cfg = saw_core::default_config();
    let samples = unsafe { &*core::ptr::addr_of!(SAMPLES) };
    let pos = unsafe { &*core::ptr::addr_of!(POSITIONS) };
    let mapper = PositionMapper::new(cfg.calibration).unwrap_or_else(|_| fail());
    let base = measure(|| {
        for s in &samples[..n] {
            black_box(black_box(s).code);
        }
    });
    let cost = measure(|| {
        for s in &samples[..n] {
            let _ = black_box(mapper.position_um(black_box(s)));
        }
    });
    report(
        "COST-STAGE",
        "position(code->um,rail-check)",
        n,
        per_sample_x10(cost, base, n),
    );
    let m = positions(n);
    let regions = RegionMap::new(
        cfg.scene.textures.len(),
        &cfg.scene.boundaries_um,
        cfg.calibration.length_um,
        cfg.scene.hysteresis_um,
    )
    .unwrap_or_else(|_| fail());
    let base = measure(|| {
        for &(p, _) in &pos[..m] {
            black_box(black_box(p));
        }
    });
    let mut r = 0u8;
    let cost = measure(|| {
        for &(p, _) in &pos[..m] {
            r = black_box(regions.track(r, black_box(p)));
        }
    });
    report(
        "COST-STAGE",
        "region(track,3-regions)",
        m,
        per_sample_x10(cost, base, m),
    );
    let timer = BurstTimer {
        clock_hz: 90_000_000,
        counter_bits: 32,
        max_burst_hz: 2_000,
    };
    let planner = FastPlanner::new(&timer, &cfg.limits, 400).unwrap_or_else(|_| fail());
    let cost = measure(|| {
        for &(p, _) in &pos[..m] {
            let hz = (p as f32) * 0.01;
            let _ = black_box(planner.plan_hz(black_box(hz)));
        }
    });
    let base2 = measure(|| {
        for &(p, _) in &pos[..m] {
            black_box((p as f32) * 0.01);
        }
    });
    report(
        "COST-STAGE",
        "burst-planner(f32-Hz->PSC/ARR/CCR)",
        m,
        per_sample_x10(cost, base2, m),
    );
}

/// Longest 2D vector, readings.
const MAX_READINGS: usize = 10_000;
const NO_OUTPUT2D: Output2d = Output2d {
    position: None,
    velocity: None,
    place: None,
    action: None,
    amplitude_permille: None,
    envelope: None,
    drive: None,
    edge: None,
    fault: None,
};
static mut FRAMES: [Frame; MAX_READINGS] = [Frame {
    x_code: 0,
    y_code: 0,
    z1_code: 0,
    z2_code: 0,
    t_us: 0,
}; MAX_READINGS];
static mut READINGS: [Reading; MAX_READINGS] = [Reading::Lifted; MAX_READINGS];
static mut OUTPUTS2D: [Output2d; MAX_READINGS] = [NO_OUTPUT2D; MAX_READINGS];

/// The 2D vectors' header.
struct Golden2d {
    timer: BurstTimer,
    period_us: u32,
    cal: [saw_core::touch::calibration::CalPoint; 3],
    host_config_crc: u32,
    /// Offset of the vector count.
    vectors: usize,
}

fn parse_golden2d() -> Golden2d {
    let mut r = format::Reader::new(GOLDEN2D);
    if r.take(4) != plane2d::MAGIC || r.u32() != plane2d::VERSION {
        defmt::error!("golden2d.bin: bad magic or version");
        fail();
    }
    let timer = BurstTimer {
        clock_hz: r.u32(),
        counter_bits: r.u8(),
        max_burst_hz: r.u32(),
    };
    let period_us = r.u32();
    let host_config_crc = r.u32();
    let cal = [
        plane2d::decode_cal(&mut r),
        plane2d::decode_cal(&mut r),
        plane2d::decode_cal(&mut r),
    ];
    Golden2d {
        timer,
        period_us,
        cal,
        host_config_crc,
        vectors: r.pos,
    }
}

/// Loads a 2D vector's frames and readings; returns (name, n, expected outputs, crc).
fn read_vector2d(r: &mut format::Reader<'static>) -> (&'static str, usize, &'static [u8], u32) {
    let name = r.name();
    let n = r.u32() as usize;
    if n > MAX_READINGS {
        defmt::error!("2d vector {=str}: {} readings > {}", name, n, MAX_READINGS);
        fail();
    }
    // SAFETY: single-threaded; no other reference to FRAMES or READINGS is alive.
    let frames = unsafe { &mut *core::ptr::addr_of_mut!(FRAMES) };
    let readings = unsafe { &mut *core::ptr::addr_of_mut!(READINGS) };
    for (f, rd) in frames.iter_mut().zip(readings.iter_mut()).take(n) {
        *f = plane2d::decode_frame(r);
        *rd = plane2d::decode_reading(r);
    }
    let len = r.u32() as usize;
    let expected = r.take(len);
    let crc = r.u32();
    (name, n, expected, crc)
}

fn new_controller2d(g: &Golden2d, cfg: &saw_core::plane::Config2d) -> Controller2d {
    let mut ctl = Controller2d::new(g.timer, g.period_us).unwrap_or_else(|_| fail());
    if ctl.load(cfg).is_err() {
        defmt::error!("2d scene rejected on target");
        fail();
    }
    ctl
}

/// The harness loop alone over 2D readings (read a frame and a reading, store an output).
fn loop_overhead2d(n: usize) -> u64 {
    let frames = unsafe { &*core::ptr::addr_of!(FRAMES) };
    let readings = unsafe { &*core::ptr::addr_of!(READINGS) };
    let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS2D) };
    measure(|| {
        for ((f, r), o) in frames[..n]
            .iter()
            .zip(&readings[..n])
            .zip(outputs[..n].iter_mut())
        {
            black_box((f.t_us, r));
            *o = black_box(Output2d::default());
        }
    })
}

/// The readings through `ctl` alone (the caller ran the sensor); returns the instructions.
fn replay_readings(ctl: &mut Controller2d, n: usize) -> u64 {
    let frames = unsafe { &*core::ptr::addr_of!(FRAMES) };
    let readings = unsafe { &*core::ptr::addr_of!(READINGS) };
    let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS2D) };
    measure(|| {
        for ((f, r), o) in frames[..n]
            .iter()
            .zip(&readings[..n])
            .zip(outputs[..n].iter_mut())
        {
            *o = ctl.on_reading(black_box(f).t_us, *black_box(r));
        }
    })
}

/// The frames through the sensor and `ctl`; returns the instructions.
fn replay_frames(
    sensor: &mut saw_core::touch::frame::TouchSensor,
    ctl: &mut Controller2d,
    n: usize,
) -> u64 {
    let frames = unsafe { &*core::ptr::addr_of!(FRAMES) };
    let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS2D) };
    measure(|| {
        for (f, o) in frames[..n].iter().zip(outputs[..n].iter_mut()) {
            let f = black_box(f);
            *o = ctl.on_reading(f.t_us, sensor.on_frame(f));
        }
    })
}

/// Compares OUTPUTS2D with the expected records; returns (crc, differing records).
fn compare2d(name: &str, n: usize, expected: &[u8]) -> (u32, u32) {
    let outputs = unsafe { &*core::ptr::addr_of!(OUTPUTS2D) };
    let mut r = format::Reader::new(expected);
    let (mut crc, mut diff) = (0u32, 0u32);
    for (i, o) in outputs[..n].iter().enumerate() {
        let mut b = plane2d::Rec::new();
        plane2d::encode_output2d(&mut b, o);
        crc = format::crc32_update(crc, b.as_slice());
        let start = r.pos;
        let want = plane2d::decode_output2d(&mut r);
        if &r.data[start..r.pos] != b.as_slice() {
            diff += 1;
            if diff <= 3 {
                defmt::println!(
                    "DIFF vector={=str} sample={=u32} within_tol=false\n  target: {}\n  host:   {}",
                    name,
                    i as u32,
                    o,
                    want
                );
            }
        }
    }
    (crc, diff)
}

fn equiv2d(name: &str, n: usize, expected: &[u8], host_crc: u32) -> bool {
    let (crc, diff) = compare2d(name, n, expected);
    defmt::println!(
        "EQUIV vector={=str} n={=u32} crc={=u32:08x} host_crc={=u32:08x} diff={=u32} beyond_tol={=u32}",
        name,
        n as u32,
        crc,
        host_crc,
        diff,
        diff
    );
    diff == 0 && crc == host_crc
}

/// The 2D vectors (issue #36): each replayed as readings into `Controller2d::on_reading`, and
/// as frames through `TouchSensor::on_frame` and the controller; both compared with the host's
/// outputs record by record, and counted per reading (`COST-2D`), with the sensor alone and the
/// costliest single reading (`COST-WORST-2D`).
fn plane_vectors() -> bool {
    let g = parse_golden2d();
    let cfg = plane2d::config();
    let crc = plane2d::config_crc(&cfg);
    if crc != g.host_config_crc {
        defmt::error!(
            "2d scene: target built {=u32:08x}, host {=u32:08x} (not the same Config2d)",
            crc,
            g.host_config_crc
        );
        return false;
    }
    let mut r = format::Reader::new(GOLDEN2D);
    r.pos = g.vectors;
    let mut ok = true;
    for _ in 0..r.u8() {
        let (name, n, expected, host_crc) = read_vector2d(&mut r);
        let mut buf = [0u8; 48];
        let overhead = loop_overhead2d(n);
        // The controller alone, on the host sensor's readings.
        let case = join(&mut buf, "plane", name);
        let mut ctl = new_controller2d(&g, &cfg);
        let cost = replay_readings(&mut ctl, n);
        ok &= equiv2d(case, n, expected, host_crc);
        report("COST-2D", case, n, per_sample_x10(cost, overhead, n));
        // The sensor and the controller, on the frames.
        let mut buf2 = [0u8; 48];
        let case2 = join(&mut buf2, "plane+sensor", name);
        let mut sensor = plane2d::sensor(g.cal).unwrap_or_else(|| fail());
        let mut ctl = new_controller2d(&g, &cfg);
        let cost = replay_frames(&mut sensor, &mut ctl, n);
        ok &= equiv2d(case2, n, expected, host_crc);
        report("COST-2D", case2, n, per_sample_x10(cost, overhead, n));
        // The sensor alone.
        let frames = unsafe { &*core::ptr::addr_of!(FRAMES) };
        let mut sensor = plane2d::sensor(g.cal).unwrap_or_else(|| fail());
        let base = measure(|| {
            for f in &frames[..n] {
                black_box(black_box(f).t_us);
            }
        });
        let cost = measure(|| {
            for f in &frames[..n] {
                black_box(sensor.on_frame(black_box(f)));
            }
        });
        let mut buf3 = [0u8; 48];
        let case3 = join(&mut buf3, "sensor", name);
        report("COST-2D", case3, n, per_sample_x10(cost, base, n));
        // Each reading timed alone: the costliest.
        let readings = unsafe { &*core::ptr::addr_of!(READINGS) };
        let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS2D) };
        let mut ctl = new_controller2d(&g, &cfg);
        let empty = measure(|| {});
        let (mut worst, mut steady) = ((0, 0), (0, 0));
        for (i, ((f, rd), o)) in frames[..n]
            .iter()
            .zip(&readings[..n])
            .zip(outputs[..n].iter_mut())
            .enumerate()
        {
            let c = measure(|| *o = ctl.on_reading(black_box(f).t_us, *black_box(rd)))
                .saturating_sub(empty);
            if c > worst.0 {
                worst = (c, i);
            }
            if i >= WORST_FROM && c > steady.0 {
                steady = (c, i);
            }
        }
        defmt::println!(
            "COST-WORST-2D case={=str} n={=u32} worst={=u64} at={=u32} steady={=u64} steady_at={=u32}",
            case,
            n as u32,
            worst.0,
            worst.1 as u32,
            steady.0,
            steady.1 as u32
        );
    }
    ok
}

/// Profiling build for a 2D vector (`EMU_PROFILE=plane/<trajectory>`): its readings through the
/// controller alone.
fn profile2d(traj: &str) -> ! {
    let g = parse_golden2d();
    let cfg = plane2d::config();
    let mut r = format::Reader::new(GOLDEN2D);
    r.pos = g.vectors;
    for _ in 0..r.u8() {
        let (name, n, _, _) = read_vector2d(&mut r);
        if name == traj {
            let mut ctl = new_controller2d(&g, &cfg);
            // Called through a pointer: with one caller `on_reading` would be inlined into
            // this loop and compiled unlike the measuring image's (where three loops call it),
            // so the profile would count other code than `scripts/emu.sh` does.
            let on_reading: fn(&mut Controller2d, u32, Reading) -> Output2d =
                black_box(Controller2d::on_reading);
            let frames = unsafe { &*core::ptr::addr_of!(FRAMES) };
            let readings = unsafe { &*core::ptr::addr_of!(READINGS) };
            let outputs = unsafe { &mut *core::ptr::addr_of_mut!(OUTPUTS2D) };
            let cost = measure(|| {
                for ((f, rd), o) in frames[..n]
                    .iter()
                    .zip(&readings[..n])
                    .zip(outputs[..n].iter_mut())
                {
                    *o = on_reading(&mut ctl, black_box(f).t_us, *black_box(rd));
                }
            });
            report("PROFILE", name, n, per_sample_x10(cost, 0, n));
            debug::exit(debug::EXIT_SUCCESS);
        }
    }
    defmt::error!("EMU_PROFILE: no 2d vector {=str}", traj);
    fail()
}

/// Profiling build (`EMU_PROFILE=<kind>/<trajectory>` at build time, scripts/emu-profile.sh):
/// replays only that one-region scene over the default scene's vector of that trajectory, so
/// QEMU's per-instruction trace holds one case.
fn profile(g: &Golden, case: &str) -> ! {
    let (kind, traj) = case.split_once('/').unwrap_or((case, "back-and-forth"));
    if kind == "plane" {
        profile2d(traj);
    }
    let mut want = [0u8; 48];
    let want = join(&mut want, "default", traj);
    let n = load_bench_inputs(g, want);
    for (k, texture, lines) in kind_cases() {
        if k == kind {
            let mut ctl = new_controller(g, &single(texture, lines));
            let cost = replay(&mut ctl, n);
            report("PROFILE", case, n, per_sample_x10(cost, 0, n));
            debug::exit(debug::EXIT_SUCCESS);
        }
    }
    defmt::error!("EMU_PROFILE: no kind {=str}", kind);
    fail()
}

#[entry]
fn main() -> ! {
    let mut cp = cortex_m::Peripherals::take().unwrap_or_else(|| fail());
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0xFF_FFFF);
    cp.SYST.clear_current();
    cp.SYST.enable_interrupt();
    cp.SYST.enable_counter();

    let g = parse_golden();
    defmt::info!(
        "boot: saw-core emulator image (Cortex-M4F, mps2-an386), {} scenes, {} bytes of golden vectors",
        g.n_scenes,
        GOLDEN.len()
    );
    // Calibration of the counter itself: an empty measurement.
    let empty = measure(|| {});
    defmt::println!(
        "SYSTICK empty_measure={=u64} instr_per_tick={=u64}",
        empty,
        INSTR_PER_TICK
    );

    if let Some(case) = option_env!("EMU_PROFILE") {
        profile(&g, case);
    }
    let ok = equivalence_and_scene_costs(&g);
    let ok = plane_vectors() && ok;
    for traj in ["back-and-forth", "rest"] {
        let mut want = [0u8; 48];
        let want = join(&mut want, "default", traj);
        let n = load_bench_inputs(&g, want);
        texture_costs(&g, traj, n);
    }
    let n = load_bench_inputs(&g, "default/back-and-forth");
    estimator_costs(&g, n);
    stage_costs(n);
    defmt::println!("DONE equivalence={=bool}", ok);
    if ok {
        debug::exit(debug::EXIT_SUCCESS);
    }
    fail()
}
