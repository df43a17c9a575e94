//! `board-model`: runs a firmware image on the model of its Nucleo board and checks what a board
//! would show (boot, clocks, carrier, ADC rate, closed loop against host-sim, caps, latency,
//! rail fault, watchdog).
use clap::{Parser, Subcommand};
use host_sim::door::{Range, Whole};
use saw_board_model::board::BoardKind;
use saw_board_model::{check, run};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;

#[derive(Parser)]
#[command(
    about = "Run the real firmware ELF on a model of its Nucleo board (Unicorn + STM32 peripheral models)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// The board checks for one image (boot log, clocks, carrier, ADC rate, closed loop against
    /// host-sim, caps, latency, rail fault, watchdog); exits 1 if any fails, 2 on a usage error.
    /// The panic-path, UDIS and F446 ART checks are the cargo tests in tests/firmware.rs.
    Check {
        /// Board: nucleo-f446re or nucleo-g474re.
        #[arg(long)]
        board: String,
        /// The firmware ELF (scripts/build-firmware.sh leaves firmware/target/<board>.elf).
        #[arg(long)]
        elf: PathBuf,
        /// Board time of the closed-loop run, s (2.1 to 60; the ADC-rate check needs two
        /// telemetry lines, logged 1 s and 2 s after boot).
        #[arg(long, default_value_t = 2.2, value_parser = duration, allow_negative_numbers = true)]
        duration: f64,
        /// Print the summary as JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Also write the JSON summary to this file.
        #[arg(long)]
        json_file: Option<PathBuf>,
    },
    /// Run the default closed loop (host-sim's back-and-forth, 1.5 ↔ 61.5 mm at 60 mm/s) and
    /// print the decoded log, then where the core stopped and how much of the time it slept.
    Run {
        /// Board: nucleo-f446re or nucleo-g474re.
        #[arg(long)]
        board: String,
        /// The firmware ELF (scripts/build-firmware.sh leaves firmware/target/<board>.elf).
        #[arg(long)]
        elf: PathBuf,
        /// Board time, s (0.001 to 60; the first telemetry line comes 1 s after boot).
        #[arg(long, default_value_t = 0.1, value_parser = run_duration, allow_negative_numbers = true)]
        duration: f64,
    },
    /// Issue #17's delayed one-pulse on a self-test image (`SELFTEST=1 scripts/build-firmware.sh`
    /// leaves firmware/target/<board>-selftest.elf): its rise, on-time, IDT B, the counter's own
    /// stop, the refused delayed triangle and the level latched before the rise, against the
    /// settings the image logs; exits 1 if any fails, 2 on a usage error.
    DelayedPulse {
        /// Board: nucleo-f446re or nucleo-g474re.
        #[arg(long)]
        board: String,
        /// The self-test ELF.
        #[arg(long)]
        elf: PathBuf,
    },
    /// Issue #35's dual interleaved acquisition on an image built with the `dual-adc` feature
    /// (`DUAL_ADC=1 scripts/build-firmware.sh` leaves firmware/target/nucleo-f446re-dual.elf):
    /// ADC2 the plan's delay after ADC1, 16 pairs per trigger, 10 kHz, the position's scale,
    /// latency, rail faults; exits 1 if any fails, 2 on a usage error. F446 only.
    DualAdc {
        /// Board: nucleo-f446re.
        #[arg(long)]
        board: String,
        /// The dual-adc ELF.
        #[arg(long)]
        elf: PathBuf,
    },
    /// Serve the image's host link behind a pseudo-terminal for `saw --port PATH` (and the
    /// panel): the firmware runs on the model paced to the wall clock (never ahead of it; as
    /// fast as it can when slower, with its speed printed), its link UART bridged to the pty, its
    /// defmt log decoded on stderr. Ctrl-C or SIGTERM stops it and removes the link.
    Serve {
        /// Board: nucleo-f446re or nucleo-g474re.
        #[arg(long)]
        board: String,
        /// The firmware ELF (scripts/build-firmware.sh leaves firmware/target/<board>.elf).
        #[arg(long)]
        elf: PathBuf,
        /// Where to put the link to the pty's slave (`saw --port` takes this path); a symlink
        /// already there is replaced, any other file refused.
        #[arg(long, value_name = "PATH")]
        pty: PathBuf,
        /// A file holding the store's flash region (F446: 256 KiB, sectors 6-7; G474: 16 KiB,
        /// the end of bank 2): loaded before boot when it exists, written back when serve stops,
        /// so a saved scene survives a restart. Same format as `host-sim serve --flash`.
        #[arg(long, value_name = "FILE")]
        flash: Option<PathBuf>,
        /// Write the decoded defmt log here instead of stderr.
        #[arg(long, value_name = "FILE")]
        log: Option<PathBuf>,
        #[arg(long, value_name = "MM_S", default_value_t = 60.0, help = SERVE_SPEED.help("Finger speed, back and forth between 1.5 and 61.5 mm"), value_parser = SERVE_SPEED.parser(), allow_negative_numbers = true)]
        speed: f64,
        #[arg(long, value_name = "MM", conflicts_with = "speed", help = SERVE_AT.help("Finger at rest here instead"), value_parser = SERVE_AT.parser(), allow_negative_numbers = true)]
        rest_at: Option<f64>,
        #[arg(long, value_name = "LSB", default_value_t = 2.0, help = SERVE_NOISE.help("ADC noise per conversion"), value_parser = SERVE_NOISE.parser(), allow_negative_numbers = true)]
        noise: f64,
        #[arg(long, default_value_t = 1, help = SERVE_SEED.help("Noise seed"), value_parser = SERVE_SEED.parser(), allow_negative_numbers = true)]
        seed: u64,
        #[arg(long, value_name = "S", help = SERVE_SECONDS.help("Stop after this much board time (default: run until stopped)"), value_parser = SERVE_SECONDS.parser(), allow_negative_numbers = true)]
        seconds: Option<f64>,
    },
    /// Every path from the per-sample roots into a panic function, from the image's Thumb code
    /// (direct calls and tail calls; indirect branches counted, not followed); exits 1 if there
    /// is one, 2 on a usage error (a root that names no function).
    PanicCheck {
        /// The firmware ELF (scripts/build-firmware.sh leaves firmware/target/<board>.elf).
        #[arg(long)]
        elf: PathBuf,
        /// A root function: its demangled name without the hash, or a prefix ending in `*`.
        /// Repeat for every root.
        #[arg(long, required = true)]
        root: Vec<String>,
        /// Functions whose panic paths are accepted, one per line: `name-or-prefix* | reason`
        /// (`#` starts a comment). The traversal does not enter them and lists them with their
        /// reason.
        #[arg(long)]
        allow_file: Option<PathBuf>,
    },
}

// `serve`'s flags, checked at the door as host-sim's are (`host_sim::door`): one line naming the
// flag, the value and the rule; NaN and inf refused.
const SERVE_SPEED: Range = Range::new(0.1, 1000.0, "mm/s");
/// The default scene's travel (63 mm): the model's wiper reads the default calibration.
const SERVE_AT: Range = Range::new(0.0, 63.0, "mm");
const SERVE_NOISE: Range = Range::new(0.0, 100.0, "LSB RMS");
const SERVE_SEED: Whole = Whole::new(0, u64::MAX);
const SERVE_SECONDS: Range = Range::new(0.01, 1e6, "s");

/// clap prints "invalid value '<v>' for '--duration <DURATION>': " before these, so they state
/// only the rule.
fn range(s: &str, lo: f64, hi: f64) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| "not a number of seconds".to_string())?;
    if !v.is_finite() || v < lo || v > hi {
        return Err(format!("must be between {lo} and {hi} s"));
    }
    Ok(v)
}

fn duration(s: &str) -> Result<f64, String> {
    range(s, 2.1, 60.0)
}

fn run_duration(s: &str) -> Result<f64, String> {
    range(s, 0.001, 60.0)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match real_main(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn real_main(cli: Cli) -> Result<ExitCode, String> {
    match cli.cmd {
        Cmd::Check {
            board,
            elf,
            duration,
            json,
            json_file,
        } => {
            let started = std::time::Instant::now();
            let kind = BoardKind::parse(&board)?;
            // A file that cannot be written is refused before minutes of emulation.
            if let Some(f) = &json_file {
                std::fs::write(f, "").map_err(|e| format!("--json-file {}: {e}", f.display()))?;
            }
            let mut rep = check::all(kind, &elf, duration)?;
            rep.passed = rep.passed();
            rep.extend(check::rail_fault(kind, &elf)?);
            rep.extend(check::watchdog(kind, &elf)?);
            if check::image_has_rf_level(&elf) {
                rep.extend(check::rf_level_panic(kind, &elf)?);
                if check::image_has_link(&elf) {
                    rep.extend(check::rf_level(kind, &elf)?);
                }
            }
            // The host link, on both boards (the F446's USART2, the G474's LPUART1).
            if check::image_has_link(&elf) {
                rep.extend(check::link(kind, &elf)?);
                rep.extend(check::save(kind, &elf)?);
                rep.extend(check::stream_cost(kind, &elf)?);
            }
            // Last: the deepest stack over every run above.
            rep.extend(check::fast_strokes(kind, &elf)?);
            let deepest = saw_board_model::stack::take_deepest();
            rep.stack = deepest;
            rep.extend(check::stack(deepest));
            rep.wall_s = started.elapsed().as_secs_f64();
            let text = serde_json::to_string_pretty(&rep).map_err(|e| e.to_string())?;
            if let Some(f) = &json_file {
                std::fs::write(f, &text)
                    .map_err(|e| format!("--json-file {}: {e}", f.display()))?;
            }
            if json {
                println!("{text}");
            } else {
                println!("board model: {} running {}", rep.board, rep.elf);
                for c in &rep.checks {
                    println!(
                        "  {} {}: {}",
                        if c.pass { "ok  " } else { "FAIL" },
                        c.name,
                        c.detail
                    );
                }
                println!(
                    "  closed loop: {:.2} s of board time, {} instructions; all runs took {:.1} s",
                    rep.emulated_s, rep.instructions, rep.wall_s
                );
            }
            Ok(if rep.passed() {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
        Cmd::DelayedPulse { board, elf } => {
            let kind = BoardKind::parse(&board)?;
            let checks = check::delayed_pulse(kind, &elf)?;
            println!(
                "board model: {} running {} (delayed pulse)",
                kind.name(),
                elf.display()
            );
            for c in &checks {
                println!(
                    "  {} {}: {}",
                    if c.pass { "ok  " } else { "FAIL" },
                    c.name,
                    c.detail
                );
            }
            Ok(if checks.iter().all(|c| c.pass) {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
        Cmd::DualAdc { board, elf } => {
            let kind = BoardKind::parse(&board)?;
            let checks = check::dual_adc(kind, &elf)?;
            println!(
                "board model: {} running {} (dual interleaved ADC)",
                kind.name(),
                elf.display()
            );
            for c in &checks {
                println!(
                    "  {} {}: {}",
                    if c.pass { "ok  " } else { "FAIL" },
                    c.name,
                    c.detail
                );
            }
            Ok(if checks.iter().all(|c| c.pass) {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            })
        }
        Cmd::Serve {
            board,
            elf,
            pty,
            flash,
            log,
            speed,
            rest_at,
            noise,
            seed,
            seconds,
        } => {
            let kind = BoardKind::parse(&board)?;
            let trajectory = match rest_at {
                Some(at) => host_sim::trajectory::Trajectory::Rest { at_um: at * 1000.0 },
                None => host_sim::trajectory::Trajectory::Triangle {
                    a_um: 1_500.0,
                    b_um: 61_500.0,
                    speed_um_s: speed * 1000.0,
                },
            };
            let opts = saw_board_model::serve::ServeOptions {
                board: kind,
                elf,
                pty,
                flash,
                log,
                trajectory,
                adc: host_sim::adc::AdcParams {
                    noise_lsb_rms: noise,
                    seed,
                    ..Default::default()
                },
                board_seconds: seconds,
            };
            // host-sim's pty handler: on SIGINT, SIGTERM or SIGHUP it removes the link at once
            // and sets STOP (its `Pty::open` installs the handler; one of our own would be
            // replaced by it and the process killed by the re-raised signal).
            host_sim::serve::pty::on_signals(&STOP);
            let stats = saw_board_model::serve::serve(&opts, &STOP, |p| {
                eprintln!(
                    "board-model serve: {} running {} on {} ({})",
                    kind.name(),
                    opts.elf.display(),
                    opts.pty.display(),
                    p.slave_path().display()
                )
            })?;
            eprintln!(
                "board-model serve: stopped at {:.3} s of board time; served {:.3} s of it in {:.3} s ({:.2}× real time); {} bytes in, {} out, {} resets",
                stats.board_s,
                stats.served_s,
                stats.wall_s,
                stats.speed(),
                stats.bytes_in,
                stats.bytes_out,
                stats.resets
            );
            Ok(ExitCode::SUCCESS)
        }
        Cmd::PanicCheck {
            elf,
            root,
            allow_file,
        } => panic_check(&elf, &root, allow_file.as_deref()),
        Cmd::Run {
            board,
            elf,
            duration,
        } => {
            let kind = BoardKind::parse(&board)?;
            let (o, m) = run::run(&run::Options::new(kind, &elf, duration))?;
            let pc = m.uc.reg_read(unicorn_engine::RegisterARM::PC).unwrap_or(0);
            if let (Some(cb), Ok(_)) = (
                m.image.symbol("_SEGGER_RTT"),
                std::env::var("BOARD_MODEL_TRACE"),
            ) {
                let mut b = [0u8; 48];
                let _ = m.uc.mem_read(cb as u64, &mut b);
                let w: Vec<String> = b
                    .chunks(4)
                    .map(|c| format!("{:08X}", u32::from_le_bytes(c.try_into().unwrap())))
                    .collect();
                eprintln!("_SEGGER_RTT @0x{cb:08X}: {}", w.join(" "));
                let sp = m.uc.reg_read(unicorn_engine::RegisterARM::SP).unwrap_or(0);
                let mut st = vec![0u8; 512];
                let _ = m.uc.mem_read(sp, &mut st);
                let ra: Vec<String> = st
                    .chunks(4)
                    .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
                    .filter(|v| (0x0800_0000..0x0808_0000).contains(v))
                    .map(|v| format!("{v:08X}"))
                    .collect();
                eprintln!("stack code addresses from sp 0x{sp:08X}: {}", ra.join(" "));
            }
            if std::env::var("BOARD_MODEL_TRACE").is_ok_and(|v| v == "writes") {
                for w in o.writes.iter().filter(|w| w.addr < 0x4000_0400) {
                    let k = o.triggers.partition_point(|&t| t <= w.at);
                    let last = if k > 0 { o.triggers[k - 1] } else { 0 };
                    eprintln!(
                        "{:12.3} µs TIM2+0x{:02X} = 0x{:08X} (mask {:08X}); {:.3} µs after TRGO #{k}",
                        w.at as f64 / 3600.0,
                        w.addr & 0x3FF,
                        w.value,
                        w.mask,
                        (w.at - last) as f64 / 3600.0
                    );
                }
                let dr: Vec<String> = o
                    .sample_completions
                    .iter()
                    .take(5)
                    .map(|t| format!("{:.3}", *t as f64 / 3600.0))
                    .collect();
                let tr: Vec<String> = o
                    .triggers
                    .iter()
                    .take(5)
                    .map(|t| format!("{:.3}", *t as f64 / 3600.0))
                    .collect();
                eprintln!(
                    "first triggers {tr:?} µs, first sample completions {dr:?} µs, t0 {:?}",
                    o.t0.map(|t| t as f64 / 3600.0)
                );
            }
            for l in &o.log {
                println!("{:10.6} {:5} {}", l.t_s, l.level, l.text);
            }
            if let Some(s) = &o.stop {
                println!("stopped: {s}");
            }
            if let Some(u) = o.stack {
                println!(
                    "stack: deepest {} B of {} B reserved, headroom {} B",
                    u.deepest(),
                    u.region.reserved(),
                    u.headroom()
                );
                // The deepest frames' return addresses (odd words in flash) from the lowest
                // overwritten word up: where the deepest stack was reached (llvm-addr2line -f -i).
                if std::env::var("BOARD_MODEL_TRACE").is_ok_and(|v| v == "stack") {
                    let mut b = vec![0u8; 1024];
                    let _ = m.uc.mem_read(u.lowest as u64, &mut b);
                    let ra: Vec<String> = b
                        .chunks(4)
                        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                        .filter(|v| v & 1 == 1 && (0x0800_0000..0x0808_0000).contains(v))
                        .map(|v| format!("0x{:08X}", v & !1))
                        .collect();
                    println!("return addresses above the deepest word: {}", ra.join(" "));
                }
            }
            println!(
                "pc 0x{pc:08X}; {:.4} s of board time, {} instructions, {} exceptions, {:.1} % asleep, in {:.2} s",
                o.end as f64 / 3.6e9,
                o.instructions,
                o.exceptions,
                100.0 * o.sleeping as f64 / o.end.max(1) as f64,
                o.wall_s
            );
            Ok(if o.stop.is_some() {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            })
        }
    }
}

/// Set by SIGINT or SIGTERM: `serve` stops at its next step, writes the flash back and removes
/// its link (the default action would kill it and leave both behind).
static STOP: AtomicBool = AtomicBool::new(false);

/// Reads the allow file: `pattern | reason` per line.
fn allow_list(path: &std::path::Path) -> Result<Vec<(String, String)>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (pat, why) = line.split_once('|').ok_or_else(|| {
            format!(
                "{}:{}: an entry is `function | reason`, and this line has no `|`",
                path.display(),
                n + 1
            )
        })?;
        let (pat, why) = (pat.trim(), why.trim());
        if why.is_empty() {
            return Err(format!(
                "{}:{}: `{pat}` is allowed without a reason; write why its panics cannot happen",
                path.display(),
                n + 1
            ));
        }
        out.push((pat.to_string(), why.to_string()));
    }
    Ok(out)
}

fn panic_check(
    elf: &std::path::Path,
    roots: &[String],
    allow_file: Option<&std::path::Path>,
) -> Result<ExitCode, String> {
    use saw_board_model::panic_check;
    let started = std::time::Instant::now();
    let g = panic_check::graph(elf)?;
    let allowed = match allow_file {
        Some(p) => allow_list(p)?,
        None => Vec::new(),
    };
    let mut root_ix = Vec::new();
    for r in roots {
        let m = g.matching(r);
        if m.is_empty() {
            return Err(format!(
                "--root {r:?} names no function in {} (inlined? give it #[inline(never)])",
                elf.display()
            ));
        }
        root_ix.extend(m);
    }
    let f = g.check(&root_ix, &allowed);
    let name = |i: usize| g.funcs[i].name.as_str();
    println!(
        "panic-check {}: {} roots, {} functions reachable, {} panic paths, {} indirect branches not followed ({:.2} s)",
        elf.display(),
        f.roots.len(),
        f.reachable,
        f.panics.len(),
        f.indirect.len(),
        started.elapsed().as_secs_f64()
    );
    for &r in &f.roots {
        println!("  root {} @ 0x{:08X}", name(r), g.funcs[r].addr);
    }
    for (i, why) in &f.allowed_reached {
        println!("  allowed, not entered: {} ({why})", name(*i));
    }
    for (i, ind) in &f.indirect {
        println!(
            "  indirect, not followed: `{}` at 0x{:08X} in {}",
            ind.what,
            ind.site,
            name(*i)
        );
    }
    for c in &f.panics {
        println!("  PANIC PATH:");
        for (k, &(i, site)) in c.iter().enumerate() {
            if k == 0 {
                println!("      {}", name(i));
            } else {
                println!("   -> {}   (from 0x{site:08X})", name(i));
            }
        }
    }
    Ok(if f.panics.is_empty() {
        println!("ok: no panic function is reachable from the roots");
        ExitCode::SUCCESS
    } else {
        println!("FAIL: {} panic paths from the roots", f.panics.len());
        ExitCode::FAILURE
    })
}
