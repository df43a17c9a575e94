//! Test helpers the link's tests, the fuzz targets (`fuzz/`) and the corpus replay share: a
//! board over the real core ([`CoreBoard`]) and the entry points that take bytes from outside
//! exactly as the firmware does ([`link_bytes`], [`scene_file_bytes`]), and the
//! structure-aware scene files of the `scene_struct` target ([`scene_struct_bytes`]).

mod scene_toml;

pub use scene_toml::scene_toml;

use embassy_futures::block_on;
use saw_core::burst::BurstTimer;
use saw_core::controller::{ConfigError, Controller, Telemetry};
use saw_core::scene::{default_config, Config};

use crate::frame::{self, Receiver, MAX_ENCODED};
use saw_core::gate::DriveMode;
use saw_core::texture::Texture;

use crate::msg::{Header, Reply, Request, SceneSource, StoreFault};
use crate::session::{Board, Identity, Session, Stamp};

/// The F446's burst timer (90 MHz, 32-bit, 2 kHz f_b limit).
pub const TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 2_000,
};

/// What a test board says it is.
pub const ID: Identity = Identity {
    firmware: "saw-firmware 0.1.0",
    board: "nucleo-f446re",
    sample_rate_hz: 10_000,
};

/// A board whose scenes load into a real [`Controller`]; its flash keeps one save in memory
/// and can be made to fail.
pub struct CoreBoard {
    pub ctrl: Controller,
    pub every: u16,
    pub saved: Option<(u32, Config)>,
    pub flash_ok: bool,
    /// The stamp of the last scene applied.
    pub stamp: Stamp,
    /// The board's clock, µs since boot: tests set it.
    pub now_us: u64,
}

impl CoreBoard {
    /// The default scene loaded, the flash working.
    pub fn new() -> Self {
        let mut ctrl = Controller::new(TIMER, 100).expect("the F446's timer and 100 µs");
        ctrl.load(&default_config())
            .expect("the default scene loads");
        Self {
            ctrl,
            every: 0,
            saved: None,
            flash_ok: true,
            stamp: Stamp::default(),
            now_us: 0,
        }
    }
}

impl Default for CoreBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl Board for CoreBoard {
    async fn apply(&mut self, config: &Config, stamp: Stamp) -> Result<(), ConfigError> {
        self.ctrl.load(config)?;
        self.stamp = stamp;
        Ok(())
    }
    fn now_us(&mut self) -> u64 {
        self.now_us
    }
    async fn telemetry(&mut self) -> Telemetry {
        self.ctrl.telemetry()
    }
    fn stream(&mut self, every_samples: u16) {
        self.every = every_samples;
    }
    fn stream_counts(&mut self) -> (u32, u32) {
        (3, 40)
    }
    async fn save(&mut self, scene_id: u32, config: &Config) -> Result<(), StoreFault> {
        if !self.flash_ok {
            return Err(StoreFault::Flash);
        }
        self.saved = Some((scene_id, config.clone()));
        Ok(())
    }
}

/// A session over the default scene.
pub fn session() -> Session {
    Session::new(ID, default_config(), SceneSource::Default)
}

/// What [`link_bytes`] saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Fed {
    /// Frames answered (whole frames, good or refused with a typed error).
    pub replies: u32,
    /// Replies that were errors or refusals.
    pub refused: u32,
}

/// Bytes from outside, as the board's link task takes them. The first byte picks the door:
/// even, the rest is the line's byte stream through the [`Receiver`] (COBS, CRC-32, size);
/// odd, the rest is one frame's header and body as the receiver hands it on (so the decoder
/// and the session are reached without guessing a CRC). Every reply is encoded as the board
/// sends it. Never panics: that is what the fuzz targets check.
pub fn link_bytes(data: &[u8]) -> Fed {
    let (mut s, mut board) = (session(), CoreBoard::new());
    let mut fed = Fed::default();
    let answer = |(h, r): (Header, Reply), fed: &mut Fed| {
        fed.replies += 1;
        if matches!(r, Reply::Error(_) | Reply::Refused(_)) {
            fed.refused += 1;
        }
        let mut wire = [0u8; MAX_ENCODED];
        // A reply too big for a frame is the board's bug, not the input's: it must encode.
        frame::encode(&h, &r, &mut wire).expect("every reply fits a frame");
    };
    match data.split_first() {
        Some((door, rest)) if door % 2 == 1 => {
            let reply = block_on(s.on_frame(&mut board, rest));
            answer(reply, &mut fed);
        }
        Some((_, rest)) => {
            let mut rx = Receiver::<MAX_ENCODED>::default();
            for &byte in rest {
                match rx.push(byte) {
                    Some(Ok(len)) => {
                        let payload = rx.payload(len).to_vec();
                        let reply = block_on(s.on_frame(&mut board, &payload));
                        answer(reply, &mut fed);
                    }
                    Some(Err(e)) => answer(s.on_bad_frame(None, e), &mut fed),
                    None => {}
                }
            }
        }
        None => {}
    }
    fed
}

/// A scene file's bytes, as `host-sim --scene`, `saw push` and the firmware's build read them:
/// UTF-8 text, parsed and checked against the F446. An accepted file is written back as a scene
/// file and read again, which must give the same configuration. Returns whether it was
/// accepted; never panics.
pub fn scene_file_bytes(data: &[u8]) -> bool {
    let Ok(text) = core::str::from_utf8(data) else {
        return false;
    };
    match saw_core::scene_file::load_for_board("fuzz.toml", text, TIMER, 100) {
        Ok(config) => {
            let again = saw_core::scene_file::to_scene_file(&config, "fuzz");
            let back = saw_core::scene_file::load_for_board("again.toml", &again, TIMER, 100)
                .expect("a scene file written from an accepted scene reads back");
            assert_eq!(back, config, "written back:\n{again}");
            true
        }
        Err(e) => {
            // The sentence a user reads names the file.
            let line = std::string::ToString::to_string(&e);
            assert!(line.starts_with("fuzz.toml"), "{line}");
            false
        }
    }
}

/// The `scene_struct` target's bytes: choices that build a scene file ([`scene_toml`]), read
/// as [`scene_file_bytes`] reads a file. Returns whether it was accepted; never panics.
pub fn scene_struct_bytes(data: &[u8]) -> bool {
    scene_file_bytes(scene_toml(data).as_bytes())
}

/// One request of every kind (`Request::VARIANTS` of them), as a host sends them.
pub fn every_request() -> std::vec::Vec<Request> {
    vec![
        Request::Hello,
        Request::GetScene,
        Request::LoadScene(default_config()),
        Request::MoveBoundary {
            index: 1,
            at_um: 40_000,
        },
        Request::SetTexture {
            region: 2,
            texture: Texture::constant_hz(250),
        },
        Request::SetDrive(DriveMode::Progressive),
        Request::Counters { reset: true },
        Request::Stream { every_samples: 10 },
        Request::Save,
        Request::Ping,
    ]
}
