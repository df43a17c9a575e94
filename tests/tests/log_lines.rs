//! Log lines a user reads on the board: `scene loaded` names what was loaded (the region and line
//! counts of each file in `scenes/`, counted here by hand), and region changes are rate-limited
//! to one line per 100 ms with the count of those left out.

use saw_boards::ALL;
use saw_core::sample::Sample;
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

/// A finger rubbing across the default scene's first boundary (18.96 mm) every 5 ms for 1 s:
/// 200 region entries. One line per 100 ms is logged (t = 0, 100, …, 900 ms: 10 lines), each
/// after the first saying the 19 changes left out since the one before.
#[test]
fn region_lines_are_rate_limited_and_count_what_they_leave_out() {
    capture_logs();
    let board = &ALL[0];
    let mut ctrl = Controller::new(host_sim::sim::burst_timer(board), 100).unwrap();
    ctrl.load(&saw_core::default_config()).unwrap();
    let mapper = *ctrl.mapper().unwrap();
    let (a, b) = (
        mapper.code_at_um(18_000.0) as u16,
        mapper.code_at_um(20_000.0) as u16,
    );
    take_logs();
    for i in 0..10_000u32 {
        let code = if (i / 50) % 2 == 0 { a } else { b };
        ctrl.on_sample(Sample {
            code,
            t_us: i * 100,
        });
    }
    let lines: Vec<String> = take_logs()
        .into_iter()
        .map(|l| l.message)
        .filter(|m| m.starts_with("region "))
        .collect();
    let left_out: Vec<u32> = lines
        .iter()
        .map(|m| {
            let n = m.rsplit_once('(').unwrap().1;
            n.strip_suffix(" changes not logged)")
                .unwrap()
                .parse()
                .unwrap()
        })
        .collect();
    assert_eq!(
        left_out,
        [0, 19, 19, 19, 19, 19, 19, 19, 19, 19],
        "{lines:?}"
    );
    assert_eq!(ctrl.telemetry().region_switches, 199);
}
