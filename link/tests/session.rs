//! The board's session against a real controller: every request does what it says, a refused
//! change leaves the running scene untouched and reads as the scene file's sentence, counters
//! reset, and bad frames are answered with a typed error while the link stays usable.

use embassy_futures::block_on;
use saw_core::controller::ConfigError;
use saw_core::gate::DriveMode;
use saw_core::sample::Sample;
use saw_core::scene::default_config;
use saw_core::texture::Texture;
use saw_link::frame::{self, Receiver, MAX_ENCODED};
use saw_link::msg::{Header, LinkError, Reply, Request, SceneSource, StoreFault, PROTOCOL_VERSION};
use saw_link::scene_id;
use saw_link::session::{Active, Session, Stamp};

use saw_link::testing::{session, CoreBoard, TIMER};

/// Sends `req` as bytes through a receiver, as the board does.
fn ask(s: &mut Session, b: &mut CoreBoard, seq: u32, req: &Request) -> (Header, Reply) {
    let mut wire = [0u8; MAX_ENCODED];
    let n = frame::encode(
        &Header {
            version: PROTOCOL_VERSION,
            seq,
        },
        req,
        &mut wire,
    )
    .unwrap();
    let mut rx = Receiver::<MAX_ENCODED>::default();
    let mut reply = None;
    for &byte in &wire[..n] {
        match rx.push(byte) {
            Some(Ok(len)) => {
                let payload = rx.payload(len).to_vec();
                reply = Some(block_on(s.on_frame(b, &payload)));
            }
            Some(Err(e)) => reply = Some(s.on_bad_frame(None, e)),
            None => {}
        }
    }
    reply.unwrap()
}

#[test]
fn hello_names_the_board_and_the_scene() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    let (h, r) = ask(&mut s, &mut b, 5, &Request::Hello);
    assert_eq!(h.seq, 5);
    let Reply::Hello(hello) = r else {
        panic!("{r:?}")
    };
    assert_eq!(hello.protocol, PROTOCOL_VERSION);
    assert_eq!(hello.board.as_str(), "nucleo-f446re");
    assert_eq!(hello.firmware.as_str(), "saw-firmware 0.1.0");
    assert_eq!(hello.sample_rate_hz, 10_000);
    assert_eq!(hello.scene_source, SceneSource::Default);
    assert_eq!(hello.scene_id, scene_id(&default_config()));
}

#[test]
fn a_boundary_move_runs_and_a_bad_one_changes_nothing() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    let (_, r) = ask(
        &mut s,
        &mut b,
        1,
        &Request::MoveBoundary {
            index: 0,
            at_um: 30_000,
        },
    );
    let moved = default_config().with_boundary(0, 30_000).unwrap();
    assert_eq!(
        r,
        Reply::Applied {
            scene_id: scene_id(&moved)
        }
    );
    assert_ne!(scene_id(&moved), scene_id(&default_config()));
    assert_eq!(s.active(), &Active::Line(moved.clone()));
    assert_eq!(s.source(), SceneSource::Link);
    // The controller runs it: at 25 mm the finger is in region 0 now (it was region 1).
    let code = |um: u32| {
        let cal = moved.calibration;
        let span = (cal.code_at_end - cal.code_at_start) as u64;
        (cal.code_at_start as u64 + span * um as u64 / cal.length_um as u64) as u32
    };
    let mut out = None;
    for k in 0..40u32 {
        out = Some(b.ctrl.on_sample(Sample {
            t_us: k * 100,
            code: code(25_000) as u16,
        }));
    }
    assert_eq!(out.unwrap().region, Some(0));

    // Past the next boundary: refused by the controller's layout check, nothing changes.
    let before = s.active().clone();
    let (_, r) = ask(
        &mut s,
        &mut b,
        2,
        &Request::MoveBoundary {
            index: 0,
            at_um: 50_000,
        },
    );
    let Reply::Refused(e) = r else {
        panic!("{r:?}")
    };
    assert!(matches!(e, ConfigError::Region(_)), "{e}");
    assert_eq!(s.active(), &before);
    // A boundary the scene does not have.
    let (_, r) = ask(
        &mut s,
        &mut b,
        3,
        &Request::MoveBoundary {
            index: 2,
            at_um: 50_000,
        },
    );
    assert_eq!(
        r,
        Reply::Refused(ConfigError::NoSuchBoundary {
            index: 2,
            boundaries: 2
        })
    );
    assert_eq!(s.active(), &before);
}

#[test]
fn a_refused_scene_reads_as_the_scene_file_sentence() {
    // A scene file that parses but that this board refuses (f_b above its 2 kHz limit).
    let text = "[[region]]\nkind = \"constant\"\nuntil_mm = 20\nf_b_hz = 80\n\n\
                [[region]]\nkind = \"constant\"\nf_b_hz = 3000\n";
    let host = saw_core::scene_file::load_for_board("fast.toml", text, TIMER, 100).unwrap_err();
    let doc = saw_core::scene_file::parse("fast.toml", text).unwrap();
    let (mut s, mut b) = (session(), CoreBoard::new());
    let (_, r) = ask(&mut s, &mut b, 1, &Request::LoadScene(doc.config.clone()));
    let Reply::Refused(e) = r else {
        panic!("{r:?}")
    };
    // Located in the file by the host tool, the board's refusal is the host's error exactly.
    assert_eq!(doc.locate(&e), host);
    assert_eq!(s.active(), &Active::Line(default_config()));
    assert_eq!(s.source(), SceneSource::Default);
}

#[test]
fn texture_and_drive_edits_and_get_scene() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    let (_, r) = ask(
        &mut s,
        &mut b,
        1,
        &Request::SetTexture {
            region: 1,
            texture: Texture::constant_hz(150),
        },
    );
    assert!(matches!(r, Reply::Applied { .. }), "{r:?}");
    let (_, r) = ask(
        &mut s,
        &mut b,
        2,
        &Request::SetDrive(DriveMode::Progressive),
    );
    assert!(matches!(r, Reply::Applied { .. }), "{r:?}");
    let (_, r) = ask(&mut s, &mut b, 3, &Request::GetScene);
    let Reply::Scene {
        scene_id: id,
        source,
        config,
    } = r
    else {
        panic!("{r:?}")
    };
    assert_eq!(config.scene.textures[1], Texture::constant_hz(150));
    assert_eq!(config.scene.drive, DriveMode::Progressive);
    assert_eq!(id, scene_id(&config));
    assert_eq!(source, SceneSource::Link);
    let (_, r) = ask(
        &mut s,
        &mut b,
        4,
        &Request::SetTexture {
            region: 3,
            texture: Texture::Off,
        },
    );
    assert_eq!(
        r,
        Reply::Refused(ConfigError::NoSuchRegion {
            index: 3,
            regions: 3
        })
    );
}

#[test]
fn counters_count_and_reset() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    for k in 0..25u32 {
        b.ctrl.on_sample(Sample {
            t_us: k * 100,
            code: 32_000,
        });
    }
    let (_, r) = ask(&mut s, &mut b, 1, &Request::Counters { reset: true });
    let Reply::Counters(c) = r else {
        panic!("{r:?}")
    };
    assert_eq!(c.core.samples, 25);
    assert_eq!((c.link.records_dropped, c.link.records_sent), (3, 40));
    // This frame is the first one answered (counted before it is handled).
    assert_eq!(c.link.frames_ok, 1);
    for k in 25..30u32 {
        b.ctrl.on_sample(Sample {
            t_us: k * 100,
            code: 32_000,
        });
    }
    let (_, r) = ask(&mut s, &mut b, 2, &Request::Counters { reset: false });
    let Reply::Counters(c) = r else {
        panic!("{r:?}")
    };
    assert_eq!(c.core.samples, 5);
    assert_eq!(c.link.frames_ok, 1);
    assert_eq!((c.link.records_dropped, c.link.records_sent), (0, 0));
    // The last values are not counts: they stay.
    assert_eq!(c.core.position_um, b.ctrl.telemetry().position_um);
}

#[test]
fn stream_and_save() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    b.now_us = 5_000_000_123;
    let (_, r) = ask(&mut s, &mut b, 1, &Request::Stream { every_samples: 10 });
    assert_eq!(
        r,
        Reply::Streaming {
            every_samples: 10,
            sample_rate_hz: 10_000,
            from_us: 5_000_000_123,
        }
    );
    assert_eq!((b.every, s.every_samples()), (10, 10));
    let (_, r) = ask(&mut s, &mut b, 2, &Request::Save);
    let id = scene_id(&default_config());
    assert_eq!(r, Reply::Saved { scene_id: id });
    assert_eq!(b.saved, Some((id, default_config())));
    assert_eq!(s.source(), SceneSource::Saved);
    b.flash_ok = false;
    let (_, r) = ask(&mut s, &mut b, 3, &Request::Save);
    assert_eq!(r, Reply::SaveFailed(StoreFault::Flash));
}

#[test]
fn a_bad_frame_gets_a_typed_error_and_the_next_request_is_answered() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    let mut wire = [0u8; MAX_ENCODED];
    let n = frame::encode(
        &Header {
            version: PROTOCOL_VERSION,
            seq: 8,
        },
        &Request::Save,
        &mut wire,
    )
    .unwrap();
    wire[2] ^= 0x10;
    let mut rx = Receiver::<MAX_ENCODED>::default();
    let mut replies = Vec::new();
    for &byte in &wire[..n] {
        if let Some(Err(e)) = rx.push(byte) {
            replies.push(s.on_bad_frame(None, e));
        }
    }
    assert_eq!(replies.len(), 1);
    assert_eq!(replies[0].0.seq, 0);
    assert!(
        matches!(replies[0].1, Reply::Error(LinkError::Crc { .. })),
        "{replies:?}"
    );
    assert_eq!(b.saved, None);
    let (h, r) = ask(&mut s, &mut b, 9, &Request::Hello);
    assert_eq!(h.seq, 9);
    assert!(matches!(r, Reply::Hello(_)));
    let (_, r) = ask(&mut s, &mut b, 10, &Request::Counters { reset: false });
    let Reply::Counters(c) = r else {
        panic!("{r:?}")
    };
    assert_eq!((c.link.frames_ok, c.link.frames_bad), (2, 1));
}

#[test]
fn a_ping_reads_the_board_clock_past_32_bits() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    // 2^32 µs is 71.6 min: the clock goes on past it.
    b.now_us = (1 << 32) + 17;
    let (h, r) = ask(&mut s, &mut b, 9, &Request::Ping);
    assert_eq!(h.seq, 9);
    assert_eq!(
        r,
        Reply::Pong {
            board_time_us: (1 << 32) + 17
        }
    );
}

#[test]
fn every_accepted_change_steps_the_stamp_and_a_refused_one_does_not() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    let boot = scene_id(&default_config());
    assert_eq!(
        s.stamp(),
        Stamp {
            scene_id: boot,
            change: 0
        }
    );
    let set = Request::SetTexture {
        region: 0,
        texture: Texture::constant_hz(250),
    };
    let (_, r) = ask(&mut s, &mut b, 1, &set);
    let Reply::Applied { scene_id: first } = r else {
        panic!("{r:?}")
    };
    assert_ne!(first, boot);
    assert_eq!(
        b.stamp,
        Stamp {
            scene_id: first,
            change: 1
        }
    );
    assert_eq!(s.stamp(), b.stamp);
    // Refused: neither the board's stamp nor the session's moves.
    let (_, r) = ask(
        &mut s,
        &mut b,
        2,
        &Request::MoveBoundary {
            index: 0,
            at_um: 999_000_000,
        },
    );
    assert!(matches!(r, Reply::Refused(_)), "{r:?}");
    assert_eq!(
        b.stamp,
        Stamp {
            scene_id: first,
            change: 1
        }
    );
    // The same scene again is still a change: a trial that repeats a condition is its own trial.
    let (_, r) = ask(&mut s, &mut b, 3, &set);
    assert_eq!(r, Reply::Applied { scene_id: first });
    assert_eq!(
        b.stamp,
        Stamp {
            scene_id: first,
            change: 2
        }
    );
}

#[test]
fn a_change_back_to_the_boot_scene_reports_its_source_again() {
    let (mut s, mut b) = (session(), CoreBoard::new());
    let (_, r) = ask(
        &mut s,
        &mut b,
        1,
        &Request::SetDrive(DriveMode::Progressive),
    );
    assert!(matches!(r, Reply::Applied { .. }), "{r:?}");
    assert_eq!(s.source(), SceneSource::Link);
    let (_, r) = ask(&mut s, &mut b, 2, &Request::SetDrive(DriveMode::Standing));
    assert_eq!(
        r,
        Reply::Applied {
            scene_id: scene_id(&default_config())
        }
    );
    assert_eq!(s.source(), SceneSource::Default);
    // After a save, the saved scene is the one to come back to.
    ask(
        &mut s,
        &mut b,
        3,
        &Request::SetDrive(DriveMode::Progressive),
    );
    ask(&mut s, &mut b, 4, &Request::Save);
    ask(&mut s, &mut b, 5, &Request::SetDrive(DriveMode::Standing));
    assert_eq!(s.source(), SceneSource::Link);
    ask(
        &mut s,
        &mut b,
        6,
        &Request::SetDrive(DriveMode::Progressive),
    );
    assert_eq!(s.source(), SceneSource::Saved);
}
