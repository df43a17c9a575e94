//! One run of a firmware image on the board model: the finger's trajectory and the rheostat/ADC
//! model from host-sim wired to the wiper input, faults injected on schedule, and what the run
//! produced (decoded log, pins, register writes, events) collected for the checks.

use crate::board::{self, BoardKind};
use crate::machine::{BusWrite, Machine, PinEdge, Stop};
use crate::periph::{seconds, Event, Time, TICKS_PER_S};
use host_sim::adc::{AdcModel, AdcParams, FaultKind};
use host_sim::trajectory::Trajectory;
use std::cell::Cell;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// What to run.
#[derive(Clone, Debug)]
pub struct Options {
    pub board: BoardKind,
    pub elf: PathBuf,
    pub trajectory: Trajectory,
    /// Virtual time to run, s (boot included).
    pub duration_s: f64,
    /// Rheostat/ADC model (noise, offset, seed, rail-fault windows in trajectory time).
    pub adc: AdcParams,
    /// From this virtual time on (s), the NVIC line of this IRQ is held high: an interrupt storm
    /// that starves the control loop (the IWDG must reset the chip).
    pub stuck_irq: Option<(f64, u16)>,
    /// How long the interrupt line stays stuck, s (None: until the end or a reset).
    pub stuck_for_s: Option<f64>,
    /// DHCSR.C_DEBUGEN as the firmware reads it.
    pub debugger: bool,
    /// At this virtual time (s), record the carrier pin (TIM1 CH1) for 20 µs: 300 periods at
    /// 15 MHz (recording it all the time would cost an event per edge).
    pub carrier_window_s: Option<f64>,
    /// At this virtual time (s), once the core is in thread mode, divert it into a real panic
    /// call site of the image (`movw/movt r0, &Location; bl panic_const_div_by_zero`): the
    /// firmware's own panic machinery runs from there, as after a division by zero.
    pub force_panic_s: Option<f64>,
    /// At this virtual time (s), the NMI is made pending (NMIPENDSET), as a flash double-ECC
    /// error or any other NMI source would.
    pub nmi_s: Option<f64>,
    /// At this virtual time (s), this IRQ — one the firmware binds no handler to — is enabled
    /// and made pending: the image's DefaultHandler runs.
    pub unhandled_irq: Option<(f64, u16)>,
    /// The RTT host is `probe-rs run`: it switches the up channel to block-when-full.
    pub rtt_host_blocking: bool,
    /// From this virtual time (s) on, the RTT host reads nothing more (stalled or killed), its
    /// up buffer left full (`Machine::stall_rtt_host_full`).
    pub rtt_host_stalls_s: Option<f64>,
    /// Nothing on the HSE pins (the F446's ST-LINK MCO absent, a dead crystal): HSERDY never
    /// sets.
    pub hse_absent: bool,
    /// A part with this much flash, KiB (None: the board's 512): FLASHSIZE reads it and the
    /// flash above is absent.
    pub flash_kib: Option<u16>,
    /// Bytes the host sends on the link UART, each batch from its virtual time (s) on.
    pub link_input: Vec<(f64, Vec<u8>)>,
    /// Flash contents written before the run (address, bytes): a store left by earlier saves.
    pub flash_preload: Vec<(u32, Vec<u8>)>,
    /// Times (s) at which the instructions executed so far in each exception are noted
    /// (`Outcome::instruction_counts`).
    pub count_at_s: Vec<f64>,
    /// Note the instructions executed so far in this exception at every ADC trigger (TIM3
    /// TRGO): `Outcome::per_trigger_counts`.
    pub count_per_trigger: Option<usize>,
    /// The 4-wire overlay on the 2D image's pins and the finger on it (`crate::touch`).
    pub touch: Option<TouchScript>,
    /// At each (virtual time s, duration µs): the core runs nothing for that long, interrupts
    /// held off (`Machine::hold_core`), peripherals running on.
    pub hold_core: Vec<(f64, f64)>,
}

/// The overlay and where the finger is at each virtual time (s since reset).
#[derive(Clone)]
pub struct TouchScript {
    pub overlay: host_sim::touch::Overlay,
    pub seed: u64,
    pub finger: crate::touch::FingerAt,
}

impl std::fmt::Debug for TouchScript {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "TouchScript {{ overlay: {:?}, seed: {} }}",
            self.overlay, self.seed
        )
    }
}

impl Options {
    /// The default closed loop: host-sim's default back-and-forth trajectory (1.5 ↔ 61.5 mm at
    /// 60 mm/s), 2 LSB noise, seed 1.
    pub fn new(board: BoardKind, elf: &Path, duration_s: f64) -> Self {
        Self {
            board,
            elf: elf.to_path_buf(),
            trajectory: Trajectory::Triangle {
                a_um: 1_500.0,
                b_um: 61_500.0,
                speed_um_s: 60_000.0,
            },
            duration_s,
            adc: AdcParams::default(),
            stuck_irq: None,
            stuck_for_s: None,
            debugger: false,
            carrier_window_s: None,
            force_panic_s: None,
            nmi_s: None,
            unhandled_irq: None,
            rtt_host_blocking: false,
            rtt_host_stalls_s: None,
            hse_absent: false,
            flash_kib: None,
            link_input: Vec::new(),
            flash_preload: Vec::new(),
            count_at_s: Vec::new(),
            count_per_trigger: None,
            touch: None,
            hold_core: Vec::new(),
        }
    }
}

/// One decoded defmt line.
#[derive(Clone, Debug, PartialEq)]
pub struct LogLine {
    /// The firmware's own timestamp (embassy uptime), s.
    pub t_s: f64,
    pub level: String,
    pub text: String,
}

/// What a run produced.
pub struct Outcome {
    /// The deepest the main stack reached in this run (the painted region's lowest overwritten
    /// word), if the image's stack region is known.
    pub stack: Option<crate::stack::Use>,
    pub stop: Option<Stop>,
    /// Virtual time reached, master ticks.
    pub end: Time,
    /// Trajectory time origin: the first conversion of the first sample.
    pub t0: Option<Time>,
    pub log: Vec<LogLine>,
    pub raw_log: Vec<u8>,
    pub pins: Vec<Vec<PinEdge>>,
    pub writes: Vec<BusWrite>,
    /// TIM3 TRGO times (the ADC triggers).
    pub triggers: Vec<Time>,
    /// ADC conversions the wiper model answered.
    pub conversions: u64,
    /// Times at which a sample's last conversion reached memory (its DMA read).
    pub sample_completions: Vec<Time>,
    pub resets: Vec<(Time, crate::periph::ResetCause)>,
    pub instructions: u64,
    pub sleeping: Time,
    pub exceptions: u64,
    pub wall_s: f64,
    /// Every byte the firmware sent on the link UART, with the time its stop bit ended.
    pub link_output: Vec<(Time, u8)>,
    /// For each `link_input` batch sent (in time order), when its last byte's stop bit ended,
    /// at the rate the UART's registers set.
    pub link_input_done: Vec<Time>,
    /// At each `Options::count_at_s`: the instructions executed so far in each exception
    /// (index: exception number, 0 = thread mode).
    pub instruction_counts: Vec<Vec<u64>>,
    /// At every TIM3 TRGO (with `Options::count_per_trigger`): (time, instructions so far in
    /// that exception).
    pub per_trigger_counts: Vec<(Time, u64)>,
    /// What DAC1's channel 1 put on PA4 (every change), and the RF drive level the finger gets.
    pub dac: Vec<crate::periph::dac::DacSample>,
    /// TRGO pulses of TIM2 (the burst timer) and TIM8 (the DAC's trigger): (time, timer).
    pub trgo: Vec<(Time, u8)>,
    /// What the overlay saw (with `Options::touch`).
    pub touch: Option<crate::touch::Trace>,
}

/// Runs `opts`.
pub fn run(opts: &Options) -> Result<(Outcome, Machine), String> {
    let started = std::time::Instant::now();
    let def = opts.board.def();
    let mut adc = AdcModel::new(saw_core::default_config().calibration, opts.adc.clone())
        .map_err(|e| format!("ADC model: {e:?}"))?;
    if opts.adc.faults.iter().any(|f| f.kind == FaultKind::Dropout) {
        return Err("a dropout fault has no meaning at the ADC input of the board model (the ADC always converts); use open or short".into());
    }
    let t0: Rc<Cell<Option<Time>>> = Rc::new(Cell::new(None));
    let conversions = Rc::new(Cell::new(0u64));
    let traj = opts.trajectory.clone();
    let (t0_w, conv_w) = (t0.clone(), conversions.clone());
    let wiper: board::Wiper = Box::new(move |t: Time| {
        let origin = match t0_w.get() {
            Some(o) => o,
            None => {
                t0_w.set(Some(t));
                t
            }
        };
        conv_w.set(conv_w.get() + 1);
        let rel = t - origin;
        let t_us = rel / (TICKS_PER_S / 1_000_000);
        match adc.fault_at(t_us) {
            Some(FaultKind::Open) => 0,
            Some(FaultKind::Short) => 4095,
            _ => adc.convert(traj.state(seconds(rel)).position_um) as u16,
        }
    });
    let panel = opts.touch.as_ref().map(|t| {
        Rc::new(std::cell::RefCell::new(crate::touch::Panel::new(
            def,
            t.overlay,
            t.seed,
            t.finger.clone(),
        )))
    });
    let mut m = board::build_with(opts.board, &opts.elf, wiper, panel.clone())?;
    for (addr, bytes) in &opts.flash_preload {
        m.preload_flash(*addr, bytes)?;
    }
    m.sim_mut().scs.debugger_attached = opts.debugger;
    if let Some(kib) = opts.flash_kib {
        m.set_flash_kib(kib)?;
    }
    if opts.hse_absent {
        use crate::periph::rcc_f4::{HseInput, RccF4};
        use crate::periph::rcc_g4::RccG4;
        for p in m.sim_mut().periphs.iter_mut() {
            let any = p.p.as_any_mut();
            if let Some(r) = any.downcast_mut::<RccF4>() {
                r.set_hse_input(HseInput::None);
            } else if let Some(r) = any.downcast_mut::<RccG4>() {
                r.set_hse_input(HseInput::None);
            }
        }
    }
    if let Some(ex) = opts.count_per_trigger {
        m.sim_mut().snapshot_on = Some((Event::Trgo { timer: 3 }, ex));
    }
    let end = (opts.duration_s * TICKS_PER_S as f64) as Time;
    // Scheduled interventions, in time order: (time, what).
    let at = |s: f64| (s * TICKS_PER_S as f64) as Time;
    let mut plan: Vec<(Time, u8)> = Vec::new();
    if let Some(w) = opts.carrier_window_s {
        plan.push((at(w), 0));
        plan.push((at(w) + TICKS_PER_S / 50_000, 1));
    }
    if let Some((s, _)) = opts.stuck_irq {
        plan.push((at(s), 2));
        if let Some(d) = opts.stuck_for_s {
            plan.push((at(s + d), 4));
        }
    }
    if let Some(s) = opts.force_panic_s {
        plan.push((at(s), 3));
    }
    for s in &opts.count_at_s {
        plan.push((at(*s), 6));
    }
    if let Some(s) = opts.nmi_s {
        plan.push((at(s), 7));
    }
    if let Some((s, _)) = opts.unhandled_irq {
        plan.push((at(s), 8));
    }
    if let Some(s) = opts.rtt_host_stalls_s {
        plan.push((at(s), 9));
    }
    for (s, _) in &opts.hold_core {
        plan.push((at(*s), 5));
    }
    m.sim_mut().rtt_host_blocking = opts.rtt_host_blocking;
    let mut instruction_counts = Vec::new();
    for (i, (s, _)) in opts.link_input.iter().enumerate() {
        plan.push((at(*s), 10 + i as u8));
    }
    plan.sort();
    let mut link_input_done = Vec::new();
    let mut stop = None;
    for (t, what) in plan {
        if t >= end {
            break;
        }
        stop = m.run_until(t);
        if stop.is_some() {
            break;
        }
        match what {
            0 => m.sim_mut().record("TIM1", 1, true),
            1 => m.sim_mut().record("TIM1", 1, false),
            2 => {
                let irq = opts.stuck_irq.unwrap().1;
                m.sim_mut().stuck_irqs.push(irq);
            }
            4 => m.sim_mut().stuck_irqs.clear(),
            5 => {
                // The hold planned at this time.
                let us = opts
                    .hold_core
                    .iter()
                    .find(|(s, _)| at(*s) == t)
                    .map_or(0.0, |h| h.1);
                stop = m.hold_core((us * 1e-6 * TICKS_PER_S as f64) as Time);
                if stop.is_some() {
                    break;
                }
            }
            6 => instruction_counts.push(m.sim().instructions_in.clone()),
            7 => m.sim_mut().scs.set_pending(crate::scs::exc::NMI),
            8 => m.sim_mut().scs.force_irq(opts.unhandled_irq.unwrap().1),
            9 => m.stall_rtt_host_full(),
            n if n >= 10 => {
                let bytes = &opts.link_input[(n - 10) as usize].1;
                let now = m.now();
                link_input_done.push(m.sim_mut().uart_send(now, bytes)?);
            }
            _ => {
                let site = m.image.call_site("panic_const_div_by_zero").ok_or(
                    "the image has no `bl panic_const_div_by_zero` call site to divert to",
                )?;
                stop = m.divert_in_thread_mode(site);
                if stop.is_some() {
                    break;
                }
            }
        }
    }
    if stop.is_none() {
        stop = m.run_until(end);
    }
    let per_sample =
        def.adc_oversample as usize / if opts.board == BoardKind::G474 { 16 } else { 1 };
    let stack = m.stack_use();
    if let Some(u) = stack {
        crate::stack::record(u);
    }
    let s = m.sim();
    let raw_log = s.log.clone();
    let log = decode(&opts.elf, &raw_log)?;
    // The ADC's triggers: TIM3 TRGO pulses from the first conversion on (a configuration UG
    // before the ADC is on also pulses TRGO, and converts nothing).
    let first = t0
        .get()
        .map_or(Time::MAX, |t| t.saturating_sub(TICKS_PER_S / 100_000));
    let triggers = s
        .events
        .iter()
        .filter(|(t, e)| *e == Event::Trgo { timer: 3 } && *t >= first)
        .map(|&(t, _)| t)
        .collect();
    let out = Outcome {
        stack,
        stop,
        end: m.now(),
        t0: t0.get(),
        log,
        raw_log,
        pins: s.pins.clone(),
        writes: s.writes.clone(),
        triggers,
        conversions: conversions.get(),
        sample_completions: s
            .dma_reads
            .iter()
            .skip(per_sample - 1)
            .step_by(per_sample)
            .copied()
            .collect(),
        resets: s.resets.clone(),
        instructions: s.instructions,
        sleeping: s.sleeping_ticks,
        exceptions: s.exceptions_taken,
        wall_s: started.elapsed().as_secs_f64(),
        link_output: s.uart_output(),
        instruction_counts,
        link_input_done,
        per_trigger_counts: s.snapshots.clone(),
        trgo: s
            .events
            .iter()
            .filter_map(|&(t, e)| match e {
                Event::Trgo { timer } if timer == 2 || timer == 8 => Some((t, timer)),
                _ => None,
            })
            .collect(),
        touch: panel.map(|p| p.borrow().trace.clone()),
        dac: s
            .periphs
            .iter()
            .find_map(|p| {
                p.p.as_any()
                    .downcast_ref::<crate::periph::dac::Dac>()
                    .map(|d| d.trace.clone())
            })
            .unwrap_or_default(),
    };
    Ok((out, m))
}

/// The defmt decoder the project installs (scripts/setup.sh).
pub(crate) fn defmt_print() -> PathBuf {
    if let Ok(p) = std::env::var("DEFMT_PRINT") {
        return PathBuf::from(p);
    }
    let home = std::env::var("HOME").unwrap_or_default();
    let local = Path::new(&home).join(".cargo/bin/defmt-print");
    if local.exists() {
        local
    } else {
        PathBuf::from("defmt-print")
    }
}

/// Decodes the RTT bytes with `defmt-print -e ELF`, one line per frame: "<t> <LEVEL> <text>".
pub fn decode(elf: &Path, raw: &[u8]) -> Result<Vec<LogLine>, String> {
    use std::io::Write;
    use std::process::{Command, Stdio};
    let mut child = Command::new(defmt_print())
        .arg("-e")
        .arg(elf)
        .args(["--log-format", "{t} {L} {s}"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("defmt-print: {e} (scripts/setup.sh installs it)"))?;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(raw)
        .map_err(|e| format!("defmt-print: {e}"))?;
    let out = child
        .wait_with_output()
        .map_err(|e| format!("defmt-print: {e}"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(format!(
            "defmt-print could not decode the log of {}: {}",
            elf.display(),
            err.lines().last().unwrap_or("no message")
        ));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut lines = Vec::new();
    for l in text.lines() {
        let mut it = l.splitn(3, ' ');
        let (Some(t), Some(level), Some(rest)) = (it.next(), it.next(), it.next()) else {
            continue;
        };
        let Ok(t_s) = t.parse::<f64>() else { continue };
        lines.push(LogLine {
            t_s,
            level: level.to_string(),
            text: rest.trim_start().to_string(),
        });
    }
    Ok(lines)
}
