//! Protocol files refused with located sentences, and the runner's orders: every pair the
//! variant asks for, counterbalanced across subjects, the same order again on resume.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use saw_experiment::protocol::{self, Design, InMemory, PairedVariant, Protocol};
use saw_experiment::runner::Runner;

const NARA: &str = include_str!("../../experiments/nara-roughness.toml");
const THRESHOLD: &str = include_str!("../../experiments/fb-threshold.toml");

fn parse(text: &str) -> Result<Protocol, protocol::ProtocolError> {
    protocol::parse("p.toml", text, &InMemory(BTreeMap::new()))
}

fn shipped() -> Protocol {
    protocol::load(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../experiments/nara-roughness.toml"
    )))
    .unwrap()
}

/// A minimal paired protocol with `variant` over `n` inline stimuli.
fn paired(variant: &str, n: usize) -> String {
    let mut s = format!(
        "[experiment]\nname = \"t\"\nseed = 7\n[[block]]\nname = \"b\"\ndesign = \"paired\"\nvariant = \"{variant}\"\nstimuli = [{}]\n",
        (0..n).map(|i| format!("\"s{i}\"")).collect::<Vec<_>>().join(", ")
    );
    for i in 0..n {
        s += &format!(
            "[[stimulus]]\nname = \"s{i}\"\nregion = {{ kind = \"constant\", f_b_hz = {} }}\n",
            20 * (i + 1)
        );
    }
    s
}

/// Every trial of a session answered 0: the (first, second) names in order.
fn pairs_of(p: &Protocol, subject: &str, index: u32) -> Vec<(String, String)> {
    let mut r = Runner::new(p.clone(), subject, index).unwrap();
    let mut out = Vec::new();
    while let Some(t) = r.next_trial().cloned() {
        out.push((
            t.intervals[0].stimulus.clone(),
            t.intervals[1].stimulus.clone(),
        ));
        let v = t.values[t.values.len() / 2];
        r.respond(v).unwrap();
    }
    out
}

#[test]
fn the_shipped_study_is_ura_with_twelve_ordered_pairs_per_set() {
    let p = shipped();
    assert_eq!(p.blocks.len(), 2);
    for b in &p.blocks {
        let Design::Paired {
            variant, stimuli, ..
        } = &b.design
        else {
            panic!("{b:?}")
        };
        assert_eq!(*variant, PairedVariant::Ura);
        assert_eq!(stimuli.len(), 4);
        assert_eq!(b.words.len(), 5, "five grades");
    }
    let trials = pairs_of(&p, "s1", 0);
    assert_eq!(trials.len(), 24, "12 comparisons per set");
    // Each set: every ordered pair exactly once.
    let set: BTreeSet<_> = trials.iter().cloned().collect();
    assert_eq!(set.len(), 24);
    // Subject 0 starts with the virtual set, subject 1 with the real one.
    assert!(trials[0].0.ends_with("Hz"), "{trials:?}");
    assert!(pairs_of(&p, "s2", 1)[0].0.starts_with('#'));
    // The threshold protocol parses too.
    parse(THRESHOLD).unwrap();
    let _ = NARA;
}

#[test]
fn each_variant_gives_the_pairs_it_asks_for() {
    let n = 4;
    // Ura: every ordered pair, each subject.
    let ura = parse(&paired("ura", n)).unwrap();
    for s in 0..3 {
        let t = pairs_of(&ura, &format!("u{s}"), s);
        assert_eq!(t.len(), 12);
        assert_eq!(t.iter().collect::<BTreeSet<_>>().len(), 12);
    }
    // Nakaya: every unordered pair once per subject; over two subjects each pair is seen in
    // both orders.
    let nak = parse(&paired("nakaya", n)).unwrap();
    let a = pairs_of(&nak, "a", 0);
    let b = pairs_of(&nak, "b", 1);
    assert_eq!(a.len(), 6);
    let unordered = |v: &[(String, String)]| -> BTreeSet<(String, String)> {
        v.iter()
            .map(|(x, y)| {
                if x < y {
                    (x.clone(), y.clone())
                } else {
                    (y.clone(), x.clone())
                }
            })
            .collect()
    };
    assert_eq!(unordered(&a).len(), 6);
    let both: BTreeSet<_> = a.iter().chain(&b).cloned().collect();
    assert_eq!(
        both.len(),
        12,
        "the two subjects' orders are each other's reverse"
    );
    // Scheffé: one ordered pair per subject; 12 subjects cover all 12.
    let sch = parse(&paired("scheffe", n)).unwrap();
    let all: BTreeSet<_> = (0..12)
        .flat_map(|s| {
            let t = pairs_of(&sch, &format!("x{s}"), s);
            assert_eq!(t.len(), 1);
            t
        })
        .collect();
    assert_eq!(all.len(), 12);
    // Haga: one pair per subject; 6 subjects cover the 6 unordered pairs, 12 both orders.
    let haga = parse(&paired("haga", n)).unwrap();
    let t: Vec<_> = (0..12)
        .flat_map(|s| pairs_of(&haga, &format!("h{s}"), s))
        .collect();
    assert_eq!(unordered(&t[..6]).len(), 6);
    assert_eq!(t.iter().collect::<BTreeSet<_>>().len(), 12);
}

#[test]
fn orders_are_random_per_subject_and_the_same_on_resume() {
    let p = parse(&paired("ura", 5)).unwrap();
    let a = pairs_of(&p, "alice", 0);
    let b = pairs_of(&p, "bob", 0);
    assert_ne!(a, b, "another subject, another order");
    assert_eq!(
        a,
        pairs_of(&p, "alice", 0),
        "the same subject, the same order"
    );

    // Resume after 7 answers: the 8th trial is the one the uninterrupted session gives.
    let mut r = Runner::new(p.clone(), "alice", 0).unwrap();
    let mut logged = Vec::new();
    for _ in 0..7 {
        let t = r.next_trial().unwrap().clone();
        let names: Vec<String> = t.intervals.iter().map(|i| i.stimulus.clone()).collect();
        r.respond(1).unwrap();
        logged.push((t.number, names, 1));
    }
    let resumed = Runner::resume(p.clone(), "alice", 0, &logged).unwrap();
    assert_eq!(resumed.next_trial(), r.next_trial());
    assert_eq!(resumed.answered(), 7);
    // A log from another order is refused with a sentence.
    logged[3].1.reverse();
    let e = Runner::resume(p, "alice", 0, &logged).unwrap_err();
    assert!(e.to_string().contains("trial 3"), "{e}");
}

#[test]
fn a_response_out_of_range_is_refused_and_changes_nothing() {
    let p = shipped();
    let mut r = Runner::new(p, "s", 0).unwrap();
    let before = r.next_trial().cloned();
    let e = r.respond(3).unwrap_err();
    assert_eq!(
        e.to_string(),
        "response 3 is not one this trial allows (it takes -2, -1, 0, 1, 2)"
    );
    assert_eq!(r.next_trial().cloned(), before);
    assert_eq!(r.answered(), 0);
}

#[test]
fn staircase_blocks_present_two_intervals_and_follow_the_track() {
    let p = parse(THRESHOLD).unwrap();
    let mut r = Runner::new(p, "s", 0).unwrap();
    let t = r.next_trial().unwrap().clone();
    assert_eq!(t.design, "staircase");
    assert_eq!(t.values, vec![1, 2]);
    let target = t.target.unwrap();
    let level = t.level.unwrap();
    // The comparison's interval carries the standard's f_b plus the level.
    let cmp = &t.intervals[target as usize - 1];
    assert_eq!(cmp.stimulus, format!("80 Hz{:+}", level));
    assert!(cmp
        .scene
        .as_ref()
        .unwrap()
        .contains(&format!("f_b_hz = {}", 80.0 + level)));
    // Answer every trial right: each track's level only goes down.
    let mut last: BTreeMap<String, f64> = BTreeMap::new();
    while let Some(t) = r.next_trial().cloned() {
        if t.design != "staircase" {
            break;
        }
        let track = t.track.clone().unwrap();
        if let Some(prev) = last.get(&track) {
            assert!(
                t.level.unwrap() <= *prev,
                "{track}: {} after {prev}",
                t.level.unwrap()
            );
        }
        last.insert(track, t.level.unwrap());
        r.respond(t.target.unwrap() as i32).unwrap();
    }
    assert_eq!(last.len(), 2, "both tracks ran: {last:?}");
}

#[test]
fn bad_protocols_are_refused_at_the_value_with_a_sentence() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "variant = \"ura\"",
            "variant = \"uraa\"",
            "block[0].variant: \"uraa\" is not a variant; it is one of scheffe, ura, haga, nakaya",
        ),
        ("seed = 7", "seed = -1", "experiment.seed: -1 is negative"),
        ("f_b_hz = 20 }", "f_b_hz = 5000 }", "stimulus[0].region:"),
        (
            "stimuli = [\"s0\"",
            "stimuli = [\"s9\"",
            "block[0].stimuli[0]: \"s9\" is not a stimulus of this file",
        ),
        (
            "design = \"paired\"",
            "design = \"pared\"",
            "block[0].design: \"pared\" is not a design",
        ),
        (
            "name = \"t\"",
            "name = \"t\"\ncolour = 1",
            "unknown field `colour`",
        ),
    ];
    for (from, to, says) in cases {
        let text = paired("ura", 3).replacen(from, to, 1);
        assert_ne!(text, paired("ura", 3), "{from}");
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.starts_with("p.toml:"), "{e}");
        assert!(e.contains(says), "{to}: {e}");
        // Located at a line of the file.
        let line: usize = e.split(':').nth(1).unwrap().parse().unwrap();
        assert!(line >= 1 && line <= text.lines().count(), "{e}");
    }
    // Even grades, and a timing out of range.
    let e = parse(&(paired("ura", 3) + "[response]\nwords = [\"a\", \"b\"]\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("response.words: 2 words"), "{e}");
    let e = parse(&(paired("ura", 3) + "[timing]\nexplore_s = 0\n"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("timing.explore_s: 0 s is outside"), "{e}");
}
