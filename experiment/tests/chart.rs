//! The analysis charts (`chart` feature): the PNG's size is the one the report implies, the
//! panels draw the data (two reports with different scales differ in pixels, and in the paired
//! panel only), each panel's elements appear in their colours, an empty report is an error
//! sentence (no file), and no report — NaN, infinite, empty, mismatched — makes it panic.
//!
//! The reports are built by hand (every type is pub with pub fields), fits and tracks by the
//! crate's own functions so they are what the analysis would hand over.
#![cfg(feature = "chart")]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_experiment::analysis::paired::{PairedAnalysis, Variant, Yardstick};
use saw_experiment::analysis::psychometric::{
    self, BootstrapKind, BootstrapOptions, FitOptions, LevelCount, Model,
};
use saw_experiment::analysis::report::{
    ConstantBlock, Correlation, ModelFit, PairedBlock, Report, Track,
};
use saw_experiment::chart::{self, CONSTANT_PX, PAIRED_PX, TITLE_PX, TRACKS_PX, WIDTH_PX};
use saw_experiment::staircase::{Staircase, StaircaseSpec, StepScale};

const STIMULI: [&str; 5] = ["#20", "#40", "#60", "#80", "#100"];

fn keyed(values: &[f64]) -> BTreeMap<String, f64> {
    STIMULI
        .iter()
        .map(|s| s.to_string())
        .zip(values.iter().copied())
        .collect()
}

/// A paired block with Scheffé's scale `scale`, yardsticks at 5 % and 1 %, and Thurstone's
/// and Bradley–Terry's values (of other units, as theirs are).
fn paired(block: &str, scale: &[f64]) -> PairedBlock {
    let yard = |alpha: f64, q: f64, y: f64| Yardstick {
        alpha,
        q,
        y,
        separated: vec![],
    };
    PairedBlock {
        block: block.into(),
        subjects: 12,
        judgments: 240,
        scheffe: PairedAnalysis {
            variant: Variant::Nakaya,
            stimuli: STIMULI.iter().map(|s| s.to_string()).collect(),
            scale: scale.to_vec(),
            subjects: (1..=12).map(|i| format!("s{i:02}")).collect(),
            replications: 12,
            anova: vec![],
            yardstick: vec![yard(0.05, 3.86, 0.41), yard(0.01, 4.64, 0.52)],
            order_effect: None,
            subject_scales: vec![],
        },
        scale: keyed(scale),
        thurstone: Some(keyed(
            &scale.iter().map(|v| v * 1.7 + 0.1).collect::<Vec<_>>(),
        )),
        bradley_terry: Some(keyed(&scale.iter().map(|v| v * 2.9).collect::<Vec<_>>())),
    }
}

/// A 2-down-1-up track run on a seeded simulated observer, as the report carries it.
fn track(subject: &str, name: &str, start: f64, seed: u64) -> Track {
    let mut s = Staircase::new(StaircaseSpec {
        name: name.into(),
        start,
        down: 2,
        up: 1,
        steps: vec![8.0, 4.0, 2.0],
        scale: StepScale::Linear,
        min: 0.0,
        max: 60.0,
        max_trials: Some(50),
        max_reversals: None,
        threshold_reversals: 6,
    })
    .expect("a valid spec");
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for _ in 0..50 {
        // Weibull observer, threshold 20, 2AFC.
        let p = 0.5 + 0.5 * (1.0 - (-(s.level() / 20.0).powf(3.0)).exp());
        s.respond(rng.random::<f64>() < p);
    }
    Track {
        subject: subject.into(),
        block: "fb threshold".into(),
        track: name.into(),
        levels: s.trials().iter().map(|t| t.level).collect(),
        correct: s.trials().iter().map(|t| t.correct).collect(),
        reversal_levels: s.reversal_levels(),
        threshold: s.threshold(),
        threshold_reversals: 6,
    }
}

fn constant() -> ConstantBlock {
    let points: Vec<LevelCount> = [
        (5.0, 40, 21),
        (10.0, 40, 24),
        (15.0, 40, 29),
        (20.0, 60, 47),
        (25.0, 40, 37),
        (30.0, 20, 20),
    ]
    .into_iter()
    .map(|(level, n_trials, n_correct)| LevelCount {
        level,
        n_trials,
        n_correct,
    })
    .collect();
    let opts = FitOptions {
        guess: 0.5,
        lapse: 0.0,
        target: 0.75,
    };
    let boot = BootstrapOptions {
        kind: BootstrapKind::Parametric,
        n_resamples: 40,
        seed: 7,
        confidence: 0.95,
    };
    let fits = [Model::Weibull, Model::Logistic]
        .into_iter()
        .map(|model| ModelFit {
            model,
            result: psychometric::bootstrap(&points, model, &opts, &boot)
                .map_err(|e| e.to_string()),
        })
        .collect();
    ConstantBlock {
        block: "fb constant".into(),
        points,
        fits,
    }
}

/// Two paired blocks (correlated), three tracks of two subjects (two panels), one
/// constant-stimuli block: five panels.
fn full(scale_a: &[f64]) -> Report {
    Report {
        paired: vec![
            paired("real", scale_a),
            paired("virtual", &[-0.61, -0.2, 0.05, 0.3, 0.46]),
        ],
        correlations: vec![Correlation {
            blocks: ("real".into(), "virtual".into()),
            pairs: STIMULI
                .iter()
                .map(|s| (s.to_string(), s.to_string()))
                .collect(),
            pearson: Some(0.97),
            spearman: Some(1.0),
        }],
        tracks: vec![
            track("s01", "from above", 50.0, 1),
            track("s01", "from below", 5.0, 2),
            track("s02", "from above", 50.0, 3),
        ],
        constant: vec![constant()],
        staircase_fits: vec![],
        refused: vec![],
    }
}

const SCALE_A: [f64; 5] = [-0.72, -0.31, 0.02, 0.38, 0.63];
const SCALE_B: [f64; 5] = [-0.1, -0.55, 0.7, -0.12, -0.09];

fn out(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("chart-{}-{name}", std::process::id()))
}

/// Width and height from a PNG's IHDR (the first chunk), after checking the signature.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert!(
        bytes.len() > 24,
        "a PNG is longer than {} bytes",
        bytes.len()
    );
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "the PNG signature");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |b: &[u8]| u32::from_be_bytes([b[0], b[1], b[2], b[3]]);
    (be(&bytes[16..20]), be(&bytes[20..24]))
}

#[test]
fn png_has_the_size_the_report_implies() {
    let report = full(&SCALE_A);
    let want = (
        WIDTH_PX,
        TITLE_PX + 2 * PAIRED_PX + 2 * TRACKS_PX + CONSTANT_PX,
    );
    assert_eq!(chart::size(&report), want);
    let rects = chart::panel_rects(&report);
    assert_eq!(rects.len(), 5);
    assert_eq!(rects[0].1, TITLE_PX as i32);
    assert_eq!(rects[4].3, want.1 as i32);
    let png = out("size.png");
    chart::draw(&report, &png).expect("the chart is drawn");
    let bytes = std::fs::read(&png).expect("the PNG is written");
    assert_eq!(png_size(&bytes), want);
    let (w, h, rgb) = chart::pixels(&report).expect("drawn in memory");
    assert_eq!((w, h), want);
    assert_eq!(rgb.len(), (w * h * 3) as usize);
    std::fs::remove_file(&png).ok();
}

/// Pixels `(x, y)` at which two images of the same size differ.
fn differing(a: &[u8], b: &[u8], w: u32) -> Vec<(i32, i32)> {
    a.chunks(3)
        .zip(b.chunks(3))
        .enumerate()
        .filter(|(_, (p, q))| p != q)
        .map(|(i, _)| ((i as u32 % w) as i32, (i as u32 / w) as i32))
        .collect()
}

#[test]
fn a_different_scale_draws_different_pixels_in_its_panel_only() {
    let (a, b) = (full(&SCALE_A), full(&SCALE_B));
    let (w, h, pa) = chart::pixels(&a).unwrap();
    let (_, _, pb) = chart::pixels(&b).unwrap();
    assert_eq!(chart::size(&b), (w, h));
    let diff = differing(&pa, &pb, w);
    // The points, labels, secondary rows and joins moved: thousands of pixels, not a few.
    assert!(diff.len() > 1000, "only {} pixels differ", diff.len());
    let first = chart::panel_rects(&a)[0];
    assert!(
        diff.iter()
            .all(|&(x, y)| x >= first.0 && x < first.2 && y >= first.1 && y < first.3),
        "pixels outside the first paired panel changed: {:?}",
        diff.iter().find(|&&(_, y)| y < first.1 || y >= first.3)
    );
    // The same through the files.
    let (fa, fb) = (out("a.png"), out("b.png"));
    chart::draw(&a, &fa).unwrap();
    chart::draw(&b, &fb).unwrap();
    assert_ne!(std::fs::read(&fa).unwrap(), std::fs::read(&fb).unwrap());
    // And the same report draws the same image (nothing random in the drawing).
    assert_eq!(chart::pixels(&a).unwrap().2, pa);
    std::fs::remove_file(&fa).ok();
    std::fs::remove_file(&fb).ok();
}

/// Pixels of colour `c` inside rectangle `r`.
fn count(rgb: &[u8], w: u32, r: (i32, i32, i32, i32), c: (u8, u8, u8)) -> usize {
    (r.1..r.3)
        .flat_map(|y| (r.0..r.2).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let i = 3 * (y as usize * w as usize + x as usize);
            (rgb[i], rgb[i + 1], rgb[i + 2]) == c
        })
        .count()
}

#[test]
fn each_panel_draws_its_elements() {
    let report = full(&SCALE_A);
    let (w, _, rgb) = chart::pixels(&report).unwrap();
    let r = chart::panel_rects(&report);
    // Paired: the 5 % bar (tab10 blue), the 1 % bar (red), Thurstone's triangles (green),
    // Bradley–Terry's squares (purple).
    for (what, c) in [
        ("5 % yardstick", (31, 119, 180)),
        ("1 % yardstick", (214, 39, 40)),
        ("Thurstone", (44, 160, 44)),
        ("Bradley–Terry", (148, 103, 189)),
    ] {
        let n = count(&rgb, w, r[0], c);
        assert!(n > 30, "{what}: {n} pixels in the paired panel");
    }
    // Staircases: the first subject's two tracks in blue and red, the second's one in blue.
    assert!(count(&rgb, w, r[2], (31, 119, 180)) > 100);
    assert!(count(&rgb, w, r[2], (214, 39, 40)) > 100);
    assert!(count(&rgb, w, r[3], (31, 119, 180)) > 100);
    assert_eq!(
        count(&rgb, w, r[3], (214, 39, 40)),
        0,
        "one track, one colour"
    );
    // Constant stimuli: both fits converged, both curves drawn.
    for f in &report.constant[0].fits {
        assert!(f.result.is_ok(), "{:?}: {:?}", f.model, f.result);
    }
    assert!(
        count(&rgb, w, r[4], (31, 119, 180)) > 200,
        "the Weibull curve"
    );
    assert!(
        count(&rgb, w, r[4], (214, 39, 40)) > 200,
        "the logistic curve"
    );
}

/// An empty report has nothing to draw: the chart refuses with a sentence and writes no file
/// (a blank PNG would pass for a chart of nothing significant).
#[test]
fn an_empty_report_is_an_error_sentence_and_no_file() {
    let empty = Report {
        paired: vec![],
        correlations: vec![],
        tracks: vec![],
        constant: vec![],
        staircase_fits: vec![],
        refused: vec![],
    };
    let png = out("empty.png");
    let e = chart::draw(&empty, &png).unwrap_err();
    assert!(
        !e.contains('\n') && e.starts_with("the report has nothing to chart"),
        "{e}"
    );
    assert!(!png.exists());
    assert_eq!(chart::pixels(&empty).unwrap_err(), e);
    assert_eq!(chart::size(&empty), (WIDTH_PX, TITLE_PX));
}

#[test]
fn files_it_cannot_write_are_error_sentences() {
    let report = full(&SCALE_A);
    let e = chart::draw(&report, Path::new("chart.jpg")).unwrap_err();
    assert!(e.contains("must end in .png") && !e.contains('\n'), "{e}");
    let missing = out("no-such-dir").join("chart.png");
    let e = chart::draw(&report, &missing).unwrap_err();
    assert!(
        e.starts_with("the chart could not be written to") && !e.contains('\n'),
        "{e}"
    );
    assert!(!missing.exists());
    // An upper-case extension is a PNG too.
    let upper = out("upper.PNG");
    chart::draw(&report, &upper).unwrap();
    assert!(upper.exists());
    std::fs::remove_file(&upper).ok();
}

/// Every part empty, NaN, infinite, huge or inconsistent at once: drawn, no panic.
#[test]
fn hostile_values_draw_without_panicking() {
    let nan = f64::NAN;
    let mut all_nan = paired("all NaN", &[nan; 5]);
    all_nan.thurstone = Some(keyed(&[nan; 5]));
    all_nan.scheffe.yardstick[0].y = nan;
    let mut mixed = paired("mixed", &[f64::INFINITY, -0.3, nan, 1e300, -1e300]);
    mixed.bradley_terry = Some(BTreeMap::new());
    mixed.scheffe.yardstick[1].y = -1.0;
    let mut one = paired("one stimulus", &[0.0]);
    one.scheffe.yardstick = vec![Yardstick {
        alpha: 0.05,
        q: 3.0,
        y: 1e308,
        separated: vec![],
    }];
    let empty_block = PairedBlock {
        scale: BTreeMap::new(),
        thurstone: None,
        bradley_terry: None,
        ..paired("empty", &[])
    };
    let mut weird_track = track("s03", "weird", 30.0, 4);
    weird_track.levels[3] = nan;
    weird_track.levels[4] = f64::INFINITY;
    weird_track.correct.truncate(10);
    weird_track.reversal_levels.push(12345.0);
    weird_track.threshold = Some(nan);
    let empty_track = Track {
        levels: vec![],
        correct: vec![],
        reversal_levels: vec![1.0],
        threshold: None,
        ..track("s04", "empty", 30.0, 5)
    };
    let flat_track = Track {
        levels: vec![7.0; 20],
        correct: vec![true; 20],
        reversal_levels: vec![],
        threshold: Some(7.0),
        ..track("s05", "flat", 7.0, 6)
    };
    let mut c = constant();
    c.points.push(LevelCount {
        level: 40.0,
        n_trials: 0,
        n_correct: 0,
    });
    c.points.push(LevelCount {
        level: nan,
        n_trials: 10,
        n_correct: 5,
    });
    c.points.push(LevelCount {
        level: 35.0,
        n_trials: 3,
        n_correct: 9,
    });
    if let Ok(ci) = &mut c.fits[0].result {
        ci.fit.alpha = nan;
        if let Some(iv) = &mut ci.level_at_target {
            iv.lower = f64::NEG_INFINITY;
            iv.upper = 1e308;
        }
    }
    c.fits[1].result = Err("no bootstrap asked for\nsecond line".into());
    let no_points = ConstantBlock {
        block: "no points".into(),
        points: vec![],
        fits: vec![],
    };
    let report = Report {
        paired: vec![all_nan, mixed, one, empty_block],
        correlations: vec![Correlation {
            blocks: ("mixed".into(), "nowhere".into()),
            pairs: vec![],
            pearson: None,
            spearman: Some(nan),
        }],
        tracks: vec![weird_track, empty_track, flat_track],
        constant: vec![c, no_points],
        staircase_fits: vec![],
        refused: vec![],
    };
    let (w, h, rgb) = chart::pixels(&report).expect("hostile values are skipped, not refused");
    assert_eq!((w, h), chart::size(&report));
    assert!(rgb.iter().any(|&b| b != 255));
    let png = out("hostile.png");
    chart::draw(&report, &png).unwrap();
    assert_eq!(png_size(&std::fs::read(&png).unwrap()), (w, h));
    std::fs::remove_file(&png).ok();
}

/// A report of more panels than [`chart::MAX_PANELS`] draws the first of them, at a bounded
/// size.
#[test]
fn panels_are_capped() {
    let tracks: Vec<Track> = (0..chart::MAX_PANELS + 8)
        .map(|i| Track {
            subject: format!("s{i:03}"),
            ..track("x", "only", 30.0, i as u64)
        })
        .collect();
    let report = Report {
        paired: vec![],
        correlations: vec![],
        tracks,
        constant: vec![],
        staircase_fits: vec![],
        refused: vec![],
    };
    assert_eq!(
        chart::size(&report),
        (WIDTH_PX, TITLE_PX + chart::MAX_PANELS as u32 * TRACKS_PX)
    );
    assert_eq!(chart::panel_rects(&report).len(), chart::MAX_PANELS);
}
