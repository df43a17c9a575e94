//! The `scene loaded` line a user reads on the board's log names what was loaded: the region and
//! line counts of the scene file, counted here by hand from each file in `scenes/`.

use saw_boards::ALL;
use saw_core::scene_file;
use saw_core::Controller;
use saw_tests::{capture_logs, take_logs};

#[test]
fn load_line_counts_each_scene_files_regions_and_lines() {
    capture_logs();
    // (file, regions, lines): `[[region]]` tables and `lines.positions_mm` entries in the file.
    let scenes = [
        ("default.toml", 3, 0),
        ("grating.toml", 3, 0),
        ("lines.toml", 1, 5),
        ("material.toml", 2, 0),
        ("random.toml", 2, 0),
    ];
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/");
    for board in ALL {
        let timer = host_sim::sim::burst_timer(board);
        for (file, regions, lines) in scenes {
            let text = std::fs::read_to_string(format!("{dir}{file}")).unwrap();
            let doc = scene_file::parse(file, &text).unwrap();
            let mut ctrl = Controller::new(timer, 100).unwrap();
            take_logs();
            ctrl.load(&doc.config).unwrap();
            let logs = take_logs();
            let loaded: Vec<_> = logs
                .iter()
                .filter(|l| l.message.starts_with("scene loaded: "))
                .collect();
            assert_eq!(loaded.len(), 1, "{file}: {logs:?}");
            let want = format!("scene loaded: {regions} regions, {lines} lines, ");
            assert!(
                loaded[0].message.starts_with(&want),
                "{file} on {}: {:?}, expected it to start with {want:?}",
                board.name,
                loaded[0].message
            );
        }
    }
}
