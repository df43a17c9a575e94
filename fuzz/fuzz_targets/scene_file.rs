//! A scene file's bytes through the reader and the board check, and an accepted one written
//! back and read again (`saw_link::testing::scene_file_bytes`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = saw_link::testing::scene_file_bytes(data);
});
