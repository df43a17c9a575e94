//! The experiment's fuzz corpora (`fuzz/corpus/{protocol,analysis_csv,session_log}/`, kept in
//! the repository) replayed through the same bodies the fuzz targets call
//! (`saw_experiment::testing`), on the stable toolchain: every input a fuzzer ever kept is
//! answered without a panic, on every `cargo test`.
//!
//! `cargo test -p saw-experiment --test fuzz_corpus -- --ignored write_the_seed_inputs`
//! (re)writes the seed inputs: the shipped protocols (`experiments/*.toml` that read as one) and three small
//! ones that reach what those do not (scene files, external stimuli, every paired variant, a
//! log-scale staircase, `[board]`); a session log of each small protocol as `saw experiment
//! run` writes it, whole and torn mid-line; the session CSV written beside each; a lab's
//! paired-comparison CSV; and a simulated participant's staircase and constant-stimuli
//! trials from `experiments/fb-threshold.toml`.

use std::path::{Path, PathBuf};

use saw_experiment::exploration::Exploration;
use saw_experiment::observer::ObserverSpec;
use saw_experiment::protocol::{self, Protocol};
use saw_experiment::runner::Runner;
use saw_experiment::session::{Header, Log, Paths, Shown, TrialRecord};
use saw_experiment::simulate::Participant;
use saw_experiment::testing::{analysis_csv, protocol as protocol_body, scene_files, session_log};

/// libFuzzer reads at most this many bytes of an input (scripts/fuzz.sh's `-max_len`).
const MAX_LEN: usize = 4096;

/// Every paired variant, an external stimulus and a scene file, over `[board]`'s scene.
const SMALL_PAIRED: &str = r#"[experiment]
name = "small paired"
seed = 3
instructions = "Compare."

[board]
scene = "default.toml"

[response]
question = "Which was rougher?"
words = ["second", "same", "first"]

[[stimulus]]
name = "a"
region = { kind = "constant", f_b_hz = 40, duty_percent = 40 }

[[stimulus]]
name = "b"
scene = "grating.toml"

[[stimulus]]
name = "c"
external = "Hand over c."
beta_um = 50

[[block]]
name = "nakaya"
design = "paired"
variant = "nakaya"
stimuli = ["a", "b", "c"]

[[block]]
name = "scheffe"
design = "paired"
variant = "scheffe"
stimuli = ["a", "c"]
repeats = 1
"#;

/// Ura and Haga, five grades, breaks.
const SMALL_URA: &str = r#"[experiment]
name = "small ura"
seed = 11
counterbalance_blocks = true
break_every = 2

[timing]
explore_s = 1.0
pause_s = 0.0
rf_off_between = false

[[stimulus]]
name = "r20"
region = { kind = "random", f_b_hz = 20, spread_percent = 30, seed = 1 }

[[stimulus]]
name = "m"
scene = "material.toml"

[[block]]
name = "ura"
design = "paired"
stimuli = ["r20", "m"]

[[block]]
name = "haga"
design = "paired"
variant = "haga"
stimuli = ["m", "r20"]
"#;

/// Constant stimuli and a log-scale staircase on a grating's wavelength.
const SMALL_INTERVALS: &str = r#"[experiment]
name = "small two-interval"
seed = 5
counterbalance_blocks = false

[timing]
explore_s = 1.5
pause_s = 0.2

[[stimulus]]
name = "g"
region = { kind = "grating", wavelength_mm = 2.0, amplitude_percent = 80 }

[[block]]
name = "c"
design = "constant"
standard = "g"
vary = "wavelength_mm"
levels = [0.5, 1.0]

[[block]]
name = "s"
design = "staircase"
standard = "g"
vary = "wavelength_mm"
question = "Which was coarser?"
words = ["1", "2"]

[[block.staircase]]
name = "t"
start = 1.0
down = 1
up = 1
steps = [2.0, 1.5]
scale = "log"
min = 0.1
max = 4.0
max_trials = 3
threshold_reversals = 2
"#;

const SMALL: [(&str, &str); 3] = [
    ("paired", SMALL_PAIRED),
    ("ura", SMALL_URA),
    ("intervals", SMALL_INTERVALS),
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn corpus(target: &str) -> PathBuf {
    root().join("fuzz/corpus").join(target)
}

fn inputs(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = corpus(target);
    let mut v: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect();
    v.sort();
    v
}

fn is_seed(p: &Path) -> bool {
    p.file_name()
        .unwrap()
        .to_string_lossy()
        .starts_with("seed-")
}

fn parse(name: &str, text: &str) -> Protocol {
    protocol::parse(name, text, &scene_files()).unwrap_or_else(|e| panic!("{e}"))
}

/// A session of `text` for subject `fuzz` as `saw experiment run` logs it, every trial
/// answered with values cycling over the trial's: the log's bytes and the CSV's text.
fn session(name: &str, text: &str, dir: &Path) -> (Vec<u8>, String) {
    let _ = std::fs::remove_dir_all(dir);
    let mut runner = Runner::new(parse(&format!("{name}.toml"), text), "fuzz", 1).unwrap();
    let board = serde_json::json!({"board": "nucleo-f446re", "firmware": "saw-firmware 0.1.0"});
    let mut header = Header::new(&runner, board, "saw 0.1.0");
    header.started_utc = "2026-01-02T03:04:05.000Z".into();
    let mut log = Log::create(dir, header).unwrap();
    let mut n = 0u64;
    while let Some(t) = runner.next_trial().cloned() {
        let shown: Vec<Shown> = t
            .intervals
            .iter()
            .enumerate()
            .map(|(k, iv)| Shown {
                stimulus: iv.stimulus.clone(),
                scene_id: iv.scene.as_ref().map(|_| 0x5a00 + k as u32),
                board_from_us: Some(1_000_000 * n + 500_000 * k as u64),
                board_to_us: Some(1_000_000 * n + 500_000 * k as u64 + 400_000),
                // One trial with the finger's summary, the rest without (size).
                exploration: (n == 0).then(|| Exploration {
                    records: 40,
                    explored_s: 1.2,
                    strokes: 3,
                    mean_speed_mm_s: 41.5,
                    peak_speed_mm_s: 90.25,
                    distance_mm: 49.8,
                    f_b_hz: 40.0,
                    faults: 0,
                    scene_ids: vec![0x5a00],
                }),
            })
            .collect();
        let v = t.values[n as usize % t.values.len()];
        let o = runner.respond(v).unwrap();
        let mut record = TrialRecord::new(&o, shown, "2026-01-02T03:04:05.678Z".into(), 812.5);
        // Fixed times, so that the seeds are written the same again.
        record.responded_utc = format!("2026-01-02T03:04:{:02}.000Z", 6 + n);
        log.append(record).unwrap();
        n += 1;
    }
    let paths = Paths::new(dir, "fuzz");
    (
        std::fs::read(&paths.log).unwrap(),
        std::fs::read_to_string(&paths.csv).unwrap(),
    )
}

/// The session CSV's columns up to `reversal` (the analysis reads no further).
const TWO_INTERVAL_HEADER: &str = "subject,subject_index,trial,block,design,track,level,target_interval,first,second,response,response_word,score,correct,reversal\n";

fn write(dir: &Path, name: &str, bytes: &[u8]) {
    assert!(bytes.len() <= MAX_LEN, "{name}: {} bytes", bytes.len());
    std::fs::write(dir.join(name), bytes).unwrap();
}

fn seed() {
    // Seeds written before and no longer written (a protocol renamed) go.
    for target in ["protocol", "analysis_csv", "session_log"] {
        let dir = corpus(target);
        std::fs::create_dir_all(&dir).unwrap();
        for (p, _) in inputs(target) {
            if is_seed(&p) {
                std::fs::remove_file(p).unwrap();
            }
        }
    }
    let dir = corpus("protocol");
    for e in std::fs::read_dir(root().join("experiments")).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let text = std::fs::read_to_string(&p).unwrap();
        // The protocols (not the simulated participants' observer files beside them).
        if name.ends_with(".toml") && protocol::parse(&name, &text, &scene_files()).is_ok() {
            write(&dir, &format!("seed-{name}"), text.as_bytes());
        }
    }
    for (name, text) in SMALL {
        write(&dir, &format!("seed-small-{name}.toml"), text.as_bytes());
    }

    let logs = corpus("session_log");
    let csvs = corpus("analysis_csv");
    std::fs::create_dir_all(&logs).unwrap();
    std::fs::create_dir_all(&csvs).unwrap();
    let scratch = std::env::temp_dir().join(format!("saw-fuzz-seeds-{}", std::process::id()));
    for (name, text) in SMALL {
        let (log, csv) = session(name, text, &scratch);
        write(&logs, &format!("seed-{name}.log.jsonl"), &log);
        // Killed mid-write: the last line without its end.
        let cut = log.len() - 40;
        write(&logs, &format!("seed-{name}-torn.log.jsonl"), &log[..cut]);
        write(&csvs, &format!("seed-session-{name}.csv"), csv.as_bytes());
    }
    let _ = std::fs::remove_dir_all(&scratch);

    // A lab's own paired comparisons: three subjects, every ordered pair of four.
    let mut lab = String::from("subject,first,second,score\n");
    let names = ["#60", "#120", "#240", "#320"];
    for s in 0..3 {
        for i in 0..4 {
            for j in 0..4 {
                if i != j {
                    let d = (j as i32 - i as i32) + ((i * 7 + j * 3 + s) % 3) as i32 - 1;
                    lab += &format!("s{s},{},{},{}\n", names[i], names[j], d.clamp(-2, 2));
                }
            }
        }
    }
    write(&csvs, "seed-lab.csv", lab.as_bytes());

    // A simulated participant through the threshold protocol: the staircases, then the
    // constant stimuli, each file the columns the analysis reads.
    let text = std::fs::read_to_string(root().join("experiments/fb-threshold.toml")).unwrap();
    let mut runner = Runner::new(parse("fb-threshold.toml", &text), "sim", 0).unwrap();
    let mut who = Participant::new(ObserverSpec {
        threshold: 8.0,
        spread: 3.0,
        seed: 4,
        ..ObserverSpec::default()
    })
    .unwrap();
    let (mut stairs, mut constant) = (
        String::from(TWO_INTERVAL_HEADER),
        String::from(TWO_INTERVAL_HEADER),
    );
    while let Some(t) = runner.next_trial().cloned() {
        let o = runner.respond(who.respond(&t, &[])).unwrap();
        let row = format!(
            "sim,0,{},{},{},{},{},{},{},{},{},{},,{},{}\n",
            t.number,
            t.block,
            t.design,
            t.track.clone().unwrap_or_default(),
            t.level.unwrap(),
            t.target.unwrap(),
            t.intervals[0].stimulus,
            t.intervals[1].stimulus,
            o.response,
            o.word,
            u8::from(o.correct.unwrap()),
            o.reversal
                .map_or(String::new(), |r| u8::from(r).to_string()),
        );
        let into = if t.design == "staircase" {
            &mut stairs
        } else {
            &mut constant
        };
        if into.len() + row.len() <= MAX_LEN {
            *into += &row;
        }
    }
    write(&csvs, "seed-staircase.csv", stairs.as_bytes());
    write(&csvs, "seed-constant.csv", constant.as_bytes());
}

#[test]
#[ignore = "writes fuzz/corpus: run by hand when the protocols or the session's formats change"]
fn write_the_seed_inputs() {
    seed();
}

#[test]
fn every_protocol_input_kept_is_read() {
    let all = inputs("protocol");
    assert!(all.len() >= 5, "{} inputs", all.len());
    let mut accepted = 0;
    for (p, bytes) in &all {
        let ran = protocol_body(bytes);
        accepted += usize::from(ran.is_some());
        // A seed is a protocol a lab runs: accepted, and every trial answered.
        if is_seed(p) {
            let ran = ran.unwrap_or_else(|| panic!("{} refused", p.display()));
            assert!(ran.finished && ran.trials > 0, "{}: {ran:?}", p.display());
        }
    }
    assert!(accepted >= 5, "{accepted} of {} accepted", all.len());
}

#[test]
fn every_analysis_csv_input_kept_is_read() {
    let all = inputs("analysis_csv");
    let mut analysed = 0;
    for (p, bytes) in &all {
        let run = analysis_csv(bytes);
        analysed += usize::from(run.is_some_and(|r| r.analysed));
        if is_seed(p) {
            let run = run.unwrap_or_else(|| panic!("{} refused", p.display()));
            assert!(run.rows > 0, "{}: {run:?}", p.display());
        }
    }
    // The lab's, the staircases', the constant stimuli's and the sessions' CSVs at least.
    assert!(analysed >= 4, "{analysed} of {} analysed", all.len());
}

#[test]
fn every_session_log_input_kept_is_reopened() {
    let all = inputs("session_log");
    for (p, bytes) in &all {
        let run = session_log(bytes);
        // A seed is a log `saw experiment run` wrote, whole or torn: reopened, its CSV read
        // and its session resumed.
        if is_seed(p) {
            let run = run.unwrap_or_else(|| panic!("{} refused", p.display()));
            assert!(
                run.resumed && run.csv_read && run.trials > 0,
                "{}: {run:?}",
                p.display()
            );
        }
    }
}
