//! What a review found, each held: designs the analysis could not read refused at the door, the
//! one-pair variants' pairs spread over block positions, constant stimuli balanced for odd
//! repeats, a session log that is locked, rewritten on resume and keeps its subject index, and
//! an analysis that reports the blocks it can when one cannot be read.

use std::collections::BTreeMap;

use saw_experiment::analysis::input::{Dataset, PairedRow};
use saw_experiment::analysis::report::{analyze, Options};
use saw_experiment::protocol::{self, InMemory, Protocol, ProtocolError};
use saw_experiment::runner::Runner;
use saw_experiment::session::{self, Header, Log, Shown, TrialRecord};

fn parse(text: &str) -> Result<Protocol, ProtocolError> {
    protocol::parse("p.toml", text, &InMemory(BTreeMap::new()))
}

const STIMULI: &str = "[[stimulus]]\nname = \"a\"\nregion = { kind = \"constant\", f_b_hz = 20 }\n[[stimulus]]\nname = \"b\"\nregion = { kind = \"constant\", f_b_hz = 40 }\n[[stimulus]]\nname = \"c\"\nregion = { kind = \"constant\", f_b_hz = 80 }\n";

fn with_blocks(blocks: &str) -> String {
    format!("[experiment]\nname = \"t\"\nseed = 3\n{STIMULI}{blocks}")
}

#[test]
fn designs_the_analysis_cannot_read_are_refused_at_the_door() {
    let cases = [
        (
            "[[block]]\nname = \"x\"\ndesign = \"paired\"\nstimuli = [\"a\", \"b\"]\nrepeats = 2\n",
            "block[0].repeats: 2 for a paired block",
        ),
        (
            "[[block]]\nname = \"x\"\ndesign = \"paired\"\nstimuli = [\"a\", \"b\"]\n[[block]]\nname = \"x\"\ndesign = \"paired\"\nstimuli = [\"b\", \"c\"]\n",
            "block[1].name: \"x\" is already the name of block[0]",
        ),
        (
            "[[block]]\nname = \"s\"\ndesign = \"staircase\"\nstandard = \"a\"\nvary = \"f_b_hz\"\n[[block.staircase]]\nname = \"t\"\nstart = 10.0\nsteps = [2.0]\nmin = 1.0\nmax = 20.0\nmax_reversals = 8\n",
            "block[0].staircase[0].max_trials: is missing",
        ),
        (
            "[[block]]\nname = \"c\"\ndesign = \"constant\"\nstandard = \"a\"\nvary = \"until_mm\"\nlevels = [1.0, 2.0]\n",
            "block[0].vary: until_mm cannot be varied",
        ),
    ];
    let cases: Vec<(String, &str)> = cases
        .iter()
        .map(|(b, s)| (b.to_string(), *s))
        .chain([
            (
                // 0.5 Hz at 40 %: an 800 ms burst, over the 50 ms on-time cap.
                "[[stimulus]]\nname = \"slow\"\nregion = { kind = \"constant\", f_b_hz = 0.5, duty_percent = 40 }\n[[block]]\nname = \"x\"\ndesign = \"paired\"\nstimuli = [\"a\", \"slow\"]\n".to_string(),
                "stimulus[3].region: f_b 0.5 Hz at 40 % duty is a burst of 800 ms, over the scene's on-time cap of 50 ms",
            ),
            (
                "[[block]]\nname = \"s\"\ndesign = \"staircase\"\nstandard = \"a\"\nvary = \"f_b_hz\"\n[[block.staircase]]\nname = \"t\"\nstart = 10.0\nsteps = [2.0]\nmin = 1.0\nmax = 20.0\nmax_trials = 50\nmax_reversals = 6\nthreshold_reversals = 10\n".to_string(),
                "block[0].staircase[0].threshold_reversals: the threshold averages the last 10 reversals, more than max_reversals = 6",
            ),
            (
                "[[block]]\nname = \"x\"\ndesign = \"paired\"\nstimuli = [\"a\", \"b\"]\nwords = [\"less\", \"\", \"more\"]\n".to_string(),
                "block[0].words: word 2 is empty",
            ),
        ])
        .collect();
    for (blocks, says) in &cases {
        let e = parse(&with_blocks(blocks)).unwrap_err().to_string();
        assert!(e.starts_with("p.toml:") && e.contains(says), "{e}");
        assert_eq!(e.lines().count(), 1, "{e}");
    }
    // A value holding a line break is quoted with it escaped: the sentence stays one line.
    let e = parse(&with_blocks(
        "[[block]]\nname = \"p\"\ndesign = \"paired\"\nstimuli = [\"a\", \"b\\nc\"]\n",
    ))
    .unwrap_err()
    .to_string();
    assert!(
        e.ends_with(
            "block[0].stimuli[1]: \"b\\nc\" is not a stimulus of this file (they are: a, b, c)"
        ),
        "{e}"
    );
    assert_eq!(e.lines().count(), 1, "{e}");
    // A file with no block: the file as a whole, no line to point at.
    let e = parse(&with_blocks("")).unwrap_err().to_string();
    assert_eq!(
        e,
        "p.toml: block: the protocol has no [[block]]; there is nothing to run"
    );
}

/// A simulated participant's file: every key has its default; a misspelt key is refused.
#[test]
fn an_observer_file_takes_defaults_and_refuses_unknown_keys() {
    use saw_experiment::observer::ObserverSpec;
    let s: ObserverSpec = toml::from_str("threshold = 6.0\n").unwrap();
    assert_eq!(s.threshold, 6.0);
    assert_eq!(s.noise, ObserverSpec::default().noise);
    let e = toml::from_str::<ObserverSpec>("nois = 0.3\n").unwrap_err();
    assert!(e.message().contains("unknown field `nois`"), "{e}");
    let shipped: ObserverSpec =
        toml::from_str(include_str!("../../experiments/fb-threshold-observer.toml")).unwrap();
    assert_eq!((shipped.threshold, shipped.spread), (6.0, 3.0));
}

#[test]
fn constant_stimuli_with_odd_repeats_put_the_comparison_first_in_about_half() {
    let p = parse(&with_blocks(
        "[[block]]\nname = \"c\"\ndesign = \"constant\"\nstandard = \"b\"\nvary = \"f_b_hz\"\nlevels = [2.0, 4.0, 8.0, 16.0]\nrepeats = 3\n",
    ))
    .unwrap();
    for s in 0..5 {
        let mut r = Runner::new(p.clone(), &format!("s{s}"), s).unwrap();
        let mut firsts: BTreeMap<String, u32> = BTreeMap::new();
        while let Some(t) = r.next_trial().cloned() {
            *firsts.entry(format!("{}", t.level.unwrap())).or_default() +=
                u32::from(t.target == Some(1));
            r.respond(1).unwrap();
        }
        // 3 presentations a level: first in one or two of them, never none or all.
        for (level, n) in &firsts {
            assert!(
                *n == 1 || *n == 2,
                "subject {s}, level {level}: first {n} of 3"
            );
        }
    }
}

#[test]
fn the_one_pair_variants_judge_every_pair_in_every_block_position() {
    // Two Scheffé blocks, counterbalanced: over 12 subjects each block sees each of its 6
    // ordered pairs once first and once second.
    let p = parse(&with_blocks(
        "[[block]]\nname = \"x\"\ndesign = \"paired\"\nvariant = \"scheffe\"\nstimuli = [\"a\", \"b\", \"c\"]\n[[block]]\nname = \"y\"\ndesign = \"paired\"\nvariant = \"scheffe\"\nstimuli = [\"a\", \"b\", \"c\"]\n",
    ))
    .unwrap();
    let mut seen: BTreeMap<(String, u32, String, String), u32> = BTreeMap::new();
    for s in 0..12 {
        let mut r = Runner::new(p.clone(), &format!("s{s}"), s).unwrap();
        while let Some(t) = r.next_trial().cloned() {
            let key = (
                t.block.clone(),
                t.block_number,
                t.intervals[0].stimulus.clone(),
                t.intervals[1].stimulus.clone(),
            );
            *seen.entry(key).or_default() += 1;
            r.respond(0).unwrap();
        }
    }
    // 2 blocks × 2 positions × 6 ordered pairs, each once.
    assert_eq!(seen.len(), 24, "{seen:?}");
    assert!(seen.values().all(|n| *n == 1));
}

fn header(runner: &Runner) -> Header {
    Header::new(runner, serde_json::Value::Null, "test")
}

fn record(runner: &mut Runner) -> TrialRecord {
    let t = runner.next_trial().unwrap().clone();
    let o = runner.respond(t.values[0]).unwrap();
    let shown = t
        .intervals
        .iter()
        .map(|i| Shown {
            stimulus: i.stimulus.clone(),
            ..Shown::default()
        })
        .collect();
    TrialRecord::new(&o, shown, session::now_utc(), 1.0)
}

#[test]
fn a_log_is_locked_rewritten_on_resume_and_keeps_its_subject_index() {
    let dir = tempfile::tempdir().unwrap();
    let p = parse(&with_blocks(
        "[[block]]\nname = \"x\"\ndesign = \"paired\"\nstimuli = [\"a\", \"b\", \"c\"]\n",
    ))
    .unwrap();
    let mut runner = Runner::new(p.clone(), "s1", 4).unwrap();
    let mut log = Log::create(dir.path(), header(&runner)).unwrap();
    log.append(record(&mut runner)).unwrap();
    log.append(record(&mut runner)).unwrap();
    // A second runner for the subject while the first holds the log: refused.
    let e = Log::resume(dir.path(), "s1").unwrap_err();
    assert!(e.contains("another runner has this session open"), "{e}");
    // A second session for the subject: refused, the log as it was.
    let e = Log::create(dir.path(), header(&runner)).unwrap_err();
    assert!(e.contains("--resume continues it"), "{e}");
    drop(log);

    // Killed after the log's sync and before the CSV's rename: the CSV is a trial behind.
    let paths = session::Paths::new(dir.path(), "s1");
    let csv = std::fs::read_to_string(&paths.csv).unwrap();
    let one_row: String = csv.lines().take(2).map(|l| format!("{l}\n")).collect();
    std::fs::write(&paths.csv, &one_row).unwrap();
    let log = Log::resume(dir.path(), "s1").unwrap();
    assert_eq!(
        std::fs::read_to_string(&paths.csv).unwrap(),
        csv,
        "rewritten on resume"
    );
    assert_eq!(log.records().len(), 2);

    // The index the session began with is kept; another is refused.
    assert_eq!(
        session::subject_index(&p, None, Some(log.header()), dir.path()).unwrap(),
        4
    );
    let e = session::subject_index(&p, Some(5), Some(log.header()), dir.path()).unwrap_err();
    assert!(e.contains("differs from the 4"), "{e}");
    // A new session counts the sessions there; a one-pair variant needs it given.
    assert_eq!(
        session::subject_index(&p, None, None, dir.path()).unwrap(),
        1
    );
    let scheffe = parse(&with_blocks(
        "[[block]]\nname = \"x\"\ndesign = \"paired\"\nvariant = \"haga\"\nstimuli = [\"a\", \"b\", \"c\"]\n",
    ))
    .unwrap();
    let e = session::subject_index(&scheffe, None, None, dir.path()).unwrap_err();
    assert!(e.contains("the subject index is required"), "{e}");
    assert_eq!(
        session::subject_index(&scheffe, Some(7), None, dir.path()).unwrap(),
        7
    );
}

fn row(block: &str, subject: &str, first: &str, second: &str, score: f64) -> PairedRow {
    PairedRow {
        block: block.into(),
        subject: subject.into(),
        first: first.into(),
        second: second.into(),
        score,
    }
}

#[test]
fn a_block_that_cannot_be_analysed_does_not_take_the_others_down() {
    let mut d = Dataset::default();
    // Block "good": Ura, 2 subjects, 3 stimuli, scores with some noise.
    let names = ["a", "b", "c"];
    for (k, s) in ["s1", "s2"].iter().enumerate() {
        for i in 0..3 {
            for j in 0..3 {
                if i != j {
                    let score =
                        (j as f64 - i as f64) + if (i + j + k) % 2 == 0 { 0.5 } else { -0.5 };
                    d.paired.push(row("good", s, names[i], names[j], score));
                }
            }
        }
    }
    // Block "short": a subject who stopped after two judgments of four pairs' worth.
    d.paired.push(row("short", "s1", "a", "b", 1.0));
    d.paired.push(row("short", "s1", "b", "a", -1.0));
    d.paired.push(row("short", "s1", "a", "c", 1.0));
    // Block "ids": stimulus columns that hold ids (swapped columns): 150 names.
    for k in 0..75 {
        d.paired.push(row(
            "ids",
            "s1",
            &format!("id{k}"),
            &format!("id{}", k + 75),
            1.0,
        ));
    }
    let r = analyze(&d, &Options::default()).unwrap();
    assert_eq!(r.paired.len(), 1);
    assert_eq!(r.paired[0].block, "good");
    let refused: Vec<&str> = r.refused.iter().map(|e| e.block.as_str()).collect();
    assert_eq!(refused, ["short", "ids"], "{:?}", r.refused);
    assert!(
        r.refused[1].message.contains("150 stimuli"),
        "{}",
        r.refused[1]
    );

    // Exactly additive judgments: no error variance, so no F and no yardstick (one of 0
    // would separate every pair).
    let mut exact = Dataset::default();
    for s in ["s1", "s2"] {
        for i in 0..3 {
            for j in 0..3 {
                if i != j {
                    exact.paired.push(row(
                        "exact",
                        s,
                        names[i],
                        names[j],
                        (j as f64 - i as f64) * 0.5,
                    ));
                }
            }
        }
    }
    let r = analyze(&exact, &Options::default()).unwrap();
    assert!(
        r.paired[0].scheffe.yardstick.is_empty(),
        "{:?}",
        r.paired[0].scheffe.yardstick
    );
}
