//! Planning studies with the simulated participant through the runner (no board: each
//! interval's f_b is the stimulus' own): the seed paper's design recovers the observer's
//! order, and when the observer cannot tell two stimuli apart the 5 % yardstick separates them
//! in no more than 5 % of 400 studies.

use std::collections::BTreeMap;

use saw_experiment::analysis::paired::{analyze, Judgment, Variant};
use saw_experiment::exploration::Exploration;
use saw_experiment::observer::ObserverSpec;
use saw_experiment::protocol::{self, InMemory, Protocol};
use saw_experiment::runner::Runner;
use saw_experiment::session::Shown;
use saw_experiment::simulate::Participant;

/// A Ura protocol over stimuli of these f_b (names `a`, `b`, …).
fn protocol(fb_hz: &[f64]) -> Protocol {
    let names: Vec<String> = (0..fb_hz.len())
        .map(|i| ((b'a' + i as u8) as char).to_string())
        .collect();
    let mut s = format!(
        "[experiment]\nname = \"plan\"\nseed = 11\n[[block]]\nname = \"b\"\ndesign = \"paired\"\nvariant = \"ura\"\nstimuli = [{}]\n",
        names.iter().map(|n| format!("\"{n}\"")).collect::<Vec<_>>().join(", ")
    );
    for (n, f) in names.iter().zip(fb_hz) {
        s += &format!(
            "[[stimulus]]\nname = \"{n}\"\nregion = {{ kind = \"constant\", f_b_hz = {f} }}\n"
        );
    }
    protocol::parse("plan.toml", &s, &InMemory(BTreeMap::new())).unwrap()
}

/// One study: `subjects` simulated participants (seeds from `seed`) through the runner.
fn study(
    p: &Protocol,
    fb: &BTreeMap<String, f64>,
    subjects: u32,
    seed: u64,
    category_width: f64,
) -> Vec<Judgment> {
    let mut out = Vec::new();
    for s in 0..subjects {
        let subject = format!("s{s}");
        let mut runner = Runner::new(p.clone(), &subject, s).unwrap();
        let mut who = Participant::new(ObserverSpec {
            seed: seed * 1000 + u64::from(s),
            category_width,
            ..ObserverSpec::default()
        })
        .unwrap();
        while let Some(t) = runner.next_trial().cloned() {
            let shown: Vec<Shown> = t
                .intervals
                .iter()
                .map(|iv| Shown {
                    stimulus: iv.stimulus.clone(),
                    exploration: Some(Exploration {
                        f_b_hz: fb[&iv.stimulus],
                        ..Exploration::default()
                    }),
                    ..Shown::default()
                })
                .collect();
            let v = who.respond(&t, &shown);
            let o = runner.respond(v).unwrap();
            out.push(Judgment {
                subject: subject.clone(),
                first: o.trial.intervals[0].stimulus.clone(),
                second: o.trial.intervals[1].stimulus.clone(),
                score: f64::from(v),
            });
        }
    }
    out
}

fn fb_map(fb_hz: &[f64]) -> BTreeMap<String, f64> {
    fb_hz
        .iter()
        .enumerate()
        .map(|(i, f)| (((b'a' + i as u8) as char).to_string(), *f))
        .collect()
}

#[test]
fn the_seed_design_recovers_the_observers_order_in_most_studies() {
    // 20, 40, 80, 200 Hz; 5 subjects; 12 comparisons each.
    let fb = [20.0, 40.0, 80.0, 200.0];
    let p = protocol(&fb);
    let m = fb_map(&fb);
    let mut in_order = 0;
    for seed in 0..50 {
        let j = study(&p, &m, 5, seed, 1.0);
        assert_eq!(j.len(), 60);
        let a = analyze(&j, None).unwrap();
        assert_eq!(a.variant, Variant::Ura);
        let scale: BTreeMap<&str, f64> = a
            .stimuli
            .iter()
            .map(String::as_str)
            .zip(a.scale.iter().copied())
            .collect();
        if scale["a"] > scale["b"] && scale["b"] > scale["c"] && scale["c"] > scale["d"] {
            in_order += 1;
        }
    }
    // Neighbours 0.69–0.92 ln units apart against the default observer's 0.3 noise: the
    // order is recovered in (nearly) every study.
    assert!(in_order >= 49, "{in_order} of 50 studies in order");
}

/// In how many of `studies` studies the 5 % yardstick separates stimuli `b` and `c`.
fn separated_b_c(fb: &[f64], studies: u64, category_width: f64) -> u32 {
    let p = protocol(fb);
    let m = fb_map(fb);
    let mut separated = 0;
    for seed in 0..studies {
        let a = analyze(&study(&p, &m, 5, 10_000 + seed, category_width), None).unwrap();
        let y5 = a
            .yardstick
            .iter()
            .find(|y| (y.alpha - 0.05).abs() < 1e-12)
            .unwrap();
        if y5
            .separated
            .iter()
            .any(|(x, y)| (x == "b" && y == "c") || (x == "c" && y == "b"))
        {
            separated += 1;
        }
    }
    separated
}

#[test]
fn the_5_percent_yardstick_separates_indistinguishable_stimuli_in_at_most_5_percent() {
    // b and c are the same stimulus to the observer (80 Hz both); a grade spans 3 noise SDs,
    // so the judgments stay within the five grades (docs/experiment.md, "Planning a study").
    let studies = 400;
    let separated = separated_b_c(&[20.0, 80.0, 80.0, 200.0], studies, 3.0);
    // At most 5 %: 20 of 400, plus the binomial margin (one-sided 95 %: 1.645 √(400·0.05·0.95)
    // = 7.2), so 27.
    println!(
        "the 5 % yardstick separated b and c in {separated} of {studies} studies (grade = 3 SD)"
    );
    assert!(separated <= 27, "{separated} of {studies}");
    // The figure docs/experiment.md publishes (seeded: the same studies every run).
    assert_eq!(separated, 11, "docs/experiment.md says 11 of 400");
}

/// Where the method breaks: when most judgments sit at the ends of the grade scale (a grade
/// of one noise SD, neighbours several grades apart), the clipped comparisons have no
/// variance, the pooled error underestimates that of the unclipped pair, and the yardstick
/// separates indistinguishable stimuli in about twice its 5 % (39 of 400 measured). Asserted so
/// the docs' warning stays true: above 5 % plus the margin.
#[test]
fn saturated_grades_make_the_yardstick_anticonservative() {
    let studies = 400;
    let separated = separated_b_c(&[20.0, 80.0, 80.0, 200.0], studies, 1.0);
    println!(
        "the 5 % yardstick separated b and c in {separated} of {studies} studies (grade = 1 SD)"
    );
    assert!(separated > 27, "{separated} of {studies}");
    assert_eq!(separated, 39, "docs/experiment.md says 39 of 400");
}
