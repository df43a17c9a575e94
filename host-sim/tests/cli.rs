//! The `host-sim` binary as a user meets it: every numeric flag of every command refused at the
//! door when out of range, NaN or infinite (exit code 2, one line naming the flag, the value and
//! the rule); contradictory flags refused with a sentence; no input reaches a panic (property
//! tests over random flag values); the default trajectories stay on the travel, and the summary
//! warns when flags take the finger off it.
//!
//! The expected messages are written out by hand here, not computed by the code under test.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use host_sim::cli::{self, Kind};
use host_sim::trajectory::Trajectory;
use host_sim::{metrics, sim};
use proptest::prelude::*;

const EXE: &str = env!("CARGO_BIN_EXE_host-sim");
const TIP: &str = "For more information, try '--help'.";

fn run(args: &[&str]) -> Output {
    Command::new(EXE)
        .args(args)
        .current_dir(scratch())
        .output()
        .expect("host-sim runs")
}

/// A folder for the charts and scene files of these tests (never `out/` of the repository).
fn scratch() -> PathBuf {
    let d = std::env::temp_dir().join("host-sim-cli-tests");
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `args` are refused before anything runs: exit code 2, nothing on stdout, and stderr is the
/// one line `want` followed by clap's tip (and, for clap's own conflict errors, its usage).
fn refused(args: &[&str], want: &str) {
    let out = run(args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert!(out.stdout.is_empty(), "{args:?} printed to stdout");
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    let mut lines = err.lines();
    assert_eq!(lines.next(), Some(want), "{args:?}");
    let rest: Vec<&str> = lines.filter(|l| !l.is_empty()).collect();
    assert_eq!(rest.last(), Some(&TIP), "{args:?}: {err}");
    assert!(
        rest.iter().all(|l| *l == TIP || l.starts_with("Usage: ")),
        "{args:?}: more than one line of message: {err}"
    );
}

/// One test per flag: each `args => expected first line of stderr`.
macro_rules! flag_test {
    ($name:ident: $($args:expr => $want:expr),+ $(,)?) => {
        #[test]
        fn $name() {
            $(refused(&$args, $want);)+
        }
    };
}

// ---------------------------------------------------------------- the simulator's flags

flag_test!(speed:
    ["--speed", "-10"] => "error: invalid value '-10' for '--speed <MM_S>': must be from 0.1 to 1000 mm/s",
    ["--speed=0"] => "error: invalid value '0' for '--speed <MM_S>': must be from 0.1 to 1000 mm/s",
    ["--speed", "1001"] => "error: invalid value '1001' for '--speed <MM_S>': must be from 0.1 to 1000 mm/s",
    ["--speed", "nan"] => "error: invalid value 'nan' for '--speed <MM_S>': must be a finite number from 0.1 to 1000 mm/s",
    ["--speed", "inf"] => "error: invalid value 'inf' for '--speed <MM_S>': must be a finite number from 0.1 to 1000 mm/s",
    ["--speed", "fast"] => "error: invalid value 'fast' for '--speed <MM_S>': not a number; must be from 0.1 to 1000 mm/s",
);

flag_test!(from:
    ["--from", "-1"] => "error: invalid value '-1' for '--from <MM>': must be from 0 to 63 mm, the travel of the default scene",
    ["--from", "63.5"] => "error: invalid value '63.5' for '--from <MM>': must be from 0 to 63 mm, the travel of the default scene",
    ["--from", "NaN"] => "error: invalid value 'NaN' for '--from <MM>': must be a finite number from 0 to the end of the travel, 63 mm for the default scene",
    ["--from", "-inf"] => "error: invalid value '-inf' for '--from <MM>': must be a finite number from 0 to the end of the travel, 63 mm for the default scene",
    ["--from", "x"] => "error: invalid value 'x' for '--from <MM>': not a number; must be from 0 to the end of the travel, 63 mm for the default scene",
);

flag_test!(to:
    ["--to", "-0.5"] => "error: invalid value '-0.5' for '--to <MM>': must be from 0 to 63 mm, the travel of the default scene",
    ["--to", "100"] => "error: invalid value '100' for '--to <MM>': must be from 0 to 63 mm, the travel of the default scene",
    ["--to", "nan"] => "error: invalid value 'nan' for '--to <MM>': must be a finite number from 0 to the end of the travel, 63 mm for the default scene",
    ["--to", "inf"] => "error: invalid value 'inf' for '--to <MM>': must be a finite number from 0 to the end of the travel, 63 mm for the default scene",
);

flag_test!(accel:
    ["--trajectory", "ramp", "--accel", "-2"] => "error: invalid value '-2' for '--accel <M_S2>': must be from 0.01 to 100 m/s²",
    ["--trajectory", "ramp", "--accel", "0"] => "error: invalid value '0' for '--accel <M_S2>': must be from 0.01 to 100 m/s²",
    ["--trajectory", "ramp", "--accel", "101"] => "error: invalid value '101' for '--accel <M_S2>': must be from 0.01 to 100 m/s²",
    ["--trajectory", "ramp", "--accel", "nan"] => "error: invalid value 'nan' for '--accel <M_S2>': must be a finite number from 0.01 to 100 m/s²",
    ["--trajectory", "ramp", "--accel", "inf"] => "error: invalid value 'inf' for '--accel <M_S2>': must be a finite number from 0.01 to 100 m/s²",
);

flag_test!(noise:
    ["--noise=-3"] => "error: invalid value '-3' for '--noise <LSB_RMS>': must be from 0 to 100 LSB RMS",
    ["--noise", "100.5"] => "error: invalid value '100.5' for '--noise <LSB_RMS>': must be from 0 to 100 LSB RMS",
    ["--noise", "nan"] => "error: invalid value 'nan' for '--noise <LSB_RMS>': must be a finite number from 0 to 100 LSB RMS",
    ["--noise", "inf"] => "error: invalid value 'inf' for '--noise <LSB_RMS>': must be a finite number from 0 to 100 LSB RMS",
);

flag_test!(offset:
    ["--offset", "-4096"] => "error: invalid value '-4096' for '--offset <LSB>': must be from -4095 to 4095 LSB",
    ["--offset", "5000"] => "error: invalid value '5000' for '--offset <LSB>': must be from -4095 to 4095 LSB",
    ["--offset=nan"] => "error: invalid value 'nan' for '--offset <LSB>': must be a finite number from -4095 to 4095 LSB",
    ["--offset", "-inf"] => "error: invalid value '-inf' for '--offset <LSB>': must be a finite number from -4095 to 4095 LSB",
);

flag_test!(duration:
    ["--duration", "0"] => "error: invalid value '0' for '--duration <S>': must be from 0.01 to 86400 s",
    ["--duration=-1"] => "error: invalid value '-1' for '--duration <S>': must be from 0.01 to 86400 s",
    ["--duration", "86401"] => "error: invalid value '86401' for '--duration <S>': must be from 0.01 to 86400 s",
    ["--duration=nan"] => "error: invalid value 'nan' for '--duration <S>': must be a finite number from 0.01 to 86400 s",
    ["--duration=inf"] => "error: invalid value 'inf' for '--duration <S>': must be a finite number from 0.01 to 86400 s",
    ["--duration", "1e400"] => "error: invalid value '1e400' for '--duration <S>': must be a finite number from 0.01 to 86400 s",
);

flag_test!(seed:
    ["--seed", "-1"] => "error: invalid value '-1' for '--seed <SEED>': must be a whole number from 0 to 18446744073709551615",
    ["--seed", "18446744073709551616"] => "error: invalid value '18446744073709551616' for '--seed <SEED>': must be a whole number from 0 to 18446744073709551615",
    ["--seed", "1.5"] => "error: invalid value '1.5' for '--seed <SEED>': must be a whole number from 0 to 18446744073709551615",
    ["--seed", "nan"] => "error: invalid value 'nan' for '--seed <SEED>': must be a whole number from 0 to 18446744073709551615",
    ["--seed", "inf"] => "error: invalid value 'inf' for '--seed <SEED>': must be a whole number from 0 to 18446744073709551615",
);

flag_test!(output:
    ["-o", "x.svg"] => "error: invalid value 'x.svg' for '--output <PNG>': the chart is a PNG file: the path must end in .png",
    ["--output", "out/"] => "error: invalid value 'out/' for '--output <PNG>': the chart is a PNG file: the path must end in .png",
);

#[test]
fn board_lists_the_boards() {
    let out = run(&["--board", "foo"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with(
            "error: invalid value 'foo' for '--board <BOARD>'\n  \
             [possible values: nucleo-f446re, nucleo-g474re]\n"
        ),
        "{err}"
    );
    // The list is saw_boards::ALL's.
    let names: Vec<&str> = saw_boards::ALL.iter().map(|b| b.name).collect();
    assert_eq!(names, ["nucleo-f446re", "nucleo-g474re"]);
}

// ---------------------------------------------------------------- contradictions

flag_test!(from_equal_to:
    ["--trajectory", "sine", "--from", "30", "--to", "30"] => "error: --from 30 and --to 30 are the same point; --trajectory sine moves between them, so they must differ",
    ["--from", "20", "--to", "20"] => "error: --from 20 and --to 20 are the same point; --trajectory back-and-forth moves between them, so they must differ",
    ["--trajectory", "constant", "--from", "61.5"] => "error: --from 61.5 and --to 61.5 (its default) are the same point; --trajectory constant moves between them, so they must differ",
    ["--trajectory", "reversal", "--to", "1.5"] => "error: --from 1.5 (its default) and --to 1.5 are the same point; --trajectory reversal moves between them, so they must differ",
    ["--trajectory", "ramp", "--from", "10", "--to", "10.0"] => "error: --from 10 and --to 10.0 are the same point; --trajectory ramp moves between them, so they must differ",
);

flag_test!(ignored_flags:
    ["--accel", "3"] => "error: --accel 3 is the acceleration of --trajectory ramp; --trajectory back-and-forth would ignore it",
    ["--trajectory", "sine", "--accel=5"] => "error: --accel 5 is the acceleration of --trajectory ramp; --trajectory sine would ignore it",
    ["--trajectory", "rest", "--to", "30"] => "error: --trajectory rest stays at --from; --to 30 would be ignored",
    ["--trajectory", "rest", "--speed", "20", "--to", "30"] => "error: --trajectory rest stays at --from; --to 30, --speed 20 would be ignored",
);

flag_test!(scenario_with_run_flags:
    ["--scenario", "s.toml", "--speed", "20"] => "error: --scenario takes the board, trajectory, noise, seed, duration and scene from its file; --speed 20 would be ignored: give one or the other",
    ["--scenario", "s.toml", "--scene", "x.toml", "--no-preload"] => "error: --scenario takes the board, trajectory, noise, seed, duration and scene from its file; --no-preload, --scene x.toml would be ignored: give one or the other",
    ["--trajectory", "sine", "--scenario", "s.toml", "--board", "nucleo-g474re"] => "error: --scenario takes the board, trajectory, noise, seed, duration and scene from its file; --trajectory sine, --board nucleo-g474re would be ignored: give one or the other",
);

/// A scene of a 40 mm substrate.
fn short_scene() -> PathBuf {
    let path = scratch().join("short.toml");
    std::fs::write(
        &path,
        "[substrate]\nlength_mm = 40.0\ncode_at_start = 1310\ncode_at_end = 64225\n\n\
         [[region]]\nkind = \"constant\"\nf_b_hz = 80\n",
    )
    .unwrap();
    path
}

#[test]
fn from_and_to_are_checked_against_the_scene_loaded() {
    let scene = short_scene();
    let s = scene.to_str().unwrap();
    refused(
        &["--scene", s, "--to", "50"],
        &format!(
            "error: invalid value '50' for '--to <MM>': must be from 0 to 40 mm, the travel of {s}"
        ),
    );
    // Without --from/--to the motion spans that scene's travel, 1.5 mm in from either end.
    let (args, m) = cli::parse_from(["host-sim", "--scene", s]).unwrap();
    let plan = cli::plan(&args, &m).unwrap();
    assert_eq!(
        plan.params.trajectory,
        Trajectory::Triangle {
            a_um: 1_500.0,
            b_um: 38_500.0,
            speed_um_s: 60_000.0
        }
    );
}

// ---------------------------------------------------------------- model, tile-to-scene, bench

flag_test!(model_stick_slip_flags:
    ["model", "stick-slip", "--delta-mu", "-0.1"] => "error: invalid value '-0.1' for '--delta-mu <X>': must be from 0 to 10",
    ["model", "stick-slip", "--delta-mu", "nan"] => "error: invalid value 'nan' for '--delta-mu <X>': must be a finite number from 0 to 10",
    ["model", "stick-slip", "--e-object-pa", "10"] => "error: invalid value '10' for '--e-object-pa <PA>': must be from 1000 to 1e12 Pa",
    ["model", "stick-slip", "--e-object-pa", "inf"] => "error: invalid value 'inf' for '--e-object-pa <PA>': must be a finite number from 1000 to 1e12 Pa",
    ["model", "stick-slip", "--nu-object", "-1"] => "error: invalid value '-1' for '--nu-object <NU>': must be from -0.99 to 0.5",
    ["model", "stick-slip", "--nu-object", "nan"] => "error: invalid value 'nan' for '--nu-object <NU>': must be a finite number from -0.99 to 0.5",
    ["model", "stick-slip", "--e-skin-pa", "2e12"] => "error: invalid value '2e12' for '--e-skin-pa <PA>': must be from 1000 to 1e12 Pa",
    ["model", "stick-slip", "--e-skin-pa", "nan"] => "error: invalid value 'nan' for '--e-skin-pa <PA>': must be a finite number from 1000 to 1e12 Pa",
    ["model", "stick-slip", "--nu-skin", "0.7"] => "error: invalid value '0.7' for '--nu-skin <NU>': must be from -0.99 to 0.5",
    ["model", "stick-slip", "--nu-skin", "inf"] => "error: invalid value 'inf' for '--nu-skin <NU>': must be a finite number from -0.99 to 0.5",
    ["model", "stick-slip", "--sigma-um", "0"] => "error: invalid value '0' for '--sigma-um <UM>': must be from 0.001 to 1000 µm",
    ["model", "stick-slip", "--sigma-um", "nan"] => "error: invalid value 'nan' for '--sigma-um <UM>': must be a finite number from 0.001 to 1000 µm",
    ["model", "stick-slip", "--beta-um", "-5"] => "error: invalid value '-5' for '--beta-um <UM>': must be from 0.001 to 10000 µm",
    ["model", "stick-slip", "--beta-um", "inf"] => "error: invalid value 'inf' for '--beta-um <UM>': must be a finite number from 0.001 to 10000 µm",
    ["model", "stick-slip", "--shear-strength-diff-pa", "-1"] => "error: invalid value '-1' for '--shear-strength-diff-pa <PA>': must be from 0 to 1e9 Pa",
    ["model", "stick-slip", "--shear-strength-diff-pa", "nan"] => "error: invalid value 'nan' for '--shear-strength-diff-pa <PA>': must be a finite number from 0 to 1e9 Pa",
    ["model", "stick-slip", "--normal-force-n", "-1"] => "error: invalid value '-1' for '--normal-force-n <N>': must be from 0 to 100 N",
    ["model", "stick-slip", "--normal-force-n", "inf"] => "error: invalid value 'inf' for '--normal-force-n <N>': must be a finite number from 0 to 100 N",
    ["model", "stick-slip", "--mass-g", "0"] => "error: invalid value '0' for '--mass-g <G>': must be from 0.001 to 1000 g",
    ["model", "stick-slip", "--mass-g", "nan"] => "error: invalid value 'nan' for '--mass-g <G>': must be a finite number from 0.001 to 1000 g",
    ["model", "stick-slip", "--stiffness-n-per-m", "-500"] => "error: invalid value '-500' for '--stiffness-n-per-m <N_PER_M>': must be from 0.001 to 1e6 N/m",
    ["model", "stick-slip", "--stiffness-n-per-m", "inf"] => "error: invalid value 'inf' for '--stiffness-n-per-m <N_PER_M>': must be a finite number from 0.001 to 1e6 N/m",
    ["model", "stick-slip", "--speed-mm-s", "-40"] => "error: invalid value '-40' for '--speed-mm-s <MM_S>': must be from 0 to 1000 mm/s",
    ["model", "stick-slip", "--speed-mm-s", "nan"] => "error: invalid value 'nan' for '--speed-mm-s <MM_S>': must be a finite number from 0 to 1000 mm/s",
);

flag_test!(model_stick_slip_contradiction:
    ["model", "stick-slip", "--delta-mu", "0.1", "--beta-um", "5"] => "error: the argument '--delta-mu <X>' cannot be used with '--beta-um <UM>'",
);

flag_test!(model_fig5_points:
    ["model", "fig5", "--points", "0"] => "error: invalid value '0' for '--points <N>': must be a whole number from 1 to 100000",
    ["model", "fig5", "--points", "-3"] => "error: invalid value '-3' for '--points <N>': must be a whole number from 1 to 100000",
    ["model", "fig5", "--points", "nan"] => "error: invalid value 'nan' for '--points <N>': must be a whole number from 1 to 100000",
    ["model", "fig5", "--points", "inf"] => "error: invalid value 'inf' for '--points <N>': must be a whole number from 1 to 100000",
);

/// The tile flags, as `grooved` and `tile-to-scene` both take them.
fn tile_flag_refusals(cmd: &[&str]) {
    let cases: [(&[&str], &str); 16] = [
        (&["--groove-mm", "0"], "error: invalid value '0' for '--groove-mm <G>': must be from 0.01 to 10 mm"),
        (&["--groove-mm", "nan"], "error: invalid value 'nan' for '--groove-mm <G>': must be a finite number from 0.01 to 10 mm"),
        (&["--land-mm", "-0.25"], "error: invalid value '-0.25' for '--land-mm <L>': must be from 0 to 10 mm"),
        (&["--land-mm", "inf"], "error: invalid value 'inf' for '--land-mm <L>': must be a finite number from 0 to 10 mm"),
        (&["--force-g", "-1"], "error: invalid value '-1' for '--force-g <F>': must be from 0 to 10000 g"),
        (&["--force-g", "100000"], "error: invalid value '100000' for '--force-g <F>': must be from 0 to 10000 g"),
        (&["--force-g", "nan"], "error: invalid value 'nan' for '--force-g <F>': must be a finite number from 0 to 10000 g"),
        (&["--k-mm-per-g", "0"], "error: invalid value '0' for '--k-mm-per-g <K>': must be from 0.001 to 1 mm/g"),
        (&["--k-mm-per-g", "inf"], "error: invalid value 'inf' for '--k-mm-per-g <K>': must be a finite number from 0.001 to 1 mm/g"),
        (&["--mu", "-0.5"], "error: invalid value '-0.5' for '--mu <MU>': must be from 0 to 10"),
        (&["--mu", "nan"], "error: invalid value 'nan' for '--mu <MU>': must be a finite number from 0 to 10"),
        (&["--pad-area-mm2", "0"], "error: invalid value '0' for '--pad-area-mm2 <MM2>': must be from 1 to 10000 mm²"),
        (&["--pad-area-mm2", "inf"], "error: invalid value 'inf' for '--pad-area-mm2 <MM2>': must be a finite number from 1 to 10000 mm²"),
        (&["--pad-ref-force-g", "-112"], "error: invalid value '-112' for '--pad-ref-force-g <G>': must be from 0.1 to 10000 g"),
        (&["--pad-ref-force-g", "nan"], "error: invalid value 'nan' for '--pad-ref-force-g <G>': must be a finite number from 0.1 to 10000 g"),
        (&["--pad-exponent", "1.5"], "error: invalid value '1.5' for '--pad-exponent <X>': must be from 0 to 1"),
    ];
    for (flags, want) in cases {
        refused(&[cmd, flags].concat(), want);
    }
    refused(
        &[cmd, &["--pad-exponent", "-inf"]].concat(),
        "error: invalid value '-inf' for '--pad-exponent <X>': must be a finite number from 0 to 1",
    );
}

#[test]
fn model_grooved_flags() {
    tile_flag_refusals(&["model", "grooved"]);
    let g = ["model", "grooved", "--groove-mm", "1", "--land-mm", "0.25"];
    for (flags, want) in [
        (["--rtol", "0"], "error: invalid value '0' for '--rtol <RTOL>': must be from 1e-16 to 0.1"),
        (["--rtol", "nan"], "error: invalid value 'nan' for '--rtol <RTOL>': must be a finite number from 1e-16 to 0.1"),
        (["--theta0", "-1"], "error: invalid value '-1' for '--theta0 <RAD>': must be from 0.001 to 1.5707963267948966 rad"),
        (["--theta0", "inf"], "error: invalid value 'inf' for '--theta0 <RAD>': must be a finite number from 0.001 to 1.5707963267948966 rad"),
    ] {
        refused(&[&g[..], &flags[..]].concat(), want);
    }
    let out = run(&[&g[..], &["--solver", "secant"]].concat());
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).starts_with(
        "error: invalid value 'secant' for '--solver <SOLVER>'\n  \
         [possible values: newton, bisection, safeguarded]"
    ));
}

#[test]
fn tile_to_scene_flags() {
    tile_flag_refusals(&["tile-to-scene"]);
    refused(
        &["tile-to-scene", "--speed-mm-s", "-1"],
        "error: invalid value '-1' for '--speed-mm-s <V>': must be from 0 to 1000 mm/s",
    );
    refused(
        &["tile-to-scene", "--speed-mm-s", "inf"],
        "error: invalid value 'inf' for '--speed-mm-s <V>': must be a finite number from 0 to 1000 mm/s",
    );
}

flag_test!(model_sandpaper_flags:
    ["model", "sandpaper", "--grit", "0"] => "error: invalid value '0' for '--grit <GRIT>': must be from 1 to 10000",
    ["model", "sandpaper", "--grit", "nan"] => "error: invalid value 'nan' for '--grit <GRIT>': must be a finite number from 1 to 10000",
    ["model", "sandpaper", "--f-b-hz", "0"] => "error: invalid value '0' for '--f-b-hz <HZ>': must be from 1 to 2000 Hz",
    ["model", "sandpaper", "--f-b-hz", "2001"] => "error: invalid value '2001' for '--f-b-hz <HZ>': must be from 1 to 2000 Hz",
    ["model", "sandpaper", "--f-b-hz", "inf"] => "error: invalid value 'inf' for '--f-b-hz <HZ>': must be a finite number from 1 to 2000 Hz",
    ["model", "sandpaper", "--grit", "180", "--f-b-hz", "60"] => "error: the argument '--grit <GRIT>' cannot be used with '--f-b-hz <HZ>'",
);

flag_test!(model_atan_bench_n:
    ["model", "atan-bench", "--impl", "libm", "--n", "0"] => "error: invalid value '0' for '--n <N>': must be a whole number from 1 to 100000000",
    ["model", "atan-bench", "--impl", "libm", "--n", "1e9"] => "error: invalid value '1e9' for '--n <N>': must be a whole number from 1 to 100000000",
    ["model", "atan-bench", "--impl", "libm", "--n", "nan"] => "error: invalid value 'nan' for '--n <N>': must be a whole number from 1 to 100000000",
);

flag_test!(bench_flags:
    ["bench", "--threads", "0"] => "error: invalid value '0' for '--threads <N>': must be a whole number from 1 to 256",
    ["bench", "--threads", "-2"] => "error: invalid value '-2' for '--threads <N>': must be a whole number from 1 to 256",
    ["bench", "--threads", "inf"] => "error: invalid value 'inf' for '--threads <N>': must be a whole number from 1 to 256",
    ["bench", "--seed", "-1"] => "error: invalid value '-1' for '--seed <SEED>': must be a whole number from 0 to 18446744073709551615",
    ["bench", "--seed", "nan"] => "error: invalid value 'nan' for '--seed <SEED>': must be a whole number from 0 to 18446744073709551615",
);

#[test]
fn subcommands_name_themselves_in_usage() {
    for (args, usage) in [
        (&["bench", "--help"][..], "Usage: host-sim bench [OPTIONS]"),
        (&["model", "--help"][..], "Usage: host-sim model <COMMAND>"),
        (
            &["model", "sandpaper", "--help"][..],
            "Usage: host-sim model sandpaper [OPTIONS] <--grit <GRIT>|--f-b-hz <HZ>>",
        ),
        (
            &["tile-to-scene", "--help"][..],
            "Usage: host-sim tile-to-scene [OPTIONS] --groove-mm <G> --land-mm <L> --force-g <F>",
        ),
        (&["--help"][..], "Usage: host-sim [OPTIONS]"),
    ] {
        let out = run(args);
        assert_eq!(out.status.code(), Some(0), "{args:?}");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.lines().any(|l| l == usage), "{args:?}:\n{text}");
    }
}

#[test]
fn help_states_unit_and_range_of_every_simulator_flag() {
    let out = run(&["--help"]);
    let text = String::from_utf8_lossy(&out.stdout);
    for line in [
        "Finger speed (peak for sine, top for ramp), mm/s (0.1 to 1000)",
        "Start (or rest) position, mm (0 to the end of the travel: 63 for the default scene) [default: 1.5]",
        "Far turning point (the direction for constant and ramp), mm (0 to the end of the travel: 63 for the default scene) [default: the end of the travel minus 1.5]",
        "Acceleration of --trajectory ramp, m/s² (0.01 to 100)",
        "ADC noise per conversion (12-bit), LSB RMS (0 to 100)",
        "ADC offset per conversion (12-bit), LSB (-4095 to 4095)",
        "Simulated time, s (0.01 to 86400) [default: 3; constant and ramp: until the finger reaches --to; reversal: until it is back at --from; a 2D path: to its end; a 2D run is at most 600 s]",
        "Noise seed (0 to 18446744073709551615)",
    ] {
        assert!(text.lines().any(|l| l.trim() == line), "missing {line:?} in\n{text}");
    }
}

/// The README's flag table gives the ranges `--help` gives (so the two cannot drift apart).
#[test]
fn readme_flag_table_matches_help() {
    use clap::CommandFactory;
    let readme = include_str!("../../README.md");
    let cmd = cli::Args::command();
    for id in ["speed", "accel", "noise", "offset", "duration", "seed"] {
        let arg = cmd.get_arguments().find(|a| a.get_id() == id).unwrap();
        let help = arg.get_help().unwrap().to_string();
        // "Finger speed (…), mm/s (0.1 to 1000)" → "0.1 to 1000"
        let range = help
            .rsplit_once(" (")
            .and_then(|(_, r)| r.split_once(')'))
            .map(|(r, _)| r)
            .unwrap();
        let row = readme
            .lines()
            .find(|l| l.starts_with(&format!("| `--{id}`")))
            .unwrap_or_else(|| panic!("README has no row for --{id}"));
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        assert_eq!(cells[3], range, "README row for --{id}: {row}");
    }
}

// ---------------------------------------------------------------- the travel

/// Every trajectory kind with its default flags stays on the 63 mm travel: no sample off it, no
/// rail fault, and the constant, ramp and reversal runs last as long as their trip.
#[test]
fn default_trajectories_stay_on_the_travel() {
    for (kind, duration_s) in [
        (Kind::BackAndForth, 3.0),
        (Kind::Sine, 3.0),
        (Kind::Rest, 3.0),
        (Kind::Constant, 1.0), // 60 mm at 60 mm/s
        (Kind::Reversal, 2.0), // there and back
        (Kind::Ramp, 1.015),   // 30 ms to 60 mm/s (0.9 mm), then 59.1 mm at 60 mm/s
    ] {
        let (args, m) = cli::parse_from(["host-sim", "--trajectory", &kind.name()]).unwrap();
        let plan = cli::plan(&args, &m).unwrap();
        assert!(
            (plan.params.duration_s - duration_s).abs() < 1e-9,
            "{kind:?}: {} s",
            plan.params.duration_s
        );
        let r = sim::run(&plan.params).unwrap();
        let mt = metrics::compute(&r);
        assert_eq!(mt.off_travel, metrics::OffTravel::default(), "{kind:?}");
        assert_eq!(mt.fault_onsets, 0, "{kind:?}");
        let ends = r.trace.iter().map(|p| p.true_um);
        let (lo, hi) = ends.fold((f64::MAX, f64::MIN), |(l, h), x| (l.min(x), h.max(x)));
        assert!(
            lo >= 1_500.0 - 1e-6 && hi <= 61_500.0 + 1e-6,
            "{kind:?}: {lo}…{hi}"
        );
    }
}

/// Flags that take the finger off the travel are run, and the summary says so: 60 mm/s from
/// 1.5 mm leaves the 63 mm travel after 1.025 s, so 1.975 s of a 3 s run are off it.
#[test]
fn summary_warns_when_the_flags_leave_the_travel() {
    let out = run(&["--trajectory", "constant", "--duration", "3", "-o", "c.png"]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.lines().any(|l| l
            == "warning: the finger is off the 63 mm travel for 1.97 s of the 3.00 s \
                (65.8 % of the samples), first at t = 1.0251 s"),
        "{text}"
    );
    let out = run(&["--trajectory", "constant", "-o", "d.png"]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(!text.contains("warning"), "{text}");
    assert!(text.contains("for 1.00 s;"), "{text}");
}

// ---------------------------------------------------------------- no panic, whatever the input

/// A value for a numeric flag: mostly inside `valid` (so that whole command lines pass and run),
/// else any float, a special or a random string.
fn value(valid: std::ops::Range<f64>) -> impl Strategy<Value = String> {
    prop_oneof![
        6 => valid.prop_map(|v| v.to_string()),
        1 => any::<f64>().prop_map(|v| v.to_string()),
        1 => prop::sample::select(vec![
            "nan", "NaN", "inf", "-inf", "", "-0", "1e309", "-1e-320", "0x10", "--", "-", "1,5",
        ])
        .prop_map(String::from),
        1 => "[-+0-9.eEa-z]{0,8}",
    ]
}

/// A duration: short when valid (a run takes about a second in the debug build), anything
/// outside the range otherwise.
fn short_duration() -> impl Strategy<Value = String> {
    value(0.01..0.05).prop_filter("valid runs stay short", |s| {
        s.trim()
            .parse::<f64>()
            .map_or(true, |d| !(0.05..=600.0).contains(&d))
    })
}

/// `flag v` with probability `p`, else nothing.
fn maybe(
    p: f64,
    flag: &'static str,
    v: impl Strategy<Value = String>,
) -> impl Strategy<Value = Vec<String>> {
    prop::option::weighted(p, v).prop_map(move |v| match v {
        Some(v) => vec![flag.to_string(), v],
        None => Vec::new(),
    })
}

/// Exit code 0 or 2, never a panic; a refusal is one `error:` line.
fn never_panics(args: &[String]) -> Result<(), TestCaseError> {
    let out = Command::new(EXE)
        .args(args)
        .current_dir(scratch())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    prop_assert!(!err.contains("panicked"), "{args:?}: {err}");
    match out.status.code() {
        Some(0) => {}
        Some(2) => prop_assert!(err.starts_with("error: "), "{args:?}: {err}"),
        c => prop_assert!(false, "{args:?}: exit {c:?}: {err}"),
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn the_simulator_never_panics(
        kind in prop::sample::select(vec!["back-and-forth", "sine", "rest", "constant", "reversal", "ramp", "zigzag"]),
        speed in maybe(0.5, "--speed", value(0.1..1000.0)),
        from in maybe(0.5, "--from", value(0.0..63.0)),
        to in maybe(0.5, "--to", value(0.0..63.0)),
        accel in maybe(0.2, "--accel", value(0.01..100.0)),
        noise in maybe(0.5, "--noise", value(0.0..100.0)),
        offset in maybe(0.5, "--offset", value(-4095.0..4095.0)),
        duration in short_duration(),
        seed in maybe(0.5, "--seed", prop_oneof![any::<u64>().prop_map(|s| s.to_string()), "[-0-9.a-z]{0,6}"]),
        board in prop::sample::select(vec!["nucleo-f446re", "nucleo-g474re", "nucleo-g474re", "nucleo-h743zi"]),
    ) {
        let mut args: Vec<String> = ["--trajectory", kind, "--board", board, "-o", "p.png"]
            .map(String::from)
            .to_vec();
        for flag in [speed, from, to, accel, noise, offset, seed] {
            args.extend(flag);
        }
        // Always a duration: without one, constant/ramp/reversal last their trip (up to 86 400 s).
        args.push(format!("--duration={duration}"));
        never_panics(&args)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn the_models_never_panic(
        cmd in prop::sample::select(vec![0usize, 1, 2, 3, 4]),
        a in value(0.0..10.0),
        b in value(0.0..10.0),
        c in value(0.0..1000.0),
        d in value(0.0..1.0),
    ) {
        let args: Vec<String> = match cmd {
            0 => ["model", "stick-slip", "--delta-mu", a.as_str(), "--speed-mm-s", c.as_str(),
                  "--mass-g", b.as_str(), "--json"].map(String::from).to_vec(),
            1 => ["model", "grooved", "--groove-mm", a.as_str(), "--land-mm", b.as_str(),
                  "--force-g", c.as_str(), "--mu", d.as_str()].map(String::from).to_vec(),
            2 => ["tile-to-scene", "--groove-mm", a.as_str(), "--land-mm", b.as_str(),
                  "--force-g", c.as_str(), "--pad-exponent", d.as_str()].map(String::from).to_vec(),
            3 => ["model", "sandpaper", "--grit", c.as_str()].map(String::from).to_vec(),
            _ => ["model", "fig5", "--points", c.as_str()].map(String::from).to_vec(),
        };
        never_panics(&args)?;
    }
}

/// Without `-o` the chart is named after what runs, so one scene's chart never overwrites
/// another's: `out/sim-<scene file>.png`, and the title names the scene.
#[test]
fn the_chart_is_named_after_the_scene() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/grating.toml");
    let out = run(&["--scene", scene.to_str().unwrap(), "--duration", "0.05"]);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let stdout = String::from_utf8(out.stdout).unwrap();
    assert!(
        stdout.lines().any(|l| l == "chart: out/sim-grating.png"),
        "{stdout}"
    );
    assert!(scratch().join("out/sim-grating.png").is_file());
}

/// `--no-preload` on a 32-bit burst timer: a counter past a shortened ARR runs on to its wrap,
/// so the gate falls silent while the core asks for bursts, and the summary says so. With
/// preload, every shipped scene runs without such a warning (an update waits for the period
/// it replaces, which is not a stall).
#[test]
fn the_summary_reports_a_stalled_gate() {
    let stalled = |args: &[&str]| {
        let out = run(args);
        assert_eq!(out.status.code(), Some(0), "{out:?}");
        String::from_utf8(out.stdout)
            .unwrap()
            .lines()
            .find(|l| l.starts_with("warning: the gate stalled"))
            .map(str::to_string)
    };
    let line = stalled(&["--no-preload", "-o", "np.png"]).expect("a stall without preload");
    assert!(
        line.ends_with("(without preload a counter past a shortened ARR runs on to its wrap)"),
        "{line}"
    );
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for scene in ["default", "grating", "material", "random", "lines"] {
        let path = scenes.join(format!("{scene}.toml"));
        let args = ["--scene", path.to_str().unwrap(), "-o", "p.png"];
        assert_eq!(stalled(&args), None, "{scene}");
    }
}

/// What tile-to-scene prints is a scene file: it loads as one, and its grating is the tile's
/// (with or without --scene-file; before, without the flag it printed keys a scene file refuses).
#[test]
fn tile_to_scene_prints_a_region_a_scene_file_accepts() {
    let board = saw_boards::NUCLEO_F446RE;
    for (groove, land, force) in [
        ("0.5", "0.25", "112"),
        ("1", "0.25", "112"),
        ("1.5", "1", "56"),
    ] {
        for flag in [&[][..], &["--scene-file"][..]] {
            let mut args = vec![
                "tile-to-scene",
                "--groove-mm",
                groove,
                "--land-mm",
                land,
                "--force-g",
                force,
            ];
            args.extend_from_slice(flag);
            let out = run(&args);
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let text = String::from_utf8(out.stdout).unwrap();
            let config = saw_core::scene_file::load_for_board(
                "tile.toml",
                &text,
                sim::burst_timer(&board),
                sim::sample_period_us(&board),
            )
            .unwrap_or_else(|e| panic!("{e}\n{text}"));
            let saw_core::texture::Texture::Grating(g) = config.scene.textures[0] else {
                panic!("{text}")
            };
            // λ = groove + land, in µm.
            let want_um = ((groove.parse::<f64>().unwrap() + land.parse::<f64>().unwrap()) * 1000.0)
                .round() as u32;
            assert_eq!(g.wavelength_um, want_um, "{text}");
            assert!((1..=1000).contains(&g.amplitude_permille), "{text}");
        }
    }
}

/// bench and model charts write outside the tracked docs/ unless asked (`--out docs`), and an
/// output path that is a file is refused before anything runs.
#[test]
fn generated_files_go_to_out_unless_asked() {
    let help = String::from_utf8(run(&["bench", "--help"]).stdout).unwrap();
    assert!(help.contains("default: out/bench"), "{help}");
    assert_eq!(host_sim::bench::default_out_dir(), Path::new("out/bench"));
    let help = String::from_utf8(run(&["model", "charts", "--help"]).stdout).unwrap();
    assert!(help.contains("[default: out/models]"), "{help}");
    let file = scratch().join("a-file");
    std::fs::write(&file, "x").unwrap();
    for cmd in [&["bench", "--out"][..], &["model", "charts", "--out"][..]] {
        let mut args = cmd.to_vec();
        let f = file.to_str().unwrap();
        args.push(f);
        let out = run(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(err.contains("a file is there, not a directory"), "{err}");
        assert!(err.contains("--out"), "{err}");
    }
}

// ---------------------------------------------------------------- `serve`'s fault injection

flag_test!(serve_fault_window:
    ["serve", "--pty", "/nonexistent/tty", "--fault", "open", "--fault-at", "nan", "--fault-for", "1"] => "error: invalid value 'nan' for '--fault-at <S>': must be a finite number from 0 to 1e6 s",
    ["serve", "--pty", "/nonexistent/tty", "--fault", "open", "--fault-at=-1", "--fault-for", "1"] => "error: invalid value '-1' for '--fault-at <S>': must be from 0 to 1e6 s",
    ["serve", "--pty", "/nonexistent/tty", "--fault", "open", "--fault-at", "1", "--fault-for", "0"] => "error: invalid value '0' for '--fault-for <S>': must be from 0.001 to 1e6 s",
    ["serve", "--pty", "/nonexistent/tty", "--fault", "short", "--fault-at", "1", "--fault-for", "inf"] => "error: invalid value 'inf' for '--fault-for <S>': must be a finite number from 0.001 to 1e6 s",
);

/// A fault without its window (or a window without its fault) is refused, naming what is missing.
#[test]
fn serve_fault_needs_its_window() {
    for args in [
        &["serve", "--pty", "/nonexistent/tty", "--fault", "open"][..],
        &[
            "serve",
            "--pty",
            "/nonexistent/tty",
            "--fault-at",
            "1",
            "--fault-for",
            "1",
        ][..],
    ] {
        let out = run(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.starts_with("error: the following required arguments were not provided:"),
            "{err}"
        );
        assert!(err.contains("--fault"), "{err}");
    }
}

// ---------------------------------------------------------------- help for every command

/// `--help` ends with the binary's other commands, one line each, and how to get their help:
/// serve and soak among them (they are dispatched before the simulator's flags are parsed, so
/// clap alone never listed them).
#[test]
fn help_lists_every_command() {
    let out = run(&["--help"]);
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().map(str::trim_end).collect();
    for want in [
        "Commands (each one's flags, units and ranges: host-sim help COMMAND, or host-sim COMMAND --help):",
        "  serve          a virtual board behind a pseudo-terminal, for saw and its panel (docs/link.md)",
        "  soak           the safety rules over random scenes, fingers and faults (docs/soak.md)",
        "  model          physical models of the display (docs/models.md)",
        "  tile-to-scene  a grooved tile as a scene file's grating region",
        "  bench          the velocity estimators measured and charted (docs/bench-results.md)",
        "  budget         lag against noise per ADC configuration (docs/conversion-budget.md)",
        "  guard          outlier guards: lag against outlier error (docs/conversion-budget.md)",
        "  touch-budget   the touch frame's phases against its period, per board (docs/touch.md)",
        "  help           this help, or a command's: host-sim help serve",
    ] {
        assert!(lines.contains(&want), "missing {want:?} in\n{text}");
    }
}

/// `host-sim help` is `--help`; `host-sim help COMMAND` is `host-sim COMMAND --help`, for
/// every command; an unknown name is refused with one line listing the commands.
#[test]
fn help_command_gives_each_commands_help() {
    let main = run(&["--help"]);
    let help = run(&["help"]);
    assert_eq!(help.status.code(), Some(0), "{help:?}");
    assert_eq!(help.stdout, main.stdout);
    for cmd in [
        "check",
        "serve",
        "soak",
        "model",
        "tile-to-scene",
        "bench",
        "budget",
        "guard",
        "touch-budget",
    ] {
        let own = run(&[cmd, "--help"]);
        let via = run(&["help", cmd]);
        assert_eq!(via.status.code(), Some(0), "help {cmd}: {via:?}");
        assert!(!own.stdout.is_empty(), "{cmd} --help printed nothing");
        assert_eq!(
            String::from_utf8_lossy(&via.stdout),
            String::from_utf8_lossy(&own.stdout),
            "help {cmd}"
        );
    }
    let serve = String::from_utf8(run(&["help", "serve"]).stdout).unwrap();
    assert!(
        serve
            .lines()
            .any(|l| l.starts_with("Usage: host-sim serve")),
        "{serve}"
    );
    let soak = String::from_utf8(run(&["help", "soak"]).stdout).unwrap();
    assert!(
        soak.lines().any(|l| l.starts_with("Usage: host-sim soak")),
        "{soak}"
    );
    let out = run(&["help", "nope"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(out.stdout.is_empty());
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(
        err.lines().next(),
        Some(
            "error: unknown command 'nope': host-sim's commands are check, serve, soak, model, \
             tile-to-scene, bench, budget, guard, touch-budget"
        )
    );
}

// ---------------------------------------------------------------- the summary's lines

/// scenes/lines.toml: five lines over one `off` region. 3 s at 60 mm/s from 1.5 to 61.5 mm and
/// back and forth is three strokes, each crossing every line once: 3 pulses per line, 15 in
/// all, and none of them a burst of the off region (whose row stays empty).
#[test]
fn the_summary_reports_lines_apart_from_regions() {
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/lines.toml");
    let out = run(&["--scene", scene.to_str().unwrap(), "-o", "lines.png"]);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert!(
        lines.contains(
            &"       0             —              —           —       —       0        0  3.00 s"
        ),
        "the off region's row:\n{text}"
    );
    assert!(
        lines.contains(
            &"tangible lines: 5 at [10.000, 20.000, 31.500, 43.000, 53.000] mm; 15 pulses \
              measured on the gate line (per line: 3, 3, 3, 3, 3); the core fired 15, skipped 0 \
              crossings to keep the duty cap"
        ),
        "{text}"
    );
    assert!(
        lines.contains(&"gate: 15 pulses (15 of them line pulses), 0 malformed (runt/doubled/stretched), 15 gate actions"),
        "{text}"
    );
}

/// A sweep whose `--out` cannot be written says so in one line naming the flag and the path,
/// exit 1, before measuring anything (a file where the directory should be).
#[test]
fn sweeps_name_an_out_dir_they_cannot_write() {
    let file = scratch().join("not-a-dir");
    std::fs::write(&file, b"x").unwrap();
    let out_dir = file.join("sub");
    let out_dir = out_dir.to_str().unwrap();
    for cmd in ["guard", "budget"] {
        let out = run(&[cmd, "--seeds", "1", "--out", out_dir]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{cmd}: {err}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{cmd}: {err}");
        let want = format!("{cmd}: --out {out_dir}: cannot create {out_dir}/charts: ");
        assert!(lines[0].starts_with(&want), "{cmd}: {err}");
    }
}

/// `host-sim check`: every shipped scene is taken by both boards (one `ok` line each, saying
/// 1D or 2D as its `[sensor]` does), and a bad file is refused on its line with exit 1, the
/// good file beside it still checked.
#[test]
fn check_reads_scene_files_as_the_boards_take_them() {
    let scenes = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes");
    let mut files: Vec<String> = std::fs::read_dir(scenes)
        .unwrap()
        .map(|e| e.unwrap().path().display().to_string())
        .filter(|p| p.ends_with(".toml"))
        .collect();
    files.sort();
    let args: Vec<&str> = std::iter::once("check")
        .chain(files.iter().map(String::as_str))
        .collect();
    let out = run(&args);
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{text}");
    assert_eq!(text.lines().count(), 2 * files.len(), "{text}");
    assert!(
        text.lines().all(|l| l.contains(": ok on nucleo-")),
        "{text}"
    );
    assert!(
        text.contains(
            "2d-fig12.toml: ok on nucleo-f446re: 2D, 3 windows and 12 edges on a 95 x 54 mm plate"
        ),
        "{text}"
    );
    assert!(
        text.contains("lines.toml: ok on nucleo-g474re: 1D, 1 region and 5 lines"),
        "{text}"
    );

    let dir = std::env::temp_dir().join("host-sim-cli-check");
    std::fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[[region]]\nkind = \"constant\"\nf_b_hz = 99999\n").unwrap();
    let bad = bad.display().to_string();
    let good = format!("{scenes}/default.toml");
    let out = run(&["check", &bad, &good, "--board", "nucleo-f446re"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{text}");
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 2, "{text}");
    assert!(
        lines[0].starts_with(&format!("{bad}: refused on nucleo-f446re: {bad}:3:")),
        "{text}"
    );
    assert!(
        lines[1].starts_with(&format!("{good}: ok on nucleo-f446re: 1D")),
        "{text}"
    );
}
