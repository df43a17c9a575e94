//! The host link of the SAW tactile display: the typed messages both ends share ([`msg`]),
//! their framing with a CRC and COBS ([`frame`]), the board's side of a session ([`session`])
//! and the telemetry stream's decimation and batching ([`stream`]). With `std`, the host's
//! blocking client ([`client`]). Wire format: `docs/link.md`.
//!
//! Why not postcard-rpc: its serial transport frames with COBS but carries no integrity check,
//! and a flipped bit in a boundary or an f_b must never reach an RF actuator. Wrapping it would
//! fork its wire format. Its ideas are kept: typed requests shared by both ends, a sequence
//! number matching each reply to its request, unsolicited stream frames beside the replies, a
//! version checked on every frame.

#![cfg_attr(not(feature = "std"), no_std)]

#[cfg(feature = "std")]
pub mod client;
#[cfg(feature = "std")]
pub mod clock;
pub mod frame;
pub mod msg;
pub mod session;
pub mod stream;
#[cfg(feature = "testing")]
pub mod testing;

use crc::{Crc, CRC_32_ISO_HDLC};
use saw_core::scene::Config;

/// A scene's id: the CRC-32 of its postcard encoding. The same scene has the same id on every
/// host and board, so a host can tell whether the board runs the file it has.
pub fn scene_id(config: &Config) -> u32 {
    let mut buf = [0u8; frame::MAX_PAYLOAD];
    match postcard::to_slice(config, &mut buf) {
        Ok(bytes) => Crc::<u32>::new(&CRC_32_ISO_HDLC).checksum(bytes),
        // Cannot happen for a Config (its largest encoding fits, see frame's tests); 0 reads
        // as "unknown".
        Err(_) => 0,
    }
}
