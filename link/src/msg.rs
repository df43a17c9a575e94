//! The messages both ends share: requests from the host, the board's replies, the telemetry
//! stream and the link's own errors. Their postcard encoding is the protocol; a change to any
//! type here that is not an appended enum variant bumps [`PROTOCOL_VERSION`].

use heapless::{String, Vec};
use saw_core::controller::{ConfigError, Telemetry};
use saw_core::gate::DriveMode;
#[cfg(feature = "plane")]
use saw_core::plane::{Config2d, Config2dError, Place, PointUm, Telemetry2d};
use saw_core::position::SensorFault;
use saw_core::scene::Config;
#[cfg(not(feature = "plane-only"))]
use saw_core::texture::Texture;
use serde::{Deserialize, Serialize};

/// The protocol this crate speaks. Every frame's header carries it; a board answers a frame of
/// another version with [`LinkError::WrongVersion`] and nothing else.
pub const PROTOCOL_VERSION: u16 = 2;

/// Telemetry records per stream frame: 8 records (≈ 130 bytes on the wire) amortise the
/// frame's 9 bytes of header, CRC and COBS overhead, and at the default 1 kHz stream a frame
/// leaves every 8 ms, well under what a person watching a trace notices.
pub const RECORDS_PER_FRAME: usize = 8;

/// The longest name a board or firmware reports.
pub const NAME_BYTES: usize = 24;

/// Frame header, first in every frame. Its layout is frozen across protocol versions so a
/// board can always say which version it speaks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Header {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub version: u16,
    /// A request's number, echoed in its reply; a stream frame's running count.
    pub seq: u32,
}

/// What the host asks. Each gets exactly one [`Reply`] with the request's `seq`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
// A whole scene rides inline: the board has no allocator to box it, and one message is held
// at a time.
#[allow(clippy::large_enum_variant)]
pub enum Request {
    /// Who is there: protocol and firmware version, board, active scene.
    Hello,
    /// The active scene, whole.
    GetScene,
    /// Replace the whole scene: compiled on the board (the same step a scene file goes
    /// through on the host) and swapped in at the next sample, or refused with nothing changed.
    LoadScene(LineScene),
    /// Move boundary `index` (where region `index` ends) to `at_um`.
    MoveBoundary {
        /// Boundary index, 0 = the end of the first region.
        index: u8,
        /// New position, µm from the start end.
        at_um: u32,
    },
    /// Give region `region` a new texture (kind and parameters).
    SetTexture {
        /// Region index, left to right from 0.
        region: u8,
        /// Its new texture.
        texture: LineTexture,
    },
    /// Standing (both IDTs) or progressive (one IDT) drive.
    SetDrive(DriveMode),
    /// The counters since boot or the last reset; `reset` starts a new count after reading.
    Counters {
        /// Start counting from zero after this read.
        reset: bool,
    },
    /// Stream one record every `every_samples` samples; 0 stops the stream.
    Stream {
        /// Decimation: 1 = every sample.
        every_samples: u16,
    },
    /// Save the active scene to flash; the board boots into it from then on.
    Save,
    /// The board's clock now, for aligning board time with the host's ([`Reply::Pong`]).
    Ping,
    // Protocol 2, appended (issue #36): 2D scenes (feature `plane`). A board of this version
    // that predates them, or is built without them, answers `UnknownRequest`; the
    // [`crate::session::Board`] defaults refuse them.
    /// Which position sensor the board reads ([`Reply::Sensor`]).
    #[cfg(feature = "plane")]
    Sensor,
    /// Replace the whole scene with a 2D one (a board with the 4-wire overlay only): compiled
    /// on the board and swapped in, or refused with nothing changed ([`Reply::Refused2d`]).
    #[cfg(feature = "plane")]
    LoadScene2d(PlaneScene),
    /// Move 2D window `window` whole: its outline's bounding box's lower-left corner goes to
    /// `to` (absolute, so a repeated request lands in the same place). Any outline moves.
    #[cfg(feature = "plane")]
    MoveWindow {
        /// Window index, topmost first from 0.
        window: u8,
        /// Where the outline's lower-left bounding corner goes, µm on the plate.
        to: PointUm,
    },
    /// Give 2D window `window`, an axis-aligned rectangle, new corners (a polygon is refused:
    /// it only moves).
    #[cfg(feature = "plane")]
    ResizeWindow {
        /// Window index, topmost first from 0.
        window: u8,
        /// Lower-left corner, µm on the plate.
        lo: PointUm,
        /// Upper-right corner, µm on the plate.
        hi: PointUm,
    },
}

// ---- 1D scene bodies, and a 2D board's build without them (`plane-only`) ----------------------
//
// A board that reads the overlay refuses every 1D scene and edit before looking at the scene
// (`Refused2d::WrongSensor`), and never sends a 1D scene, refusal, counters or stream. Built for
// such a board (feature `plane-only`: the firmware's 2D image), the 1D bodies are types that cost
// no code: a request's 1D scene or texture is left unread (the request is the frame's last field,
// so nothing after it is misread) and the replies' 1D variants hold an uninhabited type, so their
// serializers are never instantiated. The variants stay where they are: the wire format (the
// variant numbers) is the same, and the host speaks to both builds alike. On the F446 2D image
// with the link this left out ~12.6 KB of flash: 129 592 B against the ~142.2 KB the linker
// reports without it (issue #36, 2026-11-30).

/// A 1D scene in a request: the scene (every build but `plane-only`).
#[cfg(not(feature = "plane-only"))]
pub type LineScene = Config;
/// A 1D scene in a request: not read on a 2D board's build (`plane-only`), which refuses it.
#[cfg(feature = "plane-only")]
pub type LineScene = Unread;
/// A 1D texture in a request (see [`LineScene`]).
#[cfg(not(feature = "plane-only"))]
pub type LineTexture = Texture;
/// A 1D texture in a request: not read on a 2D board's build (see [`LineScene`]).
#[cfg(feature = "plane-only")]
pub type LineTexture = Unread;
/// A 1D reply's body: itself (every build but `plane-only`).
#[cfg(not(feature = "plane-only"))]
pub type LineReply<T> = T;
/// A 1D reply's body on a 2D board's build (`plane-only`): never sent.
#[cfg(feature = "plane-only")]
pub type LineReply<T> = Never<T>;

/// A request field a 2D board's build leaves unread: it decodes from nothing (postcard's empty
/// tuple) and encodes to nothing. Only the request's last field may be one.
#[cfg(feature = "plane-only")]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Unread;

#[cfg(feature = "plane-only")]
impl Serialize for Unread {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        s.serialize_tuple(0)?.end()
    }
}

#[cfg(feature = "plane-only")]
impl<'de> Deserialize<'de> for Unread {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Nothing;
        impl<'de> serde::de::Visitor<'de> for Nothing {
            type Value = Unread;
            fn expecting(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                f.write_str("nothing")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, _: A) -> Result<Unread, A::Error> {
                Ok(Unread)
            }
        }
        d.deserialize_tuple(0, Nothing)
    }
}

/// A reply a 2D board's build never sends (a 1D scene, refusal, counters or stream): no value
/// of it exists, so nothing encodes or decodes one.
#[cfg(feature = "plane-only")]
pub enum Never<T> {
    #[doc(hidden)]
    _Of(core::convert::Infallible, core::marker::PhantomData<T>),
}

#[cfg(feature = "plane-only")]
impl<T> Never<T> {
    fn absurd<U>(&self) -> U {
        match *self {
            Never::_Of(never, _) => match never {},
        }
    }
}

#[cfg(feature = "plane-only")]
impl<T> Clone for Never<T> {
    fn clone(&self) -> Self {
        self.absurd()
    }
}

#[cfg(feature = "plane-only")]
impl<T> PartialEq for Never<T> {
    fn eq(&self, _: &Self) -> bool {
        self.absurd()
    }
}

#[cfg(feature = "plane-only")]
impl<T> core::fmt::Debug for Never<T> {
    fn fmt(&self, _: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        self.absurd()
    }
}

#[cfg(all(feature = "plane-only", feature = "defmt"))]
impl<T> defmt::Format for Never<T> {
    fn format(&self, _: defmt::Formatter<'_>) {
        self.absurd()
    }
}

#[cfg(feature = "plane-only")]
impl<T> Serialize for Never<T> {
    fn serialize<S: serde::Serializer>(&self, _: S) -> Result<S::Ok, S::Error> {
        self.absurd()
    }
}

#[cfg(feature = "plane-only")]
impl<'de, T> Deserialize<'de> for Never<T> {
    fn deserialize<D: serde::Deserializer<'de>>(_: D) -> Result<Self, D::Error> {
        Err(serde::de::Error::custom(
            "a 1D reply, which this build never reads",
        ))
    }
}

/// Where the active scene came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SceneSource {
    /// The firmware's built-in default scene (fig. 11).
    Default,
    /// The scene embedded at build time (`SAW_SCENE`).
    BuildTime,
    /// The scene saved in flash.
    Saved,
    /// Loaded or edited over the link since boot.
    Link,
}

/// The answer to [`Request::Hello`].
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Hello {
    /// The board's [`PROTOCOL_VERSION`].
    pub protocol: u16,
    /// Firmware name and version, e.g. `saw-firmware 0.1.0`.
    pub firmware: String<NAME_BYTES>,
    /// Board name, e.g. `nucleo-f446re`.
    pub board: String<NAME_BYTES>,
    /// Samples per second of the control loop.
    pub sample_rate_hz: u32,
    /// The active scene's id ([`crate::scene_id`]).
    pub scene_id: u32,
    /// Where the active scene came from.
    pub scene_source: SceneSource,
}

/// Counters of the sample path and of the link since boot or the last reset.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// The control core's counters (samples, faults, region switches, pulses, skips) and its
    /// last values; the last values are never reset.
    pub core: Telemetry,
    /// The link's own.
    pub link: LinkCounters,
}

/// What the link saw, per kind of frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkCounters {
    /// Frames decoded and answered.
    pub frames_ok: u32,
    /// Frames refused: COBS, CRC, oversize, version or decoding errors.
    pub frames_bad: u32,
    /// Telemetry records dropped because the link was busy (the stream never stalls the
    /// sample path: a full queue drops).
    pub records_dropped: u32,
    /// Telemetry records sent.
    pub records_sent: u32,
}

/// One sample of the telemetry stream.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Record {
    /// The sample's time, µs since the board booted (64 bits: never wraps).
    pub time_us: u64,
    /// The id of the scene in force at this sample ([`crate::scene_id`]).
    pub scene_id: u32,
    /// Scene changes since boot (loads and edits over the link) at this sample: the first
    /// record of every change is always sent, whatever the decimation, so a continuous log
    /// splits into trials at the records where this count steps.
    pub change: u32,
    /// Position, µm, while the sensor is healthy.
    pub position_um: Option<i32>,
    /// Velocity, µm/s, once the estimator has a full window.
    pub velocity_um_s: Option<i32>,
    /// Region under the finger.
    pub region: Option<u8>,
    /// Burst frequency in force, mHz (0: no bursts).
    pub burst_millihz: u32,
    /// Bursts are running (the burst timer gates the carrier); false while the line is held
    /// off. The instantaneous enable level, sampled at the stream's rate, would only alias the
    /// burst frequency.
    pub bursting: bool,
    /// The sensor fault in force.
    pub fault: Option<SensorFault>,
}

/// A frame of the telemetry stream.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stream {
    /// Records the board dropped since boot (a full queue; never reset): a host sees a gap
    /// as a jump of this count between two frames.
    pub dropped: u32,
    /// The records, oldest first.
    pub records: Vec<Record, RECORDS_PER_FRAME>,
}

/// What the board sends: the reply to a request, or a stream frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
// A whole scene rides inline: the board has no allocator to box it, and one message is held
// at a time.
#[allow(clippy::large_enum_variant)]
pub enum Reply {
    /// To [`Request::Hello`].
    Hello(Hello),
    /// To [`Request::GetScene`].
    Scene {
        /// Its id.
        scene_id: u32,
        /// Where it came from.
        source: SceneSource,
        /// The scene.
        config: LineReply<Config>,
    },
    /// A scene, boundary, texture or drive change is running from the next sample.
    Applied {
        /// The id of the scene now active.
        scene_id: u32,
    },
    /// The change was refused and nothing changed: the same error (and sentence) a scene file
    /// with these values gets on the host.
    Refused(LineReply<ConfigError>),
    /// To [`Request::Counters`].
    Counters(LineReply<Counters>),
    /// To [`Request::Stream`]: the decimation in force and the sample rate it divides.
    Streaming {
        /// Records every this many samples (0: stopped).
        every_samples: u16,
        /// Samples per second of the control loop.
        sample_rate_hz: u32,
        /// The board's clock when the request was handled, µs since boot: records of an
        /// earlier time are stale (still in transit from a stream asked for before) and the
        /// host drops them.
        from_us: u64,
    },
    /// The active scene is in flash.
    Saved {
        /// The id saved.
        scene_id: u32,
    },
    /// The save failed; the scene saved before (if any) is still there.
    SaveFailed(StoreFault),
    /// A stream frame (unsolicited; its header's `seq` counts stream frames).
    Stream(LineReply<Stream>),
    /// The request's frame was refused.
    Error(LinkError),
    /// To [`Request::Ping`].
    Pong {
        /// The board's clock when it handled the ping, µs since boot.
        board_time_us: u64,
    },
    // Protocol 2, appended (issue #36).
    /// To [`Request::GetScene`] when the active scene is 2D.
    #[cfg(feature = "plane")]
    Scene2d {
        /// Its id ([`crate::plane_scene_id`]).
        scene_id: u32,
        /// Where it came from.
        source: SceneSource,
        /// The scene and the plate it is drawn on.
        scene: PlaneScene,
    },
    /// A 2D request, or a 1D one on a board that runs 2D scenes, was refused: nothing changed.
    #[cfg(feature = "plane")]
    Refused2d(Refused2d),
    /// To [`Request::Sensor`].
    #[cfg(feature = "plane")]
    Sensor(Sensor),
    /// To [`Request::Counters`] on a board running a 2D scene.
    #[cfg(feature = "plane")]
    Counters2d(Counters2d),
    /// A 2D stream frame (unsolicited; its header's `seq` counts stream frames).
    #[cfg(feature = "plane")]
    Stream2d(Stream2d),
}

/// Which position sensor a board reads: what kind of scene it runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg(feature = "plane")]
pub enum Sensor {
    /// The slide rheostat: 1D scenes (regions along the stroke).
    Rheostat,
    /// The 4-wire resistive touch overlay: 2D scenes (windows and edges on the plate).
    FourWire {
        /// The overlay's touch area, µm (width, height): a scene's plate must fit it.
        plate_um: (u32, u32),
    },
}

#[cfg(feature = "plane")]
impl core::fmt::Display for Sensor {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Sensor::Rheostat => f.write_str("the slide rheostat (1D scenes)"),
            Sensor::FourWire { plate_um: (w, h) } => write!(
                f,
                "the 4-wire touch overlay, {} x {} mm (2D scenes)",
                Millimetres(w as i64),
                Millimetres(h as i64)
            ),
        }
    }
}

/// A 2D scene as the link carries it: the scene file's `[screen] size_mm` (which
/// [`Config2d`] does not hold) with the configuration, so the scene read back is the file
/// pushed (`saw_core::scene_file::to_scene_file_2d`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg(feature = "plane")]
pub struct PlaneScene {
    /// The plate the scene is drawn on, µm (width, height): every vertex and edge end lies on
    /// it, from (0, 0).
    pub plate_um: (u32, u32),
    /// The scene, caps and stale limit.
    pub config: Config2d,
}

/// Which kind of scene a request was about (for [`Refused2d::WrongSensor`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg(feature = "plane")]
pub enum SceneKind {
    /// Regions along the rheostat's stroke.
    Line,
    /// Windows and edges on the touch overlay.
    Plane,
}

/// Why a 2D request (or a 1D request on a 2D board) was refused. The running scene is untouched
/// by every one of these; each reads as one sentence naming the value and the rule.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg(feature = "plane")]
pub enum Refused2d {
    /// The board's sensor does not read this kind of scene (or edit).
    WrongSensor {
        /// What the request was for.
        asked: SceneKind,
        /// What the board reads.
        board: Sensor,
    },
    /// The board's firmware reads the overlay but cannot run 2D scenes yet.
    Unsupported,
    /// The controller refused the scene (the same sentence a scene file with these values gets).
    Config(Config2dError),
    /// The scene's plate is wider or taller than the board's overlay.
    PlateTooLarge {
        /// The scene's plate, µm.
        scene_um: (u32, u32),
        /// The board's overlay, µm.
        board_um: (u32, u32),
    },
    /// A vertex or edge end lies off the scene's plate.
    OffPlate {
        /// Window `index`, or free edge `index` when `edge` is set.
        index: u8,
        /// A free edge's end, not a window's vertex.
        edge: bool,
        /// The point, µm.
        at: PointUm,
        /// The plate, µm.
        plate_um: (u32, u32),
    },
    /// No such window.
    NoWindow {
        /// The index asked for.
        window: u8,
        /// Windows in the scene.
        windows: u8,
    },
    /// A resize of a window that is not an axis-aligned rectangle (polygons only move).
    NotARectangle {
        /// The window.
        window: u8,
        /// Its vertices.
        vertices: u8,
    },
    /// A resize whose corners are not lower-left and upper-right.
    BadCorners {
        /// Lower-left asked, µm.
        lo: PointUm,
        /// Upper-right asked, µm.
        hi: PointUm,
    },
}

/// µm shown as mm, with a sign: 95000 → 95, -1500 → -1.5.
#[cfg(feature = "plane")]
struct Millimetres(i64);

#[cfg(feature = "plane")]
impl core::fmt::Display for Millimetres {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let (sign, v) = if self.0 < 0 {
            ("-", -self.0)
        } else {
            ("", self.0)
        };
        let (whole, frac) = (v / 1000, v % 1000);
        if frac == 0 {
            write!(f, "{sign}{whole}")
        } else {
            let mut digits = frac;
            let mut width = 3;
            while digits % 10 == 0 {
                digits /= 10;
                width -= 1;
            }
            write!(f, "{sign}{whole}.{digits:0width$}")
        }
    }
}

#[cfg(feature = "plane")]
impl core::fmt::Display for Refused2d {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let mm = |v: i32| Millimetres(v as i64);
        match *self {
            Refused2d::WrongSensor {
                asked: SceneKind::Plane,
                board,
            } => write!(
                f,
                "this board reads {board}: a 2D scene ([sensor] kind = \"4-wire\") or a window edit needs a board with the 4-wire touch overlay"
            ),
            Refused2d::WrongSensor { board, .. } => write!(
                f,
                "this board reads {board}: a 1D scene (regions, boundaries; no [sensor] table) needs a board with the slide rheostat"
            ),
            Refused2d::Unsupported => f.write_str(
                "this board's firmware does not run 2D scenes yet: nothing changed",
            ),
            Refused2d::Config(e) => e.fmt(f),
            Refused2d::PlateTooLarge { scene_um, board_um } => write!(
                f,
                "the scene's plate {} x {} mm does not fit this board's overlay {} x {} mm",
                Millimetres(scene_um.0 as i64),
                Millimetres(scene_um.1 as i64),
                Millimetres(board_um.0 as i64),
                Millimetres(board_um.1 as i64)
            ),
            Refused2d::OffPlate {
                index,
                edge,
                at,
                plate_um,
            } => write!(
                f,
                "{} {index}: the point ({} mm, {} mm) is off the plate (0 to {} mm, 0 to {} mm)",
                if edge { "edge" } else { "window" },
                mm(at.x_um),
                mm(at.y_um),
                Millimetres(plate_um.0 as i64),
                Millimetres(plate_um.1 as i64)
            ),
            Refused2d::NoWindow { window, windows } => match windows {
                0 => write!(f, "window {window}: the board's scene has no windows"),
                1 => write!(f, "window {window}: the board's scene has 1 window (0)"),
                n => write!(
                    f,
                    "window {window}: the board's scene has {n} windows (0 to {})",
                    n - 1
                ),
            },
            Refused2d::NotARectangle { window, vertices } => write!(
                f,
                "window {window}: a polygon of {vertices} vertices, not an axis-aligned rectangle: it can be moved, not resized"
            ),
            Refused2d::BadCorners { lo, hi } => write!(
                f,
                "corners ({} mm, {} mm) and ({} mm, {} mm): the first must be left of and below the second",
                mm(lo.x_um),
                mm(lo.y_um),
                mm(hi.x_um),
                mm(hi.y_um)
            ),
        }
    }
}

/// The counters of a board running a 2D scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg(feature = "plane")]
pub struct Counters2d {
    /// The 2D control core's (readings, faults, lifts, window switches, pulses, skips).
    pub core: Telemetry2d,
    /// The link's own.
    pub link: LinkCounters,
}

/// The touch sensor's fault in a 2D record.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg(feature = "plane")]
pub enum Fault2d {
    /// An axis on a rail (an open or shorted terminal).
    Rail {
        /// The y axis (else x).
        y_axis: bool,
        /// Which rail.
        fault: SensorFault,
    },
    /// No reading for longer than the stale limit.
    Stale,
}

#[cfg(feature = "plane")]
impl From<saw_core::plane::TouchFault> for Fault2d {
    /// The controller's fault as the stream carries it (the board and the virtual board alike).
    fn from(f: saw_core::plane::TouchFault) -> Self {
        match f {
            saw_core::plane::TouchFault::Rail(a) => Fault2d::Rail {
                y_axis: a.axis == saw_core::touch::fault::Axis::Y,
                fault: a.fault,
            },
            saw_core::plane::TouchFault::Stale => Fault2d::Stale,
        }
    }
}

#[cfg(feature = "plane")]
impl Record2d {
    /// The burst frequency a gate action sets, mHz, for [`Record2d::burst_millihz`]: the timer's
    /// kernel clock over the settings' period (saturating); 0 for an Off and for a one-pulse (an
    /// edge's, which sets no frequency).
    pub fn millihz_of(clock_hz: u32, action: saw_core::gate::GateAction) -> u32 {
        use saw_core::gate::GateAction;
        match action {
            GateAction::Start(s) | GateAction::Update(s) => (clock_hz as u64 * 1000)
                .checked_div(s.period_clocks())
                .unwrap_or(0)
                .min(u32::MAX as u64)
                as u32,
            GateAction::Off | GateAction::Pulse(_) => 0,
        }
    }
}

/// One touch reading of the 2D telemetry stream.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg(feature = "plane")]
pub struct Record2d {
    /// The reading's time, µs since the board booted.
    pub time_us: u64,
    /// The id of the scene in force ([`crate::plane_scene_id`]).
    pub scene_id: u32,
    /// Scene changes since boot at this reading (as [`Record::change`]).
    pub change: u32,
    /// The finger, µm on the plate, while it presses without a fault.
    pub position: Option<PointUm>,
    /// Velocity per axis, µm/s, where the scene reads it and both axes have a full window.
    pub velocity_um_s: Option<(i32, i32)>,
    /// What is under the finger while it renders: a window or the background.
    pub place: Option<Place>,
    /// The edge crossed (its pulse fired) since the stream's previous record: at `--every 1`
    /// on this reading; decimated, the last one crossed on the readings the stream skipped
    /// ([`crate::stream::EdgeLatch`]), so no pulse goes unreported.
    pub edge: Option<u8>,
    /// Burst frequency in force, mHz (0: no bursts).
    pub burst_millihz: u32,
    /// Bursts (or an edge pulse) are running.
    pub bursting: bool,
    /// No finger on the overlay.
    pub lifted: bool,
    /// The sensor fault in force.
    pub fault: Option<Fault2d>,
}

/// A frame of the 2D telemetry stream.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg(feature = "plane")]
pub struct Stream2d {
    /// Records the board dropped since boot.
    pub dropped: u32,
    /// The records, oldest first.
    pub records: Vec<Record2d, RECORDS_PER_FRAME>,
}

/// Why a save failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum StoreFault {
    /// The board has no scene store.
    NoStore,
    /// The flash refused a write or an erase.
    Flash,
    /// The scene does not fit the store's item.
    TooLarge,
    /// Appended (issue #36): the store keeps 1D scenes only, and the active scene is 2D.
    NotFor2d,
}

/// A frame the board could not act on. The running scene is untouched by every one of these.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum LinkError {
    /// The frame's COBS encoding is broken (a byte lost or flipped on the line).
    Cobs,
    /// The frame's CRC-32 does not match its contents.
    Crc {
        /// The CRC the frame carried.
        carried: u32,
        /// The CRC of what arrived.
        computed: u32,
    },
    /// The frame is longer than the receive buffer; it was skipped to its end.
    Oversize {
        /// The receive buffer, bytes.
        max_bytes: u16,
    },
    /// Too short to hold a header and a CRC.
    Truncated {
        /// Bytes received.
        bytes: u16,
    },
    /// The sender speaks another protocol version.
    WrongVersion {
        /// The version this end speaks.
        ours: u16,
        /// The version the frame carried.
        theirs: u16,
    },
    /// A request number this protocol version does not define.
    UnknownRequest {
        /// The request's variant number.
        variant: u32,
    },
    /// The request's fields do not decode.
    Malformed,
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            LinkError::Cobs => write!(f, "a frame's COBS encoding was broken (a byte lost or corrupted on the line)"),
            LinkError::Crc { carried, computed } => write!(
                f,
                "a frame's CRC-32 {carried:#010x} does not match its contents ({computed:#010x}): corrupted on the line"
            ),
            LinkError::Oversize { max_bytes } => {
                write!(f, "a frame was longer than the {max_bytes}-byte receive buffer and was skipped")
            }
            LinkError::Truncated { bytes } => {
                write!(f, "a frame of {bytes} bytes is too short for a header and a CRC")
            }
            LinkError::WrongVersion { ours, theirs } => write!(
                f,
                "protocol version {theirs} is not this end's version {ours}: update the firmware or the host tool so they match"
            ),
            LinkError::UnknownRequest { variant } => write!(
                f,
                "request number {variant} is not defined in protocol version {PROTOCOL_VERSION}"
            ),
            LinkError::Malformed => write!(f, "a request's fields did not decode"),
        }
    }
}

impl core::fmt::Display for StoreFault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            StoreFault::NoStore => write!(f, "this board has no scene store"),
            StoreFault::Flash => write!(
                f,
                "the flash refused a write or an erase; the scene saved before is kept"
            ),
            StoreFault::TooLarge => write!(f, "the scene does not fit the store's item"),
            StoreFault::NotFor2d => write!(
                f,
                "this board's store keeps 1D scenes only: the 2D scene runs until power-off and is not saved"
            ),
        }
    }
}

impl Request {
    /// How many request variants this protocol version defines (postcard numbers them 0..N).
    #[cfg(feature = "plane")]
    pub const VARIANTS: u32 = 14;
    /// How many request variants this protocol version defines (postcard numbers them 0..N).
    #[cfg(not(feature = "plane"))]
    pub const VARIANTS: u32 = 10;
}
