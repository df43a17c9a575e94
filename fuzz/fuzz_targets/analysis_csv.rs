//! A session or lab CSV's bytes through the analysis' reader, and the rows read analysed
//! (`saw_experiment::testing::analysis_csv`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = saw_experiment::testing::analysis_csv(data);
});
