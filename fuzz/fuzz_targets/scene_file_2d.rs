//! A 2D scene file's bytes (issue #36: `[sensor] kind = "4-wire"`, `[screen]`, `[[window]]`,
//! `[[edge]]`, …) through the 2D reader and the board check (`load_2d_for_board`, which dry-runs
//! a `Controller2d`), the sensor and plate queries beside it; an accepted file written back
//! (`to_scene_file_2d`) reads back to the same configuration. A refusal's sentence names the
//! file. Seeds: the shipped 2D scenes (scenes/2d-*.toml).
#![no_main]

use saw_core::scene_file::{load_2d_for_board, plate_um_of, sensor_of, to_scene_file_2d};
use saw_link::testing::TIMER;

/// The F446's touch frame period on the default plates, µs (host-sim's schedule, 2 889 Hz).
const FRAME_US: u32 = 347;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let Ok(text) = core::str::from_utf8(data) else {
        return;
    };
    let _ = sensor_of("fuzz.toml", text);
    let plate = plate_um_of("fuzz.toml", text);
    match load_2d_for_board("fuzz.toml", text, TIMER, FRAME_US) {
        Ok(config) => {
            let plate = plate.expect("an accepted 2D file has a plate");
            let again = to_scene_file_2d(&config, plate, "fuzz");
            let back = load_2d_for_board("again.toml", &again, TIMER, FRAME_US)
                .expect("a 2D scene file written from an accepted scene reads back");
            assert_eq!(back, config, "written back:\n{again}");
        }
        Err(e) => {
            let line = e.to_string();
            assert!(line.starts_with("fuzz.toml"), "{line}");
        }
    }
});
