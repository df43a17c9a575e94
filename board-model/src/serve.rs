//! `board-model serve`: the real firmware image on the board model, its link UART (F446 USART2,
//! G474 LPUART1) bridged to a pseudo-terminal, so `saw` and the panel talk to the firmware
//! itself exactly as they talk to `host-sim serve` or a Nucleo on `/dev/ttyACM0`.
//!
//! Virtual time is paced to the wall clock and never runs ahead of it; when the model is slower
//! than the board it runs as fast as it can, and the measured speed (board seconds per wall
//! second) is printed, because every wall-clock timeout on the host side meets a board that
//! slow. Bytes from the pty enter the UART at the current virtual time (back to back at the
//! line rate the firmware configured); the firmware's bytes go out to the pty once their stop
//! bit has ended in virtual time. The defmt log is decoded as it comes (`defmt-print`).

use crate::board::{self, BoardKind};
use crate::machine::Machine;
use crate::periph::{lpuart_g4::LpuartG4, seconds, usart_f4::UsartF4, Time, TICKS_PER_S};
use host_sim::adc::{AdcModel, AdcParams};
use host_sim::serve::pty::Pty;
use host_sim::trajectory::Trajectory;
use std::cell::Cell;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What to serve.
#[derive(Clone, Debug)]
pub struct ServeOptions {
    pub board: BoardKind,
    pub elf: PathBuf,
    /// Where the link to the pty's slave goes (`saw --port` takes this path).
    pub pty: PathBuf,
    /// The store's flash region (`saw_boards::StoreLayout`) kept in this file across runs: read
    /// before boot, written back when serve stops. The same format as `host-sim serve --flash`.
    pub flash: Option<PathBuf>,
    /// Where the decoded defmt log goes (None: stderr).
    pub log: Option<PathBuf>,
    /// The finger.
    pub trajectory: Trajectory,
    /// Rheostat/ADC model (noise, seed).
    pub adc: AdcParams,
    /// Stop after this much board time, s (None: until stopped).
    pub board_seconds: Option<f64>,
}

/// What a serve run did.
#[derive(Clone, Copy, Debug, Default)]
pub struct ServeStats {
    /// Board time reached, s (the boot included).
    pub board_s: f64,
    /// Board time since the link appeared, s.
    pub served_s: f64,
    /// Wall time since the link appeared, s.
    pub wall_s: f64,
    /// Bytes the host sent in, and the firmware sent out.
    pub bytes_in: u64,
    pub bytes_out: u64,
    /// Watchdog or software resets of the chip during the run.
    pub resets: usize,
}

impl ServeStats {
    /// Board seconds per wall second while serving (1.0 when the model keeps up: it is paced).
    pub fn speed(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.served_s / self.wall_s
        } else {
            0.0
        }
    }
}

/// Virtual time run between two looks at the pty when the model is behind the wall clock: short
/// enough that a request waits little for its bytes to enter (0.5 ms of board time is 46 bytes
/// at 921 600 baud), long enough that the emulator's entry cost stays small.
const SLICE: Time = TICKS_PER_S / 2_000;
/// Board time the image runs before the pty appears: its boot, the store read included (the
/// link checks of `board-model check` send their first request at 0.2 s).
pub const BOOT: Time = TICKS_PER_S * 3 / 10;
/// How long the loop sleeps when the model has caught up with the wall clock.
const IDLE: Duration = Duration::from_micros(300);
/// How often the speed is reported on stderr while serving.
const REPORT_EVERY: Duration = Duration::from_secs(10);

/// Runs the image behind a pty until `stop` is set (or `board_seconds` of board time pass).
/// `ready` is called once the pty's link exists.
pub fn serve(
    o: &ServeOptions,
    stop: &AtomicBool,
    ready: impl FnOnce(&Pty),
) -> Result<ServeStats, String> {
    let def = o.board.def();
    let store = def.store;
    // The flash file is read (and its size checked) before anything runs.
    let preload = match &o.flash {
        Some(path) => match std::fs::read(path) {
            Ok(b) if b.len() == store.bytes as usize => Some(b),
            Ok(b) => {
                return Err(format!(
                    "--flash {}: {} bytes, not {}'s {}-byte store",
                    path.display(),
                    b.len(),
                    o.board.name(),
                    store.bytes
                ))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(format!("--flash {}: {e}", path.display())),
        },
        None => None,
    };
    let mut m = build(o)?;
    if let Some(bytes) = &preload {
        m.preload_flash(store.origin, bytes)?;
    }
    if let Some(path) = &o.flash {
        // Written once now so an unwritable path is refused before serving, not at exit.
        write_flash(&m, path, store.origin, store.bytes)?;
    }
    let mut log = LogSink::start(&o.elf, o.log.as_deref())?;
    // The image boots before the link appears, as a board is powered before its port is opened:
    // bytes sent before the firmware's receiver is running are lost on the model as on a chip.
    if let Some(s) = m.run_until(BOOT) {
        log.feed(&m);
        return Err(format!("the image did not boot on the model: {s}"));
    }
    log.feed(&m);
    let pty = Pty::open(&o.pty)?;
    ready(&pty);
    let result = pump(o, &mut m, &pty, &mut log, stop);
    // Whatever ended the run, the flash is written back and the log drained.
    let flushed = match &o.flash {
        Some(path) => write_flash(&m, path, store.origin, store.bytes),
        None => Ok(()),
    };
    log.feed(&m);
    log.finish();
    let stats = result?;
    flushed?;
    Ok(stats)
}

/// The machine with the wiper wired to host-sim's trajectory and ADC model (as `run::run`).
fn build(o: &ServeOptions) -> Result<Machine, String> {
    let mut adc = AdcModel::new(saw_core::default_config().calibration, o.adc.clone())
        .map_err(|e| format!("ADC model: {e:?}"))?;
    let t0: Rc<Cell<Option<Time>>> = Rc::new(Cell::new(None));
    let traj = o.trajectory.clone();
    let wiper: board::Wiper = Box::new(move |t: Time| {
        // The trajectory starts at the first conversion, as in `run::run`.
        let origin = match t0.get() {
            Some(o) => o,
            None => {
                t0.set(Some(t));
                t
            }
        };
        adc.convert(traj.state(seconds(t - origin)).position_um) as u16
    });
    board::build(o.board, &o.elf, wiper)
}

/// The store region as it is in the model's flash, to `path`.
fn write_flash(m: &Machine, path: &Path, origin: u32, bytes: u32) -> Result<(), String> {
    let mut buf = vec![0u8; bytes as usize];
    m.uc.mem_read(origin as u64, &mut buf)
        .map_err(|e| format!("reading the store at 0x{origin:08X}: {e:?}"))?;
    std::fs::write(path, &buf).map_err(|e| format!("--flash {}: {e}", path.display()))
}

/// The link UART's transmitted bytes, read in place (`Sim::uart_output` copies them all).
fn uart_out(m: &Machine) -> &[(Time, u8)] {
    m.sim()
        .periphs
        .iter()
        .find_map(|p| {
            let a = p.p.as_any();
            a.downcast_ref::<UsartF4>()
                .map(|u| u.output())
                .or_else(|| a.downcast_ref::<LpuartG4>().map(|u| u.output()))
        })
        .unwrap_or(&[])
}

fn pump(
    o: &ServeOptions,
    m: &mut Machine,
    pty: &Pty,
    log: &mut LogSink,
    stop: &AtomicBool,
) -> Result<ServeStats, String> {
    let start = Instant::now();
    // The board's present at `start` (its boot) is the wall clock's `start`; the board is never
    // ahead of it.
    let origin = m.now();
    let board_at = |wall: Duration| origin + (wall.as_secs_f64() * TICKS_PER_S as f64) as Time;
    let end = o.board_seconds.map(|s| (s * TICKS_PER_S as f64) as Time);
    let mut stats = ServeStats::default();
    let mut sent = 0usize;
    let mut pending: Vec<u8> = Vec::new();
    let mut inbuf = [0u8; 4096];
    let mut last_report = (start, origin);
    let mut first_report = true;
    while !stop.load(Ordering::Relaxed) {
        let now = m.now();
        if end.is_some_and(|e| now >= e) {
            break;
        }
        // The host's bytes enter at the board's present.
        let n = pty.read(&mut inbuf).map_err(|e| format!("pty: {e}"))?;
        if n > 0 {
            m.sim_mut().uart_send(now, &inbuf[..n])?;
            stats.bytes_in += n as u64;
        }
        let wall = board_at(start.elapsed());
        let target = wall.min(now + SLICE).min(end.unwrap_or(Time::MAX));
        if target > now {
            if let Some(s) = m.run_until(target) {
                stats.board_s = m.now() as f64 / TICKS_PER_S as f64;
                return Err(format!(
                    "the model stopped at {:.6} s of board time: {s}",
                    stats.board_s
                ));
            }
        } else {
            std::thread::sleep(IDLE);
        }
        // The firmware's bytes whose stop bit has ended.
        let out = uart_out(m);
        let done = out[sent..].partition_point(|&(t, _)| t <= m.now());
        pending.extend(out[sent..sent + done].iter().map(|&(_, b)| b));
        sent += done;
        if !pending.is_empty() {
            // A full pty (no one reading) keeps the bytes for later, as a UART's host buffer
            // would; the firmware is never held up by it.
            let w = pty.write(&pending).map_err(|e| format!("pty: {e}"))?;
            stats.bytes_out += w as u64;
            pending.drain(..w);
            if pending.len() > 1 << 20 {
                // Nobody has read for a long time: keep the newest, as a host's driver drops.
                let cut = pending.len() - (1 << 20);
                pending.drain(..cut);
            }
        }
        log.feed(m);
        let elapsed = last_report.0.elapsed();
        if elapsed
            >= if first_report {
                Duration::from_secs(1)
            } else {
                REPORT_EVERY
            }
        {
            let board_s = (m.now() - last_report.1) as f64 / TICKS_PER_S as f64;
            eprintln!(
                "board-model serve: {:.3} s of board time in {:.3} s of wall time ({:.2}× real time{})",
                board_s,
                elapsed.as_secs_f64(),
                board_s / elapsed.as_secs_f64(),
                if board_s / elapsed.as_secs_f64() < 0.99 {
                    "; slower than a board: host timeouts must allow for it"
                } else {
                    ", paced to the wall clock"
                }
            );
            last_report = (Instant::now(), m.now());
            first_report = false;
        }
    }
    stats.board_s = m.now() as f64 / TICKS_PER_S as f64;
    stats.served_s = seconds(m.now() - origin);
    stats.wall_s = start.elapsed().as_secs_f64();
    stats.resets = m.sim().resets.len();
    Ok(stats)
}

/// The defmt log, decoded by one `defmt-print` fed as the RTT bytes arrive.
struct LogSink {
    child: Option<Child>,
    fed: usize,
}

impl LogSink {
    fn start(elf: &Path, to: Option<&Path>) -> Result<Self, String> {
        let out = match to {
            Some(p) => Stdio::from(
                std::fs::File::create(p).map_err(|e| format!("--log {}: {e}", p.display()))?,
            ),
            None => our_stderr(),
        };
        let child = Command::new(crate::run::defmt_print())
            .arg("-e")
            .arg(elf)
            .args(["--log-format", "{t} {L} {s}"])
            .stdin(Stdio::piped())
            .stdout(out)
            .spawn()
            .map_err(|e| format!("defmt-print: {e} (scripts/setup.sh installs it)"))?;
        Ok(Self {
            child: Some(child),
            fed: 0,
        })
    }

    /// Passes on the RTT bytes drained since the last call.
    fn feed(&mut self, m: &Machine) {
        let log = &m.sim().log;
        if log.len() <= self.fed {
            return;
        }
        if let Some(stdin) = self.child.as_mut().and_then(|c| c.stdin.as_mut()) {
            // A decoder that died takes the log with it, not the board.
            let _ = stdin.write_all(&log[self.fed..]);
            let _ = stdin.flush();
        }
        self.fed = log.len();
    }

    fn finish(&mut self) {
        if let Some(mut c) = self.child.take() {
            drop(c.stdin.take());
            let _ = c.wait();
        }
    }
}

impl Drop for LogSink {
    fn drop(&mut self) {
        self.finish();
    }
}

/// Our stderr for a child, so its lines interleave with ours (stdout stays free for scripts).
fn our_stderr() -> Stdio {
    use std::os::fd::AsFd;
    match std::io::stderr().as_fd().try_clone_to_owned() {
        Ok(fd) => Stdio::from(fd),
        Err(_) => Stdio::inherit(),
    }
}
