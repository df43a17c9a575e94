//! The 2D image's host link and scene store (feature `touch-2d`, issue #36): the board glue
//! behind `saw_link`'s 2D session (`Session::new_2d`: push, read back, move and resize windows,
//! counters, save), the hand-over of a compiled 2D scene to the control loop, the 2D stream's
//! tap (one `Record2d` per frame at the stream's rate), and the boot scene (the 2D scene saved in
//! flash if it reads back and compiles, else the built-in one).
//!
//! What is not 2D is the 1D image's, shared: the UART task (`link::link`), the save's hold of
//! RF and the watchdog (`link::quiet`, `link::hold_rf`), the store's flash, hooks and boot repair
//! (`store.rs`). A 2D scene is an item of the same store under its own tag (`saw_store::FORMAT_2D`),
//! so this image never loads a 1D scene and the 1D image never loads a 2D one.

use core::sync::atomic::{AtomicBool, AtomicPtr, Ordering};

use defmt::{info, warn};
use embassy_stm32::gpio::Output;
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{RingBufferedUartRx, UartTx};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use saw_core::burst::BurstTimer;
use saw_core::controller::{ConfigError, Telemetry};
use saw_core::gate::Envelope;
use saw_core::plane::{
    Config2d, Config2dError, Controller2d, EdgePulse, Output2d, Telemetry2d,
};
use saw_core::touch::frame::Reading;
use saw_link::msg::{Fault2d, PlaneScene, Record2d, SceneSource, StoreFault};
use saw_link::session::{Active, Apply2dError, Board, Identity, Session, Stamp};
use saw_link::stream::{Decimator, EdgeLatch, QUEUE_RECORDS};
use saw_store::{SceneStore, ITEM_BYTES_2D};

use crate::board::{StoreFlash, BOARD};
use crate::link::{
    self, Streaming, DROPPED, EVERY, STAMP_CHANGE, STAMP_SCENE, TELEMETRY_WANTED,
};
use crate::rf::{BurstGate, Line};

// PLATE_UM: written by build.rs (the built-in scene's plate, the calibration's).
include!(concat!(env!("OUT_DIR"), "/plate2d.rs"));

/// The 2D store: the 1D store's flash and layout, a 2D scene's item buffer.
pub type Store2d = SceneStore<StoreFlash, ITEM_BYTES_2D>;

/// A 2D scene on its way to the control loop, which compiles and installs it between two frames
/// (`Controller2d::load`: all or nothing, the old scene kept on a refusal) and answers in
/// `APPLIED`. Not compiled in the link task as the 1D scene is: a compiled 2D scene is ~9.5 KB, and
/// handing it over would keep a second copy in RAM and stack `Prepared2d::compile`'s ~36 KB frame on
/// the link task's ~42 KB poll frame, more than the F446's stack (the board model's stack check).
/// Compiled in the control loop it stacks on an idle thread mode instead (the link task waits for
/// the answer); the frames arriving meanwhile wait in their queue (4 frames, 1.4 ms on the F446).
///
/// The link task stores the scene's address while `FULL` is clear, then sets `FULL` and waits; the
/// control loop reads the scene while `FULL` is set, then clears it and answers. The scene lives in
/// the session's `apply_2d` future, which the link task awaits until the answer (the link task's
/// futures are never cancelled: `link::link` awaits each request to its end).
static SCENE: AtomicPtr<PlaneScene> = AtomicPtr::new(core::ptr::null_mut());
static FULL: AtomicBool = AtomicBool::new(false);
/// Sets `FULL` from a task of its own (`arm2d`): the executor polls it after the link task's
/// poll has returned, so the control loop never compiles a scene (~46 KB of stack) on top of the
/// link task's ~42 KB poll frame. Set from inside that poll, the first push on the board model
/// ran the F446's stack off the start of RAM (board-model/tests/link2d.rs, the save test).
static ARM: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// `FULL` has been set: wakes the control loop while it waits for the boot scene
/// (`ControlLink::boot`; after that it finds `FULL` between two frames).
static ARMED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// The boot scene is in (or refused, and the built-in one tried): the acquisition may start.
static BOOTED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// The control loop's answer: the scene runs, or the controller's refusal.
static APPLIED: Signal<CriticalSectionRawMutex, Result<(), Config2dError>> = Signal::new();
/// The 2D counters, handed over between two frames (asked by `link::TELEMETRY_WANTED`).
static TELEMETRY_2D: Signal<CriticalSectionRawMutex, Telemetry2d> = Signal::new();
/// Records from the control loop to the link.
pub static RECORDS_2D: Channel<CriticalSectionRawMutex, Record2d, QUEUE_RECORDS> = Channel::new();

/// Builds the triangle table of `edge`'s one-pulse now (between frames or at boot: ~80 µs on
/// the G474), so the first edge's pulse does not build it on the frame's path.
pub(crate) fn prebuild(burst: &mut BurstGate, timer: &BurstTimer, edge: &EdgePulse) {
    let clocks = edge.pulse_us as u64 * timer.clock_hz as u64 / 1_000_000;
    if let (Envelope::Triangular, Ok(s)) = (edge.envelope, timer.one_pulse(clocks)) {
        let us = burst.prebuild_triangle(&s, edge.amplitude_permille);
        info!("rf level: the edge pulse's triangle built in {} us", us);
    }
}

/// The control loop's end of the 2D stream: one atomic load and a compare per frame while
/// stopped, a record queued when one is due.
pub struct Tap2d {
    decimator: Decimator,
    /// `EVERY` as last seen (decimation and request count).
    every: u32,
    stamp: Stamp,
    last_us: Option<(u32, u64)>,
    /// The f_b of the periodic burst last started or updated, mHz (0 after an off or a pulse).
    burst_millihz: u32,
    /// The edge the next record reports: the last crossed since the record before, so a
    /// decimated stream reports every pulse (saw-link's `EdgeLatch`; one store per crossing).
    edge: EdgeLatch,
}

impl Tap2d {
    const fn new(stamp: Stamp) -> Self {
        Self {
            decimator: Decimator::new(),
            every: 0,
            stamp,
            last_us: None,
            burst_millihz: 0,
            edge: EdgeLatch::new(),
        }
    }

    /// After a frame went through the controller (`out`) onto the gate (`line`): its record, if
    /// the stream wants one. The f_b is the running burst's, as the virtual board reports it
    /// (host-sim `serve/board2d.rs`): from the last start or update, 0 while the line is off or
    /// firing a pulse.
    #[inline]
    pub fn record(&mut self, t_us: u32, reading: Reading, out: &Output2d, line: Line) {
        if let Some(a) = out.action {
            self.burst_millihz = Record2d::millihz_of(BOARD.burst_timer_clk_hz, a);
        }
        let word = EVERY.load(Ordering::Relaxed);
        if word != self.every {
            self.every = word;
            self.decimator.set(word as u16);
            // A new stream's first record is widened against the clock again.
            self.last_us = None;
            // ... and reports no crossing from before it.
            self.edge.clear();
        }
        self.edge.note(out.edge);
        if !self.decimator.take() {
            return;
        }
        let bursting = line != Line::Off;
        let record = Record2d {
            time_us: link::widen(&mut self.last_us, t_us),
            scene_id: self.stamp.scene_id,
            change: self.stamp.change,
            position: out.position,
            velocity_um_s: out.velocity.map(|v| (v.vx_um_s, v.vy_um_s)),
            place: out.place,
            edge: self.edge.take(),
            burst_millihz: if line == Line::Running {
                self.burst_millihz
            } else {
                0
            },
            bursting,
            lifted: reading == Reading::Lifted,
            fault: out.fault.map(Fault2d::from),
        };
        push(record);
    }
}

/// Queues a record, or counts it dropped. Never inlined: the panic check's allow list names the
/// 1D `StreamTap::push` for the channel's RefCell borrow, which cannot fail; this is the same.
#[inline(never)]
fn push(record: Record2d) {
    if RECORDS_2D.try_send(record).is_err() {
        DROPPED.fetch_add(1, Ordering::Relaxed);
    }
}

/// What the 2D control loop owns of the link: the stream tap, the RF arm (low until a scene is
/// installed, and while a save holds RF off) and the watchdog timeout a save replaced.
pub struct ControlLink {
    pub tap: Tap2d,
    rf_arm: Output<'static>,
    held: Option<crate::store::Timeout>,
}

impl ControlLink {
    /// Records stamped with `stamp` (the scene booted into); `rf_arm` low: raised when the first
    /// scene is installed (`service`), so the amplifier is not armed through the boot, nor at
    /// all when both boot scenes are refused (pre-flash review, 2026-11-30).
    pub fn new(rf_arm: Output<'static>, stamp: Stamp) -> Self {
        Self {
            tap: Tap2d::new(stamp),
            rf_arm,
            held: None,
        }
    }

    /// Before the acquisition starts: the boot scene's hand-over(s) from the link task
    /// (`boot_scene`), each compiled and installed here when `arm2d` raises `FULL`, until the
    /// link task says the boot is done. The plates are not switched yet: the compile's log lines
    /// (interrupts held off while defmt encodes them) and the edge pulse's table build delay no
    /// plate event (with the acquisition running, the boot scene's compile made the F446's Z1
    /// switch 100 µs late and cost a frame: board-model tests/touch2d.rs,
    /// `plate_switching_at_its_designed_times`). `pet` feeds the watchdog meanwhile.
    pub async fn boot(&mut self, ctrl: &mut Controller2d, burst: &mut BurstGate, mut pet: impl FnMut()) {
        use embassy_futures::select::{select, Either};
        loop {
            let done = matches!(select(ARMED.wait(), BOOTED.wait()).await, Either::Second(()));
            self.service(ctrl, burst);
            pet();
            if done {
                return;
            }
        }
    }

    /// Between two frames: a scene compiled by the link (installed, its edge pulse's table built,
    /// its first frame a record), a counters request, a save's hold of RF.
    pub fn service(&mut self, ctrl: &mut Controller2d, burst: &mut BurstGate) {
        if FULL.load(Ordering::Acquire) {
            let scene = SCENE.load(Ordering::Relaxed);
            // SAFETY: `FULL` is set: `scene` is the address of the scene the link task's
            // `apply_2d` holds while it waits for `APPLIED` (see `SCENE`), read only here.
            let result = match unsafe { scene.as_ref() } {
                Some(scene) => install(ctrl, burst, scene),
                // Cannot happen (`apply_2d` stores a reference's address before `FULL`); the
                // stale limit's sentence is the nearest the controller has for "no scene".
                None => Err(Config2dError::StaleLimit { stale_after_us: 0, min_us: 0 }),
            };
            if result.is_ok() {
                // The planted defect `plant-link2d-old-stamp` (never in a real image) keeps the
                // old stamp: the board model's link2d test must fail on it.
                if !cfg!(feature = "plant-link2d-old-stamp") {
                    self.tap.stamp = Stamp {
                        scene_id: STAMP_SCENE.load(Ordering::Relaxed),
                        change: STAMP_CHANGE.load(Ordering::Relaxed),
                    };
                }
                self.tap.decimator.force_next();
                // The old scene's edge numbers mean nothing in the new one.
                self.tap.edge.clear();
                // A scene runs: the amplifier may be armed (not while a save holds RF off; the
                // link answers no push during a save, so this is the boot's or a push's).
                if self.held.is_none() {
                    self.rf_arm.set_high();
                }
            }
            FULL.store(false, Ordering::Release);
            APPLIED.signal(result);
        }
        if TELEMETRY_WANTED.swap(false, Ordering::Relaxed) {
            TELEMETRY_2D.signal(ctrl.telemetry());
        }
        if let Some(quiet) = link::QUIET.try_take() {
            link::hold_rf(quiet, &mut self.rf_arm, &mut self.held);
        }
    }
}

/// The 2D board as the session sees it.
pub struct Board2d {
    sent: u32,
    /// The scene store; None when the board has none (then `save` says so).
    store: Option<Store2d>,
    /// Who the board is (a session made again at boot, `boot_scene`).
    identity: Identity,
    /// The built-in scene's encoding (`SAW_SCENE_2D`) and file: booted when the saved one is
    /// refused.
    builtin: &'static [u8],
    builtin_file: &'static str,
}

impl Board for Board2d {
    async fn apply(
        &mut self,
        _config: &saw_core::scene::Config,
        _stamp: Stamp,
    ) -> Result<(), ConfigError> {
        // Never asked: the session refuses a 1D scene on a board with the overlay before the
        // glue sees it (`Refused2d::WrongSensor`). Refused here too, should that change.
        Err(ConfigError::Limits(
            saw_core::burst::BurstError::ZeroFrequency,
        ))
    }

    fn now_us(&mut self) -> u64 {
        embassy_time::Instant::now().as_micros()
    }

    async fn telemetry(&mut self) -> Telemetry {
        Telemetry::default()
    }

    fn stream(&mut self, every_samples: u16) {
        link::request_stream(every_samples);
        // Records of the stream before are stale to whoever asked: the line is not spent on them.
        RECORDS_2D.clear();
    }

    fn stream_counts(&mut self) -> (u32, u32) {
        (DROPPED.load(Ordering::Relaxed), self.sent)
    }

    async fn save(
        &mut self,
        _scene_id: u32,
        _config: &saw_core::scene::Config,
    ) -> Result<(), StoreFault> {
        // Never asked: the session saves a 2D scene with `save_2d`.
        Err(StoreFault::NotFor2d)
    }

    /// Compiled and installed by the control loop between two frames (see `SCENE`); refused:
    /// nothing changes.
    async fn apply_2d(&mut self, scene: &PlaneScene, stamp: Stamp) -> Result<(), Apply2dError> {
        hand_over(scene, stamp).await.map_err(Apply2dError::Config)
    }

    async fn telemetry_2d(&mut self) -> Telemetry2d {
        TELEMETRY_2D.reset();
        TELEMETRY_WANTED.store(true, Ordering::Relaxed);
        TELEMETRY_2D.wait().await
    }

    /// As the 1D save (`link::FirmwareBoard::save`): RF held off from before the first flash
    /// operation to after the last, the watchdog lengthened meanwhile.
    async fn save_2d(&mut self, scene_id: u32, scene: &PlaneScene) -> Result<(), StoreFault> {
        let Some(store) = self.store.as_mut() else {
            return Err(StoreFault::NoStore);
        };
        link::quiet(true).await;
        let result = store.save_2d(scene_id, scene).await;
        link::quiet(false).await;
        match result {
            Ok(()) => {
                info!("store: 2D scene {=u32:08x} saved", scene_id);
                Ok(())
            }
            Err(e) => {
                warn!("store: 2D scene {=u32:08x} not saved: {}", scene_id, e);
                Err(e.into())
            }
        }
    }
}

impl Streaming for Board2d {
    type Record = Record2d;
    fn records(&self) -> &'static Channel<CriticalSectionRawMutex, Record2d, QUEUE_RECORDS> {
        &RECORDS_2D
    }
    fn count_sent(&mut self) {
        self.sent = self.sent.wrapping_add(1);
    }
}

/// `scene` compiled and installed (`Controller2d::load`, in a frame of its own: ~36 KB with its
/// compile), its edge pulse's triangle table built; the controller's refusal otherwise, nothing
/// changed.
#[inline(never)]
fn install(ctrl: &mut Controller2d, burst: &mut BurstGate, scene: &PlaneScene) -> Result<(), Config2dError> {
    ctrl.load(&scene.config)?;
    let timer = *ctrl.timer();
    prebuild(burst, &timer, &scene.config.scene.edge_pulse);
    Ok(())
}

/// `scene` to the control loop, which compiles and installs it between two frames (see `SCENE`),
/// records then stamped with `stamp`; its answer. The link task's: a push, and the boot scene
/// (`boot_scene`).
async fn hand_over(scene: &PlaneScene, stamp: Stamp) -> Result<(), Config2dError> {
    STAMP_SCENE.store(stamp.scene_id, Ordering::Relaxed);
    STAMP_CHANGE.store(stamp.change, Ordering::Relaxed);
    APPLIED.reset();
    SCENE.store(scene as *const PlaneScene as *mut PlaneScene, Ordering::Relaxed);
    // `FULL` is set by `arm2d`, after this task's poll has returned (see `ARM`).
    ARM.signal(());
    APPLIED.wait().await
}

/// The built-in scene (`SAW_SCENE_2D`, checked by build.rs on the host) on the overlay's plate;
/// an empty configuration, which the controller refuses (no scene, RF off), if it does not
/// decode.
fn builtin_scene(builtin: &[u8]) -> PlaneScene {
    let config = match postcard::from_bytes::<Config2d>(builtin) {
        Ok(c) => c,
        Err(_) => {
            warn!("boot: the 2D scene does not decode; no scene, RF stays off");
            Config2d::default()
        }
    };
    PlaneScene {
        plate_um: PLATE_UM,
        config,
    }
}

/// The session's scene (from `boot`) compiled and installed by the control loop, as a push is
/// (`hand_over`): the link task's first step, so the compile (~36 KB of stack with the largest
/// scene) stacks on an idle thread mode, not on main's poll frame (there the G474 kept 1 568 B
/// of stack headroom with the largest 2D scene; board-model tests/touch2d.rs's stack check).
/// A saved scene the controller refuses gives way to the built-in one (the session made again
/// over it); a refused built-in scene leaves no scene, RF off. Logs which.
pub async fn boot_scene(session: &mut Session, board: &mut Board2d) {
    let saved = session.source() == SceneSource::Saved;
    let result = match session.active() {
        Active::Plane(scene) => hand_over(scene, session.stamp()).await,
    };
    match result {
        Ok(()) if saved => info!(
            "boot: the 2D scene saved in flash (id {=u32:08x})",
            session.scene_id()
        ),
        Ok(()) => info!("boot: the 2D scene built in ({})", board.builtin_file),
        Err(_) if saved => {
            warn!("boot: the saved 2D scene {=u32:08x} is refused", session.scene_id());
            *session = Session::new_2d(
                board.identity,
                PLATE_UM,
                builtin_scene(board.builtin),
                SceneSource::BuildTime,
            );
            let result = match session.active() {
                Active::Plane(scene) => hand_over(scene, session.stamp()).await,
            };
            match result {
                Ok(()) => info!("boot: the 2D scene built in ({})", board.builtin_file),
                Err(_) => warn!("boot: the 2D scene is refused; no scene, RF stays off"),
            }
        }
        Err(_) => warn!("boot: the 2D scene is refused; no scene, RF stays off"),
    }
    BOOTED.signal(());
}

/// The session and the board glue, from the boot.
pub struct Booted {
    pub session: Session,
    pub board: &'static mut Board2d,
}

/// The scene to boot into and the link's session over it: the 2D scene saved in flash if it
/// reads back and fits the overlay, else the one built in (`SAW_SCENE_2D`, checked by build.rs on
/// the host). Not compiled here: the link task has the control loop compile it first thing
/// (`boot_scene`), and falls back to the built-in one if the controller refuses the saved one.
pub async fn boot(
    flash: Option<StoreFlash>,
    builtin: &'static [u8],
    builtin_file: &'static str,
    frame_us: u32,
) -> Booted {
    let identity = Identity {
        firmware: concat!("saw-firmware ", env!("CARGO_PKG_VERSION")),
        board: BOARD.name,
        sample_rate_hz: 1_000_000 / frame_us.max(1),
    };
    // The glue (with the store's 2 KB item buffer) in its static before the load, and nothing of
    // the scene held across the load's await: main's future (a static of its own for good) holds
    // a reference and the load's state only. Holding the store and the scene, it was 4 880 B,
    // which the G474's stack lacked (board-model tests/link2d.rs's stack checks).
    static BOARD2D: static_cell::StaticCell<Board2d> = static_cell::StaticCell::new();
    let board = BOARD2D.init(Board2d {
        sent: 0,
        store: crate::store::open(flash),
        identity,
        builtin,
        builtin_file,
    });
    let loaded = match board.store.as_mut() {
        Some(s) => Some(crate::store::load_2d_at_boot(s).await),
        None => None,
    };
    let saved = match loaded {
        Some(Ok(Some(saved))) => {
            if saved.scene.plate_um.0 <= PLATE_UM.0 && saved.scene.plate_um.1 <= PLATE_UM.1 {
                Some(saved.scene)
            } else {
                warn!(
                    "boot: the saved 2D scene {=u32:08x} does not fit the overlay",
                    saved.scene_id
                );
                None
            }
        }
        Some(Ok(None)) => {
            info!("boot: no scene saved in flash");
            None
        }
        Some(Err(e)) => {
            warn!("boot: the saved scene cannot be read ({})", e);
            None
        }
        None => {
            info!("boot: no scene store on this board");
            None
        }
    };
    let session = match saved {
        Some(scene) => Session::new_2d(identity, PLATE_UM, scene, SceneSource::Saved),
        None => Session::new_2d(identity, PLATE_UM, builtin_scene(builtin), SceneSource::BuildTime),
    };
    Booted { session, board }
}

/// Starts the link (and `arm2d`), either board; the link task's first step is the boot scene's
/// compile (`boot_scene`). The G474 runs it since the link task's future shrank from 25 016 B to 8 824 B (the session
/// holds each request and scene once, `Session::on_frame`; the session and this glue are
/// statics, `link::spawn`): before, its 96 KiB RAM left too little stack for the boot's scene
/// compile (the board model found a stack overflow 3.3 ms after reset).
pub fn start(spawner: embassy_executor::Spawner, tx: UartTx<'static, Async>, mut rx: RingBufferedUartRx<'static>, booted: Booted) {
    // The receive ring runs from now, not from the link task's first read, which comes after
    // the boot scene's compile: a request a host sends just after a reset waits in the ring
    // (1 KiB, ~11 ms at 921 600 baud) instead of overrunning the USART (pre-flash review,
    // 2026-11-30).
    rx.start_uart();
    link::spawn_on(spawner, tx, rx, booted.session, booted.board);
    spawner.spawn(defmt::unwrap!(arm2d()));
}

/// Arms the hand-over (`ARM`): a shallow task, so the control loop's compile stacks on little.
#[embassy_executor::task]
pub async fn arm2d() {
    loop {
        ARM.wait().await;
        FULL.store(true, Ordering::Release);
        ARMED.signal(());
        // Thread mode stays here, shallow, until the control loop has answered. Returning would
        // let the executor poll the link task again on a stale waker of its dropped `select`
        // (the record queue, RX, the flush timer) while it waits for `APPLIED`, and a frame or
        // tick starting the compile then would stack it (~36 KB with the largest scene) on the
        // link task's ~16 KB poll frame instead of this one (pre-flash review, 2026-11-30: the
        // G474's push headroom would fall from ~19 KB to ~3.5 KB). The link task waits for the
        // answer anyway; the control loop preempts this from its interrupt executor, and it,
        // not thread mode, feeds the watchdog. At most a frame plus the compile (~4 ms).
        // A plain load loop: `spin_loop`'s YIELD hint buys nothing on one core without an
        // OS, and the board model (Unicorn) stops on it.
        while FULL.load(Ordering::Acquire) {}
    }
}

