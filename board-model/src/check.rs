//! The checks a firmware image must pass on the board model, each a named result with its
//! measured value: boot log, clock tree, carrier, ADC sample rate, the closed loop against
//! host-sim, duty and on-time caps, sensor-to-gate latency, and the fault paths.

use crate::board::{BoardKind, PIN_BURST_A, PIN_BURST_B, PIN_CARRIER, PIN_RF_ARM};
use crate::machine::PinEdge;
use crate::periph::{ticks_per_cycle, ResetCause, Time, TICKS_PER_S};
use crate::run::{self, Options, Outcome};
use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::timer::{Edge, Waveform};
use serde::Serialize;
use std::path::Path;

/// One check's result.
#[derive(Clone, Debug, Serialize)]
pub struct Check {
    pub name: String,
    pub pass: bool,
    /// What was measured, as a sentence.
    pub detail: String,
}

fn check(name: &str, pass: bool, detail: impl Into<String>) -> Check {
    Check {
        name: name.to_string(),
        pass,
        detail: detail.into(),
    }
}

/// Burst-timer kernel clock of the board, Hz.
fn burst_clk(board: BoardKind) -> u64 {
    board.def().burst_timer_clk_hz as u64
}

/// Converts recorded pin edges (master ticks) into a host-sim waveform in timer clocks relative
/// to `t0`, from `from` on.
pub fn waveform(edges: &[PinEdge], t0: Time, from: Time, end: Time, clk_hz: u64) -> Waveform {
    let per = ticks_per_cycle(clk_hz);
    let mut out = Vec::new();
    for e in edges.iter().filter(|e| e.at >= from && e.at >= t0) {
        let t = (e.at - t0) / per;
        if out.last().map_or(e.high, |l: &Edge| l.high != e.high) {
            out.push(Edge { t, high: e.high });
        }
    }
    Waveform {
        edges: out,
        // The DAC's own trace (`Outcome::dac`) carries the level; these waveforms compare edges.
        levels: Vec::new(),
        clock_hz: clk_hz as u32,
        end: end.saturating_sub(t0) / per,
    }
}

/// A run of pulses with one period and on-time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Segment {
    /// First rise, timer clocks.
    pub start: u64,
    /// Fall to fall, timer clocks.
    pub period: u64,
    /// On-time of the segment's second pulse (the first after a Start rises when the firmware
    /// switches the channel to PWM mode, a few ticks after the counter starts).
    pub on: u64,
    pub pulses: usize,
}

/// Groups the waveform's pulses into segments of equal period (±1 tick). The period is taken
/// fall to fall: in PWM mode 1 a fall is the CCR match, exact in every period, while the first
/// rise after a Start comes when the firmware selects PWM mode, after the counter started.
pub fn segments(w: &Waveform) -> Vec<Segment> {
    let pulses = w.pulses();
    let mut out: Vec<Segment> = Vec::new();
    for (i, p) in pulses.iter().enumerate() {
        let Some(next) = pulses.get(i + 1) else { break };
        // A gap of more than one period is not this segment any more (Off, restart).
        let period = next.fall - p.fall;
        match out.last_mut() {
            Some(s) if s.period.abs_diff(period) <= 1 => {
                if s.pulses == 1 {
                    s.on = p.on();
                }
                s.pulses += 1;
            }
            _ => out.push(Segment {
                start: p.rise,
                period,
                on: p.on(),
                pulses: 1,
            }),
        }
    }
    // Single stray pulses (a region crossed in under one period) are not a segment of a period.
    out.retain(|s| s.pulses >= 2);
    out
}

/// Every pulse keeps the duty cap over its own period and the on-time cap; returns the
/// violations as sentences.
pub fn caps(w: &Waveform, cap_permille: u64, max_on_us: u64) -> Vec<String> {
    let mut bad = Vec::new();
    let max_on = max_on_us * w.clock_hz as u64 / 1_000_000;
    for p in w.pulses() {
        if p.on() > max_on {
            bad.push(format!(
                "pulse at {} clocks is on for {} clocks, above the on-time cap of {max_on}",
                p.rise,
                p.on()
            ));
        }
        if let Some(period) = p.period() {
            if p.on() * 1000 > cap_permille * period {
                bad.push(format!(
                    "pulse at {} clocks: {} on in a {} period is {} permille, above the {cap_permille} permille cap",
                    p.rise,
                    p.on(),
                    period,
                    p.on() * 1000 / period
                ));
            }
        }
    }
    bad
}

fn log_has(o: &Outcome, part: &str) -> bool {
    o.log.iter().any(|l| l.text.contains(part))
}

/// Samples processed, from the firmware's 1 Hz telemetry lines ("samples: N").
pub fn telemetry_samples(o: &Outcome) -> Vec<(f64, u64)> {
    o.log
        .iter()
        .filter(|l| l.text.starts_with("telemetry"))
        .filter_map(|l| {
            let i = l.text.find("samples: ")? + "samples: ".len();
            let n: String = l.text[i..]
                .chars()
                .take_while(|c| c.is_ascii_digit())
                .collect();
            Some((l.t_s, n.parse().ok()?))
        })
        .collect()
}

fn level_at(edges: &[PinEdge], t: Time) -> bool {
    edges
        .iter()
        .take_while(|e| e.at <= t)
        .last()
        .is_some_and(|e| e.high)
}

fn high_within(edges: &[PinEdge], from: Time, to: Time) -> bool {
    level_at(edges, from) || edges.iter().any(|e| e.at > from && e.at < to && e.high)
}

fn fmt_us(v: Option<f64>) -> String {
    v.map_or("never".to_string(), |v| format!("{v:.1} µs"))
}

fn us(t: Time) -> f64 {
    t as f64 * 1e6 / TICKS_PER_S as f64
}

/// Summary of one board's checks.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Every check passed.
    pub passed: bool,
    pub board: String,
    pub elf: String,
    pub checks: Vec<Check>,
    pub carrier_hz_registers: Option<f64>,
    pub carrier_hz_edges: Option<f64>,
    pub samples_per_s: Option<u64>,
    pub latency_us_median: Option<f64>,
    pub latency_us_worst: Option<f64>,
    pub emulated_s: f64,
    pub instructions: u64,
    pub wall_s: f64,
    /// The deepest stack over every run of the check (`stack.rs`).
    pub stack: Option<crate::stack::Use>,
}

impl Report {
    pub fn passed(&self) -> bool {
        self.checks.iter().all(|c| c.pass)
    }

    /// Adds checks and updates `passed`.
    pub fn extend(&mut self, checks: Vec<Check>) {
        self.checks.extend(checks);
        self.passed = self.passed();
    }
}

/// Runs every check for `board` on `elf`.
pub fn all(board: BoardKind, elf: &Path, duration_s: f64) -> Result<Report, String> {
    let mut checks = Vec::new();
    let def = board.def();
    let mut opts = Options::new(board, elf, duration_s);
    opts.carrier_window_s = Some(0.5);
    let (o, mut m) = run::run(&opts)?;
    if let Some(s) = &o.stop {
        checks.push(check(
            "runs to the end",
            false,
            format!(
                "the run stopped at {:.6} s: {s}",
                o.end as f64 / TICKS_PER_S as f64
            ),
        ));
    } else {
        checks.push(check(
            "runs to the end",
            true,
            format!("{duration_s} s of board time without an unmodelled access, fault or lockup"),
        ));
    }

    // Boot log.
    for (what, part) in [
        ("boot line", "saw-firmware v"),
        ("clock line", "clocks: "),
        ("carrier line", "carrier: "),
        ("scene loaded", "scene loaded"),
    ] {
        let line = o
            .log
            .iter()
            .find(|l| l.text.contains(part))
            .map(|l| l.text.clone());
        checks.push(check(
            &format!("log: {what}"),
            line.is_some(),
            line.unwrap_or_else(|| format!("no line containing {part:?}")),
        ));
    }

    // Clock tree as the RCC registers configure it.
    let c = m.sim().clocks;
    let want = &def.clocks;
    let ok = c.sysclk_hz == want.sysclk_hz as u64
        && c.pclk1_hz == want.pclk1_hz() as u64
        && c.pclk2_hz == want.pclk2_hz() as u64
        && c.tim_apb2_hz == def.carrier_timer_clk_hz as u64
        && c.tim_apb1_hz == def.burst_timer_clk_hz as u64;
    checks.push(check(
        "clock tree",
        ok,
        format!(
            "SYSCLK {} Hz, PCLK1 {} Hz, PCLK2 {} Hz, APB1 timers {} Hz, APB2 timers {} Hz; expected the board plan SYSCLK {} Hz, PCLK1 {} Hz, PCLK2 {} Hz",
            c.sysclk_hz, c.pclk1_hz, c.pclk2_hz, c.tim_apb1_hz, c.tim_apb2_hz, want.sysclk_hz, want.pclk1_hz(), want.pclk2_hz()
        ),
    ));

    // Carrier from TIM1's registers and from its recorded edges.
    let tim1 = if board == BoardKind::F446 {
        0x4001_0000
    } else {
        0x4001_2C00
    };
    let psc = m.sim_mut().peek(tim1 + 0x28).unwrap_or(0) as u64;
    let arr = m.sim_mut().peek(tim1 + 0x2C).unwrap_or(0) as u64;
    let f_reg = c.tim_apb2_hz as f64 / ((psc + 1) * (arr + 1)) as f64;
    checks.push(check(
        "carrier from registers",
        f_reg == 15e6,
        format!(
            "TIM1 {} Hz / (PSC {psc} + 1) / (ARR {arr} + 1) = {f_reg} Hz",
            c.tim_apb2_hz
        ),
    ));
    let rises: Vec<Time> = o.pins[PIN_CARRIER]
        .iter()
        .filter(|e| e.high)
        .map(|e| e.at)
        .collect();
    let periods: Vec<Time> = rises.windows(2).map(|w| w[1] - w[0]).collect();
    let f_edges = periods.first().map(|&p| TICKS_PER_S as f64 / p as f64);
    let uniform = !periods.is_empty() && periods.iter().all(|&p| p == periods[0]);
    checks.push(check(
        "carrier from edges",
        uniform && f_edges == Some(15e6) && periods.len() >= 100,
        format!(
            "{} periods recorded on PA8 in 20 µs, {}; expected ≥ 100 periods of exactly 66.67 ns (15 MHz)",
            periods.len(),
            match (periods.first(), uniform) {
                (Some(&p), true) => format!("every one {:.2} ns → {} Hz", p as f64 * 1e9 / TICKS_PER_S as f64, TICKS_PER_S / p),
                (Some(_), false) => "not all the same length".to_string(),
                (None, _) => "none".to_string(),
            }
        ),
    ));

    // ADC: triggers exactly 100 µs apart, and the firmware's own count of processed samples.
    let trig_ok = o
        .triggers
        .windows(2)
        .all(|w| w[1] - w[0] == TICKS_PER_S / def.sample_rate_hz as u64);
    checks.push(check(
        "ADC trigger period",
        trig_ok && o.triggers.len() > 1000,
        format!(
            "{} TIM3 TRGO pulses from the first conversion on, {}; expected > 1000, each 100 µs after the last",
            o.triggers.len(),
            match o.triggers.windows(2).find(|w| w[1] - w[0] != TICKS_PER_S / def.sample_rate_hz as u64) {
                None => "each 100 µs after the last".to_string(),
                Some(w) => format!("but one at {:.3} ms came {:.3} µs after the one before", us(w[1]) / 1e3, us(w[1] - w[0])),
            }
        ),
    ));
    let tele = telemetry_samples(&o);
    let rate = tele
        .windows(2)
        .map(|w| (w[1].1 - w[0].1) as f64 / (w[1].0 - w[0].0))
        .next_back();
    let samples_per_s = rate.map(|r| r.round() as u64);
    checks.push(check(
        "ADC samples reach the control loop",
        samples_per_s == Some(def.sample_rate_hz as u64),
        format!(
            "{}; expected exactly {} samples/s between the telemetry lines at 1 s and 2 s",
            match samples_per_s {
                Some(r) => format!("{r} samples/s ({} telemetry lines)", tele.len()),
                None => format!("{} telemetry lines, two are needed", tele.len()),
            },
            def.sample_rate_hz
        ),
    ));

    // Closed loop against host-sim for the same trajectory, noise and seed.
    let (t0, end) = (o.t0.unwrap_or(0), o.end);
    let clk = burst_clk(board);
    let model_w = waveform(&o.pins[PIN_BURST_A], t0, t0, end, clk);
    let host_duration = (end.saturating_sub(t0)) as f64 / TICKS_PER_S as f64;
    let mut params = host_sim::sim::SimParams::new(def, opts.trajectory.clone(), host_duration);
    params.adc = opts.adc.clone();
    let host = host_sim::sim::run(&params).map_err(|e| format!("host-sim: {e}"))?;
    let (ms, hs) = (segments(&model_w), segments(&host.waveform));
    if std::env::var("BOARD_MODEL_TRACE").is_ok_and(|v| v == "segments") {
        for (i, s) in ms.iter().enumerate() {
            eprintln!("model {i}: {s:?}");
        }
        for (i, s) in hs.iter().enumerate() {
            eprintln!("host  {i}: {s:?}");
        }
    }
    let pos = |t_clk: u64| opts.trajectory.state(t_clk as f64 / clk as f64).position_um / 1000.0;
    let mut worst_pos: f64 = 0.0;
    let mut worst_ticks = 0u64;
    for (a, b) in ms.iter().zip(&hs) {
        worst_ticks = worst_ticks
            .max(a.period.abs_diff(b.period))
            .max(a.on.abs_diff(b.on));
        worst_pos = worst_pos.max((pos(a.start) - pos(b.start)).abs());
    }
    checks.push(check(
        "closed loop: same bursts as host-sim",
        !ms.is_empty() && ms.len() == hs.len() && worst_ticks <= 1 && worst_pos <= 0.2,
        format!(
            "{} burst segments on the model, {} on host-sim; worst period/on-time difference {worst_ticks} timer clocks (limit 1), worst switch position difference {:.3} mm (limit 0.2)",
            ms.len(),
            hs.len(),
            worst_pos
        ),
    ));
    let cap = def_cap(&host);
    let bad = caps(&model_w, cap.0, cap.1);
    checks.push(check(
        "duty and on-time caps on every pulse",
        bad.is_empty() && !model_w.pulses().is_empty(),
        if bad.is_empty() {
            format!(
                "{} pulses, none above {} permille or {} µs",
                model_w.pulses().len(),
                cap.0,
                cap.1
            )
        } else {
            bad[0].clone()
        },
    ));

    checks.push(check(
        "no access to an unclocked peripheral",
        m.sim().unclocked.is_empty(),
        match m.sim().unclocked.first() {
            None => "every register access found its peripheral clocked".to_string(),
            Some(u) => format!(
                "{} such accesses (ignored on the chip), the first: {u}",
                m.sim().unclocked.len()
            ),
        },
    ));

    // Sensor-to-gate latency.
    let lat = latency(&o, board);
    let (median, worst) = (lat.get(lat.len() / 2).copied(), lat.last().copied());
    checks.push(check(
        "sensor-to-gate latency ≤ 100 µs",
        worst.is_some_and(|w| w <= 100.0),
        match (median, worst) {
            (Some(md), Some(w)) => format!(
                "{} burst-timer updates: median {md:.1} µs, worst {w:.1} µs (model CPU: 1 instruction = 1 HCLK cycle, ART on)",
                lat.len()
            ),
            _ => "no burst-timer update acted on a sample: no latency to measure".to_string(),
        },
    ));

    let rep = Report {
        passed: false,
        board: board.name().into(),
        elf: elf.display().to_string(),
        carrier_hz_registers: Some(f_reg),
        carrier_hz_edges: f_edges,
        samples_per_s,
        latency_us_median: median,
        latency_us_worst: worst,
        emulated_s: o.end as f64 / TICKS_PER_S as f64,
        instructions: o.instructions,
        wall_s: o.wall_s,
        stack: None,
        checks,
    };
    Ok(rep)
}

/// The duty cap (permille) and on-time cap (µs) of the scene host-sim ran.
fn def_cap(host: &host_sim::sim::SimResult) -> (u64, u64) {
    let l = host.params.config.limits;
    (l.max_duty_permille as u64, l.max_on_time_us as u64)
}

/// Sensor-to-gate latency, µs, sorted: for each group of burst-timer writes (the firmware acting
/// on one sample), the time from the TIM3 trigger of the newest sample whose conversions had all
/// reached memory to the group's last write.
pub fn latency(o: &Outcome, board: BoardKind) -> Vec<f64> {
    let _ = board;
    latency_from(o, &o.triggers, &o.sample_completions)
}

/// [`latency`] against the given sample-start triggers and sample completions.
fn latency_from(o: &Outcome, triggers: &[Time], completions: &[Time]) -> Vec<f64> {
    let tim2: Vec<Time> = o
        .writes
        .iter()
        .filter(|w| w.addr < 0x4000_0400)
        .map(|w| w.at)
        .collect();
    let mut groups = Vec::new();
    let gap = TICKS_PER_S / 100_000; // 10 µs between writes starts a new group
    let mut last: Option<Time> = None;
    for &t in &tim2 {
        match last {
            Some(l) if t - l <= gap => {
                *groups.last_mut().unwrap() = t;
            }
            _ => groups.push(t),
        }
        last = Some(t);
    }
    let mut out = Vec::new();
    for w in groups {
        // Newest sample complete before the write.
        let k = completions.partition_point(|&c| c <= w);
        if k == 0 || k > triggers.len() {
            continue;
        }
        out.push(us(w - triggers[k - 1]));
    }
    out.sort_by(|a, b| a.partial_cmp(b).unwrap());
    out
}

/// [`latency`] for an acquisition of `tps` triggers per sample (`o.sample_completions` then
/// counts triggers' worth of DMA reads): from the first trigger of the newest sample whose
/// conversions had all reached memory.
pub fn latency_per_sample(o: &Outcome, tps: usize) -> Vec<f64> {
    let tps = tps.max(1);
    let triggers: Vec<Time> = o.triggers.iter().copied().step_by(tps).collect();
    let completions: Vec<Time> = o
        .sample_completions
        .iter()
        .copied()
        .skip(tps - 1)
        .step_by(tps)
        .collect();
    latency_from(o, &triggers, &completions)
}

/// Sensor fault: the wiper opens (reads 0) from 105 to 305 ms of trajectory time — 5 ms into a
/// 20 ms burst of the 20 Hz region, so the line is high when the fault begins. The enables must
/// be low from the first faulted sample's processing on, through the fault window.
pub fn rail_fault(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    rail_fault_of(board, elf, FaultKind::Open)
}

/// [`rail_fault`] with the wiper fault `kind` (Open: the pull-down's 0; Short: the supply's 4095).
pub fn rail_fault_of(board: BoardKind, elf: &Path, kind: FaultKind) -> Result<Vec<Check>, String> {
    let mut opts = Options::new(board, elf, 0.5);
    opts.adc.faults = vec![FaultWindow {
        kind,
        start_us: 105_000,
        end_us: 305_000,
    }];
    let (o, _m) = run::run(&opts)?;
    let mut out = Vec::new();
    let t0 = o.t0.unwrap_or(0);
    let start = t0 + TICKS_PER_S * 105 / 1000;
    let stop = t0 + TICKS_PER_S * 305 / 1000;
    // The first trigger whose conversions are all faulted, and the sample period. The ADC holds
    // its input at the end of each sampling time, so a trigger up to one sampling time before
    // the onset still converts only faulted input; 0.5 µs is under the shortest sampling time
    // either board uses or has tried (the G474's 47.5 cycles at 37.5 MHz = 1.27 µs, 92.5 = 2.47
    // µs before, 24.5 = 653 ns in the conversion budget's 64× point; the F446's 56 cycles = 2.5
    // µs). The 1 µs this
    // was before let a 24.5-cycle G474 trigger 0.7 µs ahead of the onset count, whose first
    // conversion is held 47 ns before it.
    let first = o
        .triggers
        .iter()
        .copied()
        .find(|&t| t + TICKS_PER_S / 2_000_000 >= start)
        .unwrap_or(start);
    let period = TICKS_PER_S / board.def().sample_rate_hz as u64;
    let deadline = first + period;
    let high_before = high_within(&o.pins[PIN_BURST_A], start - TICKS_PER_S / 10, start);
    let a = high_within(&o.pins[PIN_BURST_A], deadline, stop);
    let b = high_within(&o.pins[PIN_BURST_B], deadline, stop);
    // When each line went low for the fault, from the fault's onset (a sample whose later
    // conversions are already faulted may turn RF off before the first fully faulted trigger).
    let low_after_onset_us = |pin: usize| {
        let e = &o.pins[pin];
        if !level_at(e, start) {
            return Some(0.0);
        }
        e.iter()
            .find(|x| x.at > start && !x.high)
            .map(|x| us(x.at - start))
    };
    out.push(check(
        "rail fault: enables low by the next sample",
        high_before && !a && !b && o.stop.is_none(),
        format!(
            "bursts in the 100 ms before the fault: {high_before}; PA0 low {} and PB10 low {} after the fault began; first fully faulted trigger {:.1} µs after the onset; expected both low one sample after it and until the fault ends (200 ms): PA0 high then: {a}, PB10 high then: {b}",
            fmt_us(low_after_onset_us(PIN_BURST_A)),
            fmt_us(low_after_onset_us(PIN_BURST_B)),
            (first as f64 - start as f64) * 1e6 / TICKS_PER_S as f64,
        ),
    ));
    // (b) RF level: 0 by the next sample, through the fault window.
    let dac_before = dac_at(&o.dac, start);
    let dac_late = o
        .dac
        .iter()
        .find(|d| d.at > deadline && d.at < stop && (d.driven && d.code != 0));
    let dac_zero = dac_at(&o.dac, deadline).code == 0 || !dac_at(&o.dac, deadline).driven;
    let zero_at = if dac_at(&o.dac, start).code == 0 {
        Some(start)
    } else {
        o.dac
            .iter()
            .find(|d| d.at > start && d.code == 0)
            .map(|d| d.at)
    };
    out.push(check(
        "rf level: 0 after a sensor fault (Off) within one sample",
        dac_before.code != 0 && dac_zero && dac_late.is_none(),
        format!(
            "DAC code {} before the fault; 0 {} after the onset ({} after the first fully faulted trigger; limit one sample, {:.0} µs); {} until the fault ends",
            dac_before.code,
            fmt_us(zero_at.map(|z| us(z - start))),
            zero_at.map_or("—".to_string(), |z| format!("{:.1} µs", (z as f64 - first as f64) * 1e6 / TICKS_PER_S as f64)),
            us(period),
            match dac_late {
                None => "held at 0".to_string(),
                Some(d) => format!("code {} at {:.4} s", d.code, d.at as f64 / TICKS_PER_S as f64),
            }
        ),
    ));
    out.push(check(
        "rail fault: logged",
        log_has(&o, "sensor fault"),
        if log_has(&o, "sensor fault") {
            "the log names the sensor fault"
        } else {
            "no \"sensor fault\" line in the log"
        },
    ));
    Ok(out)
}

/// A stuck interrupt (storm) from 1.0 s starves the control loop: the IWDG must reset the chip,
/// with the enables low from the reset on until the new boot, which must come up again.
pub fn watchdog(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    let mut opts = Options::new(board, elf, 1.2);
    let irq = match board {
        BoardKind::F446 => 56, // DMA2_STREAM0: the ADC's DMA
        BoardKind::G474 => 11, // DMA1_CHANNEL1
    };
    opts.stuck_irq = Some((1.0, irq));
    let (o, _m) = run::run(&opts)?;
    let mut out = Vec::new();
    let reset = o
        .resets
        .iter()
        .find(|r| r.1 == ResetCause::IndependentWatchdog)
        .map(|r| r.0);
    let storm = TICKS_PER_S;
    let after_ms = reset.map(|r| (r as f64 - storm as f64) / TICKS_PER_S as f64 * 1e3);
    out.push(check(
        "stalled loop: IWDG resets the chip",
        reset.is_some() && after_ms.is_some_and(|ms| ms > 0.0 && ms <= 60.0),
        format!(
            "{}; expected 50 ms after the last pet (the IWDG timeout), so within 60 ms of the storm",
            match after_ms {
                Some(ms) => format!("IWDG reset {ms:.1} ms after the interrupt storm began"),
                None => "no IWDG reset".to_string(),
            }
        ),
    ));
    if let Some(r) = reset {
        let reboot = o
            .log
            .iter()
            .filter(|l| l.text.contains("saw-firmware v"))
            .count();
        // From the reset until the new boot arms RF, enables and arm stay low.
        let arm_high = o.pins[PIN_RF_ARM]
            .iter()
            .find(|e| e.at > r && e.high)
            .map(|e| e.at)
            .unwrap_or(o.end);
        let a = high_within(&o.pins[PIN_BURST_A], r, arm_high);
        let b = high_within(&o.pins[PIN_BURST_B], r, arm_high);
        let arm = level_at(&o.pins[PIN_RF_ARM], r);
        out.push(check(
            "stalled loop: enables and arm low through the reset",
            !a && !b && !arm && reboot >= 2,
            format!("after the reset PA0 high: {a}, PB10 high: {b}, RF arm high at the reset: {arm}; boots logged: {reboot}"),
        ));
    }
    Ok(out)
}

/// Whether the image drives the RF level (its symbols name the firmware's `level` module).
pub fn image_has_rf_level(elf: &Path) -> bool {
    std::fs::read(elf).is_ok_and(|b| b.windows(7).any(|w| w == b"RfLevel"))
}

/// Whether the image carries the host link (its symbols name `saw_link`).
pub fn image_has_link(elf: &Path) -> bool {
    std::fs::read(elf).is_ok_and(|b| b.windows(8).any(|w| w == b"saw_link"))
}

/// The frames the board sent, decoded, each with the time its last byte left; and how many were
/// refused.
fn board_replies(
    bytes: &[(Time, u8)],
) -> (
    Vec<(Time, saw_link::msg::Header, saw_link::msg::Reply)>,
    usize,
) {
    use saw_link::frame::{self, Receiver, MAX_ENCODED};
    let mut rx = Receiver::<MAX_ENCODED>::default();
    let (mut replies, mut bad) = (Vec::new(), 0);
    for &(t, b) in bytes {
        match rx.push(b) {
            Some(Ok(n)) => match frame::message::<saw_link::msg::Reply>(rx.payload(n)) {
                Ok((h, r)) => replies.push((t, h, r)),
                Err(_) => bad += 1,
            },
            Some(Err(_)) => bad += 1,
            None => {}
        }
    }
    (replies, bad)
}

/// `req` as the host sends it: a zero first (any partial frame before it is dropped), then the
/// frame with sequence number `seq`.
pub fn request_frame(seq: u32, req: &saw_link::msg::Request) -> Vec<u8> {
    use saw_link::frame::{self, MAX_ENCODED};
    use saw_link::msg::{Header, PROTOCOL_VERSION};
    let mut out = vec![0u8; MAX_ENCODED + 1];
    let n = frame::encode(
        &Header {
            version: PROTOCOL_VERSION,
            seq,
        },
        req,
        &mut out[1..],
    )
    .expect("a request frames");
    out.truncate(n + 1);
    out
}

/// The host link on the firmware image (issue #13): frames in on the UART, answers out, while
/// the finger moves. Hello; a boundary moved live (the answer carries the new scene's id); a
/// frame with a flipped bit refused; the counters; a stream of records that follow the finger.
/// Also the boundary move's round trip in board time, from its last byte in to its answer's
/// last byte out.
pub fn link(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    use saw_link::msg::{LinkError, Reply, Request, PROTOCOL_VERSION};
    let frame_of = request_frame;
    let mut flipped = frame_of(3, &Request::Save);
    flipped[3] ^= 0x08;
    let mut opts = Options::new(board, elf, 0.62);
    opts.link_input = vec![
        (0.20, frame_of(1, &Request::Hello)),
        (
            0.25,
            frame_of(
                2,
                &Request::MoveBoundary {
                    index: 0,
                    at_um: 30_000,
                },
            ),
        ),
        (0.30, flipped),
        (0.35, frame_of(4, &Request::Counters { reset: false })),
        (0.40, frame_of(5, &Request::Stream { every_samples: 10 })),
        (0.45, frame_of(7, &Request::Ping)),
        (0.50, frame_of(6, &Request::Stream { every_samples: 0 })),
    ];
    let (o, m) = run::run(&opts)?;
    let mut out = Vec::new();
    if let Some(s) = &o.stop {
        out.push(check(
            "link: runs to the end",
            false,
            format!("stopped: {s}"),
        ));
        return Ok(out);
    }
    // The answers, each with the time its last byte left.
    let (replies, bad) = board_replies(&o.link_output);
    let answer = |seq: u32| {
        replies
            .iter()
            .find(|(_, h, r)| h.seq == seq && !matches!(r, Reply::Stream(_)))
            .cloned()
    };
    let def = board.def();
    out.push(check(
        "link: hello",
        matches!(answer(1), Some((_, _, Reply::Hello(ref h))) if h.board.as_str() == def.name && h.protocol == PROTOCOL_VERSION),
        format!("{:?}", answer(1).map(|a| a.2)),
    ));
    let moved_config = saw_core::default_config()
        .with_boundary(0, 30_000)
        .map_err(|e| e.to_string())?;
    let want = saw_link::scene_id(&moved_config);
    let moved = answer(2);
    // The request's last byte in, at the line rate the UART's registers set (the batches are
    // sent in time order; the move is the second).
    let last_in = o.link_input_done.get(1).copied();
    let rtt_ms = moved
        .as_ref()
        .zip(last_in)
        .map(|((t, _, _), last_in)| (*t as f64 - last_in as f64) * 1e3 / TICKS_PER_S as f64);
    // The line rate the UART's registers set, from the move's bytes (queued back to back from
    // their start, 10 bits each).
    let baud = last_in.map(|done| {
        let start = (opts.link_input[1].0 * TICKS_PER_S as f64) as Time;
        let bits = 10.0 * opts.link_input[1].1.len() as f64;
        bits * TICKS_PER_S as f64 / (done - start) as f64
    });
    out.push(check(
        "link: boundary moved live",
        matches!(moved, Some((_, _, Reply::Applied { scene_id })) if scene_id == want),
        format!(
            "answer {} (want Applied, scene {want:#010x}); round trip {} from the request's last byte to the answer's; line {} (from the UART's registers)",
            match moved.as_ref().map(|a| &a.2) {
                Some(Reply::Applied { scene_id }) => format!("Applied, scene {scene_id:#010x}"),
                other => format!("{other:?}"),
            },
            rtt_ms.map_or("—".into(), |r| format!("{r:.3} ms")),
            baud.map_or("—".into(), |b| format!("{b:.0} baud")),
        ),
    ));
    let refused = replies.iter().find(|(_, h, r)| {
        h.seq == 0 && matches!(r, Reply::Error(LinkError::Crc { .. } | LinkError::Cobs))
    });
    out.push(check(
        "link: a flipped bit is refused, the next request answered",
        refused.is_some() && answer(3).is_none() && answer(4).is_some(),
        format!(
            "refusal: {:?}; answer to the corrupted Save: {:?}",
            refused.map(|r| &r.2),
            answer(3).map(|a| a.2)
        ),
    ));
    out.push(check(
        "link: counters",
        matches!(answer(4), Some((_, _, Reply::Counters(c))) if c.core.samples > 1000 && c.link.frames_bad == 1),
        format!("{:?}", answer(4).map(|a| a.2)),
    ));
    // The stream: ~1000 records/s for 0.1 s, following the trajectory (the model's finger).
    let records: Vec<saw_link::msg::Record> = replies
        .iter()
        .filter_map(|(_, _, r)| match r {
            Reply::Stream(s) => Some(s.records.clone()),
            _ => None,
        })
        .flatten()
        .collect();
    let t0 = o.t0.unwrap_or(0);
    let mut worst_um = 0.0f64;
    for r in &records {
        // The record's µs clock is the firmware's uptime; compare with the trajectory at the
        // same board time (the wiper model's origin is the first conversion, `t0`).
        let at = r.time_us as u64 * (TICKS_PER_S / 1_000_000);
        let rel = at.saturating_sub(t0);
        let truth = opts
            .trajectory
            .state(rel as f64 / TICKS_PER_S as f64)
            .position_um;
        if let Some(p) = r.position_um {
            worst_um = worst_um.max((p as f64 - truth).abs());
        }
    }
    // Protocol 2: every record carries the scene in force (the moved one, the first change since
    // boot), none is older than the stream's start, and a ping reads the board's µs clock at the
    // time its request arrived (the records' clock: the model's time since reset).
    let from_us = match answer(5) {
        Some((_, _, Reply::Streaming { from_us, .. })) => Some(from_us),
        _ => None,
    };
    let stamped = records
        .iter()
        .all(|r| r.scene_id == want && r.change == 1 && from_us.is_some_and(|f| r.time_us >= f));
    out.push(check(
        "link: records carry the scene in force and start after the request",
        !records.is_empty() && stamped,
        format!(
            "from_us {from_us:?}; first record {:?}",
            records.first().map(|r| (r.time_us, r.scene_id, r.change))
        ),
    ));
    // The board's µs clock starts with its time driver, after reset: compared by differences.
    // Between the stream request and the ping the board's clock moved as far as the model's
    // time between their last bytes in, give or take the link task's latency (< 0.5 ms).
    let in_us = |i: usize| {
        o.link_input_done
            .get(i)
            .map(|t| *t as f64 * 1e6 / TICKS_PER_S as f64)
    };
    let pong = match answer(7) {
        Some((_, _, Reply::Pong { board_time_us })) => Some(board_time_us),
        _ => None,
    };
    let board_dt = pong.zip(from_us).map(|(p, f)| p as f64 - f as f64);
    let model_dt = in_us(5).zip(in_us(4)).map(|(p, s)| p - s);
    out.push(check(
        "link: a ping reads the board clock",
        board_dt
            .zip(model_dt)
            .is_some_and(|(b, m)| (b - m).abs() < 500.0),
        format!(
            "stream request to ping: {board_dt:?} µs on the board's clock, {model_dt:?} µs of model time"
        ),
    ));
    out.push(check(
        "link: stream follows the finger",
        (90..=110).contains(&records.len()) && worst_um < 300.0 && bad == 0,
        format!(
            "{} records in 0.1 s at every 10th sample; worst distance from the true position {worst_um:.0} µm (one sample's travel and the sampler's delay); {bad} frames from the board refused",
            records.len()
        ),
    ));
    let _ = m;
    Ok(out)
}

/// Saving a scene on the board (issue #13), from a store that earlier saves have filled up to
/// the point where the next save must erase a unit (`store_image::before_an_erase`): the board
/// boots into the last of them and says so; a boundary moved live is saved over the link — the
/// erase and every write happen with the RF arm low, and the watchdog (lengthened for the F446's
/// second-long sector erase, which stalls every fetch) does not reset the chip; after the save the
/// watchdog bites at its own 50 ms again (a stuck interrupt at 1.9 s must reset the chip within
/// 60 ms), and the board comes back up in the scene just saved.
pub fn save(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    // The save starts at 0.3 s and lasts 1.2 s on the F446 (a 1 s erase and the migration).
    const STUCK_S: f64 = 1.9;
    use saw_link::msg::{Reply, Request, SceneSource};
    let def = board.def();
    let scene = |i: usize| {
        saw_core::default_config()
            .with_boundary(0, 25_000 + (i as u32 % 50) * 100)
            .expect("a boundary between 25 and 30 mm is valid in the default scene")
    };
    let (image, last, saves) = crate::store_image::before_an_erase(def, scene)?;
    let frame_of = request_frame;
    let mut opts = Options::new(board, elf, 2.5);
    opts.flash_preload = vec![(def.store.origin, image)];
    opts.link_input = vec![
        (0.20, frame_of(1, &Request::Hello)),
        (
            0.25,
            frame_of(
                2,
                &Request::MoveBoundary {
                    index: 0,
                    at_um: 30_000,
                },
            ),
        ),
        (0.30, frame_of(3, &Request::Save)),
        (2.35, frame_of(4, &Request::Hello)),
    ];
    opts.stuck_irq = Some((
        STUCK_S,
        match board {
            BoardKind::F446 => 56,
            BoardKind::G474 => 11,
        },
    ));
    opts.stuck_for_s = Some(0.1);
    let at = |s: f64| (s * TICKS_PER_S as f64) as Time;
    let (o, mut m) = run::run(&opts)?;
    let mut out = Vec::new();
    if let Some(s) = &o.stop {
        out.push(check(
            "save: runs to the end",
            false,
            format!("stopped: {s}"),
        ));
        return Ok(out);
    }
    let replies: Vec<(Time, u32, Reply)> = board_replies(&o.link_output)
        .0
        .into_iter()
        .map(|(t, h, r)| (t, h.seq, r))
        .collect();
    let answer = |seq: u32| replies.iter().find(|r| r.1 == seq).cloned();
    let hello = |seq: u32| match answer(seq) {
        Some((_, _, Reply::Hello(h))) => Some((h.scene_id, h.scene_source)),
        _ => None,
    };
    let boot_line = |id: u32| format!("boot: the scene saved in flash (id {id:08x})");
    out.push(check(
        "save: boots into the saved scene",
        hello(1) == Some((last.scene_id, SceneSource::Saved))
            && o.log.iter().any(|l| l.text == boot_line(last.scene_id)),
        format!(
            "a store holding {saves} earlier saves, the last scene {:#010x}: hello says {:?}; log {}",
            last.scene_id,
            hello(1),
            if o.log.iter().any(|l| l.text == boot_line(last.scene_id)) { "names it" } else { "does not name it" }
        ),
    ));
    let moved = saw_core::default_config()
        .with_boundary(0, 30_000)
        .map_err(|e| e.to_string())?;
    let moved_id = saw_link::scene_id(&moved);
    let saved = answer(3);
    out.push(check(
        "save: answered Saved",
        matches!(saved, Some((_, _, Reply::Saved { scene_id })) if scene_id == moved_id),
        format!(
            "{:?} {} after the request",
            saved.as_ref().map(|a| &a.2),
            saved.as_ref().map_or("—".into(), |a| format!(
                "{:.1} ms",
                (a.0 as f64 - at(0.30) as f64) * 1e3 / TICKS_PER_S as f64
            ))
        ),
    ));
    // Every flash operation of the save, with the arm line's level.
    let (fi, flash_prog) = (m.sim().chip.flash_if, m.sim().chip.flash_prog);
    let ops = flash_prog(&mut *m.sim_mut().periphs[fi].p)
        .operations()
        .to_vec();
    let erases: Vec<_> = ops.iter().filter(|o| o.erase).collect();
    let arm = &o.pins[PIN_RF_ARM];
    let armed_during = ops
        .iter()
        .filter(|op| high_within(arm, op.start, op.end))
        .count();
    let (first, last_end) = (
        ops.first().map(|o| o.start),
        ops.iter().map(|o| o.end).max(),
    );
    out.push(check(
        "save: RF arm low through every flash operation",
        !ops.is_empty() && !erases.is_empty() && armed_during == 0,
        format!(
            "{} operations ({} erases of {}) from {} to {}; the arm high during {armed_during} of them; the core waited {:.3} s for the flash",
            ops.len(),
            erases.len(),
            erases.first().map_or("—".into(), |e| format!("0x{:08X}", e.addr)),
            first.map_or("—".into(), |t| format!("{:.4} s", t as f64 / TICKS_PER_S as f64)),
            last_end.map_or("—".into(), |t| format!("{:.4} s", t as f64 / TICKS_PER_S as f64)),
            m.sim().flash_stalled_ticks as f64 / TICKS_PER_S as f64,
        ),
    ));
    let resets: Vec<_> = o
        .resets
        .iter()
        .map(|r| (r.0 as f64 / TICKS_PER_S as f64, r.1))
        .collect();
    let during_save = o.resets.iter().filter(|r| r.0 < at(STUCK_S)).count();
    let bite = o
        .resets
        .iter()
        .find(|r| r.0 >= at(STUCK_S) && r.1 == ResetCause::IndependentWatchdog)
        .map(|r| (r.0 - at(STUCK_S)) as f64 * 1e3 / TICKS_PER_S as f64);
    out.push(check(
        "save: the watchdog does not bite during the save, and bites at 50 ms after it",
        during_save == 0 && bite.is_some_and(|ms| ms <= 60.0),
        format!(
            "resets {resets:?}; the stuck interrupt at {STUCK_S} s reset the chip after {}",
            bite.map_or("never (by the end of the run)".into(), |ms| format!(
                "{ms:.1} ms"
            ))
        ),
    ));
    let boots = o
        .log
        .iter()
        .filter(|l| l.text == boot_line(moved_id))
        .count();
    out.push(check(
        "save: after a reset the board runs the scene just saved",
        hello(4) == Some((moved_id, SceneSource::Saved)) && boots == 1,
        format!(
            "hello says {:?} (want {moved_id:#010x}, Saved); boot lines naming it: {boots}",
            hello(4)
        ),
    ));
    Ok(out)
}

/// What a stream at every sample may add to the sample path beyond the tap's 10 %, instructions
/// per sample: the velocity estimator's update over its rest (docs/sample-contract.md), which the
/// records' velocity needs on every sample. Measured on the G474 image (2026-11-29): 1 163
/// instructions per sample stopped with the estimator resting, 1 199 with it forced on (a
/// one-off image, not kept), so 36; 40 allowed.
pub const STREAM_VELOCITY_ALLOWANCE: f64 = 40.0;

/// What the telemetry stream costs the sample path (issue #13: "nothing on the link may delay
/// the control loop"): instructions executed per sample inside the sample path's interrupt
/// executor (UART4's vector, position 52 on both chips: RM0390 table 38, RM0440 table 97) over
/// 0.1 s with the stream stopped, at every 10th sample and at every sample (more records than the
/// line carries: the queue drops and counts), and, for information, in thread mode (the link task
/// that frames and sends the records). Asserted: the tap at every sample adds at most 10 % to the
/// sample path, plus [`STREAM_VELOCITY_ALLOWANCE`]: since issue #35 the stopped sample path rests
/// the velocity estimator in the default scene's constant regions, and a stream at every sample
/// wakes it (its records carry the velocity), so that much of the difference is the estimator's
/// update, not the tap.
pub fn stream_cost(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    use saw_link::msg::Request;
    const SAMPLE_PATH: usize = 16 + 52;
    let frame_of = request_frame;
    let mut opts = Options::new(board, elf, 0.75);
    opts.link_input = vec![
        (0.40, frame_of(1, &Request::Stream { every_samples: 10 })),
        (0.55, frame_of(2, &Request::Stream { every_samples: 1 })),
        (0.70, frame_of(3, &Request::Stream { every_samples: 0 })),
    ];
    opts.count_at_s = vec![0.25, 0.35, 0.45, 0.55, 0.60, 0.70];
    let (o, _m) = run::run(&opts)?;
    if let Some(s) = &o.stop {
        return Ok(vec![check(
            "stream cost: runs to the end",
            false,
            format!("stopped: {s}"),
        )]);
    }
    let c = &o.instruction_counts;
    if c.len() != 6 {
        return Err(format!("{} instruction counts, 6 asked", c.len()));
    }
    // 0.1 s at 10 kHz: 1 000 samples per window.
    let per_sample = |a: usize, b: usize, ex: usize| (c[b][ex] - c[a][ex]) as f64 / 1000.0;
    let (off, tenth, every) = (
        per_sample(0, 1, SAMPLE_PATH),
        per_sample(2, 3, SAMPLE_PATH),
        per_sample(4, 5, SAMPLE_PATH),
    );
    let (t_off, t_tenth, t_every) = (
        per_sample(0, 1, 0),
        per_sample(2, 3, 0),
        per_sample(4, 5, 0),
    );
    Ok(vec![check(
        "stream cost: the tap adds at most 10 % to the sample path",
        off > 0.0 && every <= off * 1.10 + STREAM_VELOCITY_ALLOWANCE,
        format!(
            "sample path (the interrupt executor) per sample: {off:.0} instructions with the stream stopped, {tenth:.0} at every 10th sample, {every:.0} at every sample (+{:.0}, +{:.1} %); thread mode (the link task) per sample: {t_off:.0}, {t_tenth:.0}, {t_every:.0}",
            every - off,
            100.0 * (every - off) / off.max(1.0)
        ),
    )])
}

// ------------------------------------------------------------------------------------------
// RF level (issue #15): DAC1 channel 1 on PA4, docs/rf-level.md
// ------------------------------------------------------------------------------------------

/// Level ‰ of a DAC code through the board's calibration table: the largest level whose code is
/// at most `code` (the inverse of `LevelTable::code`, exact for the codes the table gives).
pub fn permille_of_code(table: &saw_boards::rf_level::LevelTable, code: u16) -> u16 {
    let n = (0..=1000u16)
        .collect::<Vec<_>>()
        .partition_point(|&l| table.code(l) <= code);
    n.saturating_sub(1) as u16
}

/// The RF drive the finger gets, ‰, as a step function: (time, enable × level) at every change
/// of the enable (PA0, TIM2 CH1) or of what the DAC shows (released = 0).
pub fn drive_trace(
    enable: &[PinEdge],
    dac: &[crate::periph::dac::DacSample],
    table: &saw_boards::rf_level::LevelTable,
) -> Vec<(Time, u16)> {
    let mut ev: Vec<(Time, Option<bool>, Option<u16>)> = enable
        .iter()
        .map(|e| (e.at, Some(e.high), None))
        .chain(dac.iter().map(|d| {
            let l = if d.driven {
                permille_of_code(table, d.code)
            } else {
                0
            };
            (d.at, None, Some(l))
        }))
        .collect();
    ev.sort_by_key(|e| e.0);
    let (mut on, mut level) = (false, 0u16);
    let mut out: Vec<(Time, u16)> = Vec::new();
    for (t, e, l) in ev {
        if let Some(e) = e {
            on = e;
        }
        if let Some(l) = l {
            level = l;
        }
        let v = if on { level } else { 0 };
        if out.last().is_none_or(|x| x.1 != v) {
            out.push((t, v));
        }
    }
    out
}

/// The DAC's sample at or before `t`.
fn dac_at(dac: &[crate::periph::dac::DacSample], t: Time) -> crate::periph::dac::DacSample {
    let k = dac.partition_point(|d| d.at <= t);
    dac[k.saturating_sub(1)]
}

/// A scene file compiled for `board`, as the host would push it over the link.
fn scene_for(board: BoardKind, file: &str) -> Result<saw_core::Config, String> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(file);
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let b = board.def();
    let timer = saw_core::burst::BurstTimer {
        clock_hz: b.burst_timer_clk_hz,
        counter_bits: b.burst_timer_bits,
        max_burst_hz: b.max_burst_hz,
    };
    saw_core::scene_file::load_for_board(file, &text, timer, 1_000_000 / b.sample_rate_hz)
        .map_err(|e| format!("{file}: {e}"))
}

/// DAC bus clocks → master ticks: the DHR → DOR latency after a trigger is three of them
/// (F446 PCLK1, G474 HCLK: `periph::dac`).
fn dac_latency(board: BoardKind) -> Time {
    let c = &board.def().clocks;
    3 * ticks_per_cycle(match board {
        BoardKind::F446 => c.pclk1_hz() as u64,
        BoardKind::G474 => c.sysclk_hz as u64,
    })
}

/// (a) Line crossings with a triangular envelope (scenes/lines.toml pushed over the link at
/// 0.2 s): during each line pulse the drive (enable × level) rises then falls, peaks within one
/// table step of the pulse's middle, never moves by more than one table entry's change, and the
/// DAC is back at 0 one step after the pulse.
/// (d) A random-amplitude scene (scenes/random.toml): every change of the DAC output falls on a
/// TIM2 TRGO (its update or start) plus the DAC's trigger latency, or is a drop to 0 with the
/// line low (an Off).
/// Also the per-sample cost of the sample path with triangles firing: worst sample and mean,
/// against the default scene (no lines).
pub fn rf_level(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    use saw_link::msg::{Reply, Request};
    const SAMPLE_PATH: usize = 16 + 52;
    let def = board.def();
    let table = &def.rf_level.table;
    let lat = dac_latency(board);
    let mut out = Vec::new();
    let run_scene = |file: Option<&str>| -> Result<(Outcome, bool), String> {
        let mut opts = Options::new(board, elf, 1.0);
        if let Some(f) = file {
            opts.link_input = vec![(
                0.2,
                request_frame(1, &Request::LoadScene(scene_for(board, f)?)),
            )];
        }
        opts.count_per_trigger = Some(SAMPLE_PATH);
        let (o, _m) = run::run(&opts)?;
        let applied = board_replies(&o.link_output)
            .0
            .iter()
            .any(|(_, h, r)| h.seq == 1 && matches!(r, Reply::Applied { .. }));
        Ok((o, applied))
    };
    // (a) lines.
    let (o, applied) = run_scene(Some("lines.toml"))?;
    if let Some(s) = &o.stop {
        return Ok(vec![check(
            "rf level: runs to the end",
            false,
            format!("stopped: {s}"),
        )]);
    }
    let from = (0.25 * TICKS_PER_S as f64) as Time;
    let a = &o.pins[PIN_BURST_A];
    let pulses: Vec<(Time, Time)> = a
        .windows(2)
        .filter(|w| w[0].high && !w[1].high && w[0].at >= from)
        .map(|w| (w[0].at, w[1].at))
        .collect();
    let drive = drive_trace(a, &o.dac, table);
    let clk = def.rf_level.envelope_timer_clk_hz as u64;
    let tpc = ticks_per_cycle(clk);
    let mut bad: Vec<String> = Vec::new();
    let mut first_desc = String::new();
    let mut worst_peak_off_us: f64 = 0.0;
    let mut worst_step_ratio: f64 = 0.0;
    let mut dac_after: Vec<(Time, u16, u16, u16, bool)> = Vec::new();
    for (i, &(s, e)) in pulses.iter().enumerate() {
        let plan = saw_boards::rf_level::triangle_plan((e - s) / tpc, clk as u32);
        let step = plan.step_clocks as u64 * tpc;
        // The drive inside the pulse: its value at s and every change up to e.
        let k0 = drive.partition_point(|d| d.0 <= s);
        let mut seq: Vec<(Time, u16)> = vec![(s, drive[k0.saturating_sub(1)].1)];
        seq.extend(drive.iter().copied().filter(|d| d.0 > s && d.0 <= e));
        let peak = seq.iter().map(|x| x.1).max().unwrap_or(0);
        let ip = seq.iter().position(|x| x.1 == peak).unwrap_or(0);
        let rising = seq[..=ip].windows(2).all(|w| w[1].1 >= w[0].1);
        let falling = seq[ip..].windows(2).all(|w| w[1].1 <= w[0].1);
        let mid = s + (e - s) / 2;
        let off = seq[ip].0 as i64 - mid as i64;
        let max_step = seq
            .windows(2)
            .map(|w| w[1].1.abs_diff(w[0].1))
            .max()
            .unwrap_or(0);
        let entry = (2 * peak as u64).div_ceil(plan.entries as u64) as u16 + 2;
        let after = dac_at(&o.dac, e + step);
        let ends = seq.last().is_some_and(|x| x.1 == 0);
        // What the DAC holds after the pulse (docs/rf-level.md: the last latched entry, code(0)
        // or, when N × step overruns the pulse, the one before: one entry's level).
        let held = if after.driven {
            permille_of_code(table, after.code)
        } else {
            0
        };
        dac_after.push((s, after.code, held, entry, level_at(a, e + step)));
        let ok = peak > 0
            && rising
            && falling
            && ends
            && off.unsigned_abs() <= step + lat
            && max_step <= entry;
        worst_peak_off_us = worst_peak_off_us.max(us(off.unsigned_abs()));
        worst_step_ratio = worst_step_ratio.max(max_step as f64 / entry as f64);
        let desc = format!(
            "pulse at {:.4} s, {:.2} ms: {} levels (plan {} entries of {:.2} µs), peak {peak} ‰ {:+.2} µs from the middle, largest step {max_step} ‰ (limit {entry}), rising {rising}, falling {falling}, ends at 0 {ends}; DAC code {} one step after the end",
            s as f64 / TICKS_PER_S as f64,
            us(e - s) / 1e3,
            seq.len(),
            plan.entries,
            us(step),
            off as f64 * 1e6 / TICKS_PER_S as f64,
            after.code
        );
        if i == 0 {
            first_desc = desc.clone();
        }
        if !ok {
            bad.push(desc);
        }
    }
    out.push(check(
        "rf level: a line crossing plays a triangle",
        applied && !pulses.is_empty() && bad.is_empty(),
        format!(
            "scenes/lines.toml {}; {} line pulses; {}; worst peak offset {worst_peak_off_us:.2} µs, worst step {:.0} % of one entry's change{}",
            if applied { "applied" } else { "NOT applied" },
            pulses.len(),
            if first_desc.is_empty() { "none".into() } else { format!("first: {first_desc}") },
            100.0 * worst_step_ratio,
            bad.first().map_or(String::new(), |b| format!("; FAILED: {b}"))
        ),
    ));
    // The step is rounded down (saw_boards::rf_level::triangle_plan), so TIM8's last update —
    // the table's last entry, code(0) — falls inside the pulse: the DAC is back at 0.
    let zero = dac_after.iter().filter(|x| x.1 == 0).count();
    let over = dac_after.iter().find(|x| x.1 != 0 || x.4);
    out.push(check(
        "rf level: after a line pulse the DAC is back at code 0, the enable low",
        !dac_after.is_empty() && over.is_none(),
        format!(
            "one step after each of {} pulses: {zero} at code 0 (the table's last entry){}",
            dac_after.len(),
            match over {
                None => String::new(),
                Some(x) => format!(
                    "; FAILED after the pulse at {:.4} s: code {} = {} ‰, enable {} (one entry is {} ‰)",
                    x.0 as f64 / TICKS_PER_S as f64,
                    x.1,
                    x.2,
                    if x.4 { "high" } else { "low" },
                    x.3
                ),
            }
        ),
    ));
    // Per-sample cost with triangles firing.
    let per_sample = |o: &Outcome| -> (f64, u64, Time) {
        let c: Vec<(Time, u64)> = o
            .per_trigger_counts
            .iter()
            .copied()
            .filter(|x| x.0 >= from)
            .collect();
        let d: Vec<(Time, u64)> = c.windows(2).map(|w| (w[0].0, w[1].1 - w[0].1)).collect();
        let mean = d.iter().map(|x| x.1).sum::<u64>() as f64 / d.len().max(1) as f64;
        let worst = d.iter().copied().max_by_key(|x| x.1).unwrap_or((0, 0));
        (mean, worst.1, worst.0)
    };
    let (lines_mean, lines_worst, lines_worst_at) = per_sample(&o);
    // (d) random amplitude.
    let (o, applied) = run_scene(Some("random.toml"))?;
    let t2: Vec<Time> = o.trgo.iter().filter(|x| x.1 == 2).map(|x| x.0).collect();
    let (mut at_update, mut offs, mut stray) = (0, 0, Vec::new());
    let mut codes = std::collections::BTreeSet::new();
    for w in o.dac.windows(2).filter(|w| w[1].at >= from) {
        let (prev, d) = (w[0], w[1]);
        if prev.code == d.code && prev.driven == d.driven {
            continue;
        }
        codes.insert(d.code);
        let g = d.at.saturating_sub(lat);
        if t2.binary_search(&g).is_ok() {
            at_update += 1;
        } else if d.code == 0 && !level_at(&o.pins[PIN_BURST_A], d.at) {
            offs += 1;
        } else {
            stray.push(d);
        }
    }
    out.push(check(
        "rf level: with a running burst the level changes only at TIM2 updates",
        applied && stray.is_empty() && at_update >= 5 && codes.len() > 3,
        format!(
            "scenes/random.toml {}; {} DAC changes after 0.25 s over {} distinct codes: {at_update} at a TIM2 TRGO + {:.3} µs, {offs} drops to 0 with the line low, {} elsewhere{}",
            if applied { "applied" } else { "NOT applied" },
            at_update + offs + stray.len(),
            codes.len(),
            us(lat),
            stray.len(),
            stray.first().map_or(String::new(), |d| format!(
                " (first: code {} at {:.6} s, PA0 {})",
                d.code,
                d.at as f64 / TICKS_PER_S as f64,
                if level_at(&o.pins[PIN_BURST_A], d.at) { "high" } else { "low" }
            ))
        ),
    ));
    // Baseline cost: the default scene.
    let (o, _) = run_scene(None)?;
    let (base_mean, base_worst, _) = per_sample(&o);
    out.push(check(
        "rf level: sample path cost with triangles",
        lines_worst > 0 && base_worst > 0,
        format!(
            "instructions per sample in the sample path (interrupt executor) from 0.25 to 1 s: lines scene (triangles firing) mean {lines_mean:.0}, worst {lines_worst} (at {:.4} s); default scene mean {base_mean:.0}, worst {base_worst}",
            lines_worst_at as f64 / TICKS_PER_S as f64
        ),
    ));
    Ok(out)
}

/// (c) A forced panic at 0.5 s while bursts run: the DAC is released (level 0) within one
/// sample and stays so until the watchdog's reset.
pub fn rf_level_panic(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    let mut opts = Options::new(board, elf, 0.58);
    opts.force_panic_s = Some(0.5);
    let (o, _m) = run::run(&opts)?;
    let at = TICKS_PER_S / 2;
    let period = TICKS_PER_S / board.def().sample_rate_hz as u64;
    let before = dac_at(&o.dac, at);
    let released = o
        .dac
        .iter()
        .find(|d| d.at >= at && !d.driven && d.code == 0);
    let reset = o.resets.iter().find(|r| r.0 >= at).map(|r| r.0);
    let until = reset.unwrap_or(o.end);
    let again = released.and_then(|r| {
        o.dac
            .iter()
            .find(|d| d.at > r.at && d.at < until && (d.driven || d.code != 0))
    });
    let delay = released.map(|r| us(r.at - at));
    Ok(vec![check(
        "rf level: 0 after a panic",
        delay.is_some_and(|d| d <= us(period)) && again.is_none(),
        format!(
            "before the panic the DAC showed code {} (driven {}); released (0 V) {} after the diversion (limit {:.0} µs), {} until the reset at {}",
            before.code,
            before.driven,
            fmt_us(delay),
            us(period),
            if again.is_none() { "held" } else { "driven again" },
            reset.map_or("— (none)".into(), |r| format!("{:.4} s", r as f64 / TICKS_PER_S as f64))
        ),
    )])
}

/// Stack the images must leave untouched below their deepest use, bytes: a margin for what the
/// model's runs do not reach (a deeper defmt argument, an interrupt nesting the runs missed).
pub const STACK_MARGIN_BYTES: u32 = 1024;

/// The harshest trajectory for the stack the other runs lack: 2 m/s strokes over the whole
/// travel (a region change every few ms, the velocity estimator at its limits) with an open
/// wiper for 50 ms in the middle (fault entry and recovery), 1.2 s of board time.
pub fn fast_strokes(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    let mut opts = Options::new(board, elf, 1.2);
    opts.trajectory = host_sim::trajectory::Trajectory::Triangle {
        a_um: 1_500.0,
        b_um: 61_500.0,
        speed_um_s: 2_000_000.0,
    };
    opts.adc.faults = vec![FaultWindow {
        kind: FaultKind::Open,
        start_us: 300_000,
        end_us: 350_000,
    }];
    let (o, _m) = run::run(&opts)?;
    let changes = o.log.iter().filter(|l| l.text.contains("region")).count();
    Ok(vec![check(
        "fast strokes (2 m/s) with an open wiper: runs to the end",
        o.stop.is_none(),
        match &o.stop {
            None => format!("1.2 s of board time, {changes} region log lines"),
            Some(s) => format!("the run stopped: {s}"),
        },
    )])
}

/// The deepest stack of every run of this process against the region flip-link leaves it.
pub fn stack(u: Option<crate::stack::Use>) -> Vec<Check> {
    let Some(u) = u else {
        return vec![check(
            "stack headroom",
            false,
            "no stack measurement: the image lacks __sdata/__ebss or its initial SP is outside RAM",
        )];
    };
    let r = &u.region;
    vec![check(
        "stack headroom",
        u.headroom() >= STACK_MARGIN_BYTES,
        format!(
            "deepest {} B of {} B reserved (0x{:08X}..0x{:08X}{}), headroom {} B (at least {STACK_MARGIN_BYTES} B), statics {} B",
            u.deepest(),
            r.reserved(),
            r.bottom,
            r.top,
            if r.flipped { ", statics above: flip-link" } else { ", statics below" },
            u.headroom(),
            r.static_bytes
        ),
    )]
}

/// What the self-test image logs about its delayed pulse (`firmware/src/selftest.rs`):
/// "self-test: delayed pulse psc P arr A ccr C: …".
fn selftest_settings(o: &Outcome) -> Option<(u64, u64, u64)> {
    let line = o
        .log
        .iter()
        .find(|l| l.text.starts_with("self-test: delayed pulse psc "))?;
    let num = |key: &str| -> Option<u64> {
        let i = line.text.find(key)? + key.len();
        line.text[i..]
            .chars()
            .take_while(|c| c.is_ascii_digit())
            .collect::<String>()
            .parse()
            .ok()
    };
    Some((num(" psc ")?, num(" arr ")?, num(" ccr ")?))
}

/// Issue #17's delayed one-pulse, on an image built with `selftest-delayed-pulse`
/// (`SELFTEST=1 scripts/build-firmware.sh` → `<board>-selftest.elf`): at boot, with the RF arm
/// still low, the port fires one `GateAction::Pulse` whose settings (logged) have arr > ccr,
/// then asks for the same pulse with a triangular envelope. Measured against the settings, on
/// the recorded pins: the rise on PA0 (IDT A) lands arr + 1 − ccr timer ticks after the CEN
/// write — to the tick: CEN starts the counter at the next kernel clock edge, so the distance
/// is delay × tick plus less than one kernel clock — the line stays high exactly ccr ticks and
/// falls at the update event; PB10 (IDT B, standing drive) the same; no other edge before the
/// arm rises (the counter stopped by itself, the delayed triangle refused with the line off);
/// and the rectangular level was latched by the DAC at CEN (TRGO = enable), before the rise.
pub fn delayed_pulse(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    let opts = Options::new(board, elf, 0.05);
    let (o, _m) = run::run(&opts)?;
    let mut checks = Vec::new();
    if let Some(s) = &o.stop {
        return Ok(vec![check(
            "delayed pulse: runs",
            false,
            format!("the run stopped: {s}"),
        )]);
    }
    let Some((psc, arr, ccr)) = selftest_settings(&o) else {
        return Ok(vec![check(
            "delayed pulse: self-test line",
            false,
            "no `self-test: delayed pulse psc …` line: is this an image built with SELFTEST=1 scripts/build-firmware.sh?",
        )]);
    };
    let tick = ticks_per_cycle(burst_clk(board)) * (psc + 1);
    let (delay, on) = ((arr + 1).saturating_sub(ccr), ccr);
    // The self-test's pulse is TIM2's first start: the first CR1 write with CEN set.
    let cen = o
        .writes
        .iter()
        .find(|w| w.addr == 0x4000_0000 && w.value & w.mask & 1 != 0)
        .map(|w| w.at);
    let arm = o.pins[PIN_RF_ARM]
        .iter()
        .find(|e| e.high)
        .map_or(o.end, |e| e.at);
    let Some(cen) = cen else {
        return Ok(vec![check(
            "delayed pulse: CEN",
            false,
            "TIM2 was never started",
        )]);
    };
    let window = |pin: usize| -> Vec<(Time, bool)> {
        o.pins[pin]
            .iter()
            .filter(|e| e.at >= cen && e.at < arm)
            .map(|e| (e.at, e.high))
            .collect()
    };
    let (a, b) = (window(PIN_BURST_A), window(PIN_BURST_B));
    let (rise, fall) = match a.as_slice() {
        [(r, true), (f, false), ..] => (Some(*r), Some(*f)),
        [(r, true)] => (Some(*r), None),
        _ => (None, None),
    };
    let fmt_ticks = |d: Time| format!("{} ticks + {} master ticks", d / tick, d % tick);
    let rise_after = rise.map(|r| r - cen);
    checks.push(check(
        "delayed pulse: rise arr + 1 − ccr ticks after CEN",
        rise_after.is_some_and(|d| d / tick == delay),
        format!(
            "settings psc {psc} arr {arr} ccr {ccr} (tick {:.2} ns); PA0 rose {} after the CEN write ({}); expected {delay} ticks ({:.3} µs) plus less than one kernel clock",
            tick as f64 * 1e9 / TICKS_PER_S as f64,
            rise_after.map_or("never".into(), fmt_ticks),
            fmt_us(rise_after.map(us)),
            us(delay * tick)
        ),
    ));
    let high = rise.zip(fall).map(|(r, f)| f - r);
    checks.push(check(
        "delayed pulse: high for ccr ticks, then low at the update event",
        high == Some(on * tick) && a.len() == 2,
        format!(
            "PA0 high for {} ({}), {} edges from CEN until the RF arm rose; expected exactly {on} ticks ({:.3} µs) and 2 edges",
            high.map_or("— (no whole pulse)".into(), fmt_ticks),
            fmt_us(high.map(us)),
            a.len(),
            us(on * tick)
        ),
    ));
    checks.push(check(
        "delayed pulse: IDT B (PB10) the same in standing drive",
        b == a,
        format!(
            "PB10 edges {:?} µs after CEN, PA0 {:?}",
            b.iter().map(|e| (us(e.0 - cen), e.1)).collect::<Vec<_>>(),
            a.iter().map(|e| (us(e.0 - cen), e.1)).collect::<Vec<_>>()
        ),
    ));
    let log_line = |part: &str| {
        o.log
            .iter()
            .find(|l| l.text.contains(part))
            .map(|l| l.text.clone())
    };
    let stopped = log_line("self-test: delayed pulse over");
    let refused = log_line("self-test: delayed triangle");
    checks.push(check(
        "delayed pulse: the counter stopped itself; a delayed triangle refused",
        stopped
            .as_deref()
            .is_some_and(|l| l.ends_with("counter stopped"))
            && refused
                .as_deref()
                .is_some_and(|l| l.contains("line Off, refused 1")),
        format!(
            "{}; {}",
            stopped.unwrap_or_else(|| "no `delayed pulse over` line".into()),
            refused.unwrap_or_else(|| "no `delayed triangle` line".into())
        ),
    ));
    let level = rise.map(|r| dac_at(&o.dac, r));
    let want_code = board.def().rf_level.table.code(1000);
    checks.push(check(
        "delayed pulse: the level latched at CEN, before the rise",
        level.is_some_and(|d| d.driven && d.code == want_code && d.at >= cen),
        match level {
            Some(d) => format!(
                "DAC code {} (driven {}) from {:.3} µs after CEN, the rise at {}; expected code {want_code} (1000 ‰) latched at or after CEN",
                d.code,
                d.driven,
                us(d.at.saturating_sub(cen)),
                fmt_us(rise_after.map(us))
            ),
            None => "no rise".into(),
        },
    ));
    Ok(checks)
}

/// Issue #35's dual interleaved acquisition (`saw_boards::NUCLEO_F446RE_DUAL`, the firmware's
/// `dual-adc` feature), on an image built with it (`DUAL_ADC=1 scripts/build-firmware.sh` leaves
/// firmware/target/nucleo-f446re-dual.elf): the ADC block's record of conversion starts shows
/// ADC1 and ADC2 alternating, ADC2 exactly the plan's delay after ADC1 (ADC_CCR.DELAY read back
/// too), 16 pairs per TIM3 trigger, the first at the trigger; 10 000 samples/s reach the core;
/// the position at rest at two places is the wiper's (the code's scale: 32 conversions halved);
/// the sensor-to-gate latency and the rail fault's and the open wiper's responses within the
/// limits `check` holds every image to.
pub fn dual_adc(board: BoardKind, elf: &Path) -> Result<Vec<Check>, String> {
    if board != BoardKind::F446 {
        return Err("dual-adc: only the NUCLEO-F446RE has a dual interleaved image".into());
    }
    const PAIRS_PER_TRIGGER: usize = 16;
    let mut out = Vec::new();
    let opts = Options::new(board, elf, 2.2);
    let (o, mut m) = run::run(&opts)?;
    // The plan the image was built with, from its `adc:` log line's conversions per sample:
    // `dual-adc` (32) or the experiment `dual-adc-128` (128).
    let conversions = o
        .log
        .iter()
        .find(|l| l.text.starts_with("adc: "))
        .and_then(|l| {
            let i = l.text.find(" Hz x")? + " Hz x".len();
            l.text[i..]
                .chars()
                .take_while(|c| c.is_ascii_digit())
                .collect::<String>()
                .parse::<u32>()
                .ok()
        });
    let def = match conversions {
        Some(128) => &saw_boards::NUCLEO_F446RE_DUAL128,
        _ => &saw_boards::NUCLEO_F446RE_DUAL,
    };
    let saw_boards::AdcMode::DualInterleaved { delay_cycles } = def.adc.mode else {
        return Err("NUCLEO_F446RE_DUAL is not dual interleaved".into());
    };
    let tps = def.adc.triggers_per_sample as usize;
    out.push(check(
        "dual: the image's plan",
        conversions == Some(def.adc.oversampling.conversions()),
        format!(
            "the adc log line says {conversions:?} conversions per sample; plan: {} conversions, {tps} trigger(s) per sample",
            def.adc.oversampling.conversions()
        ),
    ));
    out.push(check(
        "dual: runs to the end",
        o.stop.is_none(),
        match &o.stop {
            None => "2.2 s of board time without an unmodelled access, fault or lockup".to_string(),
            Some(s) => format!("stopped at {:.6} s: {s}", o.end as f64 / TICKS_PER_S as f64),
        },
    ));
    // ADCCLK = PCLK2 / 4 (the binding's ADCPRE), in master ticks.
    let adcclk_ticks = TICKS_PER_S * 4 / m.sim().clocks.pclk2_hz.max(1);
    let ccr = m.sim_mut().peek(0x4001_2304).unwrap_or(0);
    let (multi, dma_mode, delay_field) = (ccr & 0x1F, (ccr >> 14) & 0x3, (ccr >> 8) & 0xF);
    let starts = m.sim().adc_interleaved_starts();
    // Pairs: ADC1 then ADC2, strictly alternating.
    let alternating = !starts.is_empty()
        && starts
            .iter()
            .enumerate()
            .all(|(i, &(adc, _))| adc == if i % 2 == 0 { 1 } else { 2 });
    let seps: Vec<Time> = starts.chunks_exact(2).map(|p| p[1].1 - p[0].1).collect();
    let want = delay_cycles as u64 * adcclk_ticks;
    let bad_sep = seps.iter().position(|&s| s != want);
    // The first pair of each trigger starts at a TIM3 TRGO; 16 pairs per trigger.
    let pair_starts: Vec<Time> = starts.chunks_exact(2).map(|p| p[0].1).collect();
    let at_trigger: Vec<usize> = pair_starts
        .iter()
        .enumerate()
        .filter(|(_, t)| o.triggers.binary_search(t).is_ok())
        .map(|(i, _)| i)
        .collect();
    let per_trigger_ok = at_trigger.len() > 10
        && at_trigger
            .windows(2)
            .all(|w| w[1] - w[0] == PAIRS_PER_TRIGGER);
    let pair_period: Option<Time> = pair_starts
        .get(1)
        .zip(pair_starts.first())
        .map(|(b, a)| b - a);
    out.push(check(
        "dual: ADC2 starts the configured delay after ADC1",
        multi == 0b00111 && dma_mode == 0b10 && delay_field as u32 + 5 == delay_cycles
            && alternating && bad_sep.is_none() && seps.len() > 100,
        format!(
            "ADC_CCR MULTI {multi:#07b} (want 00111, dual interleaved), DMA mode {dma_mode} (want 2), DELAY {} cycles (plan {delay_cycles}); {} starts recorded, {}; ADC2 − ADC1 {}",
            delay_field + 5,
            starts.len(),
            if alternating { "ADC1, ADC2 alternating" } else { "NOT alternating ADC1, ADC2" },
            match bad_sep {
                None => format!("{:.3} µs = {delay_cycles} ADCCLK cycles in all {} pairs", us(want), seps.len()),
                Some(i) => format!("{:.3} µs in pair {i}, want {:.3} µs ({delay_cycles} cycles)", us(seps[i]), us(want)),
            }
        ),
    ));
    out.push(check(
        "dual: 16 pairs per trigger, the first at the TIM3 trigger",
        per_trigger_ok,
        format!(
            "{} pair starts at a TRGO among {}; pair period {}",
            at_trigger.len(),
            pair_starts.len(),
            pair_period.map_or("—".into(), |p| format!(
                "{:.3} µs ({} ADCCLK cycles)",
                us(p),
                p / adcclk_ticks.max(1)
            ))
        ),
    ));
    let tele = telemetry_samples(&o);
    let rate = tele
        .windows(2)
        .map(|w| (w[1].1 - w[0].1) as f64 / (w[1].0 - w[0].0))
        .next_back()
        .map(|r| r.round() as u64);
    out.push(check(
        "dual: samples reach the core at 10 kHz",
        rate == Some(def.sample_rate_hz as u64),
        format!(
            "{rate:?} samples/s between the telemetry lines at 1 s and 2 s; want {}",
            def.sample_rate_hz
        ),
    ));
    // From the trigger that starts a sample's conversions (the first of its `tps`).
    let lat = latency_per_sample(&o, tps);
    let worst = lat.last().copied();
    out.push(check(
        "dual: sensor-to-gate latency ≤ 100 µs",
        worst.is_some_and(|w| w <= 100.0),
        format!(
            "{} burst-timer updates: median {}, worst {}",
            lat.len(),
            fmt_us(lat.get(lat.len() / 2).copied()),
            fmt_us(worst)
        ),
    ));
    // The code's scale: at rest, the telemetry position is the wiper's.
    for at_um in [12_000.0, 47_000.0] {
        let mut opts = Options::new(board, elf, 1.1);
        opts.trajectory = host_sim::trajectory::Trajectory::Rest { at_um };
        let (o, _m) = run::run(&opts)?;
        let pos = o
            .log
            .iter()
            .filter(|l| l.text.starts_with("telemetry"))
            .find_map(|l| {
                let i = l.text.find("position_um: ")? + "position_um: ".len();
                l.text[i..]
                    .chars()
                    .take_while(|c| c.is_ascii_digit() || *c == '-')
                    .collect::<String>()
                    .parse::<f64>()
                    .ok()
            });
        out.push(check(
            &format!(
                "dual: position at rest at {:.0} mm is the wiper's",
                at_um / 1000.0
            ),
            pos.is_some_and(|p| (p - at_um).abs() <= 200.0),
            format!(
                "telemetry position {} µm at 1 s; the wiper at {at_um:.0} µm (limit ±200 µm)",
                pos.map_or("—".into(), |p| format!("{p:.0}"))
            ),
        ));
    }
    for (what, kind) in [
        ("open wiper", FaultKind::Open),
        ("wiper at the supply", FaultKind::Short),
    ] {
        out.extend(rail_fault_of(board, elf, kind)?.into_iter().map(|mut c| {
            c.name = format!("dual, {what}: {}", c.name);
            c
        }));
    }
    out.extend(fast_strokes(board, elf)?.into_iter().map(|mut c| {
        c.name = format!("dual: {}", c.name);
        c
    }));
    Ok(out)
}
