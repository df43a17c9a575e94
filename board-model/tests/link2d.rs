//! The 2D images' host link and scene store (issue #36, `firmware/src/link2d.rs`) over the
//! modelled UART (F446 USART2, G474 LPUART1), with the 4-wire overlay and a finger: 2D scenes
//! pushed and read back, refusals that change nothing, windows moved and resized live (seen in
//! the stream and on the burst pin), the stream's x and y against the modelled finger, a save
//! that boots after a reboot, and power cuts inside a save.
//!
//! Every expectation is worked out here from the scene files and the finger script, not read
//! from the image: scenes are read with the scene-file reader as `saw push` reads them, edited
//! windows are built here vertex by vertex, f_b comes from the files' `f_b_hz`.
//!
//! Needs `$SAW_FIRMWARE_DIR/<board>-2d.elf` (`TOUCH_2D=1 scripts/build-firmware.sh`, the 2D image,
//! which runs the link; default directory `../firmware/target`; scripts/board-model.sh builds it
//! when missing).

use host_sim::touch::{Finger, Overlay};
use saw_board_model::board::{BoardKind, PIN_BURST_A};
use saw_board_model::machine::Machine;
use saw_board_model::periph::flash_prog::Operation;
use saw_board_model::periph::{Time, TICKS_PER_S};
use saw_board_model::run::{self, LogLine, Options, Outcome, TouchScript};
use saw_core::plane::{Place, PointUm};
use saw_core::touch::plates::{AdcTiming, PlateRc, Schedule};
use saw_link::msg::{
    LinkError, PlaneScene, Record2d, Refused2d, Reply, Request, SceneSource, Sensor,
};
use std::path::PathBuf;
use std::rc::Rc;

/// Both boards' 2D images: the push, read-back and refusal test and the stack checks run on each
/// (the G474's image ran off the start of its 96 KiB RAM at boot until the link task's future
/// went from 25 016 B to 8 824 B, `saw_link::session::Session::on_frame`; then kept 1 568 B of
/// headroom at boot until the boot scene's compile left main's poll frame,
/// `firmware/src/link2d.rs`, `boot_scene`).
const BOTH: [BoardKind; 2] = [BoardKind::F446, BoardKind::G474];
/// The heavier tests (windows edited live, the stream, the save and its power cuts) run on the
/// F446's only: the link task, the session and the store are the same code on both, and CI's
/// time is short.
const BOARDS: [BoardKind; 1] = [BoardKind::F446];
/// The overlay's touch area (scenes/2d-fig12.toml's plate, which the image calibrates to), mm.
const PLATE_MM: (f64, f64) = (95.0, 54.0);
/// The firmware's margin after each phase's conversions (docs/touch.md, "Firmware").
const MARGIN_NS: u64 = 4_000;
/// Least headroom below the deepest stack (the brief's and tests/touch2d.rs's).
const MIN_HEADROOM: u32 = 16 * 1024;

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

/// The board's frame, µs: the core's schedule (default plates, the board's acquisition as
/// saw-boards' `touch_adc` states it) plus the firmware's margin after each of the 4 phases,
/// rounded up.
fn frame_us(board: BoardKind) -> u32 {
    let t = saw_boards::touch::touch_adc(board.def());
    let adc = AdcTiming {
        conversion_ns: t.conversion_ns,
        conversions_position: t.conversions_position,
        conversions_pressure: t.conversions_pressure,
        discard: t.discard,
    };
    let sched = Schedule::new(&PlateRc::DEFAULT, &adc).unwrap();
    (sched.frame_ns() + 4 * MARGIN_NS).div_ceil(1_000) as u32
}

/// A 2D scene file as `saw push` reads it for `board`: its plate and its configuration.
fn plane(board: BoardKind, path: &str) -> PlaneScene {
    let full = concat!(env!("CARGO_MANIFEST_DIR"), "/../").to_string() + path;
    let text = std::fs::read_to_string(&full).unwrap();
    let def = board.def();
    let timer = saw_core::burst::BurstTimer {
        clock_hz: def.burst_timer_clk_hz,
        counter_bits: def.burst_timer_bits,
        max_burst_hz: def.max_burst_hz,
    };
    let config = saw_core::scene_file::load_2d_for_board(path, &text, timer, frame_us(board))
        .unwrap_or_else(|e| panic!("{path}: {e}"));
    let plate_um = saw_core::scene_file::plate_um_of(path, &text).unwrap();
    PlaneScene { plate_um, config }
}

fn fig12(board: BoardKind) -> PlaneScene {
    plane(board, "scenes/2d-fig12.toml")
}

fn largest(board: BoardKind) -> PlaneScene {
    plane(board, "board-model/scenes/2d-largest.toml")
}

fn id(s: &PlaneScene) -> u32 {
    saw_link::plane_scene_id(s)
}

/// `scene` with window `w`'s outline replaced by the rectangle `lo`–`hi` (mm), its vertices in
/// the order the file gave them (lower left, lower right, upper right, upper left).
fn with_rect(scene: &PlaneScene, w: usize, lo: (i32, i32), hi: (i32, i32)) -> PlaneScene {
    let mut s = scene.clone();
    let v = &mut s.config.scene.windows[w].outline.vertices;
    let old: Vec<PointUm> = v.iter().copied().collect();
    let (x0, y0) = (
        old.iter().map(|p| p.x_um).min().unwrap(),
        old.iter().map(|p| p.y_um).min().unwrap(),
    );
    for p in v.iter_mut() {
        let x = if p.x_um == x0 {
            lo.0 * 1000
        } else {
            hi.0 * 1000
        };
        let y = if p.y_um == y0 {
            lo.1 * 1000
        } else {
            hi.1 * 1000
        };
        *p = PointUm::new(x, y);
    }
    s
}

fn at(mm: (f64, f64)) -> Option<Finger> {
    Some(Finger {
        x: mm.0 / PLATE_MM.0,
        y: mm.1 / PLATE_MM.1,
        force_n: 1.0,
    })
}

fn frame(seq: u32, req: &Request) -> Vec<u8> {
    saw_board_model::check::request_frame(seq, req)
}

/// Every message the board sent: (time its last byte left, sequence number, reply).
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

/// The answer to request `seq` (stream frames have their own numbering: left out).
fn answer(o: &Outcome, seq: u32) -> (Time, Reply) {
    replies(&o.link_output)
        .into_iter()
        .find(|(_, s, r)| *s == seq && !matches!(r, Reply::Stream2d(_)))
        .map(|(t, _, r)| (t, r))
        .unwrap_or_else(|| panic!("no answer to request {seq}; log:\n{}", show(&o.log)))
}

/// Every 2D stream record, in order.
fn records(o: &Outcome) -> Vec<Record2d> {
    replies(&o.link_output)
        .into_iter()
        .filter_map(|(_, _, r)| match r {
            Reply::Stream2d(s) => Some(s.records.into_iter().collect::<Vec<_>>()),
            _ => None,
        })
        .flatten()
        .collect()
}

fn show(log: &[LogLine]) -> String {
    log.iter()
        .map(|l| format!("  {:.6} {} {}", l.t_s, l.level, l.text))
        .collect::<Vec<_>>()
        .join("\n")
}

fn secs(t: Time) -> f64 {
    t as f64 / TICKS_PER_S as f64
}

/// A run of `board`'s 2D image for `secs` with the finger at `finger(t)` and `input` on the link.
fn run2d(
    board: BoardKind,
    secs: f64,
    finger: impl Fn(f64) -> Option<Finger> + 'static,
    input: Vec<(f64, Vec<u8>)>,
    flash: Option<Vec<u8>>,
) -> (Outcome, Machine) {
    let mut o = Options::new(board, &elf(board), secs);
    o.touch = Some(TouchScript {
        overlay: Overlay::default(),
        seed: 11,
        finger: Rc::new(finger),
    });
    o.link_input = input;
    if let Some(f) = flash {
        o.flash_preload = vec![(board.def().store.origin, f)];
    }
    let (out, m) = run::run(&o).expect("the run starts");
    assert!(
        out.stop.is_none(),
        "{board:?}: the run stopped: {:?}",
        out.stop
    );
    (out, m)
}

fn check_stack(board: BoardKind, o: &Outcome, what: &str) {
    let s = o.stack.expect("the image's stack region");
    eprintln!(
        "{board:?} {what}: deepest stack {} B of {} B reserved, headroom {} B",
        s.deepest(),
        s.region.reserved(),
        s.headroom()
    );
    assert!(
        s.headroom() >= MIN_HEADROOM,
        "{board:?} {what}: stack headroom {} B < 16 KiB",
        s.headroom()
    );
}

/// The finger resting on fig12's background, between windows 0 and 1.
const REST_MM: (f64, f64) = (32.5, 27.0);

/// Push and read back: the built-in scene reads back as scenes/2d-fig12.toml; the largest 2D
/// scene (1.4 KB on the wire, more than the link's 1 KiB receive ring) is applied and reads back
/// equal; then a plate too large, a configuration the controller refuses, an oversized frame and
/// a request that does not decode are each refused with their sentence, and the largest scene
/// still runs: read back, and every record after them carries its id. The deepest stack over the
/// run keeps 16 KiB of headroom.
#[test]
fn a_2d_scene_pushed_reads_back_and_a_bad_one_changes_nothing() {
    for board in BOTH {
        let (fig, big) = (fig12(board), largest(board));
        let mut bad_config = fig.clone();
        // Below twice the frame period: the controller's stale-limit rule.
        bad_config.config.stale_after_us = 1;
        let tall = plane_unchecked("scenes/2d-concave.toml", board);
        // A body that is not a request's: variant 11 (LoadScene2d) followed by junk.
        let malformed = {
            use saw_link::msg::{Header, PROTOCOL_VERSION};
            let mut out = vec![0u8; saw_link::frame::MAX_ENCODED + 1];
            let n = saw_link::frame::encode(
                &Header {
                    version: PROTOCOL_VERSION,
                    seq: 8,
                },
                &(11u8, [0xFFu8; 12]),
                &mut out[1..],
            )
            .unwrap();
            out.truncate(n + 1);
            out
        };
        let mut oversize = vec![0x55u8; saw_link::frame::MAX_ENCODED + 64];
        oversize.push(0);
        // A 1D scene as `saw push scenes/default.toml` sends it, and a 1D texture edit: the 2D
        // image leaves their bodies unread (saw-link's `plane-only`) and refuses them.
        let line = {
            let text = std::fs::read_to_string(
                concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/default.toml"),
            )
            .unwrap();
            let def = board.def();
            let timer = saw_core::burst::BurstTimer {
                clock_hz: def.burst_timer_clk_hz,
                counter_bits: def.burst_timer_bits,
                max_burst_hz: def.max_burst_hz,
            };
            saw_core::scene_file::load_for_board("scenes/default.toml", &text, timer, 100)
                .unwrap()
        };
        let texture = line.scene.textures[0];
        let input = vec![
            (0.30, frame(1, &Request::Hello)),
            (0.31, frame(2, &Request::Sensor)),
            (0.32, frame(3, &Request::GetScene)),
            (0.34, frame(4, &Request::LoadScene2d(big.clone()))),
            (0.42, frame(5, &Request::GetScene)),
            (0.45, frame(6, &Request::LoadScene2d(tall.clone()))),
            (0.48, frame(7, &Request::LoadScene2d(bad_config.clone()))),
            (0.50, malformed),
            (0.52, oversize),
            (0.53, frame(11, &Request::LoadScene(line))),
            (0.54, frame(12, &Request::SetTexture { region: 0, texture })),
            (0.56, frame(9, &Request::GetScene)),
            (0.58, frame(10, &Request::Stream { every_samples: 1 })),
        ];
        let (o, _m) = run2d(
            board,
            0.70,
            |t| if t > 0.05 { at(REST_MM) } else { None },
            input,
            None,
        );
        let ctx = || show(&o.log);
        match answer(&o, 1).1 {
            Reply::Hello(h) => {
                assert_eq!(h.board.as_str(), board.name(), "{board:?}");
                assert_eq!(h.scene_id, id(&fig), "{board:?}: hello's scene");
                assert_eq!(h.sample_rate_hz, 1_000_000 / frame_us(board), "{board:?}");
            }
            r => panic!("{board:?}: hello answered {r:?}"),
        }
        assert_eq!(
            answer(&o, 2).1,
            Reply::Sensor(Sensor::FourWire {
                plate_um: (95_000, 54_000)
            }),
            "{board:?}"
        );
        assert_eq!(
            answer(&o, 3).1,
            Reply::Scene2d {
                scene_id: id(&fig),
                source: SceneSource::BuildTime,
                scene: fig.clone()
            },
            "{board:?}: the built-in scene read back; log:\n{}",
            ctx()
        );
        assert_eq!(
            answer(&o, 4).1,
            Reply::Applied { scene_id: id(&big) },
            "{board:?}; log:\n{}",
            ctx()
        );
        let back = Reply::Scene2d {
            scene_id: id(&big),
            source: SceneSource::Link,
            scene: big.clone(),
        };
        assert_eq!(
            answer(&o, 5).1,
            back,
            "{board:?}: the pushed scene read back"
        );
        let refused = |seq: u32| match answer(&o, seq).1 {
            Reply::Refused2d(r) => r,
            r => panic!("{board:?}: request {seq} answered {r:?}"),
        };
        let r = refused(6);
        assert_eq!(
            r.to_string(),
            "the scene's plate 80 x 60 mm does not fit this board's overlay 95 x 54 mm",
            "{board:?}"
        );
        let r = refused(7);
        assert!(matches!(r, Refused2d::Config(_)), "{board:?}: {r:?}");
        let sentence = r.to_string();
        assert!(
            sentence.starts_with("stale limit 0.001 ms must be at least two sample periods"),
            "{board:?}: {sentence}"
        );
        eprintln!("{board:?}: refused: {sentence}");
        assert!(
            matches!(answer(&o, 8).1, Reply::Error(LinkError::Malformed)),
            "{board:?}"
        );
        let oversized = replies(&o.link_output)
            .into_iter()
            .any(|(_, _, r)| matches!(r, Reply::Error(LinkError::Oversize { .. })));
        assert!(oversized, "{board:?}: the oversized frame was not refused");
        for seq in [11, 12] {
            let r = refused(seq);
            assert!(
                matches!(r, Refused2d::WrongSensor { .. }),
                "{board:?}: request {seq}: {r:?}"
            );
            assert_eq!(
                r.to_string(),
                "this board reads the 4-wire touch overlay, 95 x 54 mm (2D scenes): a 1D scene \
                 (regions, boundaries; no [sensor] table) needs a board with the slide rheostat",
                "{board:?}"
            );
        }
        assert_eq!(
            answer(&o, 9).1,
            back,
            "{board:?}: the refusals changed the scene"
        );
        // The scene keeps running: every streamed frame is the largest scene's, change 1, the
        // finger where it rests.
        let (t_stream, _) = answer(&o, 10);
        let recs = records(&o);
        assert!(recs.len() > 100, "{board:?}: {} records", recs.len());
        let xs: Vec<f64> = recs
            .iter()
            .map(|r| {
                assert_eq!((r.scene_id, r.change), (id(&big), 1), "{board:?}: {r:?}");
                let p = r.position.expect("pressed, no fault");
                assert!(
                    (p.y_um as f64 / 1e3 - REST_MM.1).abs() < 0.3,
                    "{board:?}: {p:?} for a finger at {REST_MM:?} mm"
                );
                p.x_um as f64 / 1e3
            })
            .collect();
        // x: steady within 0.3 mm; its offset from the finger is the built-in calibration's
        // (build.rs's design divider against the overlay model), reported, not asserted here.
        // x within 0.3 mm of the finger but for a few frames (≤ 2 %) whose X phase reads
        // wrong: the acquisition's (a late plate switch: docs/board-model.md, "Issue #36",
        // the link), counted and reported here.
        let off = xs.iter().filter(|x| (*x - REST_MM.0).abs() >= 0.3).count();
        let worst = xs.iter().map(|x| (x - REST_MM.0).abs()).fold(0.0, f64::max);
        eprintln!(
            "{board:?}: at rest {off} of {} records' x more than 0.3 mm off (worst {worst:.3} mm)",
            xs.len()
        );
        assert!(
            off * 50 <= xs.len(),
            "{board:?}: {off} of {} records' x off the finger",
            xs.len()
        );
        eprintln!(
            "{board:?}: {} records from {:.3} s, every frame; answer to the 1.4 KB push {:.2} ms after its last byte",
            recs.len(),
            secs(t_stream),
            (answer(&o, 4).0 - o.link_input_done[3]) as f64 * 1e3 / TICKS_PER_S as f64
        );
        let s = o.stack.expect("the image's stack region");
        eprintln!(
            "{board:?} pushes: deepest stack {} B of {} B reserved, headroom {} B",
            s.deepest(),
            s.region.reserved(),
            s.headroom()
        );
    }
}

/// The deepest stack over a push of the largest scene keeps 16 KiB of headroom: F446 62 824 B of
/// 95 264 B, 32 440 B (18 112 B while the link task's future was 25 KB; 13 760 B before its
/// wrapper went, firmware/src/link.rs).
#[test]
fn pushes_keep_16_kib_of_stack_headroom() {
    for board in BOTH {
        let input = vec![(0.34, frame(1, &Request::LoadScene2d(largest(board))))];
        let (o, _m) = run2d(
            board,
            0.45,
            |t| if t > 0.05 { at(REST_MM) } else { None },
            input,
            None,
        );
        check_stack(board, &o, "a push of the largest scene");
    }
}

/// The G474's 2D image boots and answers hello with 16 KiB of stack headroom (it overflowed its
/// stack at boot while the link task's future was 25 KB; then kept 1 568 B with the boot scene
/// compiled under main's poll frame, 60 920 B of 62 488 B: now the control loop compiles it on
/// an idle thread mode, `firmware/src/link2d.rs`, `boot_scene`). The largest scene's boot is
/// tests/touch2d.rs's stack check.
#[test]
fn g474_2d_image_boots_with_the_link() {
    let board = BoardKind::G474;
    let (o, _m) = run2d(
        board,
        0.35,
        |_| None,
        vec![(0.30, frame(1, &Request::Hello))],
        None,
    );
    assert!(matches!(answer(&o, 1).1, Reply::Hello(_)));
    check_stack(board, &o, "boot and hello");
}

/// A scene file read without the board's checks (its plate may not fit the board).
fn plane_unchecked(path: &str, board: BoardKind) -> PlaneScene {
    let full = concat!(env!("CARGO_MANIFEST_DIR"), "/../").to_string() + path;
    let text = std::fs::read_to_string(&full).unwrap();
    let def = board.def();
    let timer = saw_core::burst::BurstTimer {
        clock_hz: def.burst_timer_clk_hz,
        counter_bits: def.burst_timer_bits,
        max_burst_hz: def.max_burst_hz,
    };
    let config =
        saw_core::scene_file::load_2d_for_board(path, &text, timer, frame_us(board)).unwrap();
    PlaneScene {
        plate_um: saw_core::scene_file::plate_um_of(path, &text).unwrap(),
        config,
    }
}

/// PA0's rising edges between `from` and `to`: of the intervals between them, the one nearest
/// `want` (s). A frame whose position reads wrong (see the push test) can switch the window for a
/// frame and restart the burst, which adds a short interval; the texture's own period is still
/// there between the others.
fn burst_period(o: &Outcome, from: Time, to: Time, want: f64) -> Option<f64> {
    let rises: Vec<Time> = o.pins[PIN_BURST_A]
        .iter()
        .filter(|e| e.high && e.at >= from && e.at < to)
        .map(|e| e.at)
        .collect();
    rises
        .windows(2)
        .map(|w| secs(w[1] - w[0]))
        .min_by(|a, b| (a - want).abs().total_cmp(&(b - want).abs()))
}

/// Windows moved and resized live, the finger resting at (32.5, 27) mm on fig12's background
/// (1 kHz): window 0 resized to (5, 5)–(34, 49) mm takes the finger (20 Hz), moved to x = 36 mm
/// leaves it on the background (1 kHz), window 1 moved to x = 30 mm takes it (80 Hz). Each edit
/// answers the id of the scene built here with the same vertices; the stream's records carry that
/// id, the next change count and the window under the finger; the burst pin PA0 runs at that
/// window's f_b (median period between rises within 2 %).
#[test]
fn windows_moved_and_resized_live_change_what_renders() {
    for board in BOARDS {
        let fig = fig12(board);
        let a = with_rect(&fig, 0, (5, 5), (34, 49));
        let b = with_rect(&a, 0, (36, 5), (65, 49));
        let c = with_rect(&b, 1, (30, 5), (55, 49));
        let p = |x: i32, y: i32| PointUm::new(x * 1000, y * 1000);
        let steps = [(0.40, 2u32), (0.62, 3), (0.74, 4)];
        let input = vec![
            (0.30, frame(1, &Request::Stream { every_samples: 4 })),
            (
                steps[0].0,
                frame(
                    2,
                    &Request::ResizeWindow {
                        window: 0,
                        lo: p(5, 5),
                        hi: p(34, 49),
                    },
                ),
            ),
            (
                steps[1].0,
                frame(
                    3,
                    &Request::MoveWindow {
                        window: 0,
                        to: p(36, 5),
                    },
                ),
            ),
            (
                steps[2].0,
                frame(
                    4,
                    &Request::MoveWindow {
                        window: 1,
                        to: p(30, 5),
                    },
                ),
            ),
        ];
        let (o, _m) = run2d(
            board,
            0.90,
            |t| if t > 0.05 { at(REST_MM) } else { None },
            input,
            None,
        );
        let ctx = || show(&o.log);
        // (scene, its id's answer time, the window under the finger, f_b in Hz from the files).
        let expect = [
            (&fig, None, Place::Background, 1000.0),
            (&a, Some(2u32), Place::Window(0), 20.0),
            (&b, Some(3), Place::Background, 1000.0),
            (&c, Some(4), Place::Window(1), 80.0),
        ];
        let recs = records(&o);
        let mut from = answer(&o, 1).0;
        for (k, (scene, seq, place, f_b)) in expect.iter().enumerate() {
            if let Some(seq) = seq {
                let (t, r) = answer(&o, *seq);
                assert_eq!(
                    r,
                    Reply::Applied {
                        scene_id: id(scene)
                    },
                    "{board:?}: edit {k}; log:\n{}",
                    ctx()
                );
                from = t;
            }
            let to = match expect.get(k + 1).and_then(|e| e.1) {
                Some(seq) => o.link_input_done[seq as usize - 1],
                None => o.end,
            };
            let mine: Vec<&Record2d> = recs.iter().filter(|r| r.scene_id == id(scene)).collect();
            assert!(
                mine.len() > 5,
                "{board:?}: step {k}: {} records of scene {:08x}",
                mine.len(),
                id(scene)
            );
            for r in &mine {
                assert_eq!(r.change, k as u32, "{board:?}: step {k}: {r:?}");
            }
            // The window under the finger in every record (2026-11-30: 0 of 85, 186, 102, 131;
            // earlier acquisitions put up to 5 % elsewhere; see the stream test).
            let elsewhere = mine.iter().filter(|r| r.place != Some(*place)).count();
            eprintln!(
                "{board:?}: step {k}: {elsewhere} of {} records not in {place:?}",
                mine.len()
            );
            assert_eq!(
                elsewhere,
                0,
                "{board:?}: step {k}: {elsewhere} of {} records not in {place:?}",
                mine.len()
            );
            // The burst line from 20 ms after the answer (the first periods after a scene
            // change start anew) to the next edit's request.
            let want = 1.0 / f_b;
            let period = burst_period(&o, from + TICKS_PER_S / 50, to, want)
                .unwrap_or_else(|| panic!("{board:?}: step {k}: no burst on PA0"));
            eprintln!(
                "{board:?}: step {k}: {:?}, PA0 period {:.4} ms (want {:.4})",
                place,
                period * 1e3,
                want * 1e3
            );
            // Every step, the 20 Hz one too (50.0000 ms measured 2026-11-30: no frame reads a
            // wrong position and restarts its burst now, which earlier kept a 50 ms period from
            // completing).
            assert!(
                (period - want).abs() <= 0.02 * want,
                "{board:?}: step {k}: PA0 period {period} s, want {want} s ({f_b} Hz)"
            );
        }
    }
}

/// The stream's x and y against the modelled finger: lifted until 0.35 s (records say lifted,
/// no position), then a stroke from (10, 40) mm along +x at 50 mm/s. Every pressed record's y
/// is within 0.3 mm of 40; x against the record's time fits a line whose slope is the finger's
/// 50 mm/s within 1 %, every record within 0.3 mm of it.
#[test]
fn the_stream_carries_the_fingers_x_and_y() {
    for board in BOARDS {
        const START_S: f64 = 0.35;
        let finger = |t: f64| {
            if t < START_S {
                None
            } else {
                at((10.0 + 50.0 * (t - START_S), 40.0))
            }
        };
        let input = vec![(0.30, frame(1, &Request::Stream { every_samples: 2 }))];
        let (o, _m) = run2d(board, 0.80, finger, input, None);
        let recs = records(&o);
        let lifted = recs.iter().filter(|r| r.lifted).count();
        assert!(lifted > 10, "{board:?}: {lifted} lifted records");
        assert!(
            recs.iter()
                .filter(|r| r.lifted)
                .all(|r| r.position.is_none()),
            "{board:?}"
        );
        // Pressed records past the landing run (the position is reported from the first).
        let pts: Vec<(f64, f64, f64)> = recs
            .iter()
            .filter_map(|r| {
                r.position.map(|p| {
                    (
                        r.time_us as f64 * 1e-6,
                        p.x_um as f64 / 1e3,
                        p.y_um as f64 / 1e3,
                    )
                })
            })
            // Past the landing (the contact's first frames, whatever the clock's offset).
            .filter(|p| p.0 > START_S + 0.02)
            .collect();
        assert!(pts.len() > 200, "{board:?}: {} pressed records", pts.len());
        let n = pts.len() as f64;
        let (mt, mx) = (
            pts.iter().map(|p| p.0).sum::<f64>() / n,
            pts.iter().map(|p| p.1).sum::<f64>() / n,
        );
        let slope = pts.iter().map(|p| (p.0 - mt) * (p.1 - mx)).sum::<f64>()
            / pts.iter().map(|p| (p.0 - mt).powi(2)).sum::<f64>();
        let worst_x = pts
            .iter()
            .map(|p| (p.1 - (mx + slope * (p.0 - mt))).abs())
            .fold(0.0, f64::max);
        let worst_y = pts.iter().map(|p| (p.2 - 40.0).abs()).fold(0.0, f64::max);
        eprintln!(
            "{board:?}: {} pressed records, x slope {slope:.3} mm/s, worst x {worst_x:.3} mm off the fit, worst y {worst_y:.3} mm off 40",
            pts.len()
        );
        let off = pts
            .iter()
            .filter(|p| (p.1 - (mx + slope * (p.0 - mt))).abs() >= 0.3 || (p.2 - 40.0).abs() >= 0.3)
            .count();
        eprintln!(
            "{board:?}: {off} of {} pressed records more than 0.3 mm off the finger's line",
            pts.len()
        );
        // The stream's period: a record every `every_samples` frames, stamped at the frame's
        // hand-over (embassy's µs clock).
        let gaps: Vec<i64> = recs
            .windows(2)
            .map(|w| w[1].time_us as i64 - w[0].time_us as i64)
            .collect();
        let (gmin, gmax) = (gaps.iter().min().unwrap(), gaps.iter().max().unwrap());
        eprintln!(
            "{board:?}: {} records, {gmin}..{gmax} µs apart (2 frames: {} µs)",
            recs.len(),
            2 * frame_us(board)
        );
        assert!((slope - 50.0).abs() < 0.5, "{board:?}: slope {slope} mm/s");
        // Every record on the finger (2026-11-30: 0 of 717 off by 0.3 mm, worst x 0.064 mm off
        // the fit, y 0.025 mm; 7–16 of ~590 were off with the 2 µs margin and 16-conversion
        // phases; the same 0 with the DMA count check planted out: no frame of this run is
        // mixed now, the acquisition's timing removed them): x within 0.1 mm, y within 0.05 mm
        // (the measured, 1.5× and 2×).
        assert_eq!(off, 0, "{board:?}: {off} of {} records off", pts.len());
        assert!(worst_x <= 0.1, "{board:?}: worst x {worst_x} mm off the fit");
        assert!(worst_y <= 0.05, "{board:?}: worst y {worst_y} mm off 40");
        // And steady: every record two frames after the last (592 µs on the F446: all 840
        // measured), within the µs clock's 1 µs.
        let want = 2 * frame_us(board) as i64;
        assert!(
            (gmin - want).abs() <= 1 && (gmax - want).abs() <= 1,
            "{board:?}: records {gmin}..{gmax} µs apart, want {want}"
        );
        // The one edge crossed, window 0's right side (x = 30 mm: edge 1, fig. 12's outlines
        // numbered from each first vertex), reported by one record, whichever of the two frames
        // it fired on (the tap's `EdgeLatch`; the stream skips every other frame).
        let edges: Vec<(f64, u8)> = recs
            .iter()
            .filter_map(|r| r.edge.map(|e| (r.time_us as f64 * 1e-6, e)))
            .collect();
        eprintln!("{board:?}: edges in the records {edges:?}");
        assert!(
            edges.len() == 1 && edges[0].1 == 1 && (0.70..0.80).contains(&edges[0].0),
            "{board:?}: edges in the records {edges:?}"
        );
        // And the time axis is the board's: the fit puts the finger's start (x = 10 mm) at 0.35
        // s of board time less the time driver's start after reset (a few ms).
        let t10 = mt + (10.0 - mx) / slope;
        assert!(
            (t10 - START_S).abs() < 0.01,
            "{board:?}: x = 10 mm at {t10} s"
        );
    }
}

fn operations(m: &mut Machine) -> Vec<Operation> {
    let (fi, prog) = (m.sim().chip.flash_if, m.sim().chip.flash_prog);
    prog(&mut *m.sim_mut().periphs[fi].p).operations().to_vec()
}

fn store_bytes(m: &Machine, board: BoardKind) -> Vec<u8> {
    let s = board.def().store;
    let mut b = vec![0u8; s.bytes as usize];
    m.uc.mem_read(s.origin as u64, &mut b)
        .expect("the store is mapped");
    b
}

fn boot_line(id: u32) -> String {
    format!("boot: the 2D scene saved in flash (id {id:08x})")
}

/// The earlier saves' scenes: fig12 with window 0's right side at 30 + i × 0.1 mm (i mod 30).
fn earlier(board: BoardKind, i: usize) -> PlaneScene {
    let right = 30_000 + (i as i32 % 30) * 100;
    let mut s = fig12(board);
    for v in s.config.scene.windows[0].outline.vertices.iter_mut() {
        if v.x_um == 30_000 {
            v.x_um = right;
        }
    }
    s
}

/// The save the power-cut checks record: from a store filled to its next erase (the last save's
/// scene boots), window 1 moved to x = 36 mm and saved. Returns the run, its machine, the store
/// before, the old and the new scene.
fn save_that_erases(board: BoardKind) -> (Outcome, Machine, Vec<u8>, PlaneScene, PlaneScene) {
    let def = board.def();
    let (image, last, saves) =
        saw_board_model::store_image::before_an_erase_2d(def, |i| earlier(board, i))
            .expect("a store image");
    eprintln!("{board:?}: the store holds {saves} saves of a 2D scene before the next must erase");
    let new = with_rect(&last.scene, 1, (36, 5), (61, 49));
    let input = vec![
        (
            0.30,
            frame(
                1,
                &Request::MoveWindow {
                    window: 1,
                    to: PointUm::new(36_000, 5_000),
                },
            ),
        ),
        (0.33, frame(2, &Request::Save)),
    ];
    // The F446's sector erase takes 1 s of it.
    let secs = if board == BoardKind::F446 { 1.7 } else { 0.6 };
    let (o, m) = run2d(board, secs, |_| at(REST_MM), input, Some(image.clone()));
    (o, m, image, last.scene, new)
}

/// Save and reboot: from a store filled to its next erase, the board boots the last 2D scene
/// saved; window 1 is moved and saved (answered `Saved` with the moved scene's id, RF arm low
/// through every flash operation); a fresh board on the flash it left boots that scene (its log
/// line), reads it back with source `Saved`, and the 1D image's store is untouched by it (the
/// tag). Reports the save's time from the request's last byte to the answer's, against saw's
/// `SAVE_TIMEOUT` (4 s).
#[test]
fn a_saved_2d_scene_boots_after_a_reboot() {
    for board in BOARDS {
        let (o, mut m, _before, old, new) = save_that_erases(board);
        let ctx = || show(&o.log);
        assert!(
            o.log.iter().any(|l| l.text == boot_line(id(&old))),
            "{board:?}: did not boot the stored scene; log:\n{}",
            ctx()
        );
        assert_eq!(
            answer(&o, 1).1,
            Reply::Applied { scene_id: id(&new) },
            "{board:?}"
        );
        let (t_saved, r) = answer(&o, 2);
        assert_eq!(
            r,
            Reply::Saved { scene_id: id(&new) },
            "{board:?}; log:\n{}",
            ctx()
        );
        let save_s = secs(t_saved - o.link_input_done[1]);
        let ops: Vec<Operation> = operations(&mut m)
            .into_iter()
            .filter(|op| op.addr >= board.def().store.origin && op.addr < board.def().store.end())
            .collect();
        let erases = ops.iter().filter(|op| op.erase).count();
        // RF arm (PB5) low from before the first operation to after the last.
        let (first, last) = (ops.first().unwrap().start, ops.last().unwrap().end);
        let arm = &o.pins[saw_board_model::board::PIN_RF_ARM];
        let level_at = |t: Time| {
            arm.iter()
                .take_while(|e| e.at <= t)
                .last()
                .is_some_and(|e| e.high)
        };
        assert!(
            !level_at(first) && !arm.iter().any(|e| e.at > first && e.at < last && e.high),
            "{board:?}: RF arm high during the save"
        );
        eprintln!(
            "{board:?}: save answered {:.1} ms after its request ({} flash operations, {erases} erase(s)); saw waits {} ms",
            save_s * 1e3,
            ops.len(),
            4000
        );
        assert!(erases >= 1, "{board:?}: the save erased nothing");
        assert!(
            save_s < 4.0 / 2.0,
            "{board:?}: the save took {save_s} s of board time"
        );
        // Reboot on the flash left.
        let flash = store_bytes(&m, board);
        let (o2, _m2) = run2d(
            board,
            0.40,
            |_| at(REST_MM),
            vec![(0.30, frame(1, &Request::GetScene))],
            Some(flash),
        );
        assert!(
            o2.log.iter().any(|l| l.text == boot_line(id(&new))),
            "{board:?}: after the reboot; log:\n{}",
            show(&o2.log)
        );
        assert_eq!(
            answer(&o2, 1).1,
            Reply::Scene2d {
                scene_id: id(&new),
                source: SceneSource::Saved,
                scene: new.clone()
            },
            "{board:?}"
        );
    }
}

/// The flash a power cut in operation `k` of `ops` leaves over `before` (as tests/flash.rs's
/// `cut_at`: the operations before done, operation `k` half done: a program's first half
/// written, an erase's range left as it was; on the G474 the cut double words marked ECC-bad).
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

/// A power cut inside the save: for the erase, the first and last few operations and every
/// `stride`-th between, a fresh board boots on the flash the cut leaves (G474: the cut double
/// words ECC-bad) and runs the old 2D scene or the new one, without a reset; the complete save
/// boots the new one.
#[test]
fn a_power_cut_in_a_2d_save_leaves_the_old_scene_or_the_new() {
    for board in BOARDS {
        let (_o, mut m, before, old, new) = save_that_erases(board);
        let s = board.def().store;
        let ops: Vec<Operation> = operations(&mut m)
            .into_iter()
            .filter(|op| op.addr >= s.origin && op.addr < s.end())
            .collect();
        let n = ops.len();
        let stride = (n / 12).max(1);
        let mut steps: Vec<usize> = (0..n)
            .filter(|k| *k < 3 || *k + 3 > n || k % stride == 0 || ops[*k].erase)
            .collect();
        steps.push(n);
        steps.dedup();
        let (mut olds, mut news) = (0, 0);
        for &k in &steps {
            let (flash, bad) = cut_at(&before, s.origin, &ops, k);
            let image = elf(board);
            let panel = Rc::new(std::cell::RefCell::new(saw_board_model::touch::Panel::new(
                board.def(),
                Overlay::default(),
                5,
                Rc::new(|_| None),
            )));
            let mut mm = saw_board_model::board::build_with(
                board,
                &image,
                Box::new(|_t: Time| 2048),
                Some(panel),
            )
            .unwrap();
            mm.preload_flash(s.origin, &flash).unwrap();
            if board == BoardKind::G474 {
                for a in &bad {
                    mm.mark_flash_ecc_bad(*a).unwrap();
                }
            }
            let stop = mm.run_until((0.35 * TICKS_PER_S as f64) as Time);
            assert!(stop.is_none(), "{board:?}: cut {k}: {stop:?}");
            let log = run::decode(&image, &mm.sim().log).unwrap();
            assert!(
                mm.sim().resets.is_empty(),
                "{board:?}: cut {k}: a reset; log:\n{}",
                show(&log)
            );
            let what = if log.iter().any(|l| l.text == boot_line(id(&old))) {
                olds += 1;
                "old"
            } else if log.iter().any(|l| l.text == boot_line(id(&new))) {
                news += 1;
                "new"
            } else {
                panic!("{board:?}: cut in operation {k} of {n}: neither the old scene nor the new booted; log:\n{}", show(&log))
            };
            eprintln!(
                "{board:?}: cut in operation {k} of {n}{}: {what}",
                if ops.get(k).is_some_and(|op| op.erase) {
                    " (erase)"
                } else {
                    ""
                }
            );
            if k == n {
                assert_eq!(what, "new", "{board:?}: the complete save");
            }
        }
        eprintln!("{board:?}: {} cuts: {olds} old, {news} new", steps.len());
    }
}
