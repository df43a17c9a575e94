//! SAW tactile display firmware (embassy). Thin: init clocks, bind peripherals, spawn tasks.
//!
//! Tasks, by priority:
//! - on the interrupt executor (the sample path, preempts everything below):
//!   - `sampler`: timer-triggered (TIM3 TRGO, 10 kHz), DMA-fed ADC; each sample the
//!     16-conversion code (F446: 16 summed; G474: 32 halved by the oversampler).
//!   - `control`: feeds every sample to `saw_core::Controller`, applies gate actions to the
//!     burst timer, runs the stale-sensor watchdog every 1 ms, logs telemetry at 1 Hz, and
//!     between samples takes what the link hands over (a compiled scene, a counters request)
//!     and taps the telemetry stream.
//! - in thread mode: `link::link`, the host link (docs/link.md): frames in and out over the
//!   ST-LINK virtual COM port, scenes compiled here and only swapped in by `control`.
#![no_std]
#![no_main]
// The 2D image leaves the 1D sample path (and the link, which serves it) unused.
#![cfg_attr(feature = "touch-2d", allow(dead_code, unused_imports))]

mod board;
mod fault;
mod flash_ecc;
mod level;
mod link;
mod rf;
#[cfg(feature = "selftest-delayed-pulse")]
mod selftest;
mod store;
#[cfg(feature = "touch-2d")]
mod touch2d;
#[cfg(feature = "touch-2d")]
mod link2d;

use defmt::{info, unwrap, warn};
use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_futures::select::{select, Either};
use embassy_stm32::gpio::Output;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Ticker};
use saw_core::burst::BurstTimer;
use saw_core::controller::Prepared;
use saw_core::gate::BurstOutput;
use saw_core::sample::Sample;
use board::Controller;

/// Panic: RF off first (the burst timer keeps running without the CPU), then the stop of the
/// fault path (`fault.rs`): with a debugger the message is logged and the core halts at a
/// breakpoint for probe-rs's backtrace; without one the chip resets at once.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    fault::stop(fault::Cause::Panic, 0, || defmt::error!("panic: {}", defmt::Display2Format(info)))
}

/// Same for hard faults.
#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    let pc = frame.pc();
    fault::stop(fault::Cause::HardFault, -13, || defmt::error!("hard fault at pc {=u32:#010x}: RF off", pc))
}

/// NMI: on the G474 a flash double-ECC error raises it (RM0440 §5.3.10); one in the store is
/// noted and handled at boot (`flash_ecc.rs`), anything else is a fault. cortex-m-rt's default
/// would spin here with RF armed.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    if flash_ecc::on_nmi() {
        return;
    }
    fault::stop(fault::Cause::Nmi, -14, || defmt::error!("NMI: RF off"))
}

/// Any exception or interrupt we bound no handler to (cortex-m-rt's default is `loop {}`).
#[cortex_m_rt::exception]
unsafe fn DefaultHandler(irqn: i16) {
    fault::stop(fault::Cause::Unhandled, irqn, || defmt::error!("unhandled interrupt {}: RF off", irqn))
}

use board::BOARD;
use rf::{BurstGate, Carrier};

const VERSION: &str = env!("CARGO_PKG_VERSION");
/// Sample period, µs (100 at 10 kHz).
const SAMPLE_PERIOD_US: u32 = 1_000_000 / BOARD.sample_rate_hz;
// The sampler counts samples instead of reading the clock: the trigger timer's period must be
// exactly SAMPLE_PERIOD_US.
const _: () = {
    let (psc, arr) = BOARD.adc_trigger_psc_arr();
    let ticks = (psc + 1) * (arr + 1) * BOARD.adc.triggers_per_sample;
    assert!(1_000_000 % BOARD.sample_rate_hz == 0 && BOARD.adc.trigger_timer_clk_hz % 1_000_000 == 0);
    assert!(ticks == BOARD.adc.trigger_timer_clk_hz / 1_000_000 * SAMPLE_PERIOD_US);
};
/// Watchdog tick for `Controller::on_tick` (stale limit is 5 ms).
const WATCHDOG_PERIOD: Duration = Duration::from_millis(1);
/// Independent watchdog: if the control loop stops petting it (hang, starvation), the chip
/// resets and every RF pin returns to its reset state (enables low, arm low). Not frozen under
/// a debugger halt on purpose: a halted CPU must not leave the burst timer driving RF. Only the
/// panic/HardFault path, after RF is off, freezes it (and only with a debugger attached).
const IWDG_TIMEOUT_US: u32 = 50_000;
/// Telemetry log period.
const TELEMETRY_PERIOD_US: u64 = 1_000_000;
/// Shortest interval between two ADC fault warnings.
const ADC_WARN_PERIOD_US: u64 = 1_000_000;

/// The sample path's executor: `sampler` and `control` run in the UART4 interrupt (UART4 is
/// unused on both boards; its vector only runs this executor), so the link task in thread mode
/// never delays a sample. Priority 6 of 0–15: below the DMA and timer interrupts embassy's
/// drivers use (their default, 0), above thread mode.
static EXECUTOR_HIGH: InterruptExecutor = InterruptExecutor::new();
const SAMPLE_PATH_PRIORITY: Priority = Priority::P6;

#[interrupt]
unsafe fn UART4() {
    // SAFETY: the executor runs only from this vector, started once in `main`.
    unsafe { EXECUTOR_HIGH.on_interrupt() }
}

/// Samples from the ADC task to the control task (6.4 ms of slack at 10 kHz).
static SAMPLES: Channel<CriticalSectionRawMutex, Sample, 64> = Channel::new();
/// The control task is running: the sampler starts the acquisition only then. The task's first
/// poll moves its arguments (the controller, 3.5 KB, and the burst gate) into its state; done
/// while the first sample waited, those copies (~8 800 instructions on the F446) put the first
/// burst 99.5 µs after its trigger (board-model check, sensor-to-gate latency, limit 100 µs).
static CONTROL_READY: Signal<CriticalSectionRawMutex, ()> = Signal::new();

// The 2D image's `main` is `touch2d::main`.
#[cfg(not(feature = "touch-2d"))]
#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let Some(p) = board::init() else {
        fault::halt_without_clock(board::HSE_SOURCE, board::HSE_TIMEOUT_MS)
    };
    let c = &BOARD.clocks;
    info!("saw-firmware v{} on {} ({})", VERSION, BOARD.name, BOARD.probe_rs_chip);
    if let Some((cause, irqn)) = fault::take_last() {
        warn!("boot: the previous run ended in the fault path ({}, exception {}): RF was turned off, then the chip reset", cause, irqn);
    }
    info!(
        "clocks: osc {} Hz /M{} xN{} /{}{} -> SYSCLK {} Hz, HCLK {} Hz, PCLK1 {} Hz, PCLK2 {} Hz",
        c.osc_hz,
        c.pll_m,
        c.pll_n,
        if matches!(c.pll_out, saw_boards::PllOut::P) { "P" } else { "R" },
        c.pll_out_div,
        c.sysclk_hz,
        c.hclk_hz(),
        c.pclk1_hz(),
        c.pclk2_hz()
    );

    let parts = board::split(p);
    let mut rf_arm: Output<'static> = parts.rf_arm;
    // The level before the burst gate: DAC on at code 0, TIM8 stopped, before TIM2 can run.
    let level = level::RfLevel::new(parts.envelope_tim, parts.dac, parts.dac_pin, parts.envelope_dma);
    let mut burst = BurstGate::new(parts.burst_tim, parts.burst_pin, parts.burst_b_pin, level, BOARD);
    let carrier = Carrier::start(parts.carrier_tim, parts.carrier_pin, BOARD);
    info!(
        "carrier: {} {} / {} = {} Hz (registers give {} Hz); burst: {} {}-bit @ {} Hz",
        BOARD.carrier.name,
        BOARD.carrier_timer_clk_hz,
        BOARD.carrier_divider,
        BOARD.carrier_hz(),
        carrier.frequency_hz(),
        BOARD.burst.name,
        BOARD.burst_timer_bits,
        BOARD.burst_timer_clk_hz
    );
    defmt::assert_eq!(carrier.frequency_hz(), saw_boards::CARRIER_HZ);
    // Carrier runs free for the life of the firmware.
    core::mem::forget(carrier);

    let timer = BurstTimer {
        clock_hz: BOARD.burst_timer_clk_hz,
        counter_bits: BOARD.burst_timer_bits,
        max_burst_hz: BOARD.max_burst_hz,
    };
    // Test images only: one delayed pulse, RF arm still low (src/selftest.rs).
    #[cfg(feature = "selftest-delayed-pulse")]
    selftest::delayed_pulse(&mut burst, &timer).await;
    let mut ctrl = unwrap!(Controller::with_window(timer, SAMPLE_PERIOD_US));
    let mut store = store::open(parts.store);
    let (config, prepared, source) = boot_scene(&timer, store.as_mut()).await;
    ctrl.install(prepared);
    let session = saw_link::session::Session::new(
        saw_link::session::Identity {
            firmware: concat!("saw-firmware ", env!("CARGO_PKG_VERSION")),
            board: BOARD.name,
            sample_rate_hz: BOARD.sample_rate_hz,
        },
        config,
        source,
    );

    // Both enable lines are forced inactive: now the amplifier may be armed.
    rf_arm.set_high();
    // The conversions made per sample and their sampling time (the G474 makes 32 and halves
    // the sum to the 16-conversion code the core reads).
    let half_cycles = BOARD.adc.sample_half_cycles;
    // Dual interleaved (`dual-adc`): ADC1 + ADC2, ADC2 the plan's delay behind.
    let adcs = match BOARD.adc.mode {
        saw_boards::AdcMode::Single => "",
        saw_boards::AdcMode::DualInterleaved { .. } => "+ADC2 interleaved",
    };
    info!(
        "adc: {}{} ch{} @ {} Hz x{} ({}.{}-cycle sampling, code = {} conversions' sum; trigger {} TRGO); enables CH{} + CH{}; rf arm high",
        BOARD.adc.adc,
        adcs,
        BOARD.adc.channel,
        BOARD.sample_rate_hz,
        BOARD.adc.oversampling.conversions(),
        half_cycles / 2,
        (half_cycles % 2) * 5,
        BOARD.adc_oversample,
        BOARD.adc.trigger_timer,
        BOARD.burst.channel,
        BOARD.burst_b_channel
    );

    let rl = &BOARD.rf_level;
    let points = rl.table.points;
    let rebuild_us = burst.time_worst_rebuild_us();
    info!(
        "rf level: DAC1_OUT1 on P{}{} ({}), buffer on, TSEL1 {} = {} TRGO; table {} points (0 ‰ -> code {}, 1000 ‰ -> code {}); envelope timer {} @ {} Hz, slave of {} (ITR{}), DMA {}; triangle table ({} entries) built in {} µs",
        rl.dac_pin.port,
        rl.dac_pin.pin,
        rl.dac_pin.header,
        rl.dac_tsel,
        rl.envelope_timer,
        points.len(),
        points[0].code,
        points[points.len() - 1].code,
        rl.envelope_timer,
        rl.envelope_timer_clk_hz,
        BOARD.burst.name,
        rl.envelope_ts,
        board::ENVELOPE_DMA,
        saw_boards::rf_level::MAX_ENVELOPE_ENTRIES,
        rebuild_us
    );

    let mut wdg = IndependentWatchdog::new(parts.iwdg, IWDG_TIMEOUT_US);
    wdg.unleash();

    interrupt::UART4.set_priority(SAMPLE_PATH_PRIORITY);
    let high = EXECUTOR_HIGH.start(interrupt::UART4);
    high.spawn(unwrap!(sampler(parts.sampler)));
    high.spawn(unwrap!(control(ctrl, burst, rf_arm, wdg, session.stamp())));
    let board = link::FirmwareBoard { timer, sample_period_us: SAMPLE_PERIOD_US, sent: 0, store };
    link::spawn(spawner, parts.link_tx, parts.link_rx, session, board);
}

/// The scene to boot into, compiled, and says which: the one saved in flash if it reads back and
/// compiles, else the one embedded at build time (`SAW_SCENE`, checked by build.rs on the host)
/// if any, else the built-in default.
async fn boot_scene(
    timer: &BurstTimer,
    store: Option<&mut saw_store::SceneStore<board::StoreFlash>>,
) -> (saw_core::scene::Config, Prepared, saw_link::msg::SceneSource) {
    use saw_link::msg::SceneSource;
    match store {
        Some(store) => match store::load_at_boot(store).await {
            Ok(Some(saved)) => {
                match Prepared::compile(timer, SAMPLE_PERIOD_US, &saved.config) {
                    Ok(p) => {
                        info!("boot: the scene saved in flash (id {=u32:08x})", saved.scene_id);
                        return (saved.config, p, SceneSource::Saved);
                    }
                    Err(e) => warn!("boot: the saved scene {=u32:08x} is refused ({})", saved.scene_id, e),
                }
            }
            Ok(None) => info!("boot: no scene saved in flash"),
            Err(e) => warn!("boot: the saved scene cannot be read ({})", e),
        },
        None => info!("boot: no scene store on this board"),
    }
    if let Some(bytes) = EMBEDDED_SCENE {
        match postcard::from_bytes::<saw_core::scene::Config>(bytes) {
            Ok(c) => match Prepared::compile(timer, SAMPLE_PERIOD_US, &c) {
                Ok(p) => {
                    info!("boot: the scene embedded at build time ({})", EMBEDDED_SCENE_FILE);
                    return (c, p, SceneSource::BuildTime);
                }
                Err(e) => warn!("boot: the embedded scene is refused ({}); the default runs", e),
            },
            Err(_) => warn!("boot: the embedded scene does not decode; the default runs"),
        }
    }
    info!("boot: the built-in default scene");
    let c = saw_core::default_config();
    let p = unwrap!(Prepared::compile(timer, SAMPLE_PERIOD_US, &c));
    (c, p, SceneSource::Default)
}

// `EMBEDDED_SCENE: Option<&[u8]>` and `EMBEDDED_SCENE_FILE: &str`, written by build.rs.
include!(concat!(env!("OUT_DIR"), "/scene.rs"));

/// Stamps a batch's samples and queues them for `control`; returns the time of the next sample.
/// The sampler's per-sample work, never inlined: a root of the panic check (see `sample_step`).
#[inline(never)]
fn deliver(batch: &board::Batch, next_t: Option<u32>, now_us: u32, dropped: &mut u32) -> u32 {
    let n = batch.codes.len() as u32;
    // The newest sample in the ring buffer has landed by now, so the batch's first one was taken
    // no later than `latest`, and (one landing per period) less than two periods before it. The
    // count carries on while it stays in that window; it is re-anchored at `latest` at start,
    // after lost samples, and whenever it would stamp a sample later than now — the core's stale
    // check (now − t, wrapping) must never see a sample from the future.
    let latest = now_us.wrapping_sub(batch.backlog.wrapping_add(n).wrapping_sub(1).wrapping_mul(SAMPLE_PERIOD_US));
    let mut t_us = match next_t {
        Some(t) if latest.wrapping_sub(t) < 2 * SAMPLE_PERIOD_US => t,
        _ => latest,
    };
    for &code in &batch.codes {
        if !queue_sample(Sample { code, t_us }) {
            // Control task is behind; the stale watchdog covers a stuck consumer.
            *dropped = dropped.wrapping_add(1);
        }
        t_us = t_us.wrapping_add(SAMPLE_PERIOD_US);
    }
    t_us
}

/// Queues a sample for `control`; false if the queue is full. Never inlined: the panic check's
/// allow list (scripts/panic-check.allow) names it for the channel's RefCell borrow, which
/// cannot fail.
#[inline(never)]
fn queue_sample(sample: Sample) -> bool {
    SAMPLES.try_send(sample).is_ok()
}

#[embassy_executor::task]
async fn sampler(mut s: board::Sampler) {
    // Acquisition restarts, and samples the control task had no room for.
    let (mut restarts, mut dropped) = (0u32, 0u32);
    let mut quiet_until_us = 0u64;
    // Time of the next sample. TIM3 triggers exactly every SAMPLE_PERIOD_US (const-checked at
    // SAMPLE_PERIOD_US) from the same APB1 timer clock as the 1 MHz time driver (TIM4), so within
    // one run of the acquisition sample n is at t0 + n × period: no drift against `Instant`, no
    // bunching when `read` hands out an older backlog. None = anchor again (after a restart).
    let mut next_t: Option<u32> = None;
    CONTROL_READY.wait().await;
    s.start();
    loop {
        match s.read().await {
            Ok(batch) => {
                let now = Instant::now().as_micros() as u32;
                next_t = Some(deliver(&batch, next_t, now, &mut dropped));
            }
            Err(fault) => {
                next_t = None;
                // The sampler has already restarted the acquisition. At most one line per
                // ADC_WARN_PERIOD_US; the totals count the ones not logged.
                restarts = restarts.wrapping_add(1);
                let now = Instant::now().as_micros();
                if now >= quiet_until_us {
                    quiet_until_us = now + ADC_WARN_PERIOD_US;
                    warn!(
                        "adc {}: acquisition restarted ({} restarts, {} samples dropped so far)",
                        fault, restarts, dropped
                    );
                }
            }
        }
    }
}

/// One sample through the core onto the burst gate and the RF level, and into the telemetry
/// stream: all the control loop does per sample. Never inlined, so the panic check
/// (scripts/panic-check.sh) can root at it: nothing reachable from here may panic.
#[inline(never)]
fn sample_step(ctrl: &mut Controller, burst: &mut BurstGate, tap: &mut link::StreamTap, sample: Sample) {
    let out = ctrl.on_sample(sample);
    // The panic check's planted defect (feature plant-sample-unwrap, never in a real image): an
    // index from the sample that can fall outside its table, unwrapped.
    #[cfg(feature = "plant-sample-unwrap")]
    core::hint::black_box([1u8, 2, 3, 4].get(usize::from(sample.code & 7)).copied().unwrap());
    // Drive mode, then amplitude, then the line (saw-core's order).
    saw_core::controller::apply(&out, burst);
    if tap.take(ctrl) && tap.started_by(sample.t_us) {
        let time_us = tap.widen(sample.t_us);
        tap.push(saw_link::msg::Record {
            time_us,
            scene_id: tap.stamp.scene_id,
            change: tap.stamp.change,
            position_um: out.position_um,
            // The sample's own when it computed one; in a region that reads no velocity the
            // estimator rests and the controller makes it from its sums, at the stream's rate
            // (docs/sample-contract.md).
            velocity_um_s: out.velocity_um_s.or_else(|| ctrl.velocity_um_s()),
            region: out.region,
            burst_millihz: ctrl.burst_millihz(),
            bursting: burst.line() != rf::Line::Off,
            fault: out.fault,
        });
    }
}

/// The stale-sensor watchdog's tick (every WATCHDOG_PERIOD): a sensor that stopped delivering
/// turns RF off. Never inlined, for the panic check's roots (see `sample_step`).
#[inline(never)]
fn tick_step(ctrl: &mut Controller, burst: &mut BurstGate, now_us: u32) {
    if let Some(a) = ctrl.on_tick(now_us) {
        burst.apply(a);
    }
}

#[embassy_executor::task]
async fn control(
    mut ctrl: Controller,
    mut burst: BurstGate,
    mut rf_arm: Output<'static>,
    mut wdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
    stamp: saw_link::session::Stamp,
) {
    // `rf_arm` is owned here for the life of the loop (a reset drops it low; an external
    // pull-down keeps the amplifier disarmed while the pin is unconfigured); it goes low only
    // while a save holds RF off.
    let mut held: Option<store::Timeout> = None;
    let mut watchdog = Ticker::every(WATCHDOG_PERIOD);
    let mut next_log = Instant::now().as_micros() + TELEMETRY_PERIOD_US;
    let mut tap = link::StreamTap::new(stamp);
    CONTROL_READY.signal(());
    loop {
        match select(SAMPLES.receive(), watchdog.next()).await {
            Either::First(sample) => sample_step(&mut ctrl, &mut burst, &mut tap, sample),
            Either::Second(()) => tick_step(&mut ctrl, &mut burst, Instant::now().as_micros() as u32),
        }
        // Between samples: a scene compiled by the link, a counters request, a save's hold.
        if let Some(quiet) = link::service(&mut ctrl, &mut tap) {
            link::hold_rf(quiet, &mut rf_arm, &mut held);
        }
        // A completed iteration is a live control loop.
        wdg.pet();
        // Checked on both branches so a busy sample queue cannot starve the log.
        let now = Instant::now().as_micros();
        if now >= next_log {
            next_log = now + TELEMETRY_PERIOD_US;
            info!("telemetry {} burst {} line {}", ctrl.telemetry(), burst.stats, burst.line());
        }
    }
}
