//! `Controller2d` over arbitrary scene configurations and readings: the fuzzer's bytes are a
//! `Config2d` (postcard, as the host link carries configurations; a fixed scene with windows,
//! edges and an oriented grating when they do not decode or load), then operations — lifted,
//! landing, down, rail-fault readings, raw frames through a calibrated `TouchSensor`, watchdog
//! ticks after arbitrary silences, clock jumps across the u32 wrap, mid-stream reloads of other
//! decoded configurations. Checked on every action, from the caps' statement rather than the
//! gate's code: no panic; every on-time within the on-time cap of the scenes in force (one timer
//! tick of rounding); no burst or pulse started on a lifted, landing or faulty reading, nor by a
//! tick; a running periodic burst stopped on such a reading.
#![no_main]

#[path = "../bodies/plane.rs"]
mod plane;

libfuzzer_sys::fuzz_target!(|data: &[u8]| plane::controller2d(data));
