//! The firmware images (scripts/build-firmware.sh) on the board model: the defects issue #9
//! found, each checked where the board would show it, and the panic path.
//!
//! Needs `$SAW_FIRMWARE_DIR/<board>.elf` (default `../firmware/target`); a missing image fails
//! the test with the command that builds it.

use saw_board_model::board::{BoardKind, PIN_BURST_A, PIN_BURST_B, PIN_RF_ARM};
use saw_board_model::machine::Stop;
use saw_board_model::periph::{ResetCause, Time, TICKS_PER_S};
use saw_board_model::run::{self, Options};
use std::path::PathBuf;

fn elf(board: BoardKind) -> PathBuf {
    let dir = std::env::var("SAW_FIRMWARE_DIR")
        .unwrap_or_else(|_| concat!(env!("CARGO_MANIFEST_DIR"), "/../firmware/target").into());
    let p = PathBuf::from(dir).join(format!("{}.elf", board.name()));
    assert!(
        p.exists(),
        "{} is missing: run scripts/build-firmware.sh first",
        p.display()
    );
    p
}

const BOARDS: [BoardKind; 2] = [BoardKind::F446, BoardKind::G474];

/// Finding 2: a running burst's new PSC/ARR/CCR1/CCR3 are written with update events disabled
/// (TIM2_CR1.UDIS = 1), so no update event can latch half of them (RM0390 §17.4.1).
#[test]
fn burst_updates_are_written_under_udis() {
    for board in BOARDS {
        let (o, _m) = run::run(&Options::new(board, &elf(board), 1.2)).unwrap();
        assert!(o.stop.is_none(), "{board:?}: {:?}", o.stop);
        let mut udis = false;
        let mut running = false;
        let mut updates = 0;
        for w in o.writes.iter().filter(|w| w.addr < 0x4000_0400) {
            match w.addr & 0x3FF {
                0x00 => {
                    udis = w.value & 2 != 0;
                    running = w.value & 1 != 0;
                }
                0x28 | 0x2C | 0x34 | 0x3C if running => {
                    assert!(udis, "{board:?}: TIM2 register 0x{:03X} written at {} µs while counting with UDIS = 0", w.addr & 0x3FF, w.at / 3600);
                    updates += 1;
                }
                _ => {}
            }
        }
        // The built-in scene changes f_b at its two region switches in this run:
        // 2 updates × (PSC, ARR, CCR1, CCR3).
        assert!(
            updates >= 8,
            "{board:?}: only {updates} running-burst register writes seen"
        );
    }
}

/// Finding 3: the F446's ART accelerator (prefetch, instruction and data caches) is on after
/// boot (RM0390 §3.8.1 FLASH_ACR: PRFTEN bit 8, ICEN bit 9, DCEN bit 10), with 5 wait states.
#[test]
fn f446_flash_accelerator_is_on() {
    let (o, mut m) = run::run(&Options::new(BoardKind::F446, &elf(BoardKind::F446), 0.05)).unwrap();
    assert!(o.stop.is_none(), "{:?}", o.stop);
    let acr = m.sim_mut().peek(0x4002_3C00).unwrap();
    assert_eq!(acr & 0xF, 5, "LATENCY");
    assert_eq!(
        acr & 0x700,
        0x700,
        "FLASH_ACR = 0x{acr:08X}: PRFTEN/ICEN/DCEN not all set"
    );
}

/// What a fault at 0.5 s must leave (issue #32): the enables, the RF arm and the RF level (DAC1
/// on PA4) low within 10 µs of the event and nothing rising after it; the chip reset by itself
/// at once (SYSRESETREQ, not the IWDG ~50 ms later, since no debugger is attached); the next boot
/// saying why the previous run ended. `event` names the fault for the messages and the expected
/// boot line.
fn rf_off_within_10_us_then_reset(board: BoardKind, opts: &Options, cause: &str) {
    let (o, _m) = run::run(opts).unwrap();
    assert!(o.stop.is_none(), "{board:?} {cause}: {:?}", o.stop);
    let t_fault: Time = TICKS_PER_S / 2;
    let deadline = t_fault + TICKS_PER_S / 100_000;
    // Bursts were running before the fault.
    assert!(
        o.pins[PIN_BURST_A].iter().any(|e| e.high && e.at < t_fault),
        "{board:?} {cause}: no burst before the fault"
    );
    let reset = o
        .resets
        .iter()
        .find(|r| r.0 >= t_fault)
        .copied()
        .unwrap_or_else(|| {
            panic!(
                "{board:?} {cause}: no reset after the fault: {:?}",
                o.resets
            )
        });
    assert_eq!(
        reset.1,
        ResetCause::Software,
        "{board:?} {cause}: reset by {:?} {} µs after the fault, not by the fault path",
        reset.1,
        (reset.0 - t_fault) / (TICKS_PER_S / 1_000_000)
    );
    assert!(
        reset.0 - t_fault < TICKS_PER_S / 1_000,
        "{board:?} {cause}: the reset came {} µs after the fault",
        (reset.0 - t_fault) / (TICKS_PER_S / 1_000_000)
    );
    for pin in [PIN_BURST_A, PIN_BURST_B, PIN_RF_ARM] {
        let e = &o.pins[pin];
        let at_deadline = e.iter().take_while(|x| x.at <= deadline).last().unwrap();
        assert!(
            !at_deadline.high,
            "{board:?} {cause}: pin {pin} still high 10 µs after the fault"
        );
        assert!(
            !e.iter()
                .any(|x| x.high && x.at > deadline && x.at < reset.0),
            "{board:?} {cause}: pin {pin} rose again before the reset"
        );
    }
    let level = o
        .dac
        .iter()
        .take_while(|d| d.at <= deadline)
        .last()
        .unwrap();
    assert!(
        !level.driven || level.code == 0,
        "{board:?} {cause}: RF level code {} 10 µs after the fault",
        level.code
    );
    assert!(
        !o.dac
            .iter()
            .any(|d| d.at > deadline && d.at < reset.0 && d.driven && d.code != 0),
        "{board:?} {cause}: RF level raised again before the reset"
    );
    let booted: Vec<_> = o
        .log
        .iter()
        .filter(|l| l.text.contains("saw-firmware v"))
        .collect();
    assert_eq!(booted.len(), 2, "{board:?} {cause}: no second boot");
    assert!(
        o.log.iter().any(|l| l.text.contains(&format!(
            "the previous run ended in the fault path ({cause}"
        ))),
        "{board:?} {cause}: the second boot does not say why: {:?}",
        o.log
    );
}

/// The panic path: at 0.5 s, while bursts run, the model diverts the core into one of the
/// image's own panic call sites (a division by zero's `bl panic_const_div_by_zero` with its real
/// `&Location`), so the firmware's panic handler runs as after a real panic. With no debugger
/// nobody reads the log: RF off, then a reset at once (issue #32: before, `udf` waited for the
/// IWDG, 50 ms with the chip in lockup).
#[test]
fn panic_turns_rf_off_and_resets_at_once() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 0.7);
        opts.force_panic_s = Some(0.5);
        rf_off_within_10_us_then_reset(board, &opts, "Panic");
    }
}

/// Issue #32: an NMI (on the G474 a flash double-ECC error raises one; here NMIPENDSET at 0.5 s)
/// and an interrupt no handler was bound to (WWDG, IRQ 0 on both chips, enabled and pended at
/// 0.5 s) each take the fault path. cortex-m-rt's defaults are `loop {}`: RF armed and TIM2
/// bursting until the IWDG, 50 ms later.
#[test]
fn an_nmi_or_an_unhandled_interrupt_turns_rf_off_within_10_us_and_resets() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 0.7);
        opts.nmi_s = Some(0.5);
        rf_off_within_10_us_then_reset(board, &opts, "Nmi");
        let mut opts = Options::new(board, &elf(board), 0.7);
        opts.unhandled_irq = Some((0.5, 0));
        rf_off_within_10_us_then_reset(board, &opts, "Unhandled");
    }
}

/// Issue #32: `probe-rs run` switches the RTT up channel to block-when-full; a host that then
/// stops reading (stalled, killed) must not freeze the control loop. With blocking defmt-rtt
/// spins in its critical section (interrupts off) once its 1 KiB fills, TIM2 bursting as last
/// set, until the IWDG resets the chip. Here the host stops reading at 0.3 s with the buffer
/// full (the next region line, at ~0.7 s, finds no room); the control loop
/// must go on: no reset, and bursts still follow the finger through the last second (region
/// changes keep changing the burst frequency: TIM2's ARR is rewritten).
#[test]
fn a_stalled_rtt_host_never_freezes_the_control_loop() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 4.0);
        opts.rtt_host_blocking = true;
        opts.rtt_host_stalls_s = Some(0.3);
        let (o, _m) = run::run(&opts).unwrap();
        assert!(o.stop.is_none(), "{board:?}: {:?}", o.stop);
        assert!(o.resets.is_empty(), "{board:?}: reset {:?}", o.resets);
        let last_s = |t: Time| t >= 3 * TICKS_PER_S;
        let rises = o.pins[PIN_BURST_A]
            .iter()
            .filter(|e| e.high && last_s(e.at))
            .count();
        assert!(rises > 10, "{board:?}: {rises} bursts in the last second");
        let arr_writes = o
            .writes
            .iter()
            .filter(|w| w.addr == 0x4000_002C && last_s(w.at))
            .count();
        assert!(
            arr_writes >= 1,
            "{board:?}: no burst-frequency change in the last second: the control loop stopped"
        );
    }
}

/// Issue #32: a board whose HSE never becomes ready (an early NUCLEO-F446RE without the
/// ST-LINK's MCO on OSC_IN, SB50 open, the ST-LINK side unpowered; a dead crystal on the G474).
/// embassy's RCC init waits for HSERDY forever: the board never started and never said why.
/// Now: one log line naming the wait and the clock source, RF lines low throughout (never
/// armed), no boot loop, and the core asleep (WFE).
#[test]
fn without_hse_the_board_says_so_and_keeps_rf_off() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 1.0);
        opts.hse_absent = true;
        let (o, _m) = run::run(&opts).unwrap();
        assert!(o.stop.is_none(), "{board:?}: {:?}", o.stop);
        assert!(o.resets.is_empty(), "{board:?}: reset {:?}", o.resets);
        let line = o
            .log
            .iter()
            .find(|l| l.text.contains("HSE not ready after at least 100 ms"))
            .unwrap_or_else(|| panic!("{board:?}: no HSE line in {:?}", o.log));
        assert!(
            line.text.contains("RF off, halted") && line.level == "ERROR",
            "{board:?}: {line:?}"
        );
        for pin in [PIN_BURST_A, PIN_BURST_B, PIN_RF_ARM] {
            assert!(
                !o.pins[pin].iter().any(|e| e.high),
                "{board:?}: pin {pin} went high without a clock"
            );
        }
        // Halted in WFE: the core sleeps most of the 1 s (the wait of at least 100 ms is spent
        // polling: `asm::delay` counts at least its cycles, ~200 ms on the model).
        assert!(
            o.sleeping > o.end * 7 / 10,
            "{board:?}: the core slept {} of {} ticks",
            o.sleeping,
            o.end
        );
    }
}

/// Issue #32, ES0430 (G474 errata): a conversion more than 1 ms after the calibration or the
/// previous conversion may be wrong. The sampler's first trigger after `start` — at boot, after
/// the calibration and the boot log — is that late; the firmware converts one sequence and
/// discards it first, so no late result reaches the DMA buffer, at boot or after the overrun
/// restart of `acquisition_recovers_from_an_overrun`'s storm.
#[test]
fn g474_no_late_conversion_reaches_the_samples() {
    use saw_board_model::periph::adc_g4::AdcG4;
    let mut opts = Options::new(BoardKind::G474, &elf(BoardKind::G474), 1.3);
    opts.stuck_irq = Some((1.2, 11));
    opts.stuck_for_s = Some(0.002);
    let (o, m) = run::run(&opts).unwrap();
    assert!(o.stop.is_none(), "{:?}", o.stop);
    assert_eq!(
        o.log
            .iter()
            .filter(|l| l.text.contains("acquisition restarted"))
            .count(),
        1,
        "the storm must restart the acquisition once"
    );
    let adc = m
        .sim()
        .periphs
        .iter()
        .find_map(|p| p.p.as_any().downcast_ref::<AdcG4>())
        .expect("the G474 model has an ADC1");
    assert!(
        adc.late_results_delivered.is_empty(),
        "late conversions in the samples at {:?} µs",
        adc.late_results_delivered
            .iter()
            .map(|t| t / (TICKS_PER_S / 1_000_000))
            .collect::<Vec<_>>()
    );
}

/// Issue #32: the same image on a part with less flash (an F446RC or G474RC, 256 KiB) has no
/// store region (F446 sectors 6–7 from 0x0804_0000; G474 bank 2's last pages near 0x0808_0000):
/// touching it faults. The firmware reads FLASHSIZE, says the store is off, boots the built-in
/// scene and runs (bursts, no reset, no fault); a save is then refused as on a board without a
/// store.
#[test]
fn a_part_with_less_flash_runs_without_a_store() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 0.5);
        opts.flash_kib = Some(256);
        let (o, _m) = run::run(&opts).unwrap();
        assert!(o.stop.is_none(), "{board:?}: {:?}", o.stop);
        assert!(o.resets.is_empty(), "{board:?}: reset {:?}", o.resets);
        assert!(
            o.log.iter().any(|l| l
                .text
                .contains("this part has 256 KiB of flash (FLASHSIZE)")),
            "{board:?}: no flash-size line in {:?}",
            o.log
        );
        assert!(
            o.log
                .iter()
                .any(|l| l.text == "boot: no scene store on this board"),
            "{board:?}: {:?}",
            o.log
        );
        assert!(
            o.pins[PIN_BURST_A].iter().any(|e| e.high),
            "{board:?}: no burst"
        );
    }
}

/// Issue #32: the G474's switch to 150 MHz must take RM0440 §7.2.7's intermediate step (AHB /2
/// for at least 1 µs above 80 MHz), which ST's HAL always takes and embassy-stm32 0.6 takes only
/// in boost mode (and there before the switch, not after it). The model records every HCLK step
/// that breaks the rule (`RccG4::hclk_step_violations`; its own test shows embassy's sequence
/// caught and the HAL's not).
/// Upstream embassy-stm32 0.6 fails it (16 -> 150 MHz in one write); the firmware builds a
/// patched copy (firmware/vendor/README.md).
#[test]
fn g474_clock_switch_takes_the_intermediate_step() {
    use saw_board_model::periph::rcc_g4::RccG4;
    let (o, m) = run::run(&Options::new(BoardKind::G474, &elf(BoardKind::G474), 0.01)).unwrap();
    assert!(o.stop.is_none(), "{:?}", o.stop);
    let rcc = m
        .sim()
        .periphs
        .iter()
        .find_map(|p| p.p.as_any().downcast_ref::<RccG4>())
        .expect("the G474 model has an RCC");
    assert!(
        rcc.hclk_step_violations.is_empty(),
        "{:?}",
        rcc.hclk_step_violations
    );
}

/// The same panic with a debugger attached (DHCSR.C_DEBUGEN = 1): the core halts at the HardFault
/// handler's breakpoint, and the fault path has frozen the IWDG for the halt (DBGMCU
/// DBG_IWDG_STOP) so probe-rs can print the backtrace: no reset in the next 200 ms, RF off.
#[test]
fn under_a_debugger_the_panic_halts_with_the_watchdog_frozen() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 0.7);
        opts.force_panic_s = Some(0.5);
        opts.debugger = true;
        // probe-rs run: RTT in block-when-full mode.
        opts.rtt_host_blocking = true;
        let (o, mut m) = run::run(&opts).unwrap();
        assert!(
            matches!(o.stop, Some(Stop::Breakpoint { .. })),
            "{board:?}: expected a breakpoint halt, got {:?}",
            o.stop
        );
        let halted = m.now();
        assert_eq!(m.run_until(halted + TICKS_PER_S / 5), None);
        assert!(
            m.sim().resets.is_empty(),
            "{board:?}: reset during the debug halt: {:?}",
            m.sim().resets
        );
        for pin in [PIN_BURST_A, PIN_BURST_B, PIN_RF_ARM] {
            assert!(
                !m.sim().pins[pin].last().unwrap().high,
                "{board:?}: pin {pin} high while halted"
            );
        }
    }
}

/// Issue #32 (review): DHCSR.C_DEBUGEN survives every reset but a power-on one, so a board whose
/// debugger detached without clearing it still reads "attached". Without an RTT host that set
/// block-when-full since this boot (probe-rs run's mark), the fault path must not halt with the
/// IWDG frozen (RF off, but stopped for good): it resets at once, as with no debugger.
#[test]
fn a_stale_debugger_flag_without_a_reading_host_still_resets() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 0.7);
        opts.force_panic_s = Some(0.5);
        opts.debugger = true;
        rf_off_within_10_us_then_reset(board, &opts, "Panic");
    }
}

/// Overrun recovery at run time: a 2 ms interrupt storm on the ADC's DMA interrupt starves the
/// sampler while the DMA laps its 2-sample ring buffer. The sampler must notice, restart the
/// acquisition, say so once in the log, and go back to 10 000 samples/s — without a sensor
/// fault (2 ms is under the 5 ms stale limit) and without a watchdog reset.
#[test]
fn acquisition_recovers_from_an_overrun() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 2.2);
        let irq = match board {
            BoardKind::F446 => 56,
            BoardKind::G474 => 11,
        };
        opts.stuck_irq = Some((1.2, irq));
        opts.stuck_for_s = Some(0.002);
        let (o, _m) = run::run(&opts).unwrap();
        assert!(o.stop.is_none(), "{board:?}: {:?}", o.stop);
        assert!(o.resets.is_empty(), "{board:?}: reset {:?}", o.resets);
        let restarts: Vec<_> = o
            .log
            .iter()
            .filter(|l| l.text.contains("acquisition restarted"))
            .collect();
        assert_eq!(restarts.len(), 1, "{board:?}: {:?}", o.log);
        let samples: Vec<u64> = saw_board_model::check::telemetry_samples(&o)
            .into_iter()
            .map(|(_, n)| n)
            .collect();
        assert_eq!(samples.len(), 2, "{board:?}");
        let lost = 10_000 - (samples[1] - samples[0]);
        // 2 ms of samples (20) plus the restart's own gap.
        assert!(
            lost <= 30,
            "{board:?}: {lost} samples lost in the second with the storm"
        );
        assert!(
            !o.log.iter().any(|l| l.text.contains("sensor fault")),
            "{board:?}: sensor fault"
        );
    }
}
