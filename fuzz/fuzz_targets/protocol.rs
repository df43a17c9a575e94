//! A protocol file's bytes through the reader (its scenes the repository's), and an accepted
//! one run by the runner, every trial answered, refused values offered, half resumed
//! (`saw_experiment::testing::protocol`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = saw_experiment::testing::protocol(data);
});
