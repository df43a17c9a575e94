//! A 2D scene file's bytes (issue #36: `[sensor] kind = "4-wire"`, `[screen]`, `[[window]]`,
//! `[[edge]]`, …) through the 2D reader and the board check (`load_2d_for_board`, which dry-runs
//! a `Controller2d`), the sensor and plate queries beside it; an accepted file written back
//! (`to_scene_file_2d`) reads back to the same configuration. A refusal's sentence names the
//! file. Seeds: the shipped 2D scenes (scenes/2d-*.toml).
#![no_main]

#[path = "../bodies/plane.rs"]
mod plane;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = plane::scene_file_2d(data);
});
