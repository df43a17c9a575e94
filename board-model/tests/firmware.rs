//! The firmware images (scripts/build-firmware.sh) on the board model: the defects issue #9
//! found, each checked where the board would show it, and the panic path.
//!
//! Needs `$SAW_FIRMWARE_DIR/<board>.elf` (default `../firmware/target`); a missing image fails
//! the test with the command that builds it.

use saw_board_model::board::{BoardKind, PIN_BURST_A, PIN_BURST_B, PIN_RF_ARM};
use saw_board_model::machine::Stop;
use saw_board_model::periph::{Time, TICKS_PER_S};
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
/// arm must be low before the first byte of the panic's log line is written.
#[test]
fn panic_turns_rf_off_before_logging() {
    for board in BOARDS {
        let mut opts = Options::new(board, &elf(board), 1.0);
        opts.force_panic_s = Some(0.5);
        let (o, _m) = run::run(&opts).unwrap();
        assert!(
            matches!(
                o.stop,
                Some(Stop::Breakpoint { .. }) | Some(Stop::Lockup { .. })
            ),
            "{board:?}: expected a halt, got {:?}",
            o.stop
        );
        let panic_line = o
            .log
            .iter()
            .position(|l| l.text.contains("panic"))
            .unwrap_or_else(|| panic!("{board:?}: no panic line in {:?}", o.log));
        let _ = panic_line;
        let t_fault: Time = TICKS_PER_S / 2;
        // Bursts were running before the fault.
        assert!(
            o.pins[PIN_BURST_A].iter().any(|e| e.high && e.at < t_fault),
            "{board:?}: no burst before the fault"
        );
        // The last edge of each line is low, and at that edge no byte of the panic line had been
        // written: decode the log up to that point.
        for pin in [PIN_BURST_A, PIN_BURST_B, PIN_RF_ARM] {
            let last = o.pins[pin].last().unwrap();
            assert!(!last.high, "{board:?}: pin {pin} ends high");
            let before = run::decode(
                &elf(board),
                &o.raw_log[..last.log_bytes.min(o.raw_log.len())],
            )
            .unwrap();
            assert!(
                !before.iter().any(|l| l.text.contains("panic")),
                "{board:?}: pin {pin} went low after the panic was logged"
            );
        }
    }
}
