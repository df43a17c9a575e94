//! Framing: a message on the wire is `COBS(header ‖ body ‖ CRC-32) 0x00`. postcard encodes the
//! header and body, the `crc` crate's CRC-32 (ISO-HDLC, the Ethernet/zlib one) guards them,
//! the `cobs` crate removes every zero so a zero ends the frame. A receiver that lands in the
//! middle of a frame (junk, a byte lost, a host unplugged mid-upload) resynchronises at the next
//! zero; a host sends a zero before each frame so a partial frame left by an earlier client is
//! closed and dropped rather than joined to the new one.

use crc::{Crc, CRC_32_ISO_HDLC};
use serde::de::DeserializeOwned;
use serde::Serialize;

use crate::msg::{Header, LinkError, Request, PROTOCOL_VERSION};

/// The largest decoded frame (header, body and CRC), bytes. The largest message is a whole
/// scene: the maximal 1D `Config` (8 regions of the largest texture, every line) encodes to
/// under 500 bytes, the maximal 2D scene (8 windows of 16 vertices at the plane's far
/// coordinates, 32 free edges, the widest textures) to 1 460 (`tests/frames.rs`,
/// `every_scene_file_round_trips_and_the_largest_scene_fits`): 2 048 leaves room for growth
/// (768 before 2D scenes, issue #36).
pub const MAX_PAYLOAD: usize = 2048;
/// The largest frame on the wire: COBS adds one byte per 254 and the zero that ends it.
pub const MAX_ENCODED: usize = MAX_PAYLOAD + MAX_PAYLOAD.div_ceil(254) + 1;

const CRC_BYTES: usize = 4;
const CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Why a message could not be framed (only a body larger than [`MAX_PAYLOAD`] or an output
/// buffer smaller than [`MAX_ENCODED`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum EncodeError {
    /// The message does not fit [`MAX_PAYLOAD`].
    TooLarge,
    /// The output buffer is too small for the encoded frame.
    OutputTooSmall,
}

impl core::fmt::Display for EncodeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            EncodeError::TooLarge => write!(
                f,
                "the message is longer than the {MAX_PAYLOAD}-byte frame limit"
            ),
            EncodeError::OutputTooSmall => write!(
                f,
                "the output buffer is smaller than a frame ({MAX_ENCODED} bytes)"
            ),
        }
    }
}

/// Frames `body` behind `header` into `out`, ending with the zero delimiter. Returns the bytes
/// written.
pub fn encode<T: Serialize>(
    header: &Header,
    body: &T,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut raw = [0u8; MAX_PAYLOAD];
    let head = postcard::to_slice(header, &mut raw)
        .map_err(|_| EncodeError::TooLarge)?
        .len();
    let rest = raw
        .get_mut(head..MAX_PAYLOAD - CRC_BYTES)
        .ok_or(EncodeError::TooLarge)?;
    let body_len = postcard::to_slice(body, rest)
        .map_err(|_| EncodeError::TooLarge)?
        .len();
    let len = head + body_len;
    let crc = CRC.checksum(&raw[..len]);
    raw[len..len + CRC_BYTES].copy_from_slice(&crc.to_le_bytes());
    let total = len + CRC_BYTES;
    let n = cobs::try_encode(&raw[..total], out).map_err(|_| EncodeError::OutputTooSmall)?;
    let end = out.get_mut(n).ok_or(EncodeError::OutputTooSmall)?;
    *end = 0;
    Ok(n + 1)
}

/// Collects bytes into frames: push each received byte; at a frame's end it says whether the
/// frame is whole (COBS and CRC checked). Never blocks, never panics, resynchronises at every
/// zero. `N` is the receive buffer, at least [`MAX_ENCODED`] to take every message.
#[derive(Debug)]
pub struct Receiver<const N: usize> {
    buf: [u8; N],
    len: usize,
    overflow: bool,
}

impl<const N: usize> Default for Receiver<N> {
    fn default() -> Self {
        Self {
            buf: [0; N],
            len: 0,
            overflow: false,
        }
    }
}

impl<const N: usize> Receiver<N> {
    /// Takes one byte. Returns `None` inside a frame (and for the empty frame between two
    /// zeros), `Some(Ok(len))` at the end of a whole frame — [`Receiver::payload`] then holds
    /// its `len` bytes of header and body — or `Some(Err)` for a frame that must be dropped.
    pub fn push(&mut self, byte: u8) -> Option<Result<usize, LinkError>> {
        if byte != 0 {
            if self.len < N {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflow = true;
            }
            return None;
        }
        let len = core::mem::take(&mut self.len);
        if core::mem::take(&mut self.overflow) {
            return Some(Err(LinkError::Oversize {
                max_bytes: N.min(u16::MAX as usize) as u16,
            }));
        }
        if len == 0 {
            return None;
        }
        Some(check(&mut self.buf[..len]))
    }

    /// The header and body of the frame [`Receiver::push`] last reported whole.
    pub fn payload(&self, len: usize) -> &[u8] {
        &self.buf[..len.min(N)]
    }
}

/// COBS-decodes `frame` in place and checks its CRC; returns the length of header and body.
fn check(frame: &mut [u8]) -> Result<usize, LinkError> {
    let n = cobs::decode_in_place(frame).map_err(|_| LinkError::Cobs)?;
    if n < CRC_BYTES + 2 {
        return Err(LinkError::Truncated {
            bytes: n.min(u16::MAX as usize) as u16,
        });
    }
    let body = n - CRC_BYTES;
    let mut carried = [0u8; CRC_BYTES];
    carried.copy_from_slice(&frame[body..n]);
    let carried = u32::from_le_bytes(carried);
    let computed = CRC.checksum(&frame[..body]);
    if carried != computed {
        return Err(LinkError::Crc { carried, computed });
    }
    Ok(body)
}

/// A frame whose header was read but which is refused: the reply carries the same `seq`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Refusal {
    /// The frame's request number, when its header decoded.
    pub seq: Option<u32>,
    /// Why.
    pub error: LinkError,
}

/// Reads the header of a whole frame's payload and checks its version; returns it and the body.
pub fn header(payload: &[u8]) -> Result<(Header, &[u8]), Refusal> {
    let (header, body): (Header, &[u8]) =
        postcard::take_from_bytes(payload).map_err(|_| Refusal {
            seq: None,
            error: LinkError::Malformed,
        })?;
    if header.version != PROTOCOL_VERSION {
        return Err(Refusal {
            seq: Some(header.seq),
            error: LinkError::WrongVersion {
                ours: PROTOCOL_VERSION,
                theirs: header.version,
            },
        });
    }
    Ok((header, body))
}

/// Decodes a request frame's payload (the board's side).
pub fn request(payload: &[u8]) -> Result<(Header, Request), Refusal> {
    let (header, body) = header(payload)?;
    let refuse = |error| Refusal {
        seq: Some(header.seq),
        error,
    };
    // postcard numbers enum variants with a leading varint: read it first so a request from a
    // newer host reads as "unknown request N", not as a decoding failure.
    let (variant, _): (u32, &[u8]) =
        postcard::take_from_bytes(body).map_err(|_| refuse(LinkError::Malformed))?;
    if variant >= Request::VARIANTS {
        return Err(refuse(LinkError::UnknownRequest { variant }));
    }
    match postcard::from_bytes::<Request>(body) {
        Ok(req) => Ok((header, req)),
        Err(_) => Err(refuse(LinkError::Malformed)),
    }
}

/// Decodes any message's payload (the host's side, and tests).
pub fn message<T: DeserializeOwned>(payload: &[u8]) -> Result<(Header, T), Refusal> {
    let (header, body) = header(payload)?;
    postcard::from_bytes::<T>(body)
        .map(|m| (header, m))
        .map_err(|_| Refusal {
            seq: Some(header.seq),
            error: LinkError::Malformed,
        })
}
