//! A session log's bytes reopened as a resume does, its CSV read by the analysis and its
//! protocol resumed with its answers (`saw_experiment::testing::session_log`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = saw_experiment::testing::session_log(data);
});
