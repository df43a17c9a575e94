//! The host link's bytes as the board takes them: the line through the frame receiver, or one
//! frame's header and body into the decoder and the session (`saw_link::testing::link_bytes`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = saw_link::testing::link_bytes(data);
});
