//! The board's side of the link: what each request does, the active scene's copy and id, the
//! counters' reset point and the link's own counters. The board glue implements [`Board`]
//! (how a scene reaches the sample path, how flash is written) and only moves bytes; every
//! decision about a request is made here, the same on the firmware and the virtual board.

use saw_core::controller::Telemetry;
#[cfg(feature = "plane")]
use saw_core::plane::{Config2dError, PointUm, Polygon, Telemetry2d};
use saw_core::scene::Config;

use crate::frame::{self, Refusal};
use crate::msg::{
    Counters, Header, Hello, LinkCounters, LinkError, Reply, Request, SceneSource, StoreFault,
    NAME_BYTES, PROTOCOL_VERSION,
};
#[cfg(feature = "plane")]
use crate::msg::{Counters2d, PlaneScene, Refused2d, SceneKind, Sensor};
#[cfg(feature = "plane")]
use crate::plane_scene_id;
#[cfg(not(feature = "plane-only"))]
use crate::scene_id;

/// Why a board did not run a 2D scene ([`Board::apply_2d`]).
#[cfg(feature = "plane")]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Apply2dError {
    /// The board's firmware has no 2D controller (the trait's default).
    Unsupported,
    /// The controller refused it (`Controller2d::load`).
    Config(Config2dError),
}

/// What the session needs from the board it runs on.
#[allow(async_fn_in_trait)] // used with concrete types only; no `Send` bound is wanted on target
pub trait Board {
    /// Compiles `config` and makes it active from the next sample, or refuses it with nothing
    /// changed (the controller's compile step: `Controller::load`). Records of the samples it
    /// runs carry `stamp`, and the first of them is sent whatever the decimation
    /// ([`crate::stream::Decimator::force_next`]).
    async fn apply(
        &mut self,
        config: &Config,
        stamp: Stamp,
    ) -> Result<(), saw_core::controller::ConfigError>;
    /// The board's clock, µs since boot.
    fn now_us(&mut self) -> u64;
    /// The control core's counters now (on the firmware the control loop hands them over
    /// between two samples).
    async fn telemetry(&mut self) -> Telemetry;
    /// Stream one record every `every_samples` samples from now (0: stop).
    fn stream(&mut self, every_samples: u16);
    /// Telemetry records (dropped, sent) since boot.
    fn stream_counts(&mut self) -> (u32, u32);
    /// Stores `config` as the scene to boot into. The board keeps the carrier off and the
    /// watchdog fed while the flash is busy.
    async fn save(&mut self, scene_id: u32, config: &Config) -> Result<(), StoreFault>;

    // 2D scenes (issue #36). A board whose session was made with [`Session::new_2d`] runs
    // them; the defaults refuse, so a 1D board's glue needs none of these.

    /// Compiles a 2D scene (`Prepared2d::compile`) and makes it active from the next reading,
    /// or refuses it with nothing changed. Records carry `stamp` as [`Board::apply`]'s do.
    #[cfg(feature = "plane")]
    async fn apply_2d(&mut self, scene: &PlaneScene, stamp: Stamp) -> Result<(), Apply2dError> {
        let _ = (scene, stamp);
        Err(Apply2dError::Unsupported)
    }
    /// The 2D control core's counters now.
    #[cfg(feature = "plane")]
    async fn telemetry_2d(&mut self) -> Telemetry2d {
        Telemetry2d::default()
    }
    /// Stores a 2D scene to boot into.
    #[cfg(feature = "plane")]
    async fn save_2d(&mut self, scene_id: u32, scene: &PlaneScene) -> Result<(), StoreFault> {
        let _ = (scene_id, scene);
        Err(StoreFault::NotFor2d)
    }
}

/// The scene a session holds: 1D (regions along the rheostat) or 2D (windows on the overlay).
#[derive(Clone, Debug, PartialEq)]
#[allow(clippy::large_enum_variant)] // no allocator to box into; one session per board
pub enum Active {
    /// A 1D scene (not in a 2D board's build, `plane-only`).
    #[cfg(not(feature = "plane-only"))]
    Line(Config),
    /// A 2D scene and its plate.
    #[cfg(feature = "plane")]
    Plane(PlaneScene),
}

impl Active {
    /// Its id ([`scene_id`], [`plane_scene_id`]).
    pub fn id(&self) -> u32 {
        match self {
            #[cfg(not(feature = "plane-only"))]
            Active::Line(c) => scene_id(c),
            #[cfg(feature = "plane")]
            Active::Plane(p) => plane_scene_id(p),
        }
    }
}

/// Which scene a sample ran under: what every stream record carries.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Stamp {
    /// The scene's id ([`crate::scene_id`]).
    pub scene_id: u32,
    /// Scene changes since boot (0: the scene the board booted into).
    pub change: u32,
}

/// Who the board is, for [`Request::Hello`] (the sensor it reads: [`Session::new`] for the
/// rheostat, [`Session::new_2d`] for the touch overlay).
#[derive(Clone, Copy, Debug)]
pub struct Identity {
    /// Firmware name and version.
    pub firmware: &'static str,
    /// Board name.
    pub board: &'static str,
    /// Samples per second of the control loop.
    pub sample_rate_hz: u32,
}

/// One board's link session.
#[derive(Debug)]
pub struct Session {
    identity: Identity,
    #[cfg(feature = "plane")]
    sensor: Sensor,
    active: Active,
    scene_id: u32,
    source: SceneSource,
    /// Scene changes applied since boot.
    change: u32,
    /// The scene the board booted into (or saved last) and where it came from: a change back
    /// to it (a bench restoring a boundary) reports that source again, not "over the link".
    origin: (u32, SceneSource),
    every_samples: u16,
    link: LinkCounters,
    /// Counter values at the last reset.
    base: Counters,
    /// The 2D core's counter values at the last reset.
    #[cfg(feature = "plane")]
    base_2d: Telemetry2d,
}

impl Session {
    /// A session of a board with the slide rheostat, over the 1D scene it booted into (already
    /// applied).
    #[cfg(not(feature = "plane-only"))]
    pub fn new(identity: Identity, active: Config, source: SceneSource) -> Self {
        Self::with(
            identity,
            #[cfg(feature = "plane")]
            Sensor::Rheostat,
            Active::Line(active),
            source,
        )
    }

    #[cfg(feature = "plane")]
    /// A session of a board with the 4-wire touch overlay of `plate_um` (its touch area, µm),
    /// over the 2D scene it booted into (already applied with [`Board::apply_2d`]).
    pub fn new_2d(
        identity: Identity,
        plate_um: (u32, u32),
        active: PlaneScene,
        source: SceneSource,
    ) -> Self {
        Self::with(
            identity,
            Sensor::FourWire { plate_um },
            Active::Plane(active),
            source,
        )
    }

    fn with(
        identity: Identity,
        #[cfg(feature = "plane")] sensor: Sensor,
        active: Active,
        source: SceneSource,
    ) -> Self {
        let id = active.id();
        Self {
            identity,
            #[cfg(feature = "plane")]
            sensor,
            scene_id: id,
            active,
            source,
            change: 0,
            origin: (id, source),
            every_samples: 0,
            link: LinkCounters::default(),
            base: Counters::default(),
            #[cfg(feature = "plane")]
            base_2d: Telemetry2d::default(),
        }
    }

    /// The active scene.
    pub fn active(&self) -> &Active {
        &self.active
    }

    /// The sensor the board reads.
    #[cfg(feature = "plane")]
    pub fn sensor(&self) -> Sensor {
        self.sensor
    }

    /// The active scene's id.
    pub fn scene_id(&self) -> u32 {
        self.scene_id
    }

    /// The active scene's stamp: what the board's records carry (the glue stamps the scene
    /// it booted into with this before the first sample).
    pub fn stamp(&self) -> Stamp {
        Stamp {
            scene_id: self.scene_id,
            change: self.change,
        }
    }

    /// Where the active scene came from.
    pub fn source(&self) -> SceneSource {
        self.source
    }

    /// The stream's decimation in force (0: stopped).
    pub fn every_samples(&self) -> u16 {
        self.every_samples
    }

    /// Answers one whole frame (the payload [`frame::Receiver`] reported). The returned header
    /// and reply are what the board sends back.
    ///
    /// Every request and scene is held once in this future, by value where it was decoded or
    /// built and by reference below it: a value matched on, or an async fn's argument, stays in
    /// the future beside the copy its body works on, and the firmware's link task future holds
    /// this one (issue #36: 25 016 B in the F446's 2D image with a Request and a Reply held
    /// four times over, 2 KB each; the G474's 2D image ran out of stack with it).
    pub async fn on_frame<B: Board>(&mut self, board: &mut B, payload: &[u8]) -> (Header, Reply) {
        let (header, request) = match frame::request(payload) {
            Ok(decoded) => decoded,
            Err(Refusal { seq, error }) => return self.on_bad_frame(seq, error),
        };
        self.link.frames_ok = self.link.frames_ok.wrapping_add(1);
        let reply = self.handle(board, &request).await;
        (reply_header(header.seq), reply)
    }

    /// Counts a refused frame and gives the error reply (seq 0 when the header did not decode).
    pub fn on_bad_frame(&mut self, seq: Option<u32>, error: LinkError) -> (Header, Reply) {
        self.link.frames_bad = self.link.frames_bad.wrapping_add(1);
        (reply_header(seq.unwrap_or(0)), Reply::Error(error))
    }

    async fn handle<B: Board>(&mut self, board: &mut B, request: &Request) -> Reply {
        match request {
            Request::Hello => Reply::Hello(Hello {
                protocol: PROTOCOL_VERSION,
                firmware: name(self.identity.firmware),
                board: name(self.identity.board),
                sample_rate_hz: self.identity.sample_rate_hz,
                scene_id: self.scene_id,
                scene_source: self.source,
            }),
            #[cfg(feature = "plane")]
            Request::Sensor => Reply::Sensor(self.sensor),
            Request::GetScene => match &self.active {
                #[cfg(not(feature = "plane-only"))]
                Active::Line(config) => Reply::Scene {
                    scene_id: self.scene_id,
                    source: self.source,
                    config: config.clone(),
                },
                #[cfg(feature = "plane")]
                Active::Plane(scene) => Reply::Scene2d {
                    scene_id: self.scene_id,
                    source: self.source,
                    scene: scene.clone(),
                },
            },
            // Each refusal returns before the await: a `Result<_, Reply>` matched around an
            // await would keep a Reply's 2 KB in the future (see `on_frame`).
            // A 2D board's build reads no 1D scene or texture (`msg::LineScene`): refused.
            #[cfg(feature = "plane-only")]
            Request::LoadScene(_) | Request::MoveBoundary { .. } | Request::SetTexture { .. } => {
                self.not_line()
            }
            #[cfg(not(feature = "plane-only"))]
            Request::LoadScene(config) => {
                if let Err(r) = self.line() {
                    return r;
                }
                self.apply(board, config).await
            }
            #[cfg(not(feature = "plane-only"))]
            Request::MoveBoundary { index, at_um } => {
                let next = match self.line().map(|a| a.with_boundary(*index, *at_um)) {
                    Ok(Ok(next)) => next,
                    Ok(Err(e)) => return Reply::Refused(e),
                    Err(r) => return r,
                };
                self.apply(board, &next).await
            }
            #[cfg(not(feature = "plane-only"))]
            Request::SetTexture { region, texture } => {
                let next = match self.line().map(|a| a.with_texture(*region, *texture)) {
                    Ok(Ok(next)) => next,
                    Ok(Err(e)) => return Reply::Refused(e),
                    Err(r) => return r,
                };
                self.apply(board, &next).await
            }
            Request::SetDrive(drive) => match &self.active {
                #[cfg(not(feature = "plane-only"))]
                Active::Line(c) => {
                    let next = c.with_drive(*drive);
                    self.apply(board, &next).await
                }
                #[cfg(feature = "plane")]
                Active::Plane(p) => {
                    let mut next = p.clone();
                    next.config.scene.drive = *drive;
                    self.apply_2d(board, &next).await
                }
            },
            #[cfg(feature = "plane")]
            Request::LoadScene2d(scene) => {
                if let Err(r) = self.plane() {
                    return r;
                }
                self.apply_2d(board, scene).await
            }
            #[cfg(feature = "plane")]
            Request::MoveWindow { window, to } => {
                let next = match self.plane().map(|a| moved(a, *window, *to)) {
                    Ok(Ok(next)) => next,
                    Ok(Err(e)) => return Reply::Refused2d(e),
                    Err(r) => return r,
                };
                self.apply_2d(board, &next).await
            }
            #[cfg(feature = "plane")]
            Request::ResizeWindow { window, lo, hi } => {
                let next = match self.plane().map(|a| resized(a, *window, *lo, *hi)) {
                    Ok(Ok(next)) => next,
                    Ok(Err(e)) => return Reply::Refused2d(e),
                    Err(r) => return r,
                };
                self.apply_2d(board, &next).await
            }
            Request::Counters { reset } => {
                let reset = *reset;
                let now = self.counters(board).await;
                let since = since(&now, &self.base);
                if reset {
                    self.base = now;
                }
                match self.active {
                    #[cfg(not(feature = "plane-only"))]
                    Active::Line(_) => Reply::Counters(since),
                    #[cfg(feature = "plane")]
                    Active::Plane(_) => {
                        let now2 = board.telemetry_2d().await;
                        let since2 = since_2d(&now2, &self.base_2d);
                        if reset {
                            self.base_2d = now2;
                        }
                        Reply::Counters2d(Counters2d {
                            core: since2,
                            link: since.link,
                        })
                    }
                }
            }
            Request::Stream { every_samples } => {
                let every_samples = *every_samples;
                // Read before the decimation changes: every record of this stream is of this
                // time or later.
                let from_us = board.now_us();
                self.every_samples = every_samples;
                board.stream(every_samples);
                Reply::Streaming {
                    every_samples,
                    sample_rate_hz: self.identity.sample_rate_hz,
                    from_us,
                }
            }
            Request::Ping => Reply::Pong {
                board_time_us: board.now_us(),
            },
            Request::Save => {
                let saved = match &self.active {
                    #[cfg(not(feature = "plane-only"))]
                    Active::Line(c) => board.save(self.scene_id, c).await,
                    #[cfg(feature = "plane")]
                    Active::Plane(p) => board.save_2d(self.scene_id, p).await,
                };
                match saved {
                    Ok(()) => {
                        self.source = SceneSource::Saved;
                        self.origin = (self.scene_id, SceneSource::Saved);
                        Reply::Saved {
                            scene_id: self.scene_id,
                        }
                    }
                    Err(e) => Reply::SaveFailed(e),
                }
            }
        }
    }

    /// The active 1D scene, or the refusal a 1D request gets on a board that reads the
    /// overlay (the board's sensor decides, not the scene).
    #[cfg(not(feature = "plane-only"))]
    fn line(&self) -> Result<&Config, Reply> {
        #[cfg(feature = "plane")]
        match (&self.sensor, &self.active) {
            (Sensor::Rheostat, Active::Line(c)) => Ok(c),
            (board, _) => Err(Reply::Refused2d(Refused2d::WrongSensor {
                asked: SceneKind::Line,
                board: *board,
            })),
        }
        #[cfg(not(feature = "plane"))]
        match &self.active {
            Active::Line(c) => Ok(c),
        }
    }

    /// The active 2D scene, or the refusal a 2D request gets on a board with the rheostat.
    #[cfg(feature = "plane")]
    fn plane(&self) -> Result<&PlaneScene, Reply> {
        match (&self.sensor, &self.active) {
            (Sensor::FourWire { .. }, Active::Plane(p)) => Ok(p),
            (board, _) => Err(Reply::Refused2d(Refused2d::WrongSensor {
                asked: SceneKind::Plane,
                board: *board,
            })),
        }
    }

    /// What a 1D request gets on a 2D board's build (`plane-only`): the board reads the overlay.
    #[cfg(feature = "plane-only")]
    fn not_line(&self) -> Reply {
        Reply::Refused2d(Refused2d::WrongSensor {
            asked: SceneKind::Line,
            board: self.sensor,
        })
    }

    /// By reference, as `apply_2d`: the copy the session keeps is made once the board took it.
    #[cfg(not(feature = "plane-only"))]
    async fn apply<B: Board>(&mut self, board: &mut B, next: &Config) -> Reply {
        let stamp = Stamp {
            scene_id: scene_id(next),
            change: self.change.wrapping_add(1),
        };
        match board.apply(next, stamp).await {
            Ok(()) => self.applied(stamp, Active::Line(next.clone())),
            Err(e) => Reply::Refused(e),
        }
    }

    #[cfg(feature = "plane")]
    /// Checks a 2D scene against the board's overlay (plate size, every point on the plate),
    /// then hands it to the board's controller.
    /// By reference (an async fn's argument by value is held twice in its future, see
    /// `on_frame`); the session's copy is made once the board took the scene.
    async fn apply_2d<B: Board>(&mut self, board: &mut B, next: &PlaneScene) -> Reply {
        if let Sensor::FourWire { plate_um } = self.sensor {
            if let Err(e) = fits(next, plate_um) {
                return Reply::Refused2d(e);
            }
        }
        let stamp = Stamp {
            scene_id: plane_scene_id(next),
            change: self.change.wrapping_add(1),
        };
        match board.apply_2d(next, stamp).await {
            Ok(()) => self.applied(stamp, Active::Plane(next.clone())),
            Err(Apply2dError::Unsupported) => Reply::Refused2d(Refused2d::Unsupported),
            Err(Apply2dError::Config(e)) => Reply::Refused2d(Refused2d::Config(e)),
        }
    }

    fn applied(&mut self, stamp: Stamp, next: Active) -> Reply {
        self.scene_id = stamp.scene_id;
        self.change = stamp.change;
        self.active = next;
        self.source = if stamp.scene_id == self.origin.0 {
            self.origin.1
        } else {
            SceneSource::Link
        };
        Reply::Applied {
            scene_id: self.scene_id,
        }
    }

    async fn counters<B: Board>(&self, board: &mut B) -> Counters {
        let (dropped, sent) = board.stream_counts();
        Counters {
            // A 2D board's 1D core counts nothing: it is not asked (its glue may have none).
            core: match self.active {
                #[cfg(not(feature = "plane-only"))]
                Active::Line(_) => board.telemetry().await,
                #[cfg(feature = "plane")]
                Active::Plane(_) => Telemetry::default(),
            },
            link: LinkCounters {
                records_dropped: dropped,
                records_sent: sent,
                ..self.link
            },
        }
    }
}

fn reply_header(seq: u32) -> Header {
    Header {
        version: PROTOCOL_VERSION,
        seq,
    }
}

fn name(s: &str) -> heapless::String<NAME_BYTES> {
    let mut out = heapless::String::new();
    for c in s.chars() {
        if out.push(c).is_err() {
            break;
        }
    }
    out
}

/// Counts since `base`; the core's last values (position, velocity, region, f_b) as they are.
fn since(now: &Counters, base: &Counters) -> Counters {
    let (n, b) = (&now.core, &base.core);
    Counters {
        core: Telemetry {
            samples: n.samples.wrapping_sub(b.samples),
            faults: n.faults.wrapping_sub(b.faults),
            region_switches: n.region_switches.wrapping_sub(b.region_switches),
            gate_actions: n.gate_actions.wrapping_sub(b.gate_actions),
            clamped: n.clamped.wrapping_sub(b.clamped),
            line_pulses: n.line_pulses.wrapping_sub(b.line_pulses),
            lines_skipped: n.lines_skipped.wrapping_sub(b.lines_skipped),
            ridge_pulses: n.ridge_pulses.wrapping_sub(b.ridge_pulses),
            ridges_skipped: n.ridges_skipped.wrapping_sub(b.ridges_skipped),
            ..*n
        },
        link: LinkCounters {
            frames_ok: now.link.frames_ok.wrapping_sub(base.link.frames_ok),
            frames_bad: now.link.frames_bad.wrapping_sub(base.link.frames_bad),
            records_dropped: now
                .link
                .records_dropped
                .wrapping_sub(base.link.records_dropped),
            records_sent: now.link.records_sent.wrapping_sub(base.link.records_sent),
        },
    }
}

/// The 2D counts since `base`.
#[cfg(feature = "plane")]
fn since_2d(n: &Telemetry2d, b: &Telemetry2d) -> Telemetry2d {
    Telemetry2d {
        readings: n.readings.wrapping_sub(b.readings),
        faults: n.faults.wrapping_sub(b.faults),
        lifts: n.lifts.wrapping_sub(b.lifts),
        window_switches: n.window_switches.wrapping_sub(b.window_switches),
        gate_actions: n.gate_actions.wrapping_sub(b.gate_actions),
        clamped: n.clamped.wrapping_sub(b.clamped),
        edge_pulses: n.edge_pulses.wrapping_sub(b.edge_pulses),
        edges_skipped: n.edges_skipped.wrapping_sub(b.edges_skipped),
        ridge_pulses: n.ridge_pulses.wrapping_sub(b.ridge_pulses),
        ridges_skipped: n.ridges_skipped.wrapping_sub(b.ridges_skipped),
    }
}

/// `p` lies on a plate of `plate_um`, from (0, 0).
#[cfg(feature = "plane")]
fn on_plate(p: PointUm, plate_um: (u32, u32)) -> bool {
    (0..=plate_um.0 as i64).contains(&(p.x_um as i64))
        && (0..=plate_um.1 as i64).contains(&(p.y_um as i64))
}

/// The scene's plate fits the overlay, and every window vertex and edge end lies on the plate
/// (what the scene file's reader checks, for a scene from any host).
#[cfg(feature = "plane")]
fn fits(scene: &PlaneScene, board_um: (u32, u32)) -> Result<(), Refused2d> {
    let plate_um = scene.plate_um;
    if plate_um.0 > board_um.0 || plate_um.1 > board_um.1 {
        return Err(Refused2d::PlateTooLarge {
            scene_um: plate_um,
            board_um,
        });
    }
    let s = &scene.config.scene;
    for (i, w) in s.windows.iter().enumerate() {
        if let Some(&at) = w.outline.vertices.iter().find(|v| !on_plate(**v, plate_um)) {
            return Err(Refused2d::OffPlate {
                index: i as u8,
                edge: false,
                at,
                plate_um,
            });
        }
    }
    for (i, e) in s.free_edges.iter().enumerate() {
        if let Some(at) = [e.a, e.b].into_iter().find(|v| !on_plate(*v, plate_um)) {
            return Err(Refused2d::OffPlate {
                index: i as u8,
                edge: true,
                at,
                plate_um,
            });
        }
    }
    Ok(())
}

/// Window `window` of `scene`, or the refusal naming how many there are.
#[cfg(feature = "plane")]
fn window_of(scene: &PlaneScene, window: u8) -> Result<&Polygon, Refused2d> {
    let windows = &scene.config.scene.windows;
    windows
        .get(usize::from(window))
        .map(|w| &w.outline)
        .ok_or(Refused2d::NoWindow {
            window,
            windows: windows.len() as u8,
        })
}

/// `scene` with window `window` moved so its outline's lower-left bounding corner is at `to`.
#[cfg(feature = "plane")]
fn moved(scene: &PlaneScene, window: u8, to: PointUm) -> Result<PlaneScene, Refused2d> {
    let outline = window_of(scene, window)?;
    let (lo, _) = outline.bounds();
    // Coordinates are within ±1 m (validated outlines; `to` is checked on the plate after), so
    // the shifted points are within i32.
    let (dx, dy) = (
        to.x_um as i64 - lo.x_um as i64,
        to.y_um as i64 - lo.y_um as i64,
    );
    let mut next = scene.clone();
    let vertices = next
        .config
        .scene
        .windows
        .get_mut(usize::from(window))
        .map(|w| w.outline.vertices.iter_mut());
    for v in vertices.into_iter().flatten() {
        let (x, y) = (v.x_um as i64 + dx, v.y_um as i64 + dy);
        let clamp = |c: i64| c.clamp(i32::MIN as i64, i32::MAX as i64) as i32;
        *v = PointUm::new(clamp(x), clamp(y));
    }
    Ok(next)
}

/// Whether `outline` is an axis-aligned rectangle: 4 vertices, each side horizontal or
/// vertical, alternating.
#[cfg(feature = "plane")]
fn is_rectangle(outline: &Polygon) -> bool {
    let v = &outline.vertices;
    if v.len() != 4 {
        return false;
    }
    let horizontal =
        |i: usize| v[i].y_um == v[(i + 1) % 4].y_um && v[i].x_um != v[(i + 1) % 4].x_um;
    let vertical = |i: usize| v[i].x_um == v[(i + 1) % 4].x_um && v[i].y_um != v[(i + 1) % 4].y_um;
    (horizontal(0) && vertical(1) && horizontal(2) && vertical(3))
        || (vertical(0) && horizontal(1) && vertical(2) && horizontal(3))
}

/// `scene` with rectangle `window` given the corners `lo`, `hi` (its vertices keep their order:
/// each takes the new x of its side and the new y of its side).
#[cfg(feature = "plane")]
fn resized(
    scene: &PlaneScene,
    window: u8,
    lo: PointUm,
    hi: PointUm,
) -> Result<PlaneScene, Refused2d> {
    let outline = window_of(scene, window)?;
    if !is_rectangle(outline) {
        return Err(Refused2d::NotARectangle {
            window,
            vertices: outline.vertices.len() as u8,
        });
    }
    if lo.x_um >= hi.x_um || lo.y_um >= hi.y_um {
        return Err(Refused2d::BadCorners { lo, hi });
    }
    let (old_lo, _) = outline.bounds();
    let mut next = scene.clone();
    let vertices = next
        .config
        .scene
        .windows
        .get_mut(usize::from(window))
        .map(|w| w.outline.vertices.iter_mut());
    for v in vertices.into_iter().flatten() {
        let x = if v.x_um == old_lo.x_um {
            lo.x_um
        } else {
            hi.x_um
        };
        let y = if v.y_um == old_lo.y_um {
            lo.y_um
        } else {
            hi.y_um
        };
        *v = PointUm::new(x, y);
    }
    Ok(next)
}
