//! Structure-aware scene files: the fuzzer's bytes as choices that build a scene (tables, keys,
//! array lengths, values), written as TOML and read as `scene_file` reads a file
//! (`saw_link::testing::scene_struct_bytes`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = saw_link::testing::scene_struct_bytes(data);
});
