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

use crate::msg::{Header, PlaneScene, Reply, Request, SceneSource, StoreFault};
use crate::session::{Apply2dError, Board, Identity, Session, Stamp};
use saw_core::plane::{Config2d, Controller2d, PointUm, Telemetry2d};

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
        Request::Sensor,
        Request::LoadScene2d(fig12()),
        Request::MoveWindow {
            window: 1,
            to: PointUm::new(10_000, 20_000),
        },
        Request::ResizeWindow {
            window: 0,
            lo: PointUm::new(5_000, 5_000),
            hi: PointUm::new(20_000, 30_000),
        },
    ]
}

/// The touch frame period the 2D test board reads at, µs (the F446's 280 µs frames:
/// `host_sim::sim2d::board_frame_period_us`, which saw's e2e2d test holds this to).
pub const FRAME_US: u32 = 280;

/// The 2D test board's overlay, µm: the 95 × 54 mm panel of `scenes/2d-*.toml`.
pub const PLATE_UM: (u32, u32) = (95_000, 54_000);

/// `scenes/2d-fig12.toml`, read for the F446 at [`FRAME_US`], with its plate.
pub fn fig12() -> PlaneScene {
    let text = include_str!("../../scenes/2d-fig12.toml");
    plane_scene("2d-fig12.toml", text)
}

/// A 2D scene file's text read for the F446 at [`FRAME_US`], with its plate.
pub fn plane_scene(file: &str, text: &str) -> PlaneScene {
    let config = saw_core::scene_file::load_2d_for_board(file, text, TIMER, FRAME_US)
        .expect("the 2D scene file loads");
    let plate_um = saw_core::scene_file::plate_um_of(file, text).expect("its plate");
    PlaneScene { plate_um, config }
}

/// A board with the 4-wire overlay whose 2D scenes load into a real [`Controller2d`].
pub struct PlaneBoard {
    pub ctrl: Controller2d,
    pub every: u16,
    pub saved: Option<(u32, PlaneScene)>,
    pub stamp: Stamp,
    pub now_us: u64,
    /// 1D scenes the glue was asked to apply (the session must never ask).
    pub applied_1d: u32,
}

impl PlaneBoard {
    /// `scenes/2d-fig12.toml` loaded.
    pub fn new() -> Self {
        let mut ctrl = Controller2d::new(TIMER, FRAME_US).expect("the F446's timer");
        ctrl.load(&fig12().config).expect("fig. 12 loads");
        Self {
            ctrl,
            every: 0,
            saved: None,
            stamp: Stamp::default(),
            now_us: 0,
            applied_1d: 0,
        }
    }
}

impl Default for PlaneBoard {
    fn default() -> Self {
        Self::new()
    }
}

impl Board for PlaneBoard {
    async fn apply(&mut self, _: &Config, _: Stamp) -> Result<(), ConfigError> {
        self.applied_1d += 1;
        Ok(())
    }
    fn now_us(&mut self) -> u64 {
        self.now_us
    }
    async fn telemetry(&mut self) -> Telemetry {
        Telemetry::default()
    }
    fn stream(&mut self, every_samples: u16) {
        self.every = every_samples;
    }
    fn stream_counts(&mut self) -> (u32, u32) {
        (0, 0)
    }
    async fn save(&mut self, _: u32, _: &Config) -> Result<(), StoreFault> {
        Err(StoreFault::NoStore)
    }
    async fn apply_2d(&mut self, scene: &PlaneScene, stamp: Stamp) -> Result<(), Apply2dError> {
        self.ctrl
            .load(&scene.config)
            .map_err(Apply2dError::Config)?;
        self.stamp = stamp;
        Ok(())
    }
    async fn telemetry_2d(&mut self) -> Telemetry2d {
        self.ctrl.telemetry()
    }
    async fn save_2d(&mut self, scene_id: u32, scene: &PlaneScene) -> Result<(), StoreFault> {
        self.saved = Some((scene_id, scene.clone()));
        Ok(())
    }
}

/// A 2D board's session over fig. 12, its overlay [`PLATE_UM`].
pub fn session_2d() -> Session {
    Session::new_2d(ID_2D, PLATE_UM, fig12(), SceneSource::BuildTime)
}

/// What a 2D test board says it is.
pub const ID_2D: Identity = Identity {
    firmware: "saw-firmware 0.1.0",
    board: "nucleo-f446re",
    sample_rate_hz: 1_000_000 / FRAME_US,
};

/// The texture whose encoding is the longest: the 1D scenes' widest (random) or a grating
/// with every field at its longest and the longest normal.
fn widest() -> saw_core::plane::PlaneTexture {
    use saw_core::plane::{OrientedGrating, PlaneTexture};
    use saw_core::texture::{Grating, GratingRender};
    let random = PlaneTexture::Plain(saw_core::scene::largest_config().scene.textures[0]);
    let oriented = PlaneTexture::Oriented(OrientedGrating {
        grating: Grating {
            wavelength_um: u32::MAX,
            duty_permille: u16::MAX,
            min_speed_um_s: u32::MAX,
            amplitude_permille: u16::MAX,
            render: GratingRender::VelocitySynthesis,
            rearm_um: u32::MAX,
        },
        normal: (-1_000_000, -1_000_000),
    });
    let len = |t: &PlaneTexture| postcard::to_allocvec(t).map_or(0, |v| v.len());
    if len(&oriented) > len(&random) {
        oriented
    } else {
        random
    }
}

/// The largest 2D scene: 8 windows of 16 vertices at the plane's far coordinates, every
/// window outlined (… edges) and the free edges to 32, each texture the widest kind.
pub fn largest_plane_scene() -> PlaneScene {
    use saw_core::plane::{Polygon, SegmentUm, Window2d, MAX_EDGES};
    let mut config = Config2d::default();
    let far = -999_999;
    for w in 0..8 {
        let pts: std::vec::Vec<PointUm> = (0..16)
            .map(|k| {
                // A convex 16-gon; far coordinates make every varint its longest.
                let a = (k as f64) * core::f64::consts::TAU / 16.0;
                PointUm::new(
                    far + 500_000 + (400_000.0 * a.cos()) as i32 + w,
                    far + 500_000 + (400_000.0 * a.sin()) as i32,
                )
            })
            .collect();
        let _ = config.scene.windows.push(Window2d {
            outline: Polygon::from_points(&pts).expect("a convex 16-gon"),
            texture: widest(),
            edge: false,
        });
    }
    config.scene.background = widest();
    for k in 0..MAX_EDGES {
        let _ = config.scene.free_edges.push(SegmentUm {
            a: PointUm::new(far, far + k as i32),
            b: PointUm::new(-far, -far - k as i32),
        });
    }
    PlaneScene {
        plate_um: (u32::MAX, u32::MAX),
        config,
    }
}
