//! The messages both ends share: requests from the host, the board's replies, the telemetry
//! stream and the link's own errors. Their postcard encoding is the protocol; a change to any
//! type here that is not an appended enum variant bumps [`PROTOCOL_VERSION`].

use heapless::{String, Vec};
use saw_core::controller::{ConfigError, Telemetry};
use saw_core::gate::DriveMode;
use saw_core::position::SensorFault;
use saw_core::scene::Config;
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
    LoadScene(Config),
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
        texture: Texture,
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
        config: Config,
    },
    /// A scene, boundary, texture or drive change is running from the next sample.
    Applied {
        /// The id of the scene now active.
        scene_id: u32,
    },
    /// The change was refused and nothing changed: the same error (and sentence) a scene file
    /// with these values gets on the host.
    Refused(ConfigError),
    /// To [`Request::Counters`].
    Counters(Counters),
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
    Stream(Stream),
    /// The request's frame was refused.
    Error(LinkError),
    /// To [`Request::Ping`].
    Pong {
        /// The board's clock when it handled the ping, µs since boot.
        board_time_us: u64,
    },
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
        }
    }
}

impl Request {
    /// How many request variants this protocol version defines (postcard numbers them 0..N).
    pub const VARIANTS: u32 = 10;
}
