//! `host-sim serve --pty PATH`: a virtual board behind a pseudo-terminal. The same core, the same
//! link code (`saw_link`) and a simulated finger run in real time, so `saw` (and any script
//! speaking the frame format) drives it exactly as it drives a Nucleo on `/dev/ttyACM0`.
//!
//! The link is paced at the board's UART rate (`--baud`, 10 bits a byte) in board time, so how
//! busy the host is does not decide what drops: replies always go out, stream frames only when
//! the line has room, and records that find the queue full are dropped and counted, as on the
//! firmware.

pub mod board;
pub mod board2d;
pub mod flash;
pub mod pty;

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::Parser;
use embassy_futures::block_on;
use saw_boards::BoardDef;
use saw_core::velocity::VelocityEstimator;
use saw_link::frame::{self, Receiver, MAX_ENCODED};
use saw_link::msg::{Header, PlaneScene, Reply, SceneSource};
use saw_link::session::{Board, Identity, Session};

use crate::door::{Range, Whole};
use crate::sim::{board_controller, burst_timer, sample_period_us, SimParams};
use crate::trajectory::Trajectory;
use board::VirtualBoard;
use board2d::VirtualBoard2d;
use pty::Pty;

/// The ST-LINK virtual COM port's rate the firmware uses (boards/README.md): 921 600 baud.
pub const LINK_BAUD: u32 = 921_600;
const SPEED: Range = Range::new(0.1, 1000.0, "mm/s");
const AT: Range = Range::new(0.0, 1000.0, "mm");
const NOISE: Range = Range::new(0.0, 100.0, "LSB RMS");
const SECONDS: Range = Range::new(0.01, 1e6, "s");
const BAUD: Whole = Whole::new(9_600, 16_000_000);
const FAULT_AT: Range = Range::new(0.0, 1e6, "s");
const FAULT_FOR: Range = Range::new(0.001, 1e6, "s");
const CLOCK_PPM: Range = Range::new(-1000.0, 1000.0, "ppm");

/// A sensor fault the virtual board's ADC sees (`--fault`): the rheostat's (`open`, `short`),
/// the touch overlay's (`rail-*`, `lift`), or either's (`dropout`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ServeFault {
    /// The wiper open: every conversion reads 0 (1D).
    Open,
    /// The wiper shorted to the supply: every conversion reads full scale (1D).
    Short,
    /// No samples (touch frames) at all: the ADC or its DMA stopped.
    Dropout,
    /// The overlay's X phase reads 0: an X terminal open or shorted low (2D).
    RailLowX,
    /// The overlay's X phase reads full scale (2D).
    RailHighX,
    /// The overlay's Y phase reads 0 (2D).
    RailLowY,
    /// The overlay's Y phase reads full scale (2D).
    RailHighY,
    /// The finger lifts off the overlay for the fault's span, then lands where its path is (2D).
    Lift,
}

impl ServeFault {
    /// What the virtual overlay does for it, or None for the rheostat's own faults.
    fn touch(self) -> Option<board2d::TouchFaultKind> {
        use board2d::TouchFaultKind as K;
        match self {
            ServeFault::Open | ServeFault::Short => None,
            ServeFault::Dropout => Some(K::Dropout),
            ServeFault::RailLowX => Some(K::Rail {
                y_axis: false,
                high: false,
            }),
            ServeFault::RailHighX => Some(K::Rail {
                y_axis: false,
                high: true,
            }),
            ServeFault::RailLowY => Some(K::Rail {
                y_axis: true,
                high: false,
            }),
            ServeFault::RailHighY => Some(K::Rail {
                y_axis: true,
                high: true,
            }),
            ServeFault::Lift => Some(K::Lift),
        }
    }
}
const SEED: Whole = Whole::new(0, u64::MAX);
/// A partial stream frame goes out after this long, so a slow stream still arrives steadily.
const FLUSH_AFTER_US: u64 = 20_000;

/// `host-sim serve`: a virtual board on a pseudo-terminal.
#[derive(Parser, Debug, Clone)]
#[command(
    name = "host-sim serve",
    about = "Run a virtual board behind a pseudo-terminal: the core, the link and a simulated finger in real time, for `saw --port PATH`."
)]
pub struct ServeArgs {
    /// Where to put the link to the pty's slave (`saw --port` takes this path).
    #[arg(long, value_name = "PATH")]
    pub pty: PathBuf,
    /// The board to stand for (its timers, acquisition and velocity window).
    #[arg(long, default_value = saw_boards::NUCLEO_F446RE.name, value_parser = crate::cli::board_parser())]
    pub board: &'static BoardDef,
    /// The scene to run when no saved scene is stored (the built-in default without it). A 2D
    /// scene (`[sensor] kind = "4-wire"`, e.g. scenes/2d-fig12.toml) makes a board with the
    /// 4-wire touch overlay of the scene's plate ([screen] size_mm) that runs 2D scenes only (a
    /// scene pushed for a larger plate is refused); its finger goes round a
    /// circle through the plate's middle at --speed, or rests at --rest-at-xy.
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// A file standing for the board's flash: `saw save` writes the scene there and a restart
    /// boots into it. Without it the board has no scene store.
    #[arg(long, value_name = "FILE")]
    pub flash: Option<PathBuf>,
    #[arg(long, value_name = "MM_S", default_value_t = 60.0, help = SPEED.help("Finger speed: back and forth over the travel (1D scenes), round the circle through the plate's middle (2D scenes)"), value_parser = SPEED.parser())]
    pub speed: f64,
    #[arg(long, value_name = "MM", conflicts_with = "speed", help = AT.help("Finger at rest here instead (within the scene's travel; 1D scenes)"), value_parser = AT.parser())]
    pub rest_at: Option<f64>,
    /// The finger at rest at X,Y mm on the overlay instead (2D scenes; each 0 to the plate's
    /// width / height: the scene's plate).
    #[arg(long, value_name = "X,Y", conflicts_with_all = ["speed", "rest_at"], allow_hyphen_values = true, value_parser = crate::cli2d::xy_mm)]
    pub rest_at_xy: Option<(f64, f64)>,
    #[arg(long, value_name = "LSB", default_value_t = 2.0, help = NOISE.help("ADC noise per conversion"), value_parser = NOISE.parser())]
    pub noise: f64,
    #[arg(long, default_value_t = 1, help = SEED.help("Noise seed"), value_parser = SEED.parser())]
    pub seed: u64,
    #[arg(long, value_name = "BAUD", default_value_t = LINK_BAUD as u64, help = BAUD.help("The link's rate, baud (10 bits a byte)"), value_parser = BAUD.parser())]
    pub baud: u64,
    #[arg(long, value_name = "S", help = SECONDS.help("Stop after this long (default: run until interrupted)"), value_parser = SECONDS.parser())]
    pub seconds: Option<f64>,
    /// A sensor fault to inject (with --fault-at and --fault-for; open and short with a 1D scene,
    /// rail-* and lift with a 2D one, dropout with either): the core turns the carrier
    /// off while it lasts and reports it in the stream.
    #[arg(long, value_enum, requires_all = ["fault_at", "fault_for"])]
    pub fault: Option<ServeFault>,
    #[arg(long, value_name = "S", requires = "fault", help = FAULT_AT.help("When the fault begins, from the board's start"), value_parser = FAULT_AT.parser())]
    pub fault_at: Option<f64>,
    #[arg(long, value_name = "S", requires = "fault", help = FAULT_FOR.help("How long the fault lasts"), value_parser = FAULT_FOR.parser())]
    pub fault_for: Option<f64>,
    #[arg(long, value_name = "PPM", default_value_t = 0.0, allow_negative_numbers = true, help = CLOCK_PPM.help("The board clock's rate error against the host's (a crystal's tolerance; positive: fast), for checking clock alignment"), value_parser = CLOCK_PPM.parser())]
    pub clock_ppm: f64,
}

/// The virtual board's clock: µs since `start` on the host's monotonic clock, scaled by the
/// crystal's rate error.
#[derive(Clone, Copy, Debug)]
pub struct BoardClock {
    /// The board's boot, on the host's clock.
    pub start: Instant,
    /// Board µs per host µs.
    pub rate: f64,
}

impl BoardClock {
    /// The board's time at host instant `at`, µs since boot.
    pub fn board_us(&self, at: Instant) -> u64 {
        (at.saturating_duration_since(self.start).as_secs_f64() * 1e6 * self.rate) as u64
    }
}

/// What a serve run did.
#[derive(Clone, Copy, Debug, Default)]
pub struct ServeStats {
    /// Requests answered (bad frames included).
    pub replies: u64,
    /// Stream frames sent.
    pub stream_frames: u64,
    /// Records dropped.
    pub dropped: u32,
}

/// `host-sim serve …` from the command line, if that is the command.
pub fn run_from_env() -> Option<ExitCode> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (cmd, rest) = args.split_first()?;
    if cmd != "serve" {
        return None;
    }
    let argv = std::iter::once("host-sim serve".to_string()).chain(rest.iter().cloned());
    let a = match ServeArgs::try_parse_from(argv) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    // SIGINT, SIGTERM, SIGHUP: the link is removed at once and the loop ends as at --seconds
    // (the flash written, the summary printed) instead of the process dying by the signal.
    static STOP: AtomicBool = AtomicBool::new(false);
    pty::on_signals(&STOP);
    let stop = &STOP;
    Some(
        match serve(&a, stop, |p| {
            eprintln!(
                "virtual board on {} ({})",
                a.pty.display(),
                p.slave_path().display()
            )
        }) {
            Ok(s) => {
                eprintln!(
                    "stopped: {} replies, {} stream frames, {} records dropped",
                    s.replies, s.stream_frames, s.dropped
                );
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::from(2)
            }
        },
    )
}

/// Runs the virtual board until `stop` is set or `--seconds` pass. `ready` is called once the
/// pty exists.
pub fn serve(
    a: &ServeArgs,
    stop: &AtomicBool,
    ready: impl FnOnce(&Pty),
) -> Result<ServeStats, String> {
    serve_with_clock(a, stop, |p, _| ready(p))
}

/// [`serve`], and `ready` is also told the board's clock (so a test can check the host's
/// clock alignment against the board's own time).
pub fn serve_with_clock(
    a: &ServeArgs,
    stop: &AtomicBool,
    ready: impl FnOnce(&Pty, BoardClock),
) -> Result<ServeStats, String> {
    let board = a.board;
    // The link first: a second board on a live link (or a locked flash file) is refused before
    // anything boots or logs.
    let pty = Pty::open(&a.pty)?;
    if let Some(scene) = scene_2d(a)? {
        let mut vb =
            VirtualBoard2d::boot(board, &scene, trajectory_2d(a, &scene)?, a.noise, a.seed)?;
        if let (Some(kind), Some(at), Some(dur)) =
            (a.fault.and_then(ServeFault::touch), a.fault_at, a.fault_for)
        {
            let start_us = (at * 1e6) as u64;
            vb.inject(board2d::TouchFaultWindow {
                kind,
                start_us,
                end_us: start_us + (dur * 1e6) as u64,
            });
        }
        let identity = Identity {
            firmware: concat!("host-sim serve ", env!("CARGO_PKG_VERSION")),
            board: board.name,
            sample_rate_hz: 1_000_000 / vb.frame_us(),
        };
        let session = Session::new_2d(identity, vb.plate_um(), scene, SceneSource::BuildTime);
        vb.set_stamp(session.stamp());
        let clock = BoardClock {
            start: Instant::now(),
            rate: 1.0 + a.clock_ppm * 1e-6,
        };
        ready(&pty, clock);
        return run(&pty, vb, session, clock, a.baud as u32, a.seconds, stop);
    }
    if a.rest_at_xy.is_some() {
        return Err("--rest-at-xy: a finger on the touch overlay needs a 2D scene (--scene with [sensor] kind = \"4-wire\"); use --rest-at MM on the rheostat".into());
    }
    let (params, source) = params(a, board)?;
    let store = match &a.flash {
        Some(path) => Some(flash::open(path, board)?),
        None => None,
    };
    let ctrl = board_controller(board).map_err(|e| e.to_string())?;
    let boot = VirtualBoard::boot(&params, ctrl, source, store).map_err(|e| e.to_string())?;
    let identity = Identity {
        firmware: concat!("host-sim serve ", env!("CARGO_PKG_VERSION")),
        board: board.name,
        sample_rate_hz: board.sample_rate_hz,
    };
    let session = Session::new(identity, boot.config, boot.source);
    let mut board = boot.board;
    board.set_stamp(session.stamp());
    let clock = BoardClock {
        start: Instant::now(),
        rate: 1.0 + a.clock_ppm * 1e-6,
    };
    ready(&pty, clock);
    run(&pty, board, session, clock, a.baud as u32, a.seconds, stop)
}

/// The 2D scene of `--scene`, when it names the 4-wire overlay: read and checked for the board
/// at its touch frame period, as `host-sim --scene` reads it. The 1D board's flags are refused
/// with it, one line naming the flag.
fn scene_2d(a: &ServeArgs) -> Result<Option<PlaneScene>, String> {
    let Some(path) = &a.scene else {
        return Ok(None);
    };
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|e| format!("--scene {name}: {e}"))?;
    if saw_core::scene_file::sensor_of(&name, &text).map_err(|e| e.to_string())?
        != saw_core::scene_file::SensorKind::FourWire
    {
        return Ok(None);
    }
    let refuse = |flag: &str, why: &str| {
        Err(format!(
            "{flag}: {why}; {name} is a 2D scene for the touch overlay"
        ))
    };
    if a.rest_at.is_some() {
        return refuse(
            "--rest-at",
            "a position on the rheostat's travel (use --rest-at-xy X,Y)",
        );
    }
    if let Some(f) = a.fault.filter(|f| f.touch().is_none()) {
        let name = clap::ValueEnum::to_possible_value(&f)
            .map_or(String::new(), |v| v.get_name().to_string());
        return refuse(
            "--fault",
            &format!("{name} is the rheostat's wiper fault (use rail-low-x, rail-high-x, rail-low-y, rail-high-y, lift or dropout)"),
        );
    }
    if a.flash.is_some() {
        return refuse("--flash", "the store keeps 1D scenes only");
    }
    let frame_us = crate::sim2d::board_frame_period_us(a.board)
        .ok_or_else(|| format!("--board {}: no touch schedule", a.board.name))?;
    let config =
        saw_core::scene_file::load_2d_for_board(&name, &text, burst_timer(a.board), frame_us)
            .map_err(|e| e.to_string())?;
    // The virtual overlay is the scene's plate (the reader has checked it: 1 mm to 1 m a side).
    let plate_um = saw_core::scene_file::plate_um_of(&name, &text).map_err(|e| e.to_string())?;
    Ok(Some(PlaneScene { plate_um, config }))
}

/// The 2D finger: at rest at `--rest-at-xy`, or round a circle through the plate's middle
/// (radius: 40 % of its shorter side) at `--speed`.
fn trajectory_2d(
    a: &ServeArgs,
    scene: &PlaneScene,
) -> Result<crate::trajectory2d::Trajectory2d, String> {
    use crate::trajectory2d::{PointUm, Trajectory2d};
    let (w, h) = scene.plate_um;
    match a.rest_at_xy {
        Some((x, y)) => {
            if !(0.0..=w as f64 / 1e3).contains(&x) || !(0.0..=h as f64 / 1e3).contains(&y) {
                return Err(format!(
                    "--rest-at-xy {x},{y}: must lie on the overlay, x 0 to {} mm and y 0 to {} mm",
                    w as f64 / 1e3,
                    h as f64 / 1e3
                ));
            }
            Trajectory2d::rest(PointUm::new(x * 1e3, y * 1e3)).map_err(|e| e.to_string())
        }
        None => {
            let (pw, ph) = (scene.plate_um.0 as f64, scene.plate_um.1 as f64);
            Trajectory2d::circle(
                PointUm::new(pw / 2.0, ph / 2.0),
                0.4 * pw.min(ph),
                a.speed * 1e3,
            )
            .map_err(|e| e.to_string())
        }
    }
}

fn params(a: &ServeArgs, board: &'static BoardDef) -> Result<(SimParams, SceneSource), String> {
    if let Some(f) = a
        .fault
        .filter(|f| f.touch().is_some() && *f != ServeFault::Dropout)
    {
        let name = clap::ValueEnum::to_possible_value(&f)
            .map_or(String::new(), |v| v.get_name().to_string());
        return Err(format!("--fault {name}: a touch overlay's fault needs a 2D scene (--scene with [sensor] kind = \"4-wire\"); the rheostat's are open, short and dropout"));
    }
    let (config, source) = match &a.scene {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| format!("--scene {}: {e}", path.display()))?;
            let c = saw_core::scene_file::load_for_board(
                &path.display().to_string(),
                &text,
                burst_timer(board),
                sample_period_us(board),
            )
            .map_err(|e| e.to_string())?;
            (c, SceneSource::BuildTime)
        }
        None => (saw_core::default_config(), SceneSource::Default),
    };
    let length_mm = config.calibration.length_um as f64 / 1000.0;
    let trajectory = match a.rest_at {
        Some(at) if at > length_mm => {
            return Err(format!(
                "--rest-at {at} mm is past the scene's travel of {length_mm} mm"
            ))
        }
        Some(at) => Trajectory::Rest { at_um: at * 1000.0 },
        None => Trajectory::Triangle {
            a_um: crate::cli::END_MARGIN_MM * 1000.0,
            b_um: (length_mm - crate::cli::END_MARGIN_MM) * 1000.0,
            speed_um_s: a.speed * 1000.0,
        },
    };
    let mut p = SimParams::new(board, trajectory, f64::INFINITY)
        .with_config(config)
        .with_noise(a.noise, a.seed);
    if let (Some(kind), Some(at), Some(dur)) = (a.fault, a.fault_at, a.fault_for) {
        let kind = match kind {
            ServeFault::Open => crate::adc::FaultKind::Open,
            ServeFault::Short => crate::adc::FaultKind::Short,
            ServeFault::Dropout => crate::adc::FaultKind::Dropout,
            // Refused before (a touch overlay's fault on the rheostat).
            _ => return Err(format!("--fault {kind:?}: not a rheostat fault")),
        };
        let start_us = (at * 1e6) as u64;
        p = p.with_faults(vec![crate::adc::FaultWindow {
            kind,
            start_us,
            end_us: start_us + (dur * 1e6) as u64,
        }]);
    }
    Ok((p, source))
}

/// What the serve loop needs of a virtual board besides the session's [`Board`].
pub trait Virtual: Board {
    /// Runs every sample (or touch frame) due before `t_us`, board time since boot.
    fn run_until(&mut self, t_us: u64);
    /// The next stream frame to send: a full batch, or (`flush`) whatever is gathered.
    fn next_frame(&mut self, flush: bool) -> Option<(Header, Reply)>;
    /// Forgets the records gathered for a stream that stopped or restarted.
    fn restart_batch(&mut self);
    /// Records dropped since boot.
    fn dropped(&self) -> u32;
}

impl<E: VelocityEstimator> Virtual for VirtualBoard<E> {
    fn run_until(&mut self, t_us: u64) {
        VirtualBoard::run_until(self, t_us)
    }
    fn next_frame(&mut self, flush: bool) -> Option<(Header, Reply)> {
        VirtualBoard::next_frame(self, flush)
    }
    fn restart_batch(&mut self) {
        VirtualBoard::restart_batch(self)
    }
    fn dropped(&self) -> u32 {
        VirtualBoard::dropped(self)
    }
}

impl Virtual for VirtualBoard2d {
    fn run_until(&mut self, t_us: u64) {
        VirtualBoard2d::run_until(self, t_us)
    }
    fn next_frame(&mut self, flush: bool) -> Option<(Header, Reply)> {
        VirtualBoard2d::next_frame(self, flush)
    }
    fn restart_batch(&mut self) {
        VirtualBoard2d::restart_batch(self)
    }
    fn dropped(&self) -> u32 {
        VirtualBoard2d::dropped(self)
    }
}

fn run<V: Virtual>(
    pty: &Pty,
    mut board: V,
    mut session: Session,
    clock: BoardClock,
    baud: u32,
    seconds: Option<f64>,
    stop: &AtomicBool,
) -> Result<ServeStats, String> {
    let start = clock.start;
    let mut uart = Uart::new(baud);
    let mut rx = Receiver::<MAX_ENCODED>::default();
    let mut stats = ServeStats::default();
    let mut inbuf = [0u8; 4096];
    let end = seconds.map(|s| start + Duration::from_secs_f64(s));
    while !stop.load(Ordering::Relaxed) && end.is_none_or(|e| Instant::now() < e) {
        let n = pty.read(&mut inbuf).map_err(|e| format!("pty: {e}"))?;
        if n > 0 {
            // The samples due so far run first (and the stream with them): a request acts at
            // the board time it arrives.
            let now_us = clock.board_us(Instant::now());
            stats.stream_frames += uart.catch_up(&mut board, now_us, |b| send(pty, b))?;
        }
        for &byte in &inbuf[..n] {
            let reply = match rx.push(byte) {
                None => continue,
                Some(Ok(len)) => block_on(session.on_frame(&mut board, rx.payload(len))),
                Some(Err(e)) => session.on_bad_frame(None, e),
            };
            if matches!(reply.1, Reply::Streaming { .. }) {
                // A stream stopped or started anew: what was gathered for the one before is
                // stale (the client drops it) and is not sent.
                uart.pending = None;
                board.restart_batch();
            }
            let bytes = encode(&reply.0, &reply.1)?;
            uart.line.spend(bytes.len());
            let _ = send(pty, &bytes);
            stats.replies += 1;
        }
        let now_us = clock.board_us(Instant::now());
        stats.stream_frames += uart.catch_up(&mut board, now_us, |b| send(pty, b))?;
        std::thread::sleep(Duration::from_micros(500));
    }
    stats.dropped = board.dropped();
    Ok(stats)
}

/// Board time run in one step before the line is served: the UART empties its queue while the
/// samples run, so the line and the queue meet at least this often in board time.
const STEP_US: u64 = 1_000;

/// The board's side of the line: its pace, the encoded frame waiting for room, when the last
/// frame went and how far the board has run, all in board time.
struct Uart {
    line: Line,
    pending: Option<Vec<u8>>,
    last_flush_us: u64,
    board_us: u64,
}

impl Uart {
    fn new(baud: u32) -> Self {
        Uart {
            line: Line::new(baud),
            pending: None,
            last_flush_us: 0,
            board_us: 0,
        }
    }

    /// Runs the board to `to_us` in steps of `STEP_US`, serving the line after each step. The
    /// stream is paced in board time, not by when this thread got the CPU: a host that leaves
    /// the loop unscheduled for 50 ms then runs 50 ms of samples with 50 ms of line beside
    /// them, so what drops is what the board's UART would drop, whatever else the machine is
    /// doing (an e2e test once saw 20 records dropped at a quarter of the line from such a
    /// stall, when the samples ran in one piece and the line had one frame of room). Returns
    /// the frames sent.
    fn catch_up<V: Virtual>(
        &mut self,
        board: &mut V,
        to_us: u64,
        mut send: impl FnMut(&[u8]) -> bool,
    ) -> Result<u64, String> {
        let mut frames = 0;
        // Until a frame finds no one reading: the rest of this catch-up's records then wait in
        // the queue (and drop there, as the board's would), not in `send`.
        let mut reader = true;
        loop {
            let step_us = (self.board_us + STEP_US).min(to_us.max(self.board_us));
            board.run_until(step_us);
            self.board_us = step_us;
            self.line.refill(step_us);
            // The stream: frames go when the line has room; until then records wait in the
            // queue, and the queue drops when full.
            while reader {
                if self.pending.is_none() {
                    let flush = step_us.saturating_sub(self.last_flush_us) >= FLUSH_AFTER_US;
                    match board.next_frame(flush) {
                        Some((h, r)) => self.pending = Some(encode(&h, &r)?),
                        None => break,
                    }
                }
                let Some(bytes) = self.pending.take() else {
                    break;
                };
                if self.line.budget < bytes.len() as f64 {
                    self.pending = Some(bytes);
                    break;
                }
                self.line.spend(bytes.len());
                reader = send(&bytes);
                self.last_flush_us = step_us;
                frames += 1;
            }
            if step_us >= to_us {
                return Ok(frames);
            }
        }
    }
}

/// The UART's pace in board time: a byte budget refilled at the line rate (10 bits a byte), at
/// most two frames ahead.
struct Line {
    budget: f64,
    last_us: u64,
    bytes_per_us: f64,
}

impl Line {
    fn new(baud: u32) -> Self {
        Line {
            budget: 0.0,
            last_us: 0,
            bytes_per_us: baud as f64 / 10.0 * 1e-6,
        }
    }

    fn refill(&mut self, now_us: u64) {
        let elapsed_us = now_us.saturating_sub(self.last_us);
        self.budget =
            (self.budget + elapsed_us as f64 * self.bytes_per_us).min(2.0 * MAX_ENCODED as f64);
        self.last_us = self.last_us.max(now_us);
    }

    /// Spends `bytes` at the last refill's time (a reply goes whether or not there is room: the
    /// budget goes negative and the stream waits for it).
    fn spend(&mut self, bytes: usize) {
        self.budget -= bytes as f64;
    }
}

fn encode(header: &Header, reply: &Reply) -> Result<Vec<u8>, String> {
    let mut out = [0u8; MAX_ENCODED];
    let n = frame::encode(header, reply, &mut out).map_err(|e| e.to_string())?;
    Ok(out[..n].to_vec())
}

/// Writes a frame; if the pty's buffer stays full (no one reading) for 500 ms, the rest is
/// dropped (the host resynchronises at the next zero).
fn send(pty: &Pty, mut bytes: &[u8]) -> bool {
    // Long enough that a reader the machine left unscheduled (a loaded CI machine) is not taken
    // for no reader: the board's time is caught up after the wait, so waiting costs no samples.
    let give_up = Instant::now() + Duration::from_millis(500);
    while !bytes.is_empty() && Instant::now() < give_up {
        match pty.write(bytes) {
            Ok(0) => std::thread::sleep(Duration::from_micros(200)),
            Ok(n) => bytes = &bytes[n..],
            Err(_) => return false,
        }
    }
    bytes.is_empty()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(extra: &[&str]) -> ServeArgs {
        let mut argv = vec!["host-sim serve", "--pty", "/nonexistent/tty"];
        argv.extend_from_slice(extra);
        ServeArgs::try_parse_from(argv).unwrap()
    }

    /// The stream is paced in board time: a host thread left unscheduled for 60 ms (as under a
    /// loaded CI machine) catches up with 60 ms of samples and 60 ms of line beside them, and a
    /// stream at a quarter of the line drops nothing. Run in one piece, the 60 ms fill the
    /// 64-record queue (25.6 ms at every fourth sample) before the line takes any: this test
    /// failed with `STEP_US` as large as the stall.
    #[test]
    fn a_stalled_host_drops_nothing_the_line_would_carry() {
        let a = args(&[]);
        let (params, source) = params(&a, a.board).unwrap();
        let ctrl = board_controller(a.board).unwrap();
        let mut board = VirtualBoard::boot(&params, ctrl, source, None)
            .unwrap()
            .board;
        Board::stream(&mut board, 4);
        let mut uart = Uart::new(LINK_BAUD);
        let mut bytes_sent = 0usize;
        let mut frames = 0;
        // 2 s in 0.5 ms turns with a 60 ms stall every 200 ms.
        let mut to_us = 0;
        while to_us < 2_000_000 {
            to_us += if to_us % 200_000 == 0 { 60_000 } else { 500 };
            frames += uart
                .catch_up(&mut board, to_us, |b| {
                    bytes_sent += b.len();
                    true
                })
                .unwrap();
        }
        assert_eq!(Virtual::dropped(&board), 0);
        // The records went: 5 000 records in 2 s at every fourth sample of 10 kHz, in frames
        // of 8, less what waits in the queue and the batch at the end.
        assert!(frames >= 600, "{frames} frames");
        // The line never carried more than its rate allows (two frames of room at the start).
        let line_bytes = 2_000_000.0 * LINK_BAUD as f64 / 10.0 * 1e-6 + 2.0 * MAX_ENCODED as f64;
        assert!((bytes_sent as f64) <= line_bytes, "{bytes_sent} bytes");
    }

    const FIG12: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/2d-fig12.toml");
    const CONCAVE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/2d-concave.toml");

    /// A 2D scene makes the overlay board, its plate the scene's; the rheostat's flags are
    /// refused with it, one line naming the flag.
    #[test]
    fn a_2d_scene_takes_the_overlay_and_refuses_the_rheostats_flags() {
        let s = scene_2d(&args(&["--scene", FIG12])).unwrap().unwrap();
        assert_eq!(s.plate_um, (95_000, 54_000));
        assert!(scene_2d(&args(&[])).unwrap().is_none());
        for (extra, starts) in [
            (vec!["--rest-at", "10"], "--rest-at: "),
            (
                vec!["--fault", "open", "--fault-at", "1", "--fault-for", "1"],
                "--fault: open is the rheostat's wiper fault",
            ),
            (vec!["--flash", "/tmp/x.bin"], "--flash: "),
        ] {
            let mut a = vec!["--scene", FIG12];
            a.extend(extra);
            let e = scene_2d(&args(&a)).unwrap_err();
            assert!(e.starts_with(starts) && !e.contains('\n'), "{e}");
        }
        // The 80 × 60 mm scene makes an 80 × 60 mm overlay (it was refused when the virtual
        // overlay was fixed at 95 × 54 mm).
        let c = scene_2d(&args(&["--scene", CONCAVE])).unwrap().unwrap();
        assert_eq!(c.plate_um, (80_000, 60_000));
        // A touch overlay's fault with a 1D scene, one line naming the flag; dropout is either's.
        let board = &saw_boards::NUCLEO_F446RE;
        let e = params(
            &args(&["--fault", "lift", "--fault-at", "1", "--fault-for", "1"]),
            board,
        )
        .unwrap_err();
        assert!(
            e.starts_with("--fault lift: a touch overlay's fault needs a 2D scene"),
            "{e}"
        );
        assert!(params(
            &args(&["--fault", "dropout", "--fault-at", "1", "--fault-for", "1"]),
            board
        )
        .is_ok());
        let f = &[
            "--scene",
            FIG12,
            "--fault",
            "rail-high-y",
            "--fault-at",
            "1",
            "--fault-for",
            "1",
        ];
        assert!(scene_2d(&args(f)).is_ok());
        // The resting finger must lie on the overlay: the scene's plate.
        let a = args(&["--scene", FIG12, "--rest-at-xy", "96,10"]);
        let e = trajectory_2d(&a, &s).unwrap_err();
        assert_eq!(
            e,
            "--rest-at-xy 96,10: must lie on the overlay, x 0 to 95 mm and y 0 to 54 mm"
        );
        let a = args(&["--scene", CONCAVE, "--rest-at-xy", "85,10"]);
        let e = trajectory_2d(&a, &c).unwrap_err();
        assert_eq!(
            e,
            "--rest-at-xy 85,10: must lie on the overlay, x 0 to 80 mm and y 0 to 60 mm"
        );
        assert!(trajectory_2d(&args(&["--scene", CONCAVE, "--rest-at-xy", "75,58"]), &c).is_ok());
    }
}
