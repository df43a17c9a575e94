//! The plane's fuzz bodies (issue #36), shared by the fuzz targets (`fuzz_targets/link_bytes_2d.rs`,
//! `scene_file_2d.rs`, `controller2d.rs`) and the corpus replay of `cargo test -p saw-tests --test
//! fuzz_corpus_2d`, each of which includes this file by `#[path]`: the replay runs exactly the
//! code the fuzzer ran (the 1D targets' bodies are in `saw_link::testing`, which the link owns).
//! Each body panics on what it checks, never otherwise.
#![allow(dead_code)] // each target uses one body

use std::sync::OnceLock;

use embassy_futures::block_on;
use saw_core::scene_file::{load_2d_for_board, plate_um_of, sensor_of, to_scene_file_2d};
use saw_link::frame::{self, Receiver, MAX_ENCODED};
use saw_link::msg::{Header, PlaneScene, Reply, SceneSource};
use saw_link::session::{Session, Stamp};
use saw_link::testing::{PlaneBoard, FRAME_US, ID_2D, PLATE_UM, TIMER};

// ---------------------------------------------------------------------------------------------
// link_bytes_2d

/// What [`link_bytes_2d`] saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fed {
    /// Frames answered.
    pub replies: u32,
    /// Replies that were errors or refusals.
    pub refused: u32,
}

/// `scenes/2d-fig12.toml` for the F446, read once: reading the file and dry-running it for
/// every input (as `session_2d` and `PlaneBoard::new` each do) took most of an execution
/// (720 executions/s).
fn fig12() -> &'static PlaneScene {
    static SCENE: OnceLock<PlaneScene> = OnceLock::new();
    SCENE.get_or_init(saw_link::testing::fig12)
}

/// `saw_link::testing::session_2d` and `PlaneBoard::new`, over the scene read once.
fn board_2d() -> (Session, PlaneBoard) {
    let scene = fig12();
    let mut ctrl = saw_core::plane::Controller2d::new(TIMER, FRAME_US).expect("the F446's timer");
    ctrl.load(&scene.config).expect("fig. 12 loads");
    let board = PlaneBoard {
        ctrl,
        every: 0,
        saved: None,
        stamp: Stamp::default(),
        now_us: 0,
        applied_1d: 0,
    };
    let session = Session::new_2d(ID_2D, PLATE_UM, scene.clone(), SceneSource::BuildTime);
    (session, board)
}

/// Bytes from outside as a board with the touch overlay takes them: `saw_link::testing::
/// link_bytes`' two doors (first byte even: the line through the frame receiver; odd: one
/// frame's header and body), into the session of a 2D board (`session_2d`, fig. 12 on the
/// 95 × 54 mm overlay) over a real `Controller2d` (`PlaneBoard`). Checked on every frame: the
/// reply encodes as the board sends it; a refusal (a bad frame, `Refused`, `Refused2d`) leaves
/// the session's scene and change count as they were; an `Applied` names the scene now in force;
/// the session never hands the 2D board a 1D scene.
pub fn link_bytes_2d(data: &[u8]) -> Fed {
    let (mut s, mut board) = board_2d();
    let mut fed = Fed::default();
    let mut answer = |s: &mut saw_link::session::Session,
                      board: &mut PlaneBoard,
                      payload: Option<&[u8]>,
                      bad: Option<saw_link::msg::LinkError>| {
        let before = s.stamp();
        let (h, r): (Header, Reply) = match (payload, bad) {
            (Some(p), _) => block_on(s.on_frame(board, p)),
            (None, Some(e)) => s.on_bad_frame(None, e),
            (None, None) => return,
        };
        fed.replies += 1;
        let mut wire = [0u8; MAX_ENCODED];
        // A reply too big for a frame is the board's bug, not the input's: it must encode.
        frame::encode(&h, &r, &mut wire).expect("every reply fits a frame");
        match r {
            Reply::Error(_) | Reply::Refused(_) | Reply::Refused2d(_) => {
                fed.refused += 1;
                assert_eq!(s.stamp(), before, "a refusal changed the scene: {r:?}");
            }
            Reply::Applied { scene_id } => {
                assert_eq!(s.stamp().scene_id, scene_id, "applied, but not in force");
            }
            _ => {}
        }
        assert_eq!(
            board.applied_1d, 0,
            "the session handed the overlay a 1D scene"
        );
    };
    match data.split_first() {
        Some((door, rest)) if door % 2 == 1 => answer(&mut s, &mut board, Some(rest), None),
        Some((_, rest)) => {
            let mut rx = Receiver::<MAX_ENCODED>::default();
            for &byte in rest {
                match rx.push(byte) {
                    Some(Ok(len)) => {
                        let payload = rx.payload(len).to_vec();
                        answer(&mut s, &mut board, Some(&payload), None);
                    }
                    Some(Err(e)) => answer(&mut s, &mut board, None, Some(e)),
                    None => {}
                }
            }
        }
        None => {}
    }
    fed
}

// ---------------------------------------------------------------------------------------------
// scene_file_2d

/// A 2D scene file's bytes (`[sensor] kind = "4-wire"`, `[screen]`, `[[window]]`, `[[edge]]`, …)
/// through the 2D reader and the board check (`load_2d_for_board`, which dry-runs a
/// `Controller2d`), the sensor and plate queries beside it; an accepted file written back
/// (`to_scene_file_2d`) reads back to the same configuration; a refusal's sentence names the
/// file. Returns whether the file was accepted.
pub fn scene_file_2d(data: &[u8]) -> bool {
    let Ok(text) = core::str::from_utf8(data) else {
        return false;
    };
    let _ = sensor_of("fuzz.toml", text);
    let plate = plate_um_of("fuzz.toml", text);
    match load_2d_for_board("fuzz.toml", text, TIMER, FRAME_US) {
        Ok(config) => {
            let plate = plate.expect("an accepted 2D file has a plate");
            let again = to_scene_file_2d(&config, plate, "fuzz");
            let back = load_2d_for_board("again.toml", &again, TIMER, FRAME_US)
                .expect("a 2D scene file written from an accepted scene reads back");
            assert_eq!(back, config, "written back:\n{again}");
            true
        }
        Err(e) => {
            let line = e.to_string();
            assert!(line.starts_with("fuzz.toml"), "{line}");
            false
        }
    }
}

// ---------------------------------------------------------------------------------------------
// controller2d

use saw_core::burst::{BurstTimer, SafetyLimits, TimerSettings};
use saw_core::gate::GateAction;
use saw_core::plane::{
    Config2d, Controller2d, OrientedGrating, PlaneTexture, PointUm, Polygon, SegmentUm, Window2d,
};
use saw_core::position::SensorFault;
use saw_core::texture::{Grating, GratingRender, Texture};
use saw_core::touch::calibration::{Affine, CalPoint};
use saw_core::touch::fault::{Axis, AxisFault, RailBands};
use saw_core::touch::frame::{Frame, Reading, TouchSensor};
use saw_core::touch::pressure::PressureConfig;

struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> Option<u8> {
        let (b, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(*b)
    }
    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes([self.u8()?, self.u8()?]))
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes([
            self.u8()?,
            self.u8()?,
            self.u8()?,
            self.u8()?,
        ]))
    }
    fn i32(&mut self) -> Option<i32> {
        self.u32().map(|v| v as i32)
    }
    /// A length-prefixed chunk decoded as a configuration.
    fn config(&mut self) -> Option<Option<Config2d>> {
        let n = (self.u16()? as usize).min(self.0.len());
        let (chunk, rest) = self.0.split_at(n);
        self.0 = rest;
        Some(postcard::from_bytes::<Config2d>(chunk).ok())
    }
}

/// A scene that loads: a constant window with a felt outline, a concave L of oriented ridges,
/// a free edge.
fn fallback() -> Config2d {
    let pt = PointUm::new;
    let mut c = Config2d::default();
    let mut g = Grating::new(2_000);
    g.render = GratingRender::PositionPhase;
    g.duty_permille = 300;
    let windows = [
        (
            Polygon::rectangle(pt(5_000, 5_000), pt(30_000, 40_000)),
            PlaneTexture::Plain(Texture::constant_hz(200)),
            true,
        ),
        (
            Polygon::from_points(&[
                pt(40_000, 5_000),
                pt(90_000, 5_000),
                pt(90_000, 20_000),
                pt(60_000, 20_000),
                pt(60_000, 50_000),
                pt(40_000, 50_000),
            ]),
            PlaneTexture::Oriented(OrientedGrating {
                grating: g,
                normal: (3, 4),
            }),
            false,
        ),
    ];
    for (outline, texture, edge) in windows {
        if let Ok(outline) = outline {
            let _ = c.scene.windows.push(Window2d {
                outline,
                texture,
                edge,
            });
        }
    }
    let _ = c.scene.free_edges.push(SegmentUm {
        a: pt(30_000, 45_000),
        b: pt(60_000, 52_000),
    });
    c
}

fn sensor() -> TouchSensor {
    let cal = [
        (6_000, 7_000, 9_500, 5_400),
        (59_000, 32_000, 85_500, 27_000),
        (32_000, 58_000, 47_500, 48_600),
    ]
    .map(|(x_code, y_code, x_um, y_um)| CalPoint {
        x_code,
        y_code,
        x_um,
        y_um,
    });
    let map = Affine::from_points(cal, &RailBands::default()).expect("a calibration");
    TouchSensor::new(PressureConfig::DEFAULT, RailBands::default(), map).expect("a sensor")
}

/// The on-time cap in timer clocks, from the cap's statement (µs × clock), rounded up.
fn on_cap_clocks(limits: &SafetyLimits, timer: &BurstTimer) -> u64 {
    (limits.max_on_time_us as u64 * timer.clock_hz as u64).div_ceil(1_000_000)
}

fn check_settings(s: &TimerSettings, caps: &[SafetyLimits], what: &str) {
    // The loosest cap in force (a pulse planned under the scene before a reload).
    let cap = caps
        .iter()
        .map(|l| on_cap_clocks(l, &TIMER))
        .max()
        .unwrap_or(0);
    // One tick of the prescaled counter for rounding.
    let tick = s.psc as u64 + 1;
    assert!(
        s.on_clocks() <= cap + tick,
        "{what}: on for {} clocks above the on-time cap of {cap} clocks ({s:?})",
        s.on_clocks()
    );
}

/// `Controller2d` over a configuration and operations read from the bytes (see
/// `fuzz_targets/controller2d.rs`); panics on a check that fails.
pub fn controller2d(data: &[u8]) {
    let mut b = Bytes(data);
    let Some(period_byte) = b.u8() else { return };
    let frame_us = 100 + period_byte as u32 * 4;
    let Ok(mut ctrl) = Controller2d::new(TIMER, frame_us) else {
        return;
    };
    let first = b.config().flatten();
    let mut limits = match first.as_ref().map(|c| ctrl.load(c)) {
        Some(Ok(())) => first.map(|c| c.limits),
        _ => {
            let c = fallback();
            ctrl.load(&c).expect("the fallback scene loads");
            Some(c.limits)
        }
    }
    .unwrap_or_default();
    // The caps of the scene before the last load, for pulses planned under it.
    let mut before = limits;
    let mut sensor = sensor();
    let mut t: u32 = b.u32().unwrap_or(0);
    let mut running = false;
    while let Some(op) = b.u8() {
        t = t.wrapping_add(frame_us);
        let reading = match op % 9 {
            0 => Reading::Lifted,
            1 => Reading::Landing {
                x_um: b.i32().unwrap_or(0),
                y_um: b.i32().unwrap_or(0),
            },
            // On and about a 95 × 54 mm plate, 2 µm steps.
            2 => Reading::Down {
                x_um: b.u16().unwrap_or(0) as i32 * 2 - 10_000,
                y_um: b.u16().unwrap_or(0) as i32 * 2 - 10_000,
                r_touch_ohm: b.u16().unwrap_or(0) as u32,
            },
            // Anywhere an i32 reaches.
            3 => Reading::Down {
                x_um: b.i32().unwrap_or(0),
                y_um: b.i32().unwrap_or(0),
                r_touch_ohm: b.u32().unwrap_or(0),
            },
            4 => Reading::Fault(AxisFault {
                axis: if op & 0x10 == 0 { Axis::X } else { Axis::Y },
                fault: if op & 0x20 == 0 {
                    SensorFault::RailLow
                } else {
                    SensorFault::RailHigh
                },
            }),
            5 => sensor.on_frame(&Frame {
                x_code: b.u16().unwrap_or(0),
                y_code: b.u16().unwrap_or(0),
                z1_code: b.u16().unwrap_or(0),
                z2_code: b.u16().unwrap_or(0),
                t_us: t,
            }),
            6 => {
                // Silence, then the watchdog: only ever an Off.
                t = t.wrapping_add(b.u16().unwrap_or(0) as u32 * 4);
                if let Some(a) = ctrl.on_tick(t) {
                    assert_eq!(a, GateAction::Off, "a tick may only stop the line");
                    running = false;
                }
                continue;
            }
            7 => {
                if let Some(Some(c)) = b.config() {
                    if ctrl.load(&c).is_ok() {
                        before = limits;
                        limits = c.limits;
                    }
                }
                continue;
            }
            _ => {
                t = t.wrapping_add(b.u32().unwrap_or(0));
                continue;
            }
        };
        let out = ctrl.on_reading(t, reading);
        let rendering = matches!(reading, Reading::Down { .. });
        match out.action {
            Some(GateAction::Start(s)) | Some(GateAction::Update(s)) => {
                assert!(rendering, "a burst on {reading:?}");
                check_settings(&s, &[limits, before], "a periodic on-time");
                running = true;
            }
            Some(GateAction::Pulse(s)) => {
                assert!(rendering, "a pulse on {reading:?}");
                check_settings(&s, &[limits, before], "a pulse");
                running = false;
            }
            Some(GateAction::Off) => running = false,
            None => assert!(
                rendering || !running,
                "a running burst left on through {reading:?}"
            ),
        }
        if let Some(a) = ctrl.on_tick(t.wrapping_add(frame_us / 2)) {
            assert_eq!(a, GateAction::Off, "a tick may only stop the line");
            running = false;
        }
    }
}
