//! The 2D images (`TOUCH_2D=1 scripts/build-firmware.sh`, feature `touch-2d`, issue #36) on the
//! board model with the 4-wire overlay (`src/touch.rs`: host-sim's plates, contact and RC, in
//! continuous virtual time, fed the GPIO modes the firmware writes) and a finger script.
//!
//! What each check expects is worked out here from the core's plate schedule
//! (`saw_core::touch::plates::Schedule` on the default plates and each board's conversion time)
//! and the firmware's documented margins (`docs/touch.md`, "Firmware"), not read from the image.
//!
//! Needs `$SAW_FIRMWARE_DIR/<board>-2d.elf` (default `../firmware/target`).

use host_sim::touch::{Finger, Overlay, TouchModel};
use saw_board_model::board::{BoardKind, PIN_BURST_A};
use saw_board_model::periph::adc_g4::AdcG4;
use saw_board_model::periph::{Time, TICKS_PER_S};
use saw_board_model::run::{self, Options, Outcome, TouchScript};
use saw_board_model::touch::{Drive, Trace};
use saw_core::touch::plates::{AdcTiming, Phase, PlateRc, Schedule, Terminal};
use std::path::PathBuf;
use std::rc::Rc;

const BOARDS: [BoardKind; 2] = [BoardKind::F446, BoardKind::G474];
const US: Time = TICKS_PER_S / 1_000_000;
/// The firmware's margin after each phase's conversions (docs/touch.md, "Firmware").
const MARGIN_NS: u64 = 4_000;
/// The plate's touch area (scenes/2d-fig12.toml), mm.
const PLATE_MM: (f64, f64) = (95.0, 54.0);

fn elf(board: BoardKind) -> PathBuf {
    let dir = std::env::var("SAW_FIRMWARE_DIR")
        .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/../firmware/target").into());
    let p = PathBuf::from(dir).join(format!("{}-2d.elf", board.name()));
    assert!(
        p.exists(),
        "{} is missing: run TOUCH_2D=1 scripts/build-firmware.sh first",
        p.display()
    );
    p
}

fn run2d(board: BoardKind, secs: f64, finger: impl Fn(f64) -> Option<Finger> + 'static) -> Outcome {
    run2d_m(board, secs, finger).0
}

/// As `run2d`, with the machine (its peripherals' records) kept.
fn run2d_m(
    board: BoardKind,
    secs: f64,
    finger: impl Fn(f64) -> Option<Finger> + 'static,
) -> (Outcome, saw_board_model::machine::Machine) {
    let mut o = Options::new(board, &elf(board), secs);
    o.touch = Some(TouchScript {
        overlay: Overlay::default(),
        seed: 7,
        finger: Rc::new(finger),
    });
    let (out, m) = run::run(&o).unwrap();
    assert!(out.stop.is_none(), "{board:?}: {:?}", out.stop);
    (out, m)
}

fn at(mm: (f64, f64)) -> Option<Finger> {
    Some(Finger {
        x: mm.0 / PLATE_MM.0,
        y: mm.1 / PLATE_MM.1,
        force_n: 1.0,
    })
}

/// Lift-off time of the script, s.
const LIFT_S: f64 = 0.060;
/// The stroke: from (2, 27) mm at 0.080 s along +x at 100 mm/s: it crosses window 0's outline
/// at x = 5 mm (0.110 s) and 30 mm (0.360 s), window 1's at 35 mm (0.410 s).
const STROKE_S: f64 = 0.080;
const RUN_S: f64 = 0.45;

/// Pressed on the background (47.5, 51.6) mm — the 1 kHz constant texture — from 10 ms, lifted
/// at 60 ms, then the stroke.
fn script(t: f64) -> Option<Finger> {
    if t < 0.010 {
        None
    } else if t < LIFT_S {
        at((47.5, 51.6))
    } else if t < STROKE_S {
        None
    } else {
        at((2.0 + 100.0 * (t - STROKE_S), 27.0))
    }
}

/// The method's phase of a drive pattern (Z1 for Z1 and Z2), or None.
fn phase_of(d: &[Drive; 4]) -> Option<Phase> {
    use Drive::*;
    match d {
        [High, Low, Float, Float] => Some(Phase::X),
        [Float, Float, High, Low] => Some(Phase::Y),
        [Float, Low, High, Float] => Some(Phase::Z1),
        _ => None,
    }
}

/// The drive's switches: the changes one interrupt makes (within 1 µs of each other) as one,
/// at its first write, with the pattern it leaves.
fn switches(tr: &Trace) -> Vec<(Time, [Drive; 4])> {
    let mut out: Vec<(Time, [Drive; 4])> = Vec::new();
    for c in &tr.drives {
        match out.last_mut() {
            Some((t0, d)) if c.at - *t0 <= US => *d = c.drive,
            _ => out.push((c.at, c.drive)),
        }
    }
    out
}

/// The switches from the first X phase on: a frame's three windows (X, Y, Z) at a time.
fn switches_from_x(tr: &Trace) -> Vec<(Time, [Drive; 4])> {
    let mut sw = switches(tr);
    let first_x = sw
        .iter()
        .position(|(_, p)| phase_of(p) == Some(Phase::X))
        .unwrap();
    sw.drain(..first_x);
    sw
}

/// The phases whose conversions were not the design's, from the first X switch on: (window
/// index, its start µs, conversions, designed conversions). A cut phase (an interrupt held off
/// past the margin) or a mixed one shows here.
fn off_design_windows(tr: &Trace, d: &Design) -> Vec<(usize, f64, usize, usize)> {
    let sw = &switches_from_x(tr);
    let mut out = Vec::new();
    for (i, w) in sw.windows(2).enumerate() {
        let n = tr
            .conversions
            .iter()
            .filter(|c| c.at > w[0].0 && c.at < w[1].0)
            .count();
        let want = match i % 3 {
            0 => d.ranks[0],
            1 => d.ranks[1],
            _ => d.ranks[2] + d.ranks[3],
        };
        if n != want {
            out.push((i, ns(w[0].0) / 1e3, n, want));
        }
    }
    out
}

/// The designed frame: the switch times of Y and Z from X's, the settling before each trigger
/// and the frame period, ns: each phase's settling and conversions from the core's schedule,
/// then the margin; the frame rounded up to whole µs.
struct Design {
    sched: Schedule,
    /// Y's and Z1's switch after X's, ns.
    y_ns: u64,
    z_ns: u64,
    frame_ns: u64,
    /// One conversion's sampling time, ticks.
    sampling: Time,
    /// Conversions of each slot (X, Y, Z1, Z2): the discarded ones first, then the summed.
    ranks: [usize; 4],
    /// Conversions discarded at the start of each slot.
    discard: usize,
}

fn design(board: BoardKind) -> Design {
    let def = board.def();
    // The board's acquisition as saw-boards states it.
    let t = saw_boards::touch::touch_adc(def);
    let adc = AdcTiming {
        conversion_ns: t.conversion_ns,
        conversions_position: t.conversions_position,
        conversions_pressure: t.conversions_pressure,
        discard: t.discard,
    };
    let sched = Schedule::new(&PlateRc::DEFAULT, &adc).unwrap();
    let s = &sched.slots;
    let y_ns = s[0].settle_ns + s[0].convert_ns + MARGIN_NS;
    let z_ns = y_ns + s[1].settle_ns + s[1].convert_ns + MARGIN_NS;
    let frame_ns = (sched.frame_ns() + 4 * MARGIN_NS).div_ceil(1_000) * 1_000;
    let sampling = def.adc.sample_half_cycles as u64 * TICKS_PER_S / (2 * def.adc.clk_hz as u64);
    let ranks = [true, true, false, false].map(|p| t.ranks(p) as usize);
    Design {
        sched,
        y_ns,
        z_ns,
        frame_ns,
        sampling,
        ranks,
        discard: t.discard as usize,
    }
}

fn ns(t: Time) -> f64 {
    t as f64 * 1e9 / TICKS_PER_S as f64
}

/// Plate switching at its designed times, and every conversion settled: after the first
/// switch, the drive runs X, Y, Z, X, … (no other pattern lasts; two plates are never driven
/// at once but through the contact in Z); every X switch one frame after the last, and Y and Z
/// at their designed offsets from it, within 1 µs (the interrupt's entry; never before); each
/// phase converts its sensed terminal once per rank of its sequence (saw-boards' `touch_adc`:
/// 1 discarded + 15 a position phase; Z: 1 + 4 on X+ for Z1, then 1 + 4 on Y− for Z2), the first
/// sampling no earlier than its settling after the switch and the last held before the next
/// switch; every pressed phase's node at its first sampling (the hold capacitor's share taken
/// out) within ½ LSB of its settled voltage; and the hold capacitor's charge sharing (`src/touch.rs`): the
/// first conversion of each channel carries it, and the mean of the summed ones — what the
/// phase's code is — stays within ½ LSB of settled on the position phases.
#[test]
fn plate_switching_at_its_designed_times() {
    for board in BOARDS {
        let d = design(board);
        let (o, m) = run2d_m(board, 0.06, script);
        if let Some(adc) = m
            .sim()
            .periphs
            .iter()
            .find_map(|p| p.p.as_any().downcast_ref::<AdcG4>())
        {
            // Pre-flash item 3 (docs/touch.md): ADSTART/ADSTP written with ADC_CR's other rs
            // bits 0, and the ES0430 dummy conversion: no late result reaches memory.
            eprintln!(
                "{board:?}: ADC_CR writes with ADEN written back: {}; late (ES0430) results in memory: {}",
                adc.aden_written_back.len(),
                adc.late_results_delivered.len()
            );
            assert!(
                adc.aden_written_back.is_empty(),
                "{board:?}: ADEN written back at {:?}",
                adc.aden_written_back
            );
            assert!(
                adc.late_results_delivered.is_empty(),
                "{board:?}: late results at {:?}",
                adc.late_results_delivered
            );
        }
        let tr = o.touch.as_ref().unwrap();
        let sw = switches(tr);
        assert!(sw.len() > 100, "{board:?}: {} switches", sw.len());
        for (t, p) in &sw {
            let driven_x = p[0] != Drive::Float || p[1] != Drive::Float;
            let driven_y = p[2] != Drive::Float || p[3] != Drive::Float;
            assert!(
                !(driven_x && driven_y) || phase_of(p) == Some(Phase::Z1),
                "{board:?}: both plates driven at {:.3} µs: {p:?}",
                ns(*t) / 1e3
            );
        }
        let first_x = sw
            .iter()
            .position(|(_, p)| phase_of(p) == Some(Phase::X))
            .unwrap();
        let sw = &sw[first_x..];
        let want = [Phase::X, Phase::Y, Phase::Z1];
        for (k, (t, p)) in sw.iter().enumerate() {
            assert_eq!(
                phase_of(p),
                Some(want[k % 3]),
                "{board:?}: switch {k} at {:.3} µs: {p:?}",
                ns(*t) / 1e3
            );
        }
        // The frame grid: frame k's X switch is designed at origin + k · frame, its Y and Z
        // switches at their offsets from it; the origin is the earliest X switch against the
        // grid (the interrupt's least latency), so every switch is at or after its design.
        let frames = sw.len() / 3;
        let origin = (0..frames)
            .map(|k| ns(sw[3 * k].0) - (k as u64 * d.frame_ns) as f64)
            .fold(f64::MAX, f64::min);
        let (mut worst_late, mut worst_early) = (0f64, 0f64);
        for (k, (t, _)) in sw.iter().enumerate() {
            let base = origin + ((k / 3) as u64 * d.frame_ns) as f64;
            let designed = base + [0, d.y_ns, d.z_ns][k % 3] as f64;
            let off = ns(*t) - designed;
            if off > MARGIN_NS as f64 && worst_late <= MARGIN_NS as f64 {
                eprintln!(
                    "{board:?}: switch {k} ({:?}) at {:.3} µs is {off:.0} ns late",
                    want[k % 3],
                    ns(*t) / 1e3
                );
            }
            worst_late = worst_late.max(off);
            worst_early = worst_early.min(off);
        }
        assert!(
            worst_late <= MARGIN_NS as f64 && worst_early >= -20.0,
            "{board:?}: switches {worst_early:.0} to +{worst_late:.0} ns off the design"
        );
        // Conversions by phase: between one switch and the next.
        let mut model = TouchModel::new(
            Overlay {
                noise_lsb: 0.0,
                ..Overlay::default()
            },
            0,
        );
        let (mut worst_lsb, mut min_settle_ns, mut min_gap_ns) = (0f64, f64::MAX, f64::MAX);
        let mut pressed = 0;
        // Charge sharing: the worst share on a discarded conversion, and the worst mean error of
        // a slot's summed conversions (the code) and of all its conversions (without the
        // discard), LSB; position and pressure slots apart.
        let (mut worst_first, mut sum_pos, mut all_pos, mut sum_z, mut all_z) =
            (0f64, 0f64, 0f64, 0f64, 0f64);
        for (k, w) in sw.windows(2).enumerate() {
            let (t0, t1) = (w[0].0, w[1].0);
            let phase = want[k % 3];
            let convs: Vec<_> = tr
                .conversions
                .iter()
                .filter(|c| c.at > t0 && c.at < t1)
                .collect();
            let (sensed, n): (&[Terminal], usize) = match phase {
                Phase::X => (&[Terminal::YPlus], d.ranks[0]),
                Phase::Y => (&[Terminal::XPlus], d.ranks[1]),
                _ => (
                    &[Terminal::XPlus, Terminal::YMinus],
                    d.ranks[2] + d.ranks[3],
                ),
            };
            assert_eq!(
                convs.len(),
                n,
                "{board:?}: {phase:?} phase at {:.1} µs",
                ns(t0) / 1e3
            );
            for (i, c) in convs.iter().enumerate() {
                let want_t = if sensed.len() == 2 && i >= d.ranks[2] {
                    sensed[1]
                } else {
                    sensed[0]
                };
                assert_eq!(c.terminal, want_t, "{board:?}: {phase:?} conversion {i}");
            }
            let settle = d.sched.slots[k % 3].settle_ns as f64;
            let first = ns(convs[0].at - d.sampling - t0);
            min_settle_ns = min_settle_ns.min(first - settle);
            min_gap_ns = min_gap_ns.min(ns(t1 - convs[n - 1].at));
            // Settled: the finger's node at its DC value (pressed frames only).
            let t_s = convs[0].at as f64 / TICKS_PER_S as f64;
            if let Some(f) = script(t_s)
                .filter(|_| script(ns(t1) / 1e9).is_some() && script(ns(t0) / 1e9).is_some())
            {
                let targets = model.targets(phase, Some(&f));
                let err = |c: &saw_board_model::touch::Conversion| {
                    let idx = match c.terminal {
                        Terminal::XPlus => 0,
                        Terminal::XMinus => 1,
                        Terminal::YPlus => 2,
                        Terminal::YMinus => 3,
                    };
                    (c.v - targets[idx].0) * 4096.0
                };
                pressed += convs.len();
                // Each slot's run of conversions: Z holds Z1's then Z2's.
                let runs: Vec<&[&saw_board_model::touch::Conversion]> = if sensed.len() == 2 {
                    vec![&convs[..d.ranks[2]], &convs[d.ranks[2]..]]
                } else {
                    vec![&convs[..]]
                };
                for run in runs {
                    // The plates' settling: the node at the run's first hold, its own share
                    // taken out (later conversions also carry the earlier ones' dips).
                    worst_lsb = worst_lsb.max((err(run[0]) - run[0].shared * 4096.0).abs());
                    let mean = |cs: &[&saw_board_model::touch::Conversion]| {
                        (cs.iter().map(|c| err(c)).sum::<f64>() / cs.len() as f64).abs()
                    };
                    for c in &run[..d.discard] {
                        worst_first = worst_first.max((c.shared * 4096.0).abs());
                    }
                    let (summed, all) = (mean(&run[d.discard..]), mean(run));
                    if phase == Phase::Z1 {
                        (sum_z, all_z) = (sum_z.max(summed), all_z.max(all));
                    } else {
                        (sum_pos, all_pos) = (sum_pos.max(summed), all_pos.max(all));
                    }
                }
            }
            let _ = &mut model;
        }
        eprintln!(
            "{board:?}: {frames} frames of {} µs; switches {worst_early:.0}..+{worst_late:.0} ns off the design; first sampling {min_settle_ns:.0} ns after the settling; last sample {min_gap_ns:.0} ns before the next switch; {pressed} pressed conversions; each channel's first sampling (its share out) within {worst_lsb:.4} LSB of settled",
            d.frame_ns / 1000
        );
        eprintln!(
            "{board:?}: hold capacitor: the discarded first conversions carry up to {worst_first:.2} LSB; mean error of a slot's summed conversions (its code) at most {sum_pos:.3} LSB position, {sum_z:.3} LSB pressure; with the first conversion summed too {all_pos:.3} / {all_z:.3} LSB"
        );
        assert!(
            worst_first >= 1.0,
            "{board:?}: the first conversions share only {worst_first:.2} LSB: nothing for the discard to take"
        );
        assert!(
            sum_pos <= 0.5,
            "{board:?}: a position code is {sum_pos:.3} LSB a conversion from settled"
        );
        assert!(
            min_settle_ns >= 0.0,
            "{board:?}: a conversion sampled {min_settle_ns:.0} ns before its phase settled"
        );
        assert!(
            min_gap_ns > 0.0,
            "{board:?}: a phase's last sample after the next switch"
        );
        assert!(pressed > 1000, "{board:?}: {pressed} pressed conversions");
        assert!(
            worst_lsb <= 0.5,
            "{board:?}: a pressed conversion {worst_lsb:.3} LSB from settled"
        );
        assert!(
            tr.odd.is_empty(),
            "{board:?}: odd drives {:?}",
            &tr.odd[..tr.odd.len().min(4)]
        );
        let _ = PIN_BURST_A;
    }
}

/// Frame deliveries: the firmware hands frame k to the control task in the interrupt that
/// switches frame k + 1's X phase (after the pins). Returns (X switch, Z switch) per frame.
fn frames(tr: &Trace) -> Vec<(Time, Time)> {
    let sw = switches(tr);
    let mut out = Vec::new();
    for w in sw.windows(3) {
        if phase_of(&w[0].1) == Some(Phase::X) && phase_of(&w[2].1) == Some(Phase::Z1) {
            out.push((w[0].0, w[2].0));
        }
    }
    out
}

/// Writes to TIM2 (the burst timer; `Sim::watch` keeps them).
fn tim2(o: &Outcome) -> Vec<(Time, u32, u32)> {
    o.writes
        .iter()
        .filter(|w| w.addr >= 0x4000_0000 && w.addr < 0x4000_0400)
        .map(|w| (w.at, w.addr & 0x3FF, w.value))
        .collect()
}

/// Lift-off: carrier off within one sample. The sample is the frame: the first frame whose Z
/// phases are read wholly after the lift reads `Lifted`, and the carrier must be off (the
/// burst gate's force-inactive write on TIM2, PA0 low and no rising edge while the finger is
/// up) by that frame's hand-over plus 100 µs of sample path. Pressed on the 1 kHz background
/// from 10 ms (bursting before the lift: checked), lifted at 60 ms, pressed again at 80 ms.
#[test]
fn lift_off_turns_the_carrier_off_within_one_frame() {
    for board in BOARDS {
        let o = run2d(board, 0.085, script);
        let tr = o.touch.as_ref().unwrap();
        let lift = (LIFT_S * TICKS_PER_S as f64) as Time;
        let back = (STROKE_S * TICKS_PER_S as f64) as Time;
        let fr = frames(tr);
        // The first frame whose Z switch is after the lift, and its hand-over.
        let k = fr.iter().position(|(_, z)| *z > lift).unwrap();
        let handover = fr[k + 1].0;
        let deadline = handover + 100 * US;
        let a = &o.pins[PIN_BURST_A];
        let rises_before = a
            .iter()
            .filter(|e| e.high && e.at > lift - 20_000 * US && e.at < lift)
            .count();
        assert!(
            rises_before >= 10,
            "{board:?}: only {rises_before} bursts in the 20 ms before the lift"
        );
        let off = tim2(&o)
            .into_iter()
            .find(|(t, off, v)| *t > lift && *off == 0x18 && (v >> 4) & 7 == 0b100)
            .map(|(t, _, _)| t)
            .expect("a force-inactive write after the lift");
        let late_rise = a.iter().find(|e| e.high && e.at > deadline && e.at < back);
        let low_at = a
            .iter()
            .rev()
            .find(|e| e.at <= deadline)
            .is_none_or(|e| !e.high);
        eprintln!(
            "{board:?}: lift at {:.1} µs, frame's Z switch +{:.1} µs, hand-over +{:.1} µs, carrier forced off +{:.1} µs (bound +{:.1} µs: hand-over + 100 µs)",
            ns(lift) / 1e3,
            ns(fr[k].1 - lift) / 1e3,
            ns(handover - lift) / 1e3,
            ns(off - lift) / 1e3,
            ns(deadline - lift) / 1e3
        );
        assert!(
            off <= deadline,
            "{board:?}: carrier forced off {:.1} µs after the hand-over",
            ns(off - handover) / 1e3
        );
        assert!(low_at, "{board:?}: PA0 high at the deadline");
        assert!(
            late_rise.is_none(),
            "{board:?}: PA0 rose at {:?} with the finger up",
            late_rise
        );
    }
}

/// The whole script: landing, lift, the stroke across three outlines.
fn stroke(board: BoardKind) -> Outcome {
    run2d(board, RUN_S, script)
}

/// Sensor-to-gate latency ≤ 100 µs, both ways: from a frame's last sample (Z2's last
/// conversion, the end of its sampling: the reading is complete), and from the start of Z2's
/// first sampling (the 1D check's measure, trigger to gate, applied to the frame's last phase),
/// to the last burst-timer write that acts on that frame (every TIM2 write between its
/// hand-over and the next), over landing, lift-off, the stroke's window switches and edge
/// pulses. And the edges: each of the stroke's three outline crossings fires one one-pulse
/// (TIM2 CR1 with OPM and CEN), its start within 15 ms before the finger reaches the outline
/// (the lead: the pulse's peak on the outline, docs/plane.md) and none elsewhere.
#[test]
fn sensor_to_gate_latency_and_edge_pulses() {
    for board in BOARDS {
        let d = design(board);
        let o = stroke(board);
        let tr = o.touch.as_ref().unwrap();
        let fr = frames(tr);
        let w = tim2(&o);
        // (from the frame's last sample, from Z2's first sampling), µs
        let mut lat: Vec<(f64, f64)> = Vec::new();
        for k in 0..fr.len().saturating_sub(2) {
            let (h0, h1) = (fr[k + 1].0, fr[k + 2].0);
            let Some(last) = w
                .iter()
                .filter(|(t, _, _)| *t >= h0 && *t < h1)
                .map(|x| x.0)
                .last()
            else {
                continue;
            };
            let z: Vec<_> = tr
                .conversions
                .iter()
                .filter(|c| c.at > fr[k].1 && c.at < h0)
                .collect();
            assert_eq!(
                z.len(),
                d.ranks[2] + d.ranks[3],
                "{board:?}: frame {k}'s Z conversions"
            );
            // Z2's first sampling (its discarded conversion: the phase's start, as the 1D
            // check counts from the trigger) and its last hold.
            let z2_start = z[d.ranks[2]].at - d.sampling;
            let done = z[z.len() - 1].at;
            lat.push((ns(last - done) / 1e3, ns(last - z2_start) / 1e3));
            if std::env::var("TOUCH2D_TRACE").is_ok() {
                let n = w.iter().filter(|(t, _, _)| *t >= h0 && *t < h1).count();
                eprintln!(
                    "  frame done at {:.1} µs: {n} TIM2 writes, hand-over +{:.1}, last +{:.1} µs",
                    ns(done) / 1e3,
                    ns(h0 - done) / 1e3,
                    ns(last - done) / 1e3
                );
            }
        }
        let stats = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            (v[v.len() / 2], v[v.len() - 1])
        };
        let (med, worst) = stats(lat.iter().map(|l| l.0).collect());
        let (med_z2, worst_z2) = stats(lat.iter().map(|l| l.1).collect());
        eprintln!(
            "{board:?}: sensor-to-gate latency over {} frames with gate writes: from the frame's last sample median {med:.1} µs, worst {worst:.1} µs; from Z2's first sampling median {med_z2:.1} µs, worst {worst_z2:.1} µs",
            lat.len(),
        );
        assert!(
            lat.len() >= 10,
            "{board:?}: {} frames wrote the gate",
            lat.len()
        );
        assert!(worst <= 100.0, "{board:?}: worst latency {worst:.1} µs");
        assert!(
            worst_z2 <= 100.0,
            "{board:?}: worst latency from Z2's first sampling {worst_z2:.1} µs"
        );
        // Edge pulses.
        let pulses: Vec<Time> = w
            .iter()
            .filter(|(_, off, v)| *off == 0 && v & 0b1001 == 0b1001)
            .map(|x| x.0)
            .collect();
        let x_at = |t: Time| 2.0 + 100.0 * (t as f64 / TICKS_PER_S as f64 - STROKE_S);
        eprintln!(
            "{board:?}: one-pulses at x = {:?} mm",
            pulses
                .iter()
                .map(|&t| (x_at(t) * 100.0).round() / 100.0)
                .collect::<Vec<_>>()
        );
        assert_eq!(pulses.len(), 3, "{board:?}: one-pulses {pulses:?}");
        for (p, outline) in pulses.iter().zip([5.0, 30.0, 35.0]) {
            let before_mm = outline - x_at(*p);
            assert!(
                (0.0..=1.5).contains(&before_mm),
                "{board:?}: the pulse for x = {outline} mm starts {before_mm:.2} mm before it"
            );
        }
    }
}

/// Stack: the deepest stack over a run of the image with the largest 2D scene
/// (`TOUCH_2D=largest scripts/build-firmware.sh`: board-model/scenes/2d-largest.toml, 8 windows
/// of 16 vertices, every texture kind, 32 outline edges) keeps ≥ 16 KiB of headroom below it
/// (the region flip-link leaves the stack, painted at reset; docs/stack.md). The finger lands,
/// strokes through the four windows of each row at 200 mm/s (crossing both outlined windows'
/// edges), lifts between the rows.
#[test]
fn largest_scene_keeps_16_kib_of_stack_headroom() {
    for board in BOARDS {
        let dir = std::env::var("SAW_FIRMWARE_DIR")
            .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/../firmware/target").into());
        let elf = PathBuf::from(dir).join(format!("{}-2d-largest.elf", board.name()));
        assert!(
            elf.exists(),
            "{} is missing: run TOUCH_2D=largest scripts/build-firmware.sh",
            elf.display()
        );
        let mut o = Options::new(board, &elf, 1.05);
        o.touch = Some(TouchScript {
            overlay: Overlay::default(),
            seed: 3,
            finger: Rc::new(|t: f64| {
                let row = |t0: f64, y: f64| at((1.0 + 200.0 * (t - t0), y));
                if (0.01..0.48).contains(&t) {
                    row(0.01, 14.0)
                } else if (0.52..1.0).contains(&t) {
                    row(0.52, 40.0)
                } else {
                    None
                }
            }),
        });
        let (out, _m) = run::run(&o).unwrap();
        assert!(out.stop.is_none(), "{board:?}: {:?}", out.stop);
        let telemetry = out
            .log
            .iter()
            .rev()
            .find(|l| l.text.starts_with("telemetry2d"))
            .map(|l| l.text.clone());
        let pulses = tim2(&out)
            .iter()
            .filter(|(_, off, v)| *off == 0 && v & 0b1001 == 0b1001)
            .count();
        let s = out.stack.expect("the image's stack region");
        eprintln!(
            "{board:?}: deepest stack {} B of {} B reserved, headroom {} B; {pulses} one-pulses; {}",
            s.deepest(),
            s.region.reserved(),
            s.headroom(),
            telemetry.unwrap_or_default()
        );
        assert!(
            pulses >= 4,
            "{board:?}: {pulses} edge pulses: the outlines were not crossed"
        );
        assert!(
            s.headroom() >= 16 * 1024,
            "{board:?}: stack headroom {} B < 16 KiB",
            s.headroom()
        );
    }
}

/// The 2D closed loop against host-sim: the stroke (from (2, 27) mm along +x at 100 mm/s over
/// scenes/2d-fig12.toml) run by host-sim's 2D loop (`host_sim::sim2d::run`: the same overlay
/// model read frame by frame at the core's schedule, the same TouchSensor calibration points,
/// Controller2d, a timer model) and by the board: the edge pulses fire at the same finger
/// positions (within 0.1 mm: the frames differ by the firmware's margins, 8–9 µs, 1 µm of travel
/// at this speed) and the burst line rises as often between them (within 2: where a stretch
/// starts and ends differs by up to a frame).
#[test]
fn the_2d_closed_loop_matches_host_sim() {
    use host_sim::sim2d::{self, Params2d};
    use host_sim::trajectory2d::PointUm;
    use host_sim::trajectory2d::Trajectory2d;
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/2d-fig12.toml"
    ))
    .unwrap();
    for board in BOARDS {
        let def = board.def();
        let frame_us = sim2d::board_frame_period_us(def).unwrap();
        let timer = saw_core::burst::BurstTimer {
            clock_hz: def.burst_timer_clk_hz,
            counter_bits: def.burst_timer_bits,
            max_burst_hz: def.max_burst_hz,
        };
        let config =
            saw_core::scene_file::load_2d_for_board("2d-fig12.toml", &text, timer, frame_us)
                .unwrap();
        let dur = RUN_S - STROKE_S;
        let traj = Trajectory2d::line(
            PointUm::new(2_000.0, 27_000.0),
            PointUm::new((2.0 + 100.0 * dur) * 1_000.0, 27_000.0),
            100_000.0,
        )
        .unwrap();
        let host = sim2d::run(&Params2d::new(def, traj, dur, config)).unwrap();
        let o = run2d(board, RUN_S, script);
        let w = tim2(&o);
        let x_at = |t_s: f64| 2.0 + 100.0 * (t_s - STROKE_S);
        let board_pulses: Vec<f64> = w
            .iter()
            .filter(|(_, off, v)| *off == 0 && v & 0b1001 == 0b1001)
            .map(|x| x_at(x.0 as f64 / TICKS_PER_S as f64))
            .collect();
        let host_pulses: Vec<f64> = host.edge_pulses.iter().map(|e| e.x_mm).collect();
        // Rising edges of the line in each stretch between pulses (and before the first, after
        // the last), board (PA0) and host (its timer model's line).
        let bounds: Vec<f64> = std::iter::once(0.0)
            .chain(host_pulses.iter().map(|x| (x - 2.0) / 100.0))
            .chain([dur])
            .collect();
        let board_rises: Vec<usize> = bounds
            .windows(2)
            .map(|b| {
                o.pins[PIN_BURST_A]
                    .iter()
                    .filter(|e| {
                        e.high && {
                            let t = e.at as f64 / TICKS_PER_S as f64 - STROKE_S;
                            t >= b[0] && t < b[1]
                        }
                    })
                    .count()
            })
            .collect();
        let host_rises: Vec<usize> = bounds
            .windows(2)
            .map(|b| {
                host.line
                    .windows(2)
                    .filter(|l| !l[0].1 && l[1].1 && l[1].0 >= b[0] && l[1].0 < b[1])
                    .count()
            })
            .collect();
        eprintln!(
            "{board:?}: edge pulses at x = board {board_pulses:.2?}, host-sim {host_pulses:.2?} mm; bursts per stretch board {board_rises:?}, host-sim {host_rises:?}"
        );
        assert_eq!(
            board_pulses.len(),
            host_pulses.len(),
            "{board:?}: edge pulses"
        );
        for (b, h) in board_pulses.iter().zip(&host_pulses) {
            assert!(
                (b - h).abs() <= 0.1,
                "{board:?}: pulse at {b:.2} mm on the board, {h:.2} in host-sim"
            );
        }
        for (b, h) in board_rises.iter().zip(&host_rises) {
            assert!(
                b.abs_diff(*h) <= 2,
                "{board:?}: bursts per stretch {board_rises:?} vs {host_rises:?}"
            );
        }
    }
}

/// Landing at any point of a frame (20 landing times 17.3 µs apart, a 1 N step on the 1 kHz
/// background): the carrier never starts before the recovery run, 16 pressed, fault-free frames
/// (`RECOVERY_SAMPLES`) — at least 15 whole frames after the landing (the first pressed frame may
/// have begun before it, its X phase still settling when the finger came: seen at 15.92) — and
/// it does start. No landing logs a touch fault: a landing between a frame's position phases and
/// its Z pair reads the floating plate's stale charge as a rail, and the core's `TouchSensor`
/// takes that frame for no finger yet (docs/touch.md, "Landing inside a frame"). Before it did,
/// 10 of 20 landings on the F446 and 8 of 20 on the G474 logged `touch fault Rail(X RailHigh)`.
#[test]
fn a_landing_anywhere_in_a_frame_waits_for_the_recovery_run() {
    for board in BOARDS {
        let d = design(board);
        let (mut faulted, n, mut min_frames) = (0, 20, f64::MAX);
        for i in 0..n {
            let land = 0.010 + i as f64 * 17.3e-6;
            let mut o = Options::new(board, &elf(board), 0.025);
            o.touch = Some(TouchScript {
                overlay: Overlay::default(),
                seed: i,
                finger: Rc::new(move |t| (t >= land).then(|| at((47.5, 51.6))).flatten()),
            });
            let (out, _m) = run::run(&o).unwrap();
            assert!(out.stop.is_none(), "{board:?}: {:?}", out.stop);
            if out.log.iter().any(|l| l.text.contains("touch fault")) {
                faulted += 1;
            }
            let land_t = (land * TICKS_PER_S as f64) as Time;
            let first = out.pins[PIN_BURST_A]
                .iter()
                .find(|e| e.high && e.at > land_t)
                .map(|e| e.at)
                .unwrap_or_else(|| panic!("{board:?}: no burst after the landing at {land} s"));
            let frames = ns(first - land_t) / d.frame_ns as f64;
            min_frames = min_frames.min(frames);
            assert!(
                frames >= 15.0,
                "{board:?}: the carrier started {frames:.2} frames after the landing"
            );
        }
        eprintln!("{board:?}: {faulted} of {n} landings read a rail fault before the touch-down; the carrier started at least {min_frames:.2} frames after a landing");
        assert_eq!(
            faulted, 0,
            "{board:?}: {faulted} of {n} landings logged a touch fault"
        );
    }
}

/// The number after `key` in a log line (`telemetry2d frames 123 late 0 mixed 1 …`).
fn field(line: &str, key: &str) -> Option<u64> {
    let mut words = line.split_whitespace();
    words.find(|w| *w == key)?;
    words.next()?.parse().ok()
}

/// Pre-flash item 1 (docs/touch.md): a phase whose conversions run past the next switch is
/// dropped and counted, never delivered. The core is held (interrupts off, as defmt-rtt's
/// critical section holds them) for the margin + 10 µs from 1 µs before a Y phase's
/// conversion start at ~0.5 s, so that start comes ~13 µs late and the phase's last
/// conversions fall after Z1's switch. Expected from the trace, not the image: the frames in
/// which some window between two switches holds a different number of conversions than its
/// sequence's ranks (the mixed ones: the held frame among them); the telemetry's `mixed` must
/// count at least the held one and no more than the trace shows, `incomplete` 0, no touch fault logged, and the carrier runs on as before (the
/// controller only misses a frame): PA0 keeps bursting at the background's 1 kHz, no
/// force-inactive write on TIM2 in the 5 ms after the hold.
#[test]
fn a_phase_converting_across_the_next_switch_is_dropped_and_counted() {
    let pressed = |t: f64| (t >= 0.010).then(|| at((47.5, 51.6))).flatten();
    for board in BOARDS {
        let d = design(board);
        // Where the frames fall (virtual time is deterministic: the held run is the same up to
        // the hold).
        let probe = run2d(board, 0.52, pressed);
        let sw = switches(probe.touch.as_ref().unwrap());
        let half = (0.5 * TICKS_PER_S as f64) as Time;
        let k = sw
            .iter()
            .position(|(t, p)| *t > half && phase_of(p) == Some(Phase::Y))
            .expect("a Y switch after 0.5 s");
        let y_start = sw[k].0 + d.sched.slots[1].settle_ns * TICKS_PER_S / 1_000_000_000;
        let hold_from = y_start - US;
        let hold_us = (MARGIN_NS / 1_000 + 10) as f64;
        let mut o = Options::new(board, &elf(board), 1.2);
        o.touch = Some(TouchScript {
            overlay: Overlay::default(),
            seed: 7,
            finger: Rc::new(pressed),
        });
        o.hold_core = vec![(hold_from as f64 / TICKS_PER_S as f64, hold_us)];
        let (out, _m) = run::run(&o).unwrap();
        assert!(out.stop.is_none(), "{board:?}: {:?}", out.stop);
        let tr = out.touch.as_ref().unwrap();
        // Mixed frames in the trace: a window's conversions ≠ its ranks (Z's window holds Z1's
        // and Z2's).
        let mut mixed_frames = std::collections::BTreeSet::new();
        for (i, at_us, n, want) in off_design_windows(tr, &d) {
            mixed_frames.insert(i / 3);
            if std::env::var("TOUCH2D_TRACE").is_ok() {
                eprintln!("  window {i} at {at_us:.1} µs: {n} conversions, {want} designed");
            }
        }
        let telemetry = out
            .log
            .iter()
            .rev()
            .find(|l| l.text.starts_with("telemetry2d"))
            .map(|l| l.text.clone())
            .expect("a telemetry2d line");
        let faults = out
            .log
            .iter()
            .filter(|l| l.text.contains("touch fault"))
            .count();
        let hold_end = hold_from + (hold_us * US as f64) as Time;
        let after = hold_end + 5_000 * US;
        let rises = out.pins[PIN_BURST_A]
            .iter()
            .filter(|e| e.high && e.at > hold_end && e.at < after)
            .count();
        let offs = tim2(&out)
            .into_iter()
            .filter(|(t, off, v)| {
                *t > hold_from && *t < after && *off == 0x18 && (v >> 4) & 7 == 0b100
            })
            .count();
        eprintln!(
            "{board:?}: held {hold_us} µs from {:.1} µs (Y start {:.1} µs): {} frame(s) mixed in the trace; {telemetry}; {faults} touch faults; {rises} bursts and {offs} forced-off writes in the 5 ms after",
            ns(hold_from) / 1e3,
            ns(y_start) / 1e3,
            mixed_frames.len()
        );
        assert!(
            !mixed_frames.is_empty(),
            "{board:?}: the hold did not push a phase across a switch"
        );
        // The held frame: a window starting within a frame of the hold.
        let frame_ticks = d.frame_ns * TICKS_PER_S / 1_000_000_000;
        let held = sw
            .windows(2)
            .enumerate()
            .filter(|(i, w)| {
                mixed_frames.contains(&(i / 3))
                    && w[0].0 + frame_ticks > hold_from
                    && w[0].0 < hold_end + frame_ticks
            })
            .map(|(i, _)| i / 3)
            .collect::<std::collections::BTreeSet<_>>();
        assert!(!held.is_empty(), "{board:?}: the held frame is not mixed");
        // The held frame is the only one mixed, and it is counted: the 1 s telemetry line's
        // own encoding (interrupts off, defmt-rtt's critical section) waits for a gap in the
        // frame's events and cuts no phase (before it did, the G474's line cut a Y phase to 6
        // of its 16 conversions here; `the_telemetry_line_cuts_no_phase` over 3 s).
        let mixed = field(&telemetry, "mixed").unwrap_or(0) as usize;
        assert!(
            mixed == held.len() && mixed_frames == held,
            "{board:?}: {mixed} counted, {} mixed in the trace ({} at the hold): {telemetry}",
            mixed_frames.len(),
            held.len()
        );
        assert_eq!(field(&telemetry, "incomplete"), Some(0), "{board:?}");
        assert_eq!(faults, 0, "{board:?}: a touch fault was logged");
        assert!(rises >= 4, "{board:?}: {rises} bursts in the 5 ms after");
        assert_eq!(offs, 0, "{board:?}: the carrier was forced off");
    }
}

/// The hold capacitor at the touch-down threshold (pre-flash item 2, docs/touch.md, "Charge
/// sharing at the touch-down threshold"): the finger at the threshold's contact (1.5 kΩ: 0.2 N
/// on the overlay's 300 Ω·N law; the largest contact whose reading is used, so the slowest
/// node, τ 5–6 µs) held 6 ms at each of five points (the corners at 10/90 % and the middle:
/// the largest steps between one phase's node and the previous conversion's). Each slot's code
/// error per conversion: the mean of its summed conversions (the first `discard` left out)
/// against the model's settled voltage, LSB, worst over the pressed frames; printed with one
/// more discard (the same trace, the second conversion left out too: what a second discard
/// would sum, 1 + 1 + 14) for the decision the docs record.
#[test]
fn charge_sharing_at_the_touch_down_threshold() {
    const POINTS: [(f64, f64); 5] = [(0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9), (0.5, 0.5)];
    const FROM_S: f64 = 0.010;
    const HOLD_S: f64 = 0.006;
    let finger = |t: f64| {
        let k = ((t - FROM_S) / HOLD_S).floor();
        (t >= FROM_S && (k as usize) < POINTS.len()).then(|| {
            let (x, y) = POINTS[k as usize];
            Finger { x, y, force_n: 0.2 }
        })
    };
    for board in BOARDS {
        let d = design(board);
        let o = run2d(board, FROM_S + HOLD_S * POINTS.len() as f64, finger);
        let tr = o.touch.as_ref().unwrap();
        let sw = &switches_from_x(tr);
        let model = TouchModel::new(
            Overlay {
                noise_lsb: 0.0,
                ..Overlay::default()
            },
            0,
        );
        // Worst per slot (X, Y, Z1, Z2): mean error of the summed conversions with one discard,
        // with two; the first conversion's share.
        let (mut one, mut two, mut first) = ([0f64; 4], [0f64; 4], [0f64; 4]);
        let mut runs = 0;
        for (k, w) in sw.windows(2).enumerate() {
            let (t0, t1) = (w[0].0, w[1].0);
            let phase = [Phase::X, Phase::Y, Phase::Z1][k % 3];
            // The same finger throughout the window (not across a point's change).
            let (f0, f1) = (finger(ns(t0) / 1e9), finger(ns(t1) / 1e9));
            let Some(f) = f0.filter(|f| f1.is_some_and(|g| g.x == f.x && g.y == f.y)) else {
                continue;
            };
            let convs: Vec<_> = tr
                .conversions
                .iter()
                .filter(|c| c.at > t0 && c.at < t1)
                .collect();
            let targets = model.targets(phase, Some(&f));
            let err = |c: &saw_board_model::touch::Conversion| {
                let i = [Terminal::XPlus, Terminal::XMinus, Terminal::YPlus, Terminal::YMinus]
                    .iter()
                    .position(|t| *t == c.terminal)
                    .unwrap();
                (c.v - targets[i].0) * 4096.0
            };
            let slots: Vec<(usize, &[&saw_board_model::touch::Conversion])> = match phase {
                Phase::X => vec![(0, &convs[..])],
                Phase::Y => vec![(1, &convs[..])],
                _ => vec![(2, &convs[..d.ranks[2]]), (3, &convs[d.ranks[2]..])],
            };
            for (s, run) in slots {
                assert_eq!(run.len(), d.ranks[s], "{board:?}: slot {s} at {:.1} µs", ns(t0) / 1e3);
                let mean = |cs: &[&saw_board_model::touch::Conversion]| {
                    (cs.iter().map(|c| err(c)).sum::<f64>() / cs.len() as f64).abs()
                };
                one[s] = one[s].max(mean(&run[d.discard..]));
                two[s] = two[s].max(mean(&run[d.discard + 1..]));
                first[s] = first[s].max(err(run[0]).abs());
                runs += 1;
            }
        }
        eprintln!(
            "{board:?}: at the touch-down threshold (0.2 N, 1.5 kΩ), {runs} slots: code error per conversion (X, Y, Z1, Z2) with 1 discard {one:.3?} LSB, with 2 discards {two:.3?} LSB; first conversion {first:.2?} LSB"
        );
        assert!(runs > 100, "{board:?}: {runs} slots measured");
        // The figures docs/touch.md publishes (2026-11-30), each within 0.01 LSB: the position
        // codes' worst with one discard and with two.
        let (want_one, want_two) = match board {
            BoardKind::F446 => (0.44, 0.27),
            _ => (0.90, 0.70),
        };
        let pos = |a: [f64; 4]| a[0].max(a[1]);
        assert!(
            (pos(one) - want_one).abs() <= 0.01 && (pos(two) - want_two).abs() <= 0.01,
            "{board:?}: position error {:.3} / {:.3} LSB, published {want_one} / {want_two}",
            pos(one),
            pos(two)
        );
    }
}

/// The 1 Hz telemetry line cuts no phase (docs/touch.md, "The telemetry line's window"):
/// defmt-rtt holds interrupts off while it encodes a line, and before the line waited for a
/// gap in the frame's events its encoding held a G474 Y phase's start ~12 µs (a phase cut to 6
/// of its 16 conversions, the frame dropped as mixed). Pressed from 10 ms over `SECS` s (a
/// telemetry line a second): every window between two switches holds its slots' ranks (no
/// mixed frame in the trace), and each line counts `mixed 0`, `late 0`, `forced 0`.
///
/// Not run by CI (`--ignored`): 3 s of both boards take ~45 s, and CI is at its time limit;
/// `a_phase_converting_across_the_next_switch_is_dropped_and_counted` checks the 1 s line of
/// its run the same way. Seen failing with the window planted out (the line emitted when due,
/// no room check): the F446's 3 s line cut an X phase to 12 of 16 conversions.
#[test]
#[ignore]
fn the_telemetry_line_cuts_no_phase() {
    const SECS: f64 = 3.05;
    let pressed = |t: f64| (t >= 0.010).then(|| at((47.5, 51.6))).flatten();
    let mut failed = Vec::new();
    for board in BOARDS {
        let d = design(board);
        let o = run2d(board, SECS, pressed);
        let tr = o.touch.as_ref().unwrap();
        let cut: Vec<(f64, usize, usize)> = off_design_windows(tr, &d)
            .into_iter()
            .map(|(_, at_us, n, want)| (at_us, n, want))
            .collect();
        let lines: Vec<&str> = o
            .log
            .iter()
            .filter(|l| l.text.starts_with("telemetry2d"))
            .map(|l| l.text.as_str())
            .collect();
        for l in &lines {
            eprintln!("{board:?}: {l}");
        }
        eprintln!(
            "{board:?}: {} switches over {SECS} s, {} telemetry lines, windows cut: {cut:?}",
            switches(tr).len(),
            lines.len()
        );
        assert!(
            lines.len() as f64 >= SECS.floor(),
            "{board:?}: {} telemetry lines",
            lines.len()
        );
        if !cut.is_empty() {
            failed.push(format!("{board:?}: phases cut: {cut:?}"));
        }
        for l in &lines {
            for key in ["mixed", "late", "forced", "incomplete"] {
                if field(l, key) != Some(0) {
                    failed.push(format!("{board:?}: {key} in {l}"));
                }
            }
        }
    }
    assert!(failed.is_empty(), "{failed:#?}");
}

/// The alternative to a second discard, measured on the board model's overlay and hold
/// capacitor (`saw_board_model::touch::Panel`) rather than the image (the sampling time is the
/// board plan's, shared with the 1D images): the firmware's sequence replayed at the core's
/// schedule — pins at each slot's start, 1 + 15 / 1 + 4 conversions from its trigger one
/// conversion apart — with the threshold's finger at the five points of
/// `charge_sharing_at_the_touch_down_threshold`, for each longer sampling time of the chip
/// (F446 84 / 112 / 144 cycles, RM0390 §13.13.4; G474 92.5 / 247.5, RM0440 §21.7.6): the worst
/// position code error per conversion and the per-axis rate of the schedule with it. Printed,
/// for the decision docs/touch.md records.
#[test]
fn charge_sharing_with_a_longer_sampling_time() {
    use saw_board_model::machine::PinMode;
    use saw_board_model::touch::Panel;
    const HI: PinMode = PinMode::Output { high: true };
    const LO: PinMode = PinMode::Output { high: false };
    const AN: PinMode = PinMode::Analog;
    const POINTS: [(f64, f64); 5] = [(0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9), (0.5, 0.5)];
    for (board, halves) in [
        (BoardKind::F446, &[112u32, 168, 224, 288][..]),
        (BoardKind::G474, &[95, 185, 495][..]),
    ] {
        let base = board.def();
        let t = saw_boards::touch::touch_adc(base);
        let p = saw_boards::touch::touch_pins(base).unwrap();
        for &half in halves {
            let mut def = *base;
            def.adc.sample_half_cycles = half;
            let extra_ns =
                (half as u64 - base.adc.sample_half_cycles as u64) * 1_000_000_000 / (2 * base.adc.clk_hz as u64);
            let conv_ns = t.conversion_ns as u64 + extra_ns;
            let adc = AdcTiming {
                conversion_ns: conv_ns as u32,
                conversions_position: t.conversions_position,
                conversions_pressure: t.conversions_pressure,
                discard: t.discard,
            };
            let sched = Schedule::new(&PlateRc::DEFAULT, &adc).unwrap();
            let sampling = half as u64 * TICKS_PER_S / (2 * def.adc.clk_hz as u64);
            let tick = |ns: u64| ns * TICKS_PER_S / 1_000_000_000;
            let mut worst = [0f64; 4];
            for (x, y) in POINTS {
                let f = Finger { x, y, force_n: 0.2 };
                let mut panel = Panel::new(
                    &def,
                    Overlay {
                        noise_lsb: 0.0,
                        ..Overlay::default()
                    },
                    1,
                    Rc::new(move |_| Some(f)),
                );
                let model = TouchModel::new(
                    Overlay {
                        noise_lsb: 0.0,
                        ..Overlay::default()
                    },
                    0,
                );
                let frame = sched.frame_ns();
                for k in 0..12u64 {
                    for (s, slot) in sched.slots.iter().enumerate() {
                        let t0 = k * frame + slot.start_ns;
                        let (pins, ch, term) = match s {
                            0 => ([HI, LO, AN, AN], p.y_plus.channel, 2),
                            1 => ([AN, AN, HI, LO], p.x_plus.channel, 0),
                            2 => ([AN, LO, HI, AN], p.x_plus.channel, 0),
                            _ => ([AN, LO, HI, AN], p.y_minus.channel, 3),
                        };
                        panel.set_pins(tick(t0), pins);
                        let n = t.ranks(s < 2) as u64;
                        let trig = t0 + slot.settle_ns;
                        let codes: Vec<f64> = (0..n)
                            .map(|i| {
                                let at = tick(trig + i * conv_ns) + sampling;
                                panel.convert(at, ch).unwrap();
                                panel.trace.conversions.last().unwrap().v
                            })
                            .collect();
                        if k < 2 {
                            continue;
                        }
                        let target = model.targets(sched.slots[s].phase, Some(&f))[term].0;
                        let summed = &codes[t.discard as usize..];
                        let mean = summed.iter().map(|v| (v - target) * 4096.0).sum::<f64>()
                            / summed.len() as f64;
                        worst[s] = worst[s].max(mean.abs());
                    }
                }
            }
            eprintln!(
                "{board:?}: sampling {:.1} cycles, conversion {conv_ns} ns: per-axis rate {:.0} Hz, frame {:.1} µs; code error per conversion at the threshold (X, Y, Z1, Z2) {worst:.3?} LSB",
                half as f64 / 2.0,
                1e9 / sched.frame_ns() as f64,
                sched.frame_ns() as f64 / 1e3
            );
            // The G474's one longer sampling time, as docs/touch.md publishes it: within ½ LSB
            // (0.36) at 3 701 Hz per axis.
            if board == BoardKind::G474 && half == 185 {
                let pos = worst[0].max(worst[1]);
                let rate = (1e9 / sched.frame_ns() as f64).round();
                assert!(
                    (pos - 0.36).abs() <= 0.01 && rate == 3_701.0,
                    "{board:?}: 92.5 cycles: {pos:.3} LSB at {rate} Hz"
                );
            }
        }
    }
}
