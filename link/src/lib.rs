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

// `plane-only` takes the 1D scenes out (a 2D board's firmware); the host needs both kinds.
#[cfg(all(feature = "plane-only", feature = "std"))]
compile_error!("saw-link: `plane-only` is for a 2D board's firmware, not with `std` (the host reads 1D and 2D scenes)");

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
use serde::Serialize;

/// A scene's id: the CRC-32 of its postcard encoding. The same scene has the same id on every
/// host and board, so a host can tell whether the board runs the file it has.
pub fn scene_id(config: &Config) -> u32 {
    crc_of(config)
}

#[cfg(feature = "plane")]
/// A 2D scene's id: the CRC-32 of its postcard encoding (plate and configuration), as
/// [`scene_id`] is a 1D scene's.
pub fn plane_scene_id(scene: &msg::PlaneScene) -> u32 {
    crc_of(scene)
}

/// The CRC-32 of `value`'s postcard encoding, fed to the CRC as it is written (no buffer).
fn crc_of<T: Serialize>(value: &T) -> u32 {
    struct Digesting<'a>(crc::Digest<'a, u32>);
    impl postcard::ser_flavors::Flavor for Digesting<'_> {
        type Output = u32;
        fn try_push(&mut self, data: u8) -> postcard::Result<()> {
            self.0.update(&[data]);
            Ok(())
        }
        fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
            self.0.update(data);
            Ok(())
        }
        fn finalize(self) -> postcard::Result<u32> {
            Ok(self.0.finalize())
        }
    }
    const CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
    // A digest flavor cannot fail; 0 reads as "unknown".
    postcard::serialize_with_flavor(value, Digesting(CRC.digest())).unwrap_or(0)
}
