//! A scene file host-sim refuses is one class of error with one exit code, 2 (as `saw push` and
//! `host-sim serve`, docs/scenes.md), whichever rule refused it — the reader's (a value out of
//! its range) or the board's dry run (an f_b above the board's limit, a boundary before the one
//! before it) — and its sentence points at the value at fault (issue #33). A file that cannot
//! be read at all stays exit code 1.

use std::path::PathBuf;

use host_sim::cli::{self, Refusal};

/// A folder of its own for this test's scene files.
fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("saw-scene-refusals-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// What `host-sim --scene FILE` refuses, FILE holding `text`.
fn refusal(name: &str, text: &str) -> Refusal {
    let path = dir().join(name);
    std::fs::write(&path, text).unwrap();
    let (args, m) = cli::parse_from(["host-sim", "--scene", path.to_str().unwrap()]).unwrap();
    match cli::plan(&args, &m) {
        Ok(_) => panic!("{name}: the scene was taken"),
        Err(r) => r,
    }
}

#[test]
fn every_scene_refusal_exits_2_and_points_at_the_value() {
    // (file, text, line:col and field after the path, the rule that refuses it).
    let cases = [
        (
            "range.toml",
            "[[region]]\nkind = \"constant\"\nf_b_hz = -3\n",
            ":3:10: `region[0].f_b_hz`: -3 Hz is outside the allowed 0.001 Hz to 1000000 Hz",
            "the reader's range",
        ),
        (
            "board.toml",
            "[[region]]\nkind = \"constant\"\nf_b_hz = 5000\n",
            ":3:10: `region[0].f_b_hz`: f_b 5000 Hz is above this board's limit of 2000 Hz",
            "the board's limit (F446, the default board)",
        ),
        (
            "until.toml",
            "[[region]]\nkind = \"off\"\nuntil_mm = 30\n\n[[region]]\nkind = \"off\"\n\
             until_mm = 20\n\n[[region]]\nkind = \"off\"\n",
            ":7:12: `region[1].until_mm`: region 1 ends at 20 mm, not after region 0 (30 mm)",
            "the region map's order",
        ),
        (
            "typo.toml",
            "[[region]]\nkind = \"constant\"\nf_b_hx = 80\n",
            ":3:1: `region[0].f_b_hx`: unknown key `f_b_hx`: did you mean `f_b_hz`?",
            "the table's keys",
        ),
    ];
    for (name, text, located, rule) in cases {
        let r = refusal(name, text);
        assert_eq!(r.exit_code(), 2, "{name} ({rule}): {r:?}");
        let Refusal::Scene(e) = &r else {
            panic!("{name} ({rule}): not a scene refusal: {r:?}");
        };
        let shown = e.to_string();
        let path = dir().join(name);
        assert_eq!(shown, format!("{}{located}", path.display()), "{rule}");
    }
}

#[test]
fn a_scene_file_that_cannot_be_read_exits_1() {
    let missing = dir().join("no-such-scene.toml");
    let (args, m) = cli::parse_from(["host-sim", "--scene", missing.to_str().unwrap()]).unwrap();
    let r = cli::plan(&args, &m)
        .err()
        .expect("a missing file is refused");
    assert!(matches!(r, Refusal::Run(_)), "{r:?}");
    assert_eq!(r.exit_code(), 1);
}
