//! The saved scene's flash on the firmware images (issue #32): what silicon does to a store that
//! the board model once could not show.
//!
//! - F446, the ART data cache across an erase (RM0390 §3.4.2, §3.8.1): a save that must erase a
//!   sector is made over the link; the caches must be reset (DCRST with DCEN = 0) after the
//!   erase, before the store's next flash operation, and the board must boot the saved scene on
//!   the flash it left. In this save the model's cache serves no stale line even without the
//!   reset (its 8 lines are refilled by the page scan and the code's literal pools long before
//!   sequential-storage reads the erased sector again: 0 of ~317 000 cached reads were stale),
//!   so the check holds the firmware to the manual's rule rather than to a symptom this flow
//!   cannot show.
//! - G474, a power cut in a save (RM0440 §5.3.2, §5.7.7): the save's flash operations are
//!   recorded, and for every one a flash is built as a cut there leaves it (the operations
//!   before done, that one half done with a bad ECC); a fresh board boots on each and must run
//!   the old scene or the new one — the double words with a bad ECC programmed to zeros and the
//!   store repaired, never erased ("nothing is lost") — and never hang in the NMI, never loop
//!   through resets.
//!
//! Needs `$SAW_FIRMWARE_DIR/<board>.elf` (default `../firmware/target`).

use saw_board_model::board::{self, BoardKind};
use saw_board_model::machine::Machine;
use saw_board_model::periph::flash_prog::Operation;
use saw_board_model::periph::{Time, TICKS_PER_S};
use saw_board_model::run::{self, LogLine, Options};
use saw_link::msg::{Reply, Request};
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

/// The board's replies: (time its last byte left, sequence number, reply).
fn replies(bytes: &[(Time, u8)]) -> Vec<(Time, u32, Reply)> {
    use saw_link::frame::{message, Receiver, MAX_ENCODED};
    let mut rx = Receiver::<MAX_ENCODED>::default();
    let mut out = Vec::new();
    for &(t, b) in bytes {
        if let Some(Ok(n)) = rx.push(b) {
            if let Ok((h, r)) = message::<Reply>(rx.payload(n)) {
                out.push((t, h.seq, r));
            }
        }
    }
    out
}

/// The scene the earlier saves stored (i = 0, 1, …): the default scene with its first boundary
/// between 25 and 30 mm.
fn earlier(i: usize) -> saw_core::scene::Config {
    saw_core::default_config()
        .with_boundary(0, 25_000 + (i as u32 % 50) * 100)
        .expect("a boundary between 25 and 30 mm is valid in the default scene")
}

/// The scene the link saves: the first boundary moved to 30 mm.
fn moved() -> (saw_core::scene::Config, u32) {
    let c = saw_core::default_config()
        .with_boundary(0, 30_000)
        .expect("30 mm is a valid boundary");
    let id = saw_link::scene_id(&c);
    (c, id)
}

fn boot_line(id: u32) -> String {
    format!("boot: the scene saved in flash (id {id:08x})")
}

fn has(log: &[LogLine], text: &str) -> bool {
    log.iter().any(|l| l.text == text)
}

fn show(log: &[LogLine]) -> String {
    log.iter()
        .map(|l| format!("  {:.6} {} {}", l.t_s, l.level, l.text))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The store's bytes as the machine holds them (the flash array).
fn store_bytes(m: &Machine, board: BoardKind) -> Vec<u8> {
    let s = board.def().store;
    let mut b = vec![0u8; s.bytes as usize];
    m.uc.mem_read(s.origin as u64, &mut b)
        .expect("the store is mapped");
    b
}

/// A save over the link from a store filled up to its next erase: moves the first boundary at
/// 0.25 s and saves at 0.30 s. Returns the run, its machine and the scene the store held before.
fn save_that_erases(board: BoardKind, duration_s: f64) -> (run::Outcome, Machine, Vec<u8>, u32) {
    let def = board.def();
    let (image, last, _saves) =
        saw_board_model::store_image::before_an_erase(def, earlier).expect("a store image");
    let mut opts = Options::new(board, &elf(board), duration_s);
    opts.flash_preload = vec![(def.store.origin, image.clone())];
    opts.link_input = vec![
        (
            0.25,
            saw_board_model::check::request_frame(
                1,
                &Request::MoveBoundary {
                    index: 0,
                    at_um: 30_000,
                },
            ),
        ),
        (
            0.30,
            saw_board_model::check::request_frame(2, &Request::Save),
        ),
    ];
    let (o, m) = run::run(&opts).expect("the run starts");
    assert!(
        o.stop.is_none(),
        "{board:?}: the save run stopped: {:?}",
        o.stop
    );
    (o, m, image, last.scene_id)
}

/// The F446 data cache's reads so far, and how many of them returned bytes the array no longer
/// held.
fn cache_reads(m: &mut Machine) -> (u64, u64) {
    let (fi, prog) = (m.sim().chip.flash_if, m.sim().chip.flash_prog);
    prog(&mut *m.sim_mut().periphs[fi].p)
        .data_cache()
        .map_or((0, 0), |c| (c.reads, c.stale_reads))
}

fn operations(m: &mut Machine) -> Vec<Operation> {
    let (fi, prog) = (m.sim().chip.flash_if, m.sim().chip.flash_prog);
    prog(&mut *m.sim_mut().periphs[fi].p).operations().to_vec()
}

/// F446 (issue #32 A): a save whose store must erase a sector, then a reboot on the flash it
/// left. The store's 128 KiB sectors hold ~1 900 saves; the image is the one just before the
/// save that reclaims the first sector. The board must answer Saved, reset its flash caches
/// after the erase (see the module doc) and boot the new scene.
#[test]
fn f446_a_save_across_a_sector_erase_boots_the_saved_scene() {
    let board = BoardKind::F446;
    let (_, moved_id) = moved();
    // The erase takes 1 s of the save (0.3 s → ~1.4 s).
    let (o, mut m, _before, old_id) = save_that_erases(board, 1.8);
    let ops = operations(&mut m);
    let erases = ops.iter().filter(|op| op.erase).count();
    assert!(
        erases >= 1,
        "the save erased nothing: the store image is not at its erase ({} operations)",
        ops.len()
    );
    assert!(
        has(&o.log, &boot_line(old_id)),
        "the first boot did not run the stored scene {old_id:08x}:\n{}",
        show(&o.log)
    );
    let answer = replies(&o.link_output)
        .into_iter()
        .find(|r| r.1 == 2)
        .map(|r| r.2);
    assert!(
        matches!(answer, Some(Reply::Saved { scene_id }) if scene_id == moved_id),
        "the save was answered {answer:?} (want Saved {moved_id:08x}); {} flash operations, {erases} erases; log:\n{}",
        ops.len(),
        show(&o.log)
    );
    // The caches flushed after the erase: FLASH_ACR written with DCRST = 1 and DCEN = 0 after
    // the erase ends (RM0390 §3.8.1: the only way to empty the data cache), then DCEN = 1 again,
    // before the store's next flash operation.
    let acr: Vec<(Time, u32)> = {
        let fi = m.sim().chip.flash_if;
        m.sim().periphs[fi]
            .p
            .as_any()
            .downcast_ref::<saw_board_model::periph::misc::FlashF4>()
            .expect("the F446's flash interface")
            .acr_history()
            .to_vec()
    };
    const DCEN: u32 = 1 << 10;
    const DCRST: u32 = 1 << 12;
    for (i, e) in ops.iter().enumerate().filter(|(_, op)| op.erase) {
        let next_op = ops.get(i + 1).map_or(Time::MAX, |n| n.start);
        let window: Vec<u32> = acr
            .iter()
            .filter(|(t, _)| *t >= e.end && *t < next_op)
            .map(|w| w.1)
            .collect();
        let reset = window.iter().position(|v| v & DCRST != 0 && v & DCEN == 0);
        let back_on =
            reset.is_some_and(|r| window[r..].iter().any(|v| v & DCEN != 0 && v & DCRST == 0));
        assert!(
            back_on,
            "the data cache is not reset after the erase of 0x{:08X} (ends {:.4} s) before the next flash operation: FLASH_ACR writes in between {:08X?}; cache: {} reads, {} of them stale",
            e.addr,
            e.end as f64 / TICKS_PER_S as f64,
            window,
            cache_reads(&mut m).0,
            cache_reads(&mut m).1
        );
    }
    // Reboot: a fresh board on the flash the save left.
    let flash = store_bytes(&m, board);
    let mut opts = Options::new(board, &elf(board), 0.3);
    opts.flash_preload = vec![(board.def().store.origin, flash)];
    let (o2, _m2) = run::run(&opts).expect("the reboot run starts");
    assert!(o2.stop.is_none(), "the reboot stopped: {:?}", o2.stop);
    assert!(
        has(&o2.log, &boot_line(moved_id)),
        "after the save the board does not boot the saved scene {moved_id:08x}:\n{}",
        show(&o2.log)
    );
}

/// The flash a power cut at operation `k` of `ops` leaves, over `before` (the store's bytes
/// before the save, from `origin`): the operations before `k` done (an erase fills its range
/// with 0xFF; a program ANDs its value into the cells, which on the G474 were erased or are
/// written with zeros), operation `k` half done. A program cut half way: the first half of its
/// bytes programmed (G474: the first word of the double word; F446: the first half-word), the
/// rest as it was, and (G474) the double word's ECC bad. An erase cut half way: its range's
/// content undefined — kept as it was here, the harder case for the store, since it still looks
/// like data — and (G474) every double word of it with a bad ECC (the F446 ignores the marks).
/// Returns the bytes and the double words to mark bad. `k = ops.len()`: the save complete,
/// nothing cut.
fn cut_at(before: &[u8], origin: u32, ops: &[Operation], k: usize) -> (Vec<u8>, Vec<u32>) {
    let mut flash = before.to_vec();
    let cell = |a: u32| (a - origin) as usize;
    for op in &ops[..k] {
        let at = cell(op.addr);
        if op.erase {
            flash[at..at + op.bytes as usize].fill(0xFF);
        } else {
            let v = op.value.to_le_bytes();
            for i in 0..op.bytes as usize {
                flash[at + i] &= v[i];
            }
        }
    }
    let mut bad = Vec::new();
    if let Some(op) = ops.get(k) {
        let at = cell(op.addr);
        if op.erase {
            bad.extend((0..op.bytes).step_by(8).map(|o| op.addr + o));
        } else {
            let v = op.value.to_le_bytes();
            for i in 0..op.bytes as usize / 2 {
                flash[at + i] &= v[i];
            }
            bad.push(op.addr & !7);
        }
    }
    (flash, bad)
}

/// What one boot on a cut flash did.
struct Boot {
    log: Vec<LogLine>,
    resets: usize,
    ecc_errors: u32,
    reached_loop: bool,
    wall_s: f64,
    store_after: Vec<u8>,
}

/// Boots a fresh `board` on `store` (the store region's bytes) with `bad` double words (G474),
/// for `duration_s` of board time, the wiper at mid-travel.
fn boot(board: BoardKind, store: &[u8], bad: &[u32], duration_s: f64) -> Boot {
    let started = std::time::Instant::now();
    let image = elf(board);
    let mut m = board::build(board, &image, Box::new(|_t: Time| 2048)).expect("the board builds");
    m.preload_flash(board.def().store.origin, store)
        .expect("the store is in flash");
    let (fi, prog) = (m.sim().chip.flash_if, m.sim().chip.flash_prog);
    for &a in bad {
        m.mark_flash_ecc_bad(a).expect("marked before the run");
    }
    let stop = m.run_until((duration_s * TICKS_PER_S as f64) as Time);
    assert!(stop.is_none(), "the boot run stopped: {stop:?}");
    let log = run::decode(&image, &m.sim().log).expect("the log decodes");
    let ecc_errors = prog(&mut *m.sim_mut().periphs[fi].p).ecc_detections();
    Boot {
        reached_loop: log.iter().any(|l| l.text.starts_with("adc: ")),
        resets: m.sim().resets.len(),
        ecc_errors,
        store_after: store_bytes(&m, board),
        log,
        wall_s: started.elapsed().as_secs_f64(),
    }
}

/// Double ECC errors one boot may raise: one per byte of a page and a handful more. A cut erase
/// leaves every double word of its 2 KiB page with a bad ECC, and the boot's scan reads each
/// once before zeroing it — byte by byte (embassy's flash read copies bytes; each load of a bad
/// double word is a double error and an NMI: 8 per double word, 2048 for the page). An NMI loop
/// would not stop there.
const MAX_ECC_ERRORS: u32 = 2048 + 64;

/// The address a `store: double ECC error at 0x…` line names, if its tail is `tail`.
fn ecc_line(log: &[LogLine], tail: &str) -> Option<u32> {
    log.iter().find_map(|l| {
        let rest = l.text.strip_prefix("store: double ECC error at 0x")?;
        let (hex, t) = rest.split_at(8.min(rest.len()));
        (t == tail)
            .then(|| u32::from_str_radix(hex, 16).ok())
            .flatten()
    })
}

/// Checks one boot after a cut and says what it ran: "old" or "new" (that scene booted from
/// flash; after a repair, with the line naming a double word inside the store), or "erased"
/// (the store erased with the line naming one, and the built-in scene booted). In every case
/// the boot reached the control loop (the `adc:` line comes after the scene, before the tasks
/// start), no reset, and at most `MAX_ECC_ERRORS` ECC errors (each an NMI: not a loop).
fn judge(board: BoardKind, step: &str, b: &Boot, old_id: u32, new_id: u32) -> &'static str {
    let s = board.def().store;
    let erased_line = ecc_line(&b.log, " (a save cut by a power loss); store erased");
    let repaired_line = b.log.iter().find_map(|l| {
        let rest = l.text.strip_prefix("store: double ECC error at 0x")?;
        let (hex, t) = rest.split_at(8.min(rest.len()));
        let n = t
            .strip_prefix(" (a save cut by a power loss); ")?
            .strip_suffix(" double word(s) zeroed, the store repaired")?;
        Some((u32::from_str_radix(hex, 16).ok()?, n.parse::<u32>().ok()?))
    });
    let ctx = || format!("{step}: log\n{}", show(&b.log));
    assert!(
        b.reached_loop,
        "{step}: never reached the control loop (a hang); {}",
        ctx()
    );
    assert_eq!(b.resets, 0, "{step}: the board reset; {}", ctx());
    assert!(
        b.ecc_errors <= MAX_ECC_ERRORS,
        "{step}: {} double ECC errors (NMIs): a loop; {}",
        b.ecc_errors,
        ctx()
    );
    if let Some(at) = erased_line {
        assert!(
            (s.origin..s.end()).contains(&at),
            "{step}: the erase line names 0x{at:08x}, outside the store; {}",
            ctx()
        );
        assert!(
            b.store_after.iter().all(|&x| x == 0xFF),
            "{step}: the store was said erased but is not; {}",
            ctx()
        );
        assert!(
            has(&b.log, "boot: the built-in default scene"),
            "{step}: the store erased, yet no default scene; {}",
            ctx()
        );
        assert!(
            !b.log
                .iter()
                .any(|l| l.text.starts_with("boot: the scene saved in flash")),
            "{step}: a scene read with an ECC error was used; {}",
            ctx()
        );
        return "erased";
    }
    match repaired_line {
        Some((at, n)) => {
            assert!(
                (s.origin..s.end()).contains(&at) && at % 8 == 0,
                "{step}: the repair line names 0x{at:08x}, not a double word of the store; {}",
                ctx()
            );
            // Each double word zeroed raised one error when the scan read it.
            assert!(
                n >= 1 && b.ecc_errors >= n,
                "{step}: {n} double words said zeroed, {} ECC errors raised; {}",
                b.ecc_errors,
                ctx()
            );
            assert_eq!(
                store_word(b, s.origin, at),
                0,
                "{step}: the double word at 0x{at:08x} is not zeros after the repair; {}",
                ctx()
            );
        }
        None => assert_eq!(
            b.ecc_errors,
            0,
            "{step}: an ECC error, yet no repair or erase line; {}",
            ctx()
        ),
    }
    if has(&b.log, &boot_line(old_id)) {
        "old"
    } else if has(&b.log, &boot_line(new_id)) {
        "new"
    } else {
        panic!("{step}: neither the old scene {old_id:08x} nor the new {new_id:08x} booted, and the store was not erased; {}", ctx())
    }
}

/// The double word at `at` of the store's bytes after a boot (`origin` the store's start).
fn store_word(b: &Boot, origin: u32, at: u32) -> u64 {
    let i = (at - origin) as usize;
    b.store_after
        .get(i..i + 8)
        .and_then(|w| w.try_into().ok())
        .map_or(u64::MAX, u64::from_le_bytes)
}

/// Board time each boot runs: past the boot's store load and scene (the `adc:` line comes at
/// ~40 ms on the G474 model), with room for an erase of the whole store (8 pages × 22 ms).
const BOOT_S: f64 = 0.35;

/// The recorded save of the power-cut checks: operations, the store before, old and new ids.
fn recorded_save(board: BoardKind) -> (Vec<Operation>, Vec<u8>, u32, u32) {
    let (_, new_id) = moved();
    // The F446's sector erase takes 1 s of it.
    let duration_s = if board == BoardKind::F446 { 1.8 } else { 0.45 };
    let (o, mut m, before, old_id) = save_that_erases(board, duration_s);
    let answer = replies(&o.link_output)
        .into_iter()
        .find(|r| r.1 == 2)
        .map(|r| r.2);
    assert!(
        matches!(answer, Some(Reply::Saved { scene_id }) if scene_id == new_id),
        "the recorded save was answered {answer:?}"
    );
    let s = board.def().store;
    let ops: Vec<Operation> = operations(&mut m)
        .into_iter()
        .filter(|op| op.addr >= s.origin && op.addr < s.end())
        .collect();
    assert!(
        ops.iter().any(|op| op.erase) && ops.iter().any(|op| !op.erase),
        "the save made no erase or no program: {ops:?}"
    );
    (ops, before, old_id, new_id)
}

/// Boots on the flash a cut at each step `steps` picks from the save's operations (`k` =
/// their count: the save complete), judging each; returns per step: `k`, the outcome, the wall
/// time and the ECC errors the boot raised.
fn cut_and_boot(
    board: BoardKind,
    steps: impl Fn(&[Operation]) -> Vec<usize>,
) -> Vec<(usize, &'static str, f64, u32)> {
    let (ops, before, old_id, new_id) = recorded_save(board);
    let origin = board.def().store.origin;
    let steps = steps(&ops);
    let mut out = Vec::new();
    for &k in steps.iter().filter(|&&k| k <= ops.len()) {
        let (flash, bad) = cut_at(&before, origin, &ops, k);
        let b = boot(board, &flash, &bad, BOOT_S);
        let what = match ops.get(k) {
            Some(op) if op.erase => format!(
                "cut in operation {k} of {} (erase of 0x{:08X})",
                ops.len(),
                op.addr
            ),
            Some(op) => format!(
                "cut in operation {k} of {} (program of 0x{:08X})",
                ops.len(),
                op.addr
            ),
            None => format!("the save complete ({} operations)", ops.len()),
        };
        let verdict = judge(board, &what, &b, old_id, new_id);
        eprintln!(
            "{what}: {verdict} ({} ECC errors, {:.2} s wall)",
            b.ecc_errors, b.wall_s
        );
        out.push((k, verdict, b.wall_s, b.ecc_errors));
    }
    // Whatever is cut, the save complete boots the new scene.
    if steps.iter().any(|&k| k >= ops.len()) {
        assert_eq!(
            out.last().map(|o| o.1),
            Some("new"),
            "the complete save does not boot the new scene"
        );
    }
    out
}

/// G474 (issue #32 B), the must-show: a power cut at every program and erase step of a save
/// that reclaims a page, then a boot on what it left. Every step is run (the save makes ~12
/// operations; each boot is a fresh board for 0.35 s of board time).
#[test]
fn g474_a_power_cut_at_every_step_of_a_save_then_boot() {
    let out = cut_and_boot(BoardKind::G474, |ops| (0..=ops.len()).collect());
    let count = |v: &str| out.iter().filter(|o| o.1 == v).count();
    eprintln!(
        "{} boots: {} old scene, {} new scene, {} store erased; {:.1} s wall in all",
        out.len(),
        count("old"),
        count("new"),
        count("erased"),
        out.iter().map(|o| o.2).sum::<f64>()
    );
    // Nothing is lost: at every cut the old or the new scene boots, the double words a cut left
    // with a bad ECC zeroed at boot (RM0440 §5.7.5: zeros are programmed over any content) and
    // the store repaired; no cut needs the store erased.
    let erased: Vec<usize> = out
        .iter()
        .filter(|o| o.1 == "erased")
        .map(|o| o.0)
        .collect();
    assert!(
        erased.is_empty(),
        "the store was erased (the old scene lost) at the cuts in operations {erased:?}: {out:?}"
    );
    // Every cut leaves a bad double word (`cut_at`), and the boot's scan reads each one.
    assert!(
        out.iter().filter(|o| o.0 < out.len() - 1).all(|o| o.3 >= 1),
        "a cut whose boot raised no ECC error: the ECC model was not exercised: {out:?}"
    );
}

/// F446: the same sweep over its sector-erasing save (39 operations). The F446's flash has no
/// ECC: a cut program leaves a half-programmed word that the store's item CRC refuses, a cut
/// erase the sector as it was (`cut_at`). Every step must boot the old or the new scene.
#[test]
#[ignore = "39 boots of the F446 image, ~40 s of wall time: run with --ignored"]
fn f446_a_power_cut_at_every_step_of_a_save_then_boot() {
    let out = cut_and_boot(BoardKind::F446, |ops| (0..=ops.len()).collect());
    assert!(out.iter().all(|o| o.1 == "old" || o.1 == "new"), "{out:?}");
}
