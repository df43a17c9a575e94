//! The fuzz bodies of the experiment's outside inputs (the `protocol`, `analysis_csv` and
//! `session_log` targets in `fuzz/`, docs/fuzzing.md), here so that the corpus replay
//! (`cargo test -p saw-experiment --test fuzz_corpus`) runs the same code on stable.
//!
//! Each takes the fuzzer's bytes as the file a lab gives the program, and holds the crate to
//! the project's rule: no input reaches a panic, and bad input gets a one-line error that
//! names the file. Beyond that each checks what the crate promises of what it accepted:
//!
//! - [`protocol`]: a protocol file through [`protocol::parse`](crate::protocol::parse); an
//!   accepted one is run by the [`Runner`] for a subject, every trial answered (up to
//!   [`MAX_TRIALS`]) with values cycling over the trial's own, each answer preceded by one the
//!   trial does not allow, which must be refused and change nothing. Every two-interval
//!   comparison presented must be a scene every board accepts (the protocol checks them at the
//!   door, not mid-session), and a session resumed from the first half of the answers must
//!   stand at the same trial.
//! - [`analysis_csv`]: a session or lab CSV through
//!   [`read_csv`](crate::analysis::input::read_csv); rows read are analysed by
//!   [`analyze`](crate::analysis::report::analyze) (no bootstrap, or two resamples) and the
//!   report serialised as `saw experiment analyze --json` does.
//! - [`session_log`]: a session log on disk reopened as `saw experiment run --resume` does
//!   ([`Log::resume`](crate::session::Log::resume): a torn last line cut off, which must leave
//!   a log that reads back the same and whole); its CSV and sidecar written, the CSV read and
//!   analysed with the sidecar's options, and the header's protocol parsed and resumed with
//!   the log's answers.

use std::collections::BTreeSet;
use std::path::PathBuf;

use crate::analysis::input::{read_csv, sidecar_options, Dataset};
use crate::analysis::report::{analyze, Options};
use crate::protocol::{self, InMemory, Protocol};
use crate::runner::{Runner, RunnerError};
use crate::session::{self, Log};

/// The most trials [`protocol`] answers of one session (a protocol may plan 10^5).
pub const MAX_TRIALS: u32 = 2000;

/// The most distinct two-interval comparisons [`protocol`] checks against the boards per
/// input (each is a scene read and compiled per board).
pub const MAX_SCENE_CHECKS: usize = 32;

/// The scene files a fuzzed protocol may name (`scene = "grating.toml"`, `[board] scene`):
/// the repository's scenes by their file names.
pub fn scene_files() -> InMemory {
    let scenes: [(&str, &str); 6] = [
        ("default.toml", include_str!("../../scenes/default.toml")),
        ("grating.toml", include_str!("../../scenes/grating.toml")),
        ("lines.toml", include_str!("../../scenes/lines.toml")),
        ("material.toml", include_str!("../../scenes/material.toml")),
        ("random.toml", include_str!("../../scenes/random.toml")),
        ("rf-off.toml", include_str!("../../scenes/rf-off.toml")),
    ];
    InMemory(
        scenes
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect(),
    )
}

/// A refusal as the user reads it: one line, naming what was read.
fn one_line(error: &str, names: &str) {
    assert!(
        !error.contains(['\n', '\r']),
        "an error of more than one line:\n{error}"
    );
    assert!(
        error.starts_with(names),
        "an error that does not begin with {names:?}: {error}"
    );
}

/// What [`protocol`] did with an accepted protocol.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProtocolRun {
    /// Trials answered.
    pub trials: u32,
    /// Every trial was answered (not stopped at [`MAX_TRIALS`]).
    pub finished: bool,
    /// Distinct two-interval comparisons checked against the boards.
    pub scenes_checked: usize,
}

/// A protocol file's bytes, named `fuzz.toml`, its scenes from [`scene_files`]. None: not
/// UTF-8 or refused (with one line naming the file). Accepted: run for subject `fuzz` with
/// index `bytes.len() % 4` (counterbalancing and the one-pair variants' pair), as described
/// in the module's documentation. Never panics: that is what the fuzz target checks.
pub fn protocol(bytes: &[u8]) -> Option<ProtocolRun> {
    let text = std::str::from_utf8(bytes).ok()?;
    match protocol::parse("fuzz.toml", text, &scene_files()) {
        Ok(p) => Some(run(p, (bytes.len() % 4) as u32)),
        Err(e) => {
            one_line(&e.to_string(), "fuzz.toml");
            None
        }
    }
}

/// A value `allowed` does not hold: one of a few, picked by `n`.
fn not_allowed(allowed: &[i32], n: u32) -> i32 {
    let lo = allowed.iter().copied().min().unwrap_or(0);
    let hi = allowed.iter().copied().max().unwrap_or(0);
    let candidates = [
        hi.saturating_add(1),
        lo.saturating_sub(1),
        i32::MIN,
        i32::MAX,
        0,
    ];
    (0..candidates.len())
        .map(|k| candidates[(n as usize + k) % candidates.len()])
        .find(|v| !allowed.contains(v))
        .expect("a trial allows at most 11 values")
}

/// Whether every supported board takes `scene` (the protocol's own door check).
fn boards_accept(scene: &str) -> Result<(), String> {
    for b in saw_boards::ALL {
        let timer = saw_core::burst::BurstTimer {
            clock_hz: b.burst_timer_clk_hz,
            counter_bits: b.burst_timer_bits,
            max_burst_hz: b.max_burst_hz,
        };
        saw_core::scene_file::load_for_board(
            "(comparison)",
            scene,
            timer,
            1_000_000 / b.sample_rate_hz,
        )
        .map_err(|e| format!("{e} (on the {})", b.name))?;
    }
    Ok(())
}

fn run(p: Protocol, k: u32) -> ProtocolRun {
    let mut ran = ProtocolRun::default();
    let mut r = match Runner::new(p.clone(), "fuzz", k) {
        Ok(r) => r,
        Err(e) => {
            // A refusal is a sentence (`saw experiment run` prints it as it is).
            one_line(&e.to_string(), "");
            return ran;
        }
    };
    let mut checked: BTreeSet<(String, u64)> = BTreeSet::new();
    while let Some(t) = r.next_trial().cloned() {
        if ran.trials >= MAX_TRIALS {
            ran.scenes_checked = checked.len();
            return ran;
        }
        let n = ran.trials;
        assert_eq!((t.number, r.answered()), (n, n), "{t:?}");
        assert_eq!(t.values.len(), t.words.len(), "{t:?}");
        assert_eq!(t.intervals.len(), 2, "{t:?}");
        assert!(!t.values.is_empty(), "{t:?}");

        // A value the trial does not allow is refused, and the trial stays as it was.
        let bad = not_allowed(&t.values, n);
        match r.respond(bad) {
            Err(e @ RunnerError::Response { .. }) => one_line(&e.to_string(), "response"),
            other => panic!("response {bad} to {t:?}: {other:?}"),
        }
        assert_eq!(r.next_trial(), Some(&t));
        assert_eq!(r.answered(), n);

        // A two-interval comparison is a scene every board runs.
        if let (Some(level), Some(target)) = (t.level, t.target) {
            assert!(target == 1 || target == 2, "{t:?}");
            let key = (t.block.clone(), level.to_bits());
            if checked.len() < MAX_SCENE_CHECKS && !checked.contains(&key) {
                if let Some(scene) = &t.intervals[target as usize - 1].scene {
                    if let Err(e) = boards_accept(scene) {
                        panic!("block {:?} at level {level} presents a scene no board runs: {e}\n{scene}", t.block);
                    }
                }
                checked.insert(key);
            }
        }

        let v = t.values[n as usize % t.values.len()];
        let o = r
            .respond(v)
            .unwrap_or_else(|e| panic!("response {v} to {t:?} refused: {e}"));
        assert_eq!((o.response, &o.trial), (v, &t));
        assert_eq!(o.correct, t.target.map(|g| v == g as i32), "{o:?}");
        ran.trials += 1;
    }
    ran.finished = true;
    ran.scenes_checked = checked.len();
    assert!(matches!(r.respond(0), Err(RunnerError::Finished)));

    // Resumed from the first half of the answers: the same next trial.
    let outcomes = r.outcomes();
    let half = outcomes.len() / 2;
    let replay: Vec<(u32, Vec<String>, i32)> = outcomes[..half]
        .iter()
        .map(|o| {
            (
                o.trial.number,
                o.trial
                    .intervals
                    .iter()
                    .map(|i| i.stimulus.clone())
                    .collect(),
                o.response,
            )
        })
        .collect();
    let resumed = Runner::resume(p, "fuzz", k, &replay)
        .unwrap_or_else(|e| panic!("resumed after {half} trials: {e}"));
    assert_eq!(resumed.answered() as usize, half);
    assert_eq!(resumed.next_trial(), outcomes.get(half).map(|o| &o.trial));
    ran
}

/// What [`analysis_csv`] did with a CSV the reader took.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CsvRun {
    /// Paired rows and two-interval rows read.
    pub rows: usize,
    /// The analysis gave a report (false: it refused with one line, or there were no rows).
    pub analysed: bool,
}

/// A session CSV's or a lab CSV's bytes, named `fuzz.csv`. None: not UTF-8 or refused by the
/// reader (with one line naming the file). Rows read are analysed as `saw experiment analyze`
/// does without a sidecar, but for each paired block's stimuli in the order they first appear
/// standing for the protocol's (so two blocks of as many stimuli are correlated); two bootstrap
/// resamples when the input's length is odd, none when even. A block refused, or the whole
/// analysis, is one line naming the block. Never panics.
pub fn analysis_csv(bytes: &[u8]) -> Option<CsvRun> {
    let text = std::str::from_utf8(bytes).ok()?;
    let mut data = Dataset::default();
    if let Err(e) = read_csv("fuzz.csv", text, &mut data) {
        one_line(&e.to_string(), "fuzz.csv");
        return None;
    }
    let rows = data.paired.len() + data.intervals.len();
    let o = Options {
        bootstrap: if bytes.len() % 2 == 1 { 2 } else { 0 },
        ..Options::default()
    };
    let analysed = rows > 0 && analysed(&data, o);
    Some(CsvRun { rows, analysed })
}

/// Analyses `data` (it has rows): whether a report came. Each paired block's stimuli in the
/// order they first appear stand for the protocol's, unless `o` has them from a sidecar.
fn analysed(data: &Dataset, mut o: Options) -> bool {
    for r in &data.paired {
        let s = o.block_stimuli.entry(r.block.clone()).or_default();
        for name in [&r.first, &r.second] {
            if !s.contains(name) {
                s.push(name.clone());
            }
        }
    }
    match analyze(data, &o) {
        Ok(report) => {
            // A block that cannot be analysed is listed with its sentence.
            for e in &report.refused {
                one_line(&e.to_string(), "block \"");
            }
            // What `--json` prints.
            let _ = serde_json::to_string(&report);
            true
        }
        Err(e) => {
            one_line(&e.to_string(), "block \"");
            false
        }
    }
}

/// What [`session_log`] did with a log it could reopen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LogRun {
    /// Trials the log holds.
    pub trials: usize,
    /// The header's protocol parsed and the runner resumed from the log's answers.
    pub resumed: bool,
    /// The session's CSV was read back by the analysis.
    pub csv_read: bool,
}

/// A scratch directory of this process and thread (the corpus replay runs tests in threads).
fn scratch() -> PathBuf {
    let thread = format!("{:?}", std::thread::current().id())
        .replace(|c: char| !c.is_ascii_alphanumeric(), "");
    std::env::temp_dir().join(format!("saw-fuzz-session-{}-{thread}", std::process::id()))
}

/// A session log's bytes, written as `fuzz.log.jsonl` in a scratch directory and reopened
/// as `saw experiment run --resume --subject fuzz` does. None: refused (with one line naming
/// the log). Reopened: the file must read back the same, with no torn line left; its CSV and
/// sidecar are written as after every trial, the CSV read by the analysis (and analysed when
/// it has rows, with the options the sidecar gives), and the protocol the header holds, when
/// it parses, resumed with the log's answers (refused with one line, or resumed). Never
/// panics.
pub fn session_log(bytes: &[u8]) -> Option<LogRun> {
    /// Removes the scratch directory however the body ends (a failed check unwinds in tests).
    struct Scratch(PathBuf);
    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
    let dir = Scratch(scratch());
    std::fs::create_dir_all(&dir.0).expect("a scratch directory");
    let path = session::Paths::new(&dir.0, "fuzz").log;
    std::fs::write(&path, bytes).expect("the scratch log is written");
    reopen(&dir.0, &path)
}

fn reopen(dir: &std::path::Path, path: &std::path::Path) -> Option<LogRun> {
    let log = match Log::resume(dir, "fuzz") {
        Ok(log) => log,
        Err(e) => {
            one_line(&e, &path.display().to_string());
            return None;
        }
    };
    // The torn line is gone: the file reads back as the log it opened.
    let again = session::read_log(path).expect("a reopened log reads again");
    assert_eq!(again.torn_bytes, 0);
    assert_eq!(&again.header, log.header());
    assert_eq!(again.records, log.records());

    let h = log.header();
    let mut run = LogRun {
        trials: log.records().len(),
        ..LogRun::default()
    };
    // The CSV and the sidecar as written after every trial, read as `saw experiment analyze`
    // reads them.
    let csv = session::csv(h, log.records());
    let sidecar = serde_json::to_string_pretty(&session::sidecar(h, log.records()))
        .expect("a sidecar is JSON");
    let mut data = Dataset::default();
    match read_csv("fuzz.csv", &csv, &mut data) {
        Ok(()) => {
            run.csv_read = true;
            if !data.paired.is_empty() || !data.intervals.is_empty() {
                let mut o = Options {
                    bootstrap: 0,
                    ..Options::default()
                };
                sidecar_options(&sidecar, &mut o);
                analysed(&data, o);
            }
        }
        Err(e) => one_line(&e.to_string(), "fuzz.csv"),
    }
    if let Ok(p) = protocol::parse("fuzz.toml", &h.protocol_text, &scene_files()) {
        match Runner::resume(p, "fuzz", h.subject_index, &log.replay()) {
            Ok(_) => run.resumed = true,
            Err(e) => one_line(&e.to_string(), ""),
        }
    }
    Some(run)
}
