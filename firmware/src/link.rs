//! The host link on the board: the ST-LINK virtual COM port (UART, DMA both ways), the session
//! of `saw_link` that decides what each request does, and the hand-over to the control loop.
//!
//! The link task runs in thread mode, below the control loop's interrupt executor: it can be
//! preempted by every sample and never delays one. Everything the two share crosses through the
//! statics below: a compiled scene goes in whole (`INSTALL`; the control loop only moves it in),
//! counters come out on request, stream records come out through a bounded queue that drops and
//! counts when the link falls behind.
//!
//! The 2D image (`link2d.rs`) runs the same UART task (`uart::link`, over the board
//! glue: [`Streaming`]), the same save hold (`QUIET`, [`quiet`], [`hold_rf`]) and the same
//! hand-over statics where they carry no 1D type (the stamp, `INSTALLED`, `TELEMETRY_WANTED`,
//! `EVERY`, `DROPPED`); only one image runs on a board, so they are never shared at run time.

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use saw_core::burst::BurstTimer;
use saw_core::controller::{ConfigError, Prepared, Telemetry};
use saw_core::scene::Config;
use saw_link::msg::{Record, StoreFault};
use saw_link::session::{Board, Stamp};
use saw_link::stream::{Decimator, QUEUE_RECORDS};


/// A compiled scene on its way to the control loop.
pub static INSTALL: Signal<CriticalSectionRawMutex, Prepared> = Signal::new();
/// The stamp its records carry (scene id, change count), set before `INSTALL`.
pub(crate) static STAMP_SCENE: AtomicU32 = AtomicU32::new(0);
pub(crate) static STAMP_CHANGE: AtomicU32 = AtomicU32::new(0);
/// The control loop has installed it.
pub static INSTALLED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// The link asks for the counters; the control loop answers in `TELEMETRY`.
pub static TELEMETRY_WANTED: AtomicBool = AtomicBool::new(false);
/// The counters, handed over between two samples.
pub static TELEMETRY: Signal<CriticalSectionRawMutex, Telemetry> = Signal::new();
/// The stream in force: its decimation (samples a record, 0: stopped) in the low 16 bits, and
/// above them a count of stream requests, so a request that repeats the decimation in force (a
/// host reconnecting) is a new stream to the tap too: its start (`STREAM_FROM_US`) is read
/// again and nothing older than it becomes a record. One word: the tap's per-sample cost stays
/// one load and a compare.
pub static EVERY: AtomicU32 = AtomicU32::new(0);

/// Starts (or stops, `every_samples` 0) a stream: the link task is `EVERY`'s only writer.
pub(crate) fn request_stream(every_samples: u16) {
    let requests = (EVERY.load(Ordering::Relaxed) >> 16).wrapping_add(1);
    EVERY.store(requests << 16 | every_samples as u32, Ordering::Relaxed);
}

/// Records from the control loop to the link.
pub static RECORDS: Channel<CriticalSectionRawMutex, Record, QUEUE_RECORDS> = Channel::new();
/// When the stream in force started (µs since boot, low 32 bits), stored before `EVERY`: a
/// sample taken before it and tapped after (still converting when the request was answered) is
/// no record of it (`StreamTap::started_by`).
pub static STREAM_FROM_US: AtomicU32 = AtomicU32::new(0);
/// Records the queue had no room for.
pub static DROPPED: AtomicU32 = AtomicU32::new(0);
/// The link asks the control loop to hold RF off (true: a save is about to touch the flash) or
/// to let it run again (false); the control loop answers in `QUIETED` once it has.
pub static QUIET: Signal<CriticalSectionRawMutex, bool> = Signal::new();
/// The control loop has done what `QUIET` asked.
pub static QUIETED: Signal<CriticalSectionRawMutex, ()> = Signal::new();

/// Streams with a record at least this often (samples) have the estimator updated on every
/// sample rather than rested (see [`StreamTap::take`]).
const STREAM_VELOCITY_EVERY_SAMPLE: u16 = 2;

/// The control loop's end of the stream: one atomic load and a compare per sample while
/// stopped.
pub struct StreamTap {
    decimator: Decimator,
    /// `EVERY` as last seen.
    every: u32,
    /// The scene in force, as its records carry it.
    pub stamp: Stamp,
    /// The last record's time, 32-bit and widened to 64: the next is widened from it.
    last_us: Option<(u32, u64)>,
    /// A new stream's start (`STREAM_FROM_US`) until its first record.
    from_us: Option<u32>,
}

impl StreamTap {
    /// Stopped; records stamped with `stamp` (the scene the board booted into).
    pub const fn new(stamp: Stamp) -> Self {
        Self { decimator: Decimator::new(), every: 0, stamp, last_us: None, from_us: None }
    }

    /// A streamed sample's 32-bit µs time as µs since boot (64 bits). From the record before:
    /// one subtraction, exact while records are less than 71.6 min apart (at most 1 s: every
    /// 10 000th sample); the first of a stream is widened against the 64-bit clock, once, so
    /// the sample path does not read the clock per record (issue #33's tap cost check).
    #[inline]
    pub fn widen(&mut self, t_us: u32) -> u64 {
        widen(&mut self.last_us, t_us)
    }

    /// Whether this sample becomes a record (follows `EVERY`). A stream that reads the
    /// velocity at every sample or every other one makes the controller update its estimator on
    /// every sample: resting it and making the slope for each record would cost the sample
    /// path more than updating it (docs/sample-contract.md; the board model's stream-cost check).
    #[inline]
    pub fn take(&mut self, ctrl: &mut crate::board::Controller) -> bool {
        let word = EVERY.load(Ordering::Relaxed);
        if word != self.every {
            self.every = word;
            let every = word as u16;
            self.decimator.set(every);
            // A new stream's first record is widened against the clock again.
            self.last_us = None;
            // Read after `EVERY`, stored before it (`FirmwareBoard::stream`); one core.
            core::sync::atomic::compiler_fence(Ordering::Acquire);
            self.from_us = Some(STREAM_FROM_US.load(Ordering::Relaxed));
            ctrl.velocity_every_sample((1..=STREAM_VELOCITY_EVERY_SAMPLE).contains(&every));
        }
        self.decimator.take()
    }

    /// Whether the sample taken at `t_us` belongs to the stream in force: not before its start.
    /// On the G474 a sample's conversions outlast the answer to a stream request (the board
    /// model's check `link: records carry the scene in force and start after the request`: a
    /// record 16 µs before `from_us`).
    #[inline]
    pub fn started_by(&mut self, t_us: u32) -> bool {
        match self.from_us {
            Some(from) if (t_us.wrapping_sub(from) as i32) < 0 => false,
            _ => {
                self.from_us = None;
                true
            }
        }
    }

    /// Queues a record, or counts it dropped. Never inlined: the panic check's allow list
    /// (scripts/panic-check.allow) names it for the channel's RefCell borrow, which cannot fail.
    #[inline(never)]
    pub fn push(&self, record: Record) {
        if RECORDS.try_send(record).is_err() {
            DROPPED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// `t_us` (32-bit µs) as µs since boot (64 bits), from the last record's pair `last_us` (then
/// updated): see [`StreamTap::widen`]; the 2D tap's too.
#[inline]
pub(crate) fn widen(last_us: &mut Option<(u32, u64)>, t_us: u32) -> u64 {
    let wide = match *last_us {
        Some((last32, last64)) => last64.wrapping_add(u64::from(t_us.wrapping_sub(last32))),
        None => {
            let now = embassy_time::Instant::now().as_micros();
            now.wrapping_sub(u64::from((now as u32).wrapping_sub(t_us)))
        }
    };
    *last_us = Some((t_us, wide));
    wide
}

/// The control loop's end of the hand-over, called once per iteration between samples.
/// Returns a `QUIET` request for the control loop to carry out (then it calls `quieted`).
pub fn service(ctrl: &mut crate::board::Controller, tap: &mut StreamTap) -> Option<bool> {
    if let Some(p) = INSTALL.try_take() {
        ctrl.install(p);
        // The new scene's first sample is a record, stamped with it.
        tap.stamp = Stamp {
            scene_id: STAMP_SCENE.load(Ordering::Relaxed),
            change: STAMP_CHANGE.load(Ordering::Relaxed),
        };
        tap.decimator.force_next();
        INSTALLED.signal(());
    }
    if TELEMETRY_WANTED.swap(false, Ordering::Relaxed) {
        TELEMETRY.signal(ctrl.telemetry());
    }
    QUIET.try_take()
}

/// The control loop has carried out a `QUIET` request.
pub fn quieted() {
    QUIETED.signal(());
}

/// The control loop carries out a `QUIET` request (`quiet`: a save is about to touch the flash):
/// RF off at the amplifier before the flash can stall us, then a watchdog long enough for an
/// erase; the gate keeps following the controller, so bursts resume in step when the arm comes
/// back. Then [`quieted`]. Both images' control loops.
pub fn hold_rf(quiet: bool, rf_arm: &mut embassy_stm32::gpio::Output<'static>, held: &mut Option<crate::store::Timeout>) {
    if quiet {
        rf_arm.set_low();
        *held = Some(crate::store::lengthen_watchdog());
        defmt::info!("save: rf arm low, watchdog lengthened");
    } else if let Some(t) = held.take() {
        crate::store::restore_watchdog(t);
        rf_arm.set_high();
        defmt::info!("save: done, watchdog restored, rf arm high");
    }
    quieted();
}

/// Asks the control loop to hold RF off (or let it run) and waits until it has.
pub(crate) async fn quiet(on: bool) {
    QUIETED.reset();
    QUIET.signal(on);
    QUIETED.wait().await;
}

/// The board as the session sees it.
pub struct FirmwareBoard {
    pub timer: BurstTimer,
    pub sample_period_us: u32,
    pub sent: u32,
    /// The scene store; None when the board has none (then `save` says so).
    pub store: Option<saw_store::SceneStore<crate::board::StoreFlash>>,
}

impl Board for FirmwareBoard {
    async fn apply(&mut self, config: &Config, stamp: Stamp) -> Result<(), ConfigError> {
        // Compiled here, at thread priority; the control loop only swaps it in.
        let p = Prepared::compile(&self.timer, self.sample_period_us, config)?;
        // Stored before the signal: the control loop reads them once it takes the scene.
        STAMP_SCENE.store(stamp.scene_id, Ordering::Relaxed);
        STAMP_CHANGE.store(stamp.change, Ordering::Relaxed);
        INSTALLED.reset();
        INSTALL.signal(p);
        INSTALLED.wait().await;
        Ok(())
    }

    async fn telemetry(&mut self) -> Telemetry {
        TELEMETRY.reset();
        TELEMETRY_WANTED.store(true, Ordering::Relaxed);
        TELEMETRY.wait().await
    }

    fn now_us(&mut self) -> u64 {
        embassy_time::Instant::now().as_micros()
    }

    fn stream(&mut self, every_samples: u16) {
        // Read after the session's `from_us`: no record is older than that.
        STREAM_FROM_US.store(embassy_time::Instant::now().as_micros() as u32, Ordering::Relaxed);
        core::sync::atomic::compiler_fence(Ordering::Release);
        request_stream(every_samples);
        // Records of the stream before are stale to whoever asked (the host drops those older
        // than the answer's `from_us`): the line is not spent on them.
        RECORDS.clear();
    }

    fn stream_counts(&mut self) -> (u32, u32) {
        (DROPPED.load(Ordering::Relaxed), self.sent)
    }

    /// Saves with RF held off from before the first flash operation to after the last: on a
    /// single-bank flash every fetch (and so the sample path) stalls while a unit is written or
    /// erased, and the burst timer would keep gating RF at the last command meanwhile. The
    /// control loop also lengthens the watchdog for that time (`store::lengthen_watchdog`).
    async fn save(&mut self, scene_id: u32, config: &Config) -> Result<(), StoreFault> {
        let Some(store) = self.store.as_mut() else {
            return Err(StoreFault::NoStore);
        };
        let saved = saw_store::Saved { scene_id, config: config.clone() };
        quiet(true).await;
        let result = store.save(&saved).await;
        quiet(false).await;
        match result {
            Ok(()) => {
                defmt::info!("store: scene {=u32:08x} saved", scene_id);
                Ok(())
            }
            Err(e) => {
                defmt::warn!("store: scene {=u32:08x} not saved: {}", scene_id, e);
                Err(e.into())
            }
        }
    }
}

/// Starts the link task over `session` and `board`, both moved into statics of their own (see
/// `uart::link`).
pub fn spawn(
    spawner: embassy_executor::Spawner,
    tx: embassy_stm32::usart::UartTx<'static, embassy_stm32::mode::Async>,
    rx: embassy_stm32::usart::RingBufferedUartRx<'static>,
    session: saw_link::session::Session,
    board: LinkBoard,
) {
    static SESSION: static_cell::StaticCell<saw_link::session::Session> = static_cell::StaticCell::new();
    static BOARD: static_cell::StaticCell<LinkBoard> = static_cell::StaticCell::new();
    spawner.spawn(defmt::unwrap!(uart::link(tx, rx, SESSION.init(session), BOARD.init(board))));
}

/// `spawn` over board glue already in its static (the 2D image's: its boot loads the saved scene
/// through the glue's store there, so main's future never holds the store).
pub fn spawn_on(
    spawner: embassy_executor::Spawner,
    tx: embassy_stm32::usart::UartTx<'static, embassy_stm32::mode::Async>,
    rx: embassy_stm32::usart::RingBufferedUartRx<'static>,
    session: saw_link::session::Session,
    board: &'static mut LinkBoard,
) {
    static SESSION: static_cell::StaticCell<saw_link::session::Session> = static_cell::StaticCell::new();
    spawner.spawn(defmt::unwrap!(uart::link(tx, rx, SESSION.init(session), board)));
}

/// The board glue the link task serves: the 1D image's, or the 2D image's (`link2d.rs`).
#[cfg(not(feature = "touch-2d"))]
pub type LinkBoard = FirmwareBoard;
#[cfg(feature = "touch-2d")]
pub type LinkBoard = crate::link2d::Board2d;

/// What the link task needs of a board besides the session's [`Board`]: the queue its stream
/// records come through (1D [`Record`]s, the 2D image's `Record2d`s) and a count of those sent.
pub trait Streaming: Board {
    /// The records it streams.
    type Record: saw_link::stream::Streamed + 'static;
    /// The queue from the control loop.
    fn records(&self) -> &'static Channel<CriticalSectionRawMutex, Self::Record, QUEUE_RECORDS>;
    /// One more record taken from the queue for a frame.
    fn count_sent(&mut self);
}

// The 2D image's saw-link (`plane-only`) has no 1D stream frame.
#[cfg(not(feature = "touch-2d"))]
impl Streaming for FirmwareBoard {
    type Record = Record;
    fn records(&self) -> &'static Channel<CriticalSectionRawMutex, Record, QUEUE_RECORDS> {
        &RECORDS
    }
    fn count_sent(&mut self) {
        self.sent = self.sent.wrapping_add(1);
    }
}

// The UART side: the F446's USART2, the G474's LPUART1 (board/*.rs bring them up).
/// The link's line rate: 921 600 baud, 8N1, a standard rate the ST-LINK/V2-1's (F446) and
/// STLINK-V3E's (G474) virtual COM ports take (not yet measured on a board). On the F446, 45 MHz / BRR 49 gives 918 367 baud,
/// 0.35 % slow, well inside the ±2 % an 8N1 receiver tolerates (RM0390 §25.4.5). On the G474,
/// LPUART1 runs from PCLK1 = 150 MHz (CCIPR.LPUART1SEL = 00, RM0440 §7.4.26) and BRR = 256 ×
/// 150 MHz / 921 600 = 41 667 (§38.4.8) gives 921 593 baud, 0.0008 % slow.
pub const BAUD: u32 = 921_600;
mod uart {
    use core::sync::atomic::Ordering;

    use defmt::{info, warn};
    use embassy_futures::select::{select3, Either3};
    use embassy_stm32::mode::Async;
    use embassy_stm32::usart::{RingBufferedUartRx, UartTx};
    use embassy_time::{Duration, Timer};
    use saw_link::frame::{self, Receiver, MAX_ENCODED};
    use saw_link::msg::{Header, Reply};
    use saw_link::session::Session;
    use saw_link::stream::Batcher;

    use super::{LinkBoard, Streaming, BAUD, DROPPED};

    /// A partial stream frame goes out after this long, so a slow stream arrives steadily.
    const FLUSH_AFTER: Duration = Duration::from_millis(20);

    /// Frames `reply` and sends it (DMA); a failed write is logged, the link goes on.
    async fn send(tx: &mut UartTx<'static, Async>, header: &Header, reply: &Reply) {
        let mut out = [0u8; MAX_ENCODED];
        match frame::encode(header, reply, &mut out) {
            Ok(n) => {
                if tx.write(&out[..n]).await.is_err() {
                    warn!("link: a reply could not be sent");
                }
            }
            Err(e) => warn!("link: a reply could not be framed: {}", e),
        }
    }

    /// The link's loop: requests in, answers out, the stream's records framed and sent; over the
    /// image's board glue (`LinkBoard`: the 1D `FirmwareBoard`, the 2D image's `link2d::Board2d`).
    /// One task, not a generic function under a task per image: a task awaiting a generic
    /// function kept its arguments beside the function's future, 1.5 KB more RAM in the 1D image.
    ///
    /// The session and the board glue are the caller's statics (`spawn`), by reference: a task's
    /// argument by value stays in its future beside the copy the body works on (the 2D image's
    /// session and store glue, 4.2 KB twice).
    #[embassy_executor::task]
    pub async fn link(
        mut tx: UartTx<'static, Async>,
        mut rx: RingBufferedUartRx<'static>,
        session: &'static mut Session,
        board: &'static mut LinkBoard,
    ) {
        info!("link: {} baud on the ST-LINK virtual COM port", BAUD);
        let mut receiver = Receiver::<MAX_ENCODED>::default();
        let mut batcher = Batcher::<<LinkBoard as Streaming>::Record>::default();
        let mut bytes = [0u8; 64];
        let records = board.records();
        // The 2D image's boot scene, compiled by the control loop before the first request.
        #[cfg(feature = "touch-2d")]
        crate::link2d::boot_scene(session, board).await;
        loop {
            match select3(rx.read(&mut bytes), records.receive(), Timer::after(FLUSH_AFTER)).await {
                Either3::First(Ok(n)) => {
                    for &b in &bytes[..n] {
                        let (header, reply) = match receiver.push(b) {
                            None => continue,
                            Some(Ok(len)) => session.on_frame(board, receiver.payload(len)).await,
                            Some(Err(e)) => session.on_bad_frame(None, e),
                        };
                        send(&mut tx, &header, &reply).await;
                    }
                }
                // An overrun or a framing error: the bytes lost are a broken frame the receiver
                // drops at the next zero; the ring buffer restarts on the next read.
                Either3::First(Err(e)) => warn!("link: uart {}", e),
                Either3::Second(record) => {
                    board.count_sent();
                    if let Some((h, r)) = batcher.push(record, DROPPED.load(Ordering::Relaxed)) {
                        send(&mut tx, &h, &r).await;
                    }
                }
                Either3::Third(()) => {
                    if let Some((h, r)) = batcher.flush(DROPPED.load(Ordering::Relaxed)) {
                        send(&mut tx, &h, &r).await;
                    }
                }
            }
        }
    }
}
