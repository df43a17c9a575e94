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
    // (file, regions, lines, kinds): `[[region]]` tables, `lines.positions_mm` entries and each
    // region's `kind` in the file.
    let scenes = [
        ("default.toml", 3, 0, &["constant"; 3][..]),
        ("grating.toml", 3, 0, &["grating"; 3][..]),
        ("lines.toml", 1, 5, &["off"][..]),
        ("material.toml", 2, 0, &["material"; 2][..]),
        ("random.toml", 2, 0, &["random"; 2][..]),
    ];
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/");
    for board in ALL {
        let timer = host_sim::sim::burst_timer(board);
        for (file, regions, lines, kinds) in scenes {
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
            // One line per region naming its texture.
            let named: Vec<String> = logs
                .iter()
                .map(|l| l.message.clone())
                .filter(|m| m.starts_with("region ") && !m.contains(" at "))
                .collect();
            let want: Vec<String> = kinds
                .iter()
                .enumerate()
                .map(|(i, k)| format!("region {i}: {k}"))
                .collect();
            assert_eq!(named, want, "{file}");
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

/// Ridges the duty cap will not let fire are counted and logged, and a steady stroke logs
/// nothing of the kind. A position-phase grating (λ = 1 mm, 40 %, default caps: 50 % over a
/// 300 ms window): a finger that crawls over each ridge at 8 mm/s (0.4 mm in 50 ms, from 0.1 mm
/// before it to 0.3 mm past) and darts to the next at 200 mm/s (0.7 mm in 3.5 ms) keeps each
/// pulse on for about 38 ms of every 53.5 ms, 71 %: the window's 150 ms hold four such pulses,
/// so about every other ridge after the first four is refused — counted, with a log line each.
/// (Under the per-pulse rule a 20 → 200 mm/s step skipped ridges too; it no longer does:
/// tests/grating.rs.)
#[test]
fn ridges_the_duty_cap_refuses_are_counted_and_logged() {
    capture_logs();
    let board = &ALL[0];
    let mut cfg = saw_core::default_config();
    cfg.scene.boundaries_um.clear();
    cfg.scene.textures.clear();
    let _ = cfg.scene.textures.push(saw_core::texture::Texture::Grating(
        saw_core::texture::Grating::new(1_000),
    ));
    let run_for = |n: u32, path: &dyn Fn(u32) -> f32| {
        let mut ctrl = Controller::new(host_sim::sim::burst_timer(board), 100).unwrap();
        ctrl.load(&cfg).unwrap();
        let mapper = *ctrl.mapper().unwrap();
        take_logs();
        for i in 0..n {
            let code = mapper.code_at_um(path(i)) as u16;
            ctrl.on_sample(Sample {
                code,
                t_us: i * 100,
            });
        }
        let skipped_lines = take_logs()
            .iter()
            .filter(|l| l.message.contains("ridge crossings without a pulse"))
            .count();
        (ctrl.telemetry(), skipped_lines)
    };
    // Steady 20 mm/s from 5.5 mm: four ridges, each fired.
    let (t, lines) = run_for(2_000, &|i| 5_500.0 + 2.0 * i as f32);
    assert_eq!((t.ridge_pulses, t.ridges_skipped, lines), (4, 0, 0));
    // 20 mm/s to 6.1 mm (30 ms), rest there 20 ms, then 200 mm/s.
    // Crawl over each ridge, dart to the next: 535 samples a ridge, from 5.9 mm. The 6 mm ridge,
    // rearm_um from the start, is an arrival, not a crossing: 10 ridges (7–16 mm) are crossed.
    // Measured: the first four fire, then every other one (6 fired, 4 refused).
    let (t, lines) = run_for(6_000, &|i| {
        let (k, j) = ((i / 535) as f32, i % 535);
        let at = if j < 500 {
            0.8 * j as f32
        } else {
            400.0 + 20.0 * (j - 500) as f32
        };
        5_900.0 + 1_000.0 * k + at
    });
    assert_eq!(
        (t.ridge_pulses, t.ridges_skipped, lines),
        (6, 4, 4),
        "{t:?}"
    );
}
