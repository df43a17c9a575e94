//! 2D scenes over the link (issue #36): the board's sensor decides which scenes it runs, a 2D
//! scene is pushed and read back whole, windows move and resize live, and every refusal is a
//! sentence with nothing changed and the link usable. Against real controllers (`Controller`,
//! `Controller2d`) behind the test boards of `saw_link::testing`.

use embassy_futures::block_on;
use saw_core::gate::DriveMode;
use saw_core::plane::{Config2dError, PointUm, Polygon};
use saw_core::scene::default_config;
use saw_core::texture::Texture;
use saw_link::msg::{
    Header, PlaneScene, Refused2d, Reply, Request, SceneKind, SceneSource, Sensor, StoreFault,
    PROTOCOL_VERSION,
};
use saw_link::session::{Active, Board, Session};
use saw_link::testing::{
    fig12, plane_scene, session, session_2d, CoreBoard, PlaneBoard, ID_2D, PLATE_UM,
};
use saw_link::{frame, plane_scene_id, scene_id};

/// `req` encoded as the host sends it and answered by the session, as the board does.
fn ask<B: Board>(s: &mut Session, b: &mut B, req: &Request) -> Reply {
    let mut wire = [0u8; frame::MAX_ENCODED];
    let header = Header {
        version: PROTOCOL_VERSION,
        seq: 9,
    };
    let n = frame::encode(&header, req, &mut wire).unwrap();
    let mut rx = frame::Receiver::<{ frame::MAX_ENCODED }>::default();
    let mut reply = None;
    for &byte in &wire[..n] {
        if let Some(Ok(len)) = rx.push(byte) {
            let payload = rx.payload(len).to_vec();
            reply = Some(block_on(s.on_frame(b, &payload)).1);
        }
    }
    reply.expect("one reply")
}

fn concave() -> PlaneScene {
    plane_scene(
        "2d-concave.toml",
        include_str!("../../scenes/2d-concave.toml"),
    )
}

/// A 2D board's session over fig. 12 on an overlay of 100 × 60 mm, which
/// `scenes/2d-concave.toml`'s 80 × 60 mm plate fits (fig. 12's 95 × 54 mm overlay does not:
/// tested below).
fn session_tall() -> Session {
    Session::new_2d(ID_2D, (100_000, 60_000), fig12(), SceneSource::BuildTime)
}

/// `outline` with every vertex moved by (dx, dy) µm.
fn shifted(outline: &Polygon, dx: i32, dy: i32) -> Polygon {
    let pts: Vec<PointUm> = outline
        .vertices
        .iter()
        .map(|v| PointUm::new(v.x_um + dx, v.y_um + dy))
        .collect();
    Polygon::from_points(&pts).unwrap()
}

fn mm(x: i32, y: i32) -> PointUm {
    PointUm::new(x * 1000, y * 1000)
}

/// The link still answers (and says the same scene as before).
fn still_usable<B: Board>(s: &mut Session, b: &mut B, id: u32) {
    match ask(s, b, &Request::Hello) {
        Reply::Hello(h) => assert_eq!(h.scene_id, id),
        r => panic!("{r:?}"),
    }
}

#[test]
fn a_board_with_the_rheostat_refuses_2d_scenes_and_window_edits_with_a_sentence() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    let before = s.scene_id();
    assert_eq!(
        ask(&mut s, &mut b, &Request::Sensor),
        Reply::Sensor(Sensor::Rheostat)
    );
    for req in [
        Request::LoadScene2d(fig12()),
        Request::MoveWindow {
            window: 0,
            to: mm(10, 10),
        },
        Request::ResizeWindow {
            window: 0,
            lo: mm(5, 5),
            hi: mm(20, 20),
        },
    ] {
        let r = ask(&mut s, &mut b, &req);
        let want = Refused2d::WrongSensor {
            asked: SceneKind::Plane,
            board: Sensor::Rheostat,
        };
        assert_eq!(r, Reply::Refused2d(want), "{req:?}");
        assert_eq!(
            want.to_string(),
            "this board reads the slide rheostat (1D scenes): a 2D scene ([sensor] kind = \"4-wire\") or a window edit needs a board with the 4-wire touch overlay"
        );
        assert_eq!(s.scene_id(), before);
        assert_eq!(s.active(), &Active::Line(default_config()));
        assert_eq!(b.stamp.change, 0, "the board was never asked");
    }
    still_usable(&mut s, &mut b, before);
}

#[test]
fn a_board_with_the_overlay_refuses_1d_scenes_and_edits_with_a_sentence() {
    let (mut s, mut b) = (session_2d(), PlaneBoard::new());
    let before = s.scene_id();
    assert_eq!(before, plane_scene_id(&fig12()));
    assert_eq!(
        ask(&mut s, &mut b, &Request::Sensor),
        Reply::Sensor(Sensor::FourWire { plate_um: PLATE_UM })
    );
    for req in [
        Request::LoadScene(default_config()),
        Request::MoveBoundary {
            index: 0,
            at_um: 30_000,
        },
        Request::SetTexture {
            region: 0,
            texture: Texture::constant_hz(80),
        },
    ] {
        let r = ask(&mut s, &mut b, &req);
        let Reply::Refused2d(e) = r else {
            panic!("{req:?}: {r:?}")
        };
        assert_eq!(
            e.to_string(),
            "this board reads the 4-wire touch overlay, 95 x 54 mm (2D scenes): a 1D scene (regions, boundaries; no [sensor] table) needs a board with the slide rheostat"
        );
        assert_eq!(s.scene_id(), before);
        assert_eq!(s.active(), &Active::Plane(fig12()));
    }
    assert_eq!(b.applied_1d, 0, "no 1D scene reached the board's glue");
    still_usable(&mut s, &mut b, before);
}

#[test]
fn a_2d_scene_is_pushed_read_back_and_written_as_the_same_file() {
    let (mut s, mut b) = (session_2d(), PlaneBoard::new());
    // Fig. 12's overlay (95 × 54 mm) is not tall enough for the concave scene's 80 × 60 mm.
    let Reply::Refused2d(e) = ask(&mut s, &mut b, &Request::LoadScene2d(concave())) else {
        panic!()
    };
    assert_eq!(
        e.to_string(),
        "the scene's plate 80 x 60 mm does not fit this board's overlay 95 x 54 mm"
    );
    let (mut s, mut b) = (session_tall(), PlaneBoard::new());
    let scene = concave();
    let r = ask(&mut s, &mut b, &Request::LoadScene2d(scene.clone()));
    assert_eq!(
        r,
        Reply::Applied {
            scene_id: plane_scene_id(&scene)
        }
    );
    assert_eq!(b.stamp.change, 1);
    let Reply::Scene2d {
        scene_id: id,
        source,
        scene: back,
    } = ask(&mut s, &mut b, &Request::GetScene)
    else {
        panic!()
    };
    assert_eq!((id, source), (plane_scene_id(&scene), SceneSource::Link));
    assert_eq!(back, scene);
    // Written back as a scene file, it reads as the configuration pushed.
    let text = saw_core::scene_file::to_scene_file_2d(&back.config, back.plate_um, "read back");
    assert_eq!(plane_scene("back.toml", &text), scene);
}

#[test]
fn a_window_moves_whole_and_a_rectangle_resizes() {
    let (mut s, mut b) = (session_2d(), PlaneBoard::new());
    // Window 1 of fig. 12 is the rectangle 35,5 – 60,49 mm: its lower-left corner to (36, 2).
    let r = ask(
        &mut s,
        &mut b,
        &Request::MoveWindow {
            window: 1,
            to: mm(36, 2),
        },
    );
    let mut want = fig12();
    want.config.scene.windows[1].outline =
        shifted(&want.config.scene.windows[1].outline, 1_000, -3_000);
    assert_eq!(
        r,
        Reply::Applied {
            scene_id: plane_scene_id(&want)
        }
    );
    assert_eq!(s.active(), &Active::Plane(want.clone()));
    // Resized to 40,10 – 62.5,30 mm.
    let hi = PointUm::new(62_500, 30_000);
    let r = ask(
        &mut s,
        &mut b,
        &Request::ResizeWindow {
            window: 1,
            lo: mm(40, 10),
            hi,
        },
    );
    // Each vertex takes the new x of its side and the new y of its side.
    let pts: Vec<PointUm> = want.config.scene.windows[1]
        .outline
        .vertices
        .iter()
        .map(|v| {
            PointUm::new(
                if v.x_um == 36_000 { 40_000 } else { 62_500 },
                if v.y_um == 2_000 { 10_000 } else { 30_000 },
            )
        })
        .collect();
    want.config.scene.windows[1].outline = Polygon::from_points(&pts).unwrap();
    assert_eq!(
        r,
        Reply::Applied {
            scene_id: plane_scene_id(&want)
        }
    );
    assert_eq!(s.active(), &Active::Plane(want));
    assert_eq!(b.stamp.change, 2);

    // A concave polygon moves (every vertex by the same step) and does not resize.
    let (mut s, mut b) = (session_tall(), PlaneBoard::new());
    let scene = concave();
    ask(&mut s, &mut b, &Request::LoadScene2d(scene.clone()));
    let r = ask(
        &mut s,
        &mut b,
        &Request::MoveWindow {
            window: 1,
            to: mm(6, 7),
        },
    );
    let mut want = scene.clone();
    // The file's polygon_mm = [[5, 5], [75, 5], [75, 30], [45, 30], [45, 22], [5, 22]], + (1, 2).
    let pts: Vec<PointUm> = [(5, 5), (75, 5), (75, 30), (45, 30), (45, 22), (5, 22)]
        .iter()
        .map(|&(x, y)| mm(x + 1, y + 2))
        .collect();
    want.config.scene.windows[1].outline = Polygon::from_points(&pts).unwrap();
    assert_eq!(
        r,
        Reply::Applied {
            scene_id: plane_scene_id(&want)
        }
    );
    let before = s.scene_id();
    let r = ask(
        &mut s,
        &mut b,
        &Request::ResizeWindow {
            window: 1,
            lo: mm(5, 5),
            hi: mm(20, 20),
        },
    );
    let Reply::Refused2d(e) = r else {
        panic!("{r:?}")
    };
    assert_eq!(
        e.to_string(),
        "window 1: a polygon of 6 vertices, not an axis-aligned rectangle: it can be moved, not resized"
    );
    assert_eq!(s.scene_id(), before);
}

#[test]
fn a_refused_window_edit_changes_nothing_and_says_why() {
    let (mut s, mut b) = (session_2d(), PlaneBoard::new());
    let before = s.scene_id();
    let cases: Vec<(Request, &str)> = vec![
        (
            // 25 mm wide: its lower-left at x = 80 puts its right side at 105 mm.
            Request::MoveWindow {
                window: 0,
                to: mm(80, 5),
            },
            "window 0: the point (105 mm, 5 mm) is off the plate (0 to 95 mm, 0 to 54 mm)",
        ),
        (
            Request::MoveWindow {
                window: 3,
                to: mm(1, 1),
            },
            "window 3: the board's scene has 3 windows (0 to 2)",
        ),
        (
            Request::ResizeWindow {
                window: 0,
                lo: mm(20, 5),
                hi: mm(10, 30),
            },
            "corners (20 mm, 5 mm) and (10 mm, 30 mm): the first must be left of and below the second",
        ),
        (
            Request::ResizeWindow {
                window: 0,
                lo: mm(-1, 5),
                hi: mm(10, 30),
            },
            "window 0: the point (-1 mm, 5 mm) is off the plate (0 to 95 mm, 0 to 54 mm)",
        ),
    ];
    for (req, sentence) in cases {
        let r = ask(&mut s, &mut b, &req);
        let Reply::Refused2d(e) = r else {
            panic!("{req:?}: {r:?}")
        };
        assert_eq!(e.to_string(), sentence);
        assert_eq!(s.scene_id(), before);
        assert_eq!(s.active(), &Active::Plane(fig12()));
    }
    // The controller's own refusal: a window no wider than the band (0.2 mm).
    let r = ask(
        &mut s,
        &mut b,
        &Request::ResizeWindow {
            window: 0,
            lo: PointUm::new(5_000, 5_000),
            hi: PointUm::new(5_100, 30_000),
        },
    );
    assert!(
        matches!(
            r,
            Reply::Refused2d(Refused2d::Config(Config2dError::Screen(_)))
        ),
        "{r:?}"
    );
    assert_eq!(s.active(), &Active::Plane(fig12()));
    assert_eq!(b.stamp.change, 0, "nothing reached the controller");
    // A scene drawn on a plate larger than the overlay.
    let mut big = fig12();
    big.plate_um = (120_000, 54_000);
    let Reply::Refused2d(e) = ask(&mut s, &mut b, &Request::LoadScene2d(big)) else {
        panic!()
    };
    assert_eq!(
        e.to_string(),
        "the scene's plate 120 x 54 mm does not fit this board's overlay 95 x 54 mm"
    );
    still_usable(&mut s, &mut b, before);
}

#[test]
fn drive_counters_and_save_on_a_2d_board() {
    let (mut s, mut b) = (session_2d(), PlaneBoard::new());
    let r = ask(&mut s, &mut b, &Request::SetDrive(DriveMode::Progressive));
    let mut want = fig12();
    want.config.scene.drive = DriveMode::Progressive;
    assert_eq!(
        r,
        Reply::Applied {
            scene_id: plane_scene_id(&want)
        }
    );
    let Reply::Counters2d(c) = ask(&mut s, &mut b, &Request::Counters { reset: true }) else {
        panic!()
    };
    assert_eq!(c.link.frames_ok, 2);
    assert_eq!(
        ask(&mut s, &mut b, &Request::Save),
        Reply::Saved {
            scene_id: plane_scene_id(&want)
        }
    );
    assert_eq!(b.saved, Some((plane_scene_id(&want), want)));
}

#[test]
fn a_board_whose_glue_has_no_2d_controller_refuses_by_the_trait_defaults() {
    // The firmware's 1D glue (CoreBoard: none of the 2D methods) under a 2D session.
    let mut s = session_tall();
    let mut b = CoreBoard::new();
    let before = s.scene_id();
    assert_eq!(
        ask(&mut s, &mut b, &Request::LoadScene2d(concave())),
        Reply::Refused2d(Refused2d::Unsupported)
    );
    assert_eq!(
        ask(&mut s, &mut b, &Request::Save),
        Reply::SaveFailed(StoreFault::NotFor2d)
    );
    assert_eq!(s.scene_id(), before);
    assert_ne!(before, scene_id(&default_config()));
    still_usable(&mut s, &mut b, before);
}

/// A gate action's burst frequency as a 2D record carries it: the kernel clock over the period
/// (worked by hand: 90 MHz over 90 000 clocks is 1 kHz, 1 000 000 mHz), 0 for an Off and for an
/// edge's one-pulse; a touch fault as the stream names it, per axis.
#[test]
fn a_records_burst_frequency_and_fault_come_from_the_gate_and_the_controller() {
    use saw_core::burst::TimerSettings;
    use saw_core::gate::GateAction;
    use saw_core::plane::TouchFault;
    use saw_core::position::SensorFault;
    use saw_core::touch::fault::{Axis, AxisFault};
    use saw_link::msg::{Fault2d, Record2d};
    let s = TimerSettings {
        psc: 8,
        arr: 9_999,
        ccr: 100,
    };
    assert_eq!(
        Record2d::millihz_of(90_000_000, GateAction::Start(s)),
        1_000_000
    );
    assert_eq!(
        Record2d::millihz_of(90_000_000, GateAction::Update(s)),
        1_000_000
    );
    assert_eq!(Record2d::millihz_of(90_000_000, GateAction::Pulse(s)), 0);
    assert_eq!(Record2d::millihz_of(90_000_000, GateAction::Off), 0);
    for (axis, y_axis) in [(Axis::X, false), (Axis::Y, true)] {
        let f = TouchFault::Rail(AxisFault {
            axis,
            fault: SensorFault::RailHigh,
        });
        assert_eq!(
            Fault2d::from(f),
            Fault2d::Rail {
                y_axis,
                fault: SensorFault::RailHigh
            }
        );
    }
    assert_eq!(Fault2d::from(TouchFault::Stale), Fault2d::Stale);
}
