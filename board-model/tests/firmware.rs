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

/// The panic path: at 0.5 s, while bursts run, the model diverts the core into one of the
/// image's own panic call sites (a division by zero's `bl panic_const_div_by_zero` with its real
/// `&Location`), so the firmware's panic handler runs as after a real panic. The enables and RF
/// arm must be low before the first byte of the panic's log line is written. With no debugger,
/// the handler's `udf` and the HardFault handler's `bkpt` end in lockup (ARMv7-M B1.5.15), and the
/// IWDG must reset the chip with the lines low throughout until the new boot arms RF.
#[test]
fn panic_turns_rf_off_before_logging_and_the_watchdog_restarts() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 0.7);
        opts.force_panic_s = Some(0.5);
        let (o, _m) = run::run(&opts).unwrap();
        assert!(o.stop.is_none(), "{board:?}: {:?}", o.stop);
        let t_fault: Time = TICKS_PER_S / 2;
        assert!(
            o.log.iter().any(|l| l.text.contains("panic")),
            "{board:?}: no panic line in {:?}",
            o.log
        );
        // Bursts were running before the fault.
        assert!(
            o.pins[PIN_BURST_A].iter().any(|e| e.high && e.at < t_fault),
            "{board:?}: no burst before the fault"
        );
        // The lockup is ended by the IWDG: about 50 ms after the last pet.
        let reset = o
            .resets
            .iter()
            .find(|r| r.1 == ResetCause::IndependentWatchdog)
            .map(|r| r.0);
        let reset = reset
            .unwrap_or_else(|| panic!("{board:?}: no IWDG reset after the panic: {:?}", o.resets));
        let ms = (reset - t_fault) as f64 * 1e3 / TICKS_PER_S as f64;
        assert!(
            (49.0..=51.0).contains(&ms),
            "{board:?}: IWDG reset {ms:.2} ms after the panic"
        );
        for pin in [PIN_BURST_A, PIN_BURST_B, PIN_RF_ARM] {
            let e = &o.pins[pin];
            // The line's state through the lockup is its last edge before the reset: it must be
            // low, and written before the panic line (emergency_off runs first) — or a natural
            // fall between bursts before the panic.
            let low = *e.iter().take_while(|x| x.at < reset).last().unwrap();
            assert!(!low.high, "{board:?}: pin {pin} high through the lockup");
            let before = run::decode(
                &elf(board),
                &o.raw_log[..low.log_bytes.min(o.raw_log.len())],
            )
            .unwrap();
            assert!(
                !before.iter().any(|l| l.text.contains("panic")),
                "{board:?}: pin {pin} went low after the panic was logged"
            );
        }
        assert_eq!(
            o.log
                .iter()
                .filter(|l| l.text.contains("saw-firmware v"))
                .count(),
            2,
            "{board:?}: no second boot"
        );
    }
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
