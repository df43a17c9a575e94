//! Scheffé's paired comparisons and their variants (`saw_experiment::analysis::paired`) against
//! published worked examples, hand-computed cases and the invariants every variant keeps.
//!
//! Published examples with data and printed results were found for Ura's and Nakaya's variants
//! (below, each cited); the expected values are copied from them as printed, never computed by our
//! code. None with data was found for Scheffé's original design or Haga's variant: those are held
//! to small cases computed by hand (the arithmetic is in the comments), to the sums of squares they
//! share with the published Ura and Nakaya examples on the same data, and to the invariants.

use saw_experiment::analysis::paired::{
    analyze, infer_variant, AnovaRow, Judgment, PairedAnalysis, PairedError, Source, Variant,
};

fn judgment(subject: &str, first: &str, second: &str, score: f64) -> Judgment {
    Judgment {
        subject: subject.to_string(),
        first: first.to_string(),
        second: second.to_string(),
        score,
    }
}

/// |ours − printed| within half a unit of the printed value's last digit.
fn assert_printed(what: &str, ours: f64, printed: &str) {
    let decimals = printed.split('.').nth(1).map_or(0, str::len);
    let half_unit = 0.5 * 10f64.powi(-(decimals as i32));
    let expected: f64 = printed.parse().unwrap();
    assert!(
        (ours - expected).abs() <= half_unit,
        "{what}: ours {ours}, printed {printed}"
    );
}

fn row(analysis: &PairedAnalysis, source: Source) -> &AnovaRow {
    analysis
        .anova
        .iter()
        .find(|r| r.source == source)
        .unwrap_or_else(|| panic!("no {source:?} row"))
}

fn sources(analysis: &PairedAnalysis) -> Vec<Source> {
    analysis.anova.iter().map(|r| r.source).collect()
}

/// A printed ANOVA line: source, SS, df, MS, F, p (the last three absent for error and total).
type PrintedRow = (
    Source,
    &'static str,
    f64,
    Option<&'static str>,
    Option<&'static str>,
    Option<&'static str>,
);

fn assert_anova(analysis: &PairedAnalysis, printed: &[PrintedRow]) {
    assert_eq!(
        sources(analysis),
        printed.iter().map(|r| r.0).collect::<Vec<_>>()
    );
    for &(source, ss, df, ms, f, p) in printed {
        let r = row(analysis, source);
        assert_printed(&format!("SS {source:?}"), r.ss, ss);
        assert_eq!(r.df, df, "df {source:?}");
        for (what, ours, printed) in [("MS", r.ms, ms), ("F", r.f, f), ("p", r.p, p)] {
            match printed {
                Some(printed) => {
                    let ours = ours.unwrap_or_else(|| panic!("{what} {source:?} missing"));
                    assert_printed(&format!("{what} {source:?}"), ours, printed);
                }
                None => {
                    if source == Source::Total {
                        assert_eq!(ours, None, "{what} {source:?}");
                    }
                }
            }
        }
    }
}

fn yardstick_y(analysis: &PairedAnalysis, alpha: f64) -> f64 {
    analysis
        .yardstick
        .iter()
        .find(|y| y.alpha == alpha)
        .map(|y| y.y)
        .unwrap_or_else(|| panic!("no yardstick at {alpha}"))
}

fn separated(analysis: &PairedAnalysis, alpha: f64) -> Vec<(String, String)> {
    analysis
        .yardstick
        .iter()
        .find(|y| y.alpha == alpha)
        .unwrap()
        .separated
        .clone()
}

fn pairs(list: &[(&str, &str)]) -> Vec<(String, String)> {
    list.iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect()
}

/// Ura's variant, worked example: 3 stimuli, 3 subjects, every ordered pair once, published by
/// MARUI Atsushi, 「シェッフェの一対比較法(浦の変法)」 (2 Sep 2012),
/// https://marui.hatenablog.com/entry/20120902/1346556118 — his R implementation of 佐藤信
/// 『統計的官能検査法』 (日科技連, 1985), ch. 19 (code also at
/// http://www.geidai.ac.jp/~marui/r_program/scheffe_ura.html). Data: per subject, the pairs
/// 1-2, 1-3, 2-1, 2-3, 3-1, 3-2 (first presented first).
fn ura_example() -> Vec<Judgment> {
    let order = [
        ("1", "2"),
        ("1", "3"),
        ("2", "1"),
        ("2", "3"),
        ("3", "1"),
        ("3", "2"),
    ];
    let data = [
        [-2.0, -1.0, 3.0, 1.0, 0.0, -2.0],
        [-2.0, -2.0, 1.0, 2.0, -1.0, -2.0],
        [-3.0, 0.0, 3.0, 3.0, 1.0, 0.0],
    ];
    let mut judgments = Vec::new();
    for (k, scores) in data.iter().enumerate() {
        for (&(first, second), &score) in order.iter().zip(scores) {
            judgments.push(judgment(&format!("s{}", k + 1), first, second, score));
        }
    }
    judgments
}

/// Nakaya's variant, worked example: 3 stimuli, 6 subjects, every unordered pair once, published
/// by MARUI Atsushi, 「シェッフェの一対比較法(中屋の変法)」 (12 Sep 2012),
/// https://marui.hatenablog.com/entry/20120912/1347435796 — his R implementation of 佐藤信
/// 『統計的官能検査法』 (日科技連, 1985), ch. 20 (code also at
/// https://www.geidai.ac.jp/~marui/r_program/scheffe_nakaya.html). Data: per subject, the pairs
/// 1-2, 1-3, 2-3.
fn nakaya_example() -> Vec<Judgment> {
    let order = [("1", "2"), ("1", "3"), ("2", "3")];
    let data = [
        [-2.0, -1.0, 1.0],
        [-2.0, -2.0, 2.0],
        [-3.0, 0.0, 3.0],
        [-3.0, 0.0, 2.0],
        [-1.0, 1.0, 2.0],
        [-3.0, -1.0, 0.0],
    ];
    let mut judgments = Vec::new();
    for (k, scores) in data.iter().enumerate() {
        for (&(first, second), &score) in order.iter().zip(scores) {
            judgments.push(judgment(&format!("s{}", k + 1), first, second, score));
        }
    }
    judgments
}

#[test]
fn ura_matches_the_published_example_to_its_printed_digits() {
    let judgments = ura_example();
    assert_eq!(infer_variant(&judgments), Ok(Variant::Ura));
    let a = analyze(&judgments, None).unwrap();
    assert_eq!(a.variant, Variant::Ura);
    assert_eq!(a.stimuli, ["1", "2", "3"]);
    assert_eq!(a.replications, 3);
    // "Average Preferences"
    for (ours, printed) in a.scale.iter().zip(["-0.9444", "1.3333", "-0.3889"]) {
        assert_printed("α̂", *ours, printed);
    }
    // "ANOVA Table"
    assert_anova(
        &a,
        &[
            (
                Source::MainEffect,
                "50.7778",
                2.0,
                Some("25.3889"),
                Some("27.2836"),
                Some("0.0003"),
            ),
            (
                Source::MainBySubject,
                "1.2222",
                4.0,
                Some("0.3056"),
                Some("0.3284"),
                Some("0.8515"),
            ),
            (
                Source::Combination,
                "0.0556",
                1.0,
                Some("0.0556"),
                Some("0.0597"),
                Some("0.8131"),
            ),
            (
                Source::Order,
                "0.0556",
                1.0,
                Some("0.0556"),
                Some("0.0597"),
                Some("0.8131"),
            ),
            (
                Source::OrderBySubject,
                "5.4444",
                2.0,
                Some("2.7222"),
                Some("2.9254"),
                Some("0.1113"),
            ),
            (Source::Error, "7.4444", 8.0, Some("0.9306"), None, None),
            (Source::Total, "65.0000", 18.0, None, None, None),
        ],
    );
    assert_printed("Y(0.05)", yardstick_y(&a, 0.05), "0.9188");
    assert_printed("Y(0.01)", yardstick_y(&a, 0.01), "1.2813");
    // "Confidence Interval": the intervals for a1−a2 and a2−a3 exclude 0 at 95 % and 99 %, the
    // one for a1−a3 (−1.4744, 0.3633; −1.8369, 0.7258) does not.
    let expected = pairs(&[("2", "1"), ("2", "3")]);
    assert_eq!(separated(&a, 0.05), expected);
    assert_eq!(separated(&a, 0.01), expected);
    // The order effect the data show: Σx / (t (t − 1) N) = −1 / 18, whose square × 18 is the
    // printed S_δ = 0.0556 (the example prints the sum of squares only).
    assert!((a.order_effect.unwrap() + 1.0 / 18.0).abs() < 1e-12);
}

#[test]
fn nakaya_matches_the_published_example_to_its_printed_digits() {
    let judgments = nakaya_example();
    assert_eq!(infer_variant(&judgments), Ok(Variant::Nakaya));
    let a = analyze(&judgments, None).unwrap();
    assert_eq!(a.variant, Variant::Nakaya);
    assert_eq!(a.replications, 6);
    for (ours, printed) in a.scale.iter().zip(["-0.9444", "1.3333", "-0.3889"]) {
        assert_printed("α̂", *ours, printed);
    }
    assert_anova(
        &a,
        &[
            (
                Source::MainEffect,
                "50.7778",
                2.0,
                Some("25.3889"),
                Some("43.1132"),
                Some("0.0007"),
            ),
            (
                Source::MainBySubject,
                "11.2222",
                10.0,
                Some("1.1222"),
                Some("1.9057"),
                Some("0.2470"),
            ),
            (
                Source::Combination,
                "0.0556",
                1.0,
                Some("0.0556"),
                Some("0.0943"),
                Some("0.7711"),
            ),
            (Source::Error, "2.9444", 5.0, Some("0.5889"), None, None),
            (Source::Total, "65.0000", 18.0, None, None, None),
        ],
    );
    assert_printed("Y(0.05)", yardstick_y(&a, 0.05), "0.8323");
    assert_printed("Y(0.01)", yardstick_y(&a, 0.01), "1.2617");
    // Printed intervals: a1−a2 (−3.1101, −1.4454) excludes 0; so, from the printed scale values
    // and yardsticks, does a2−a3 (1.7222 > 1.2617) and a1−a3 does not (0.5556 < 0.8323).
    let expected = pairs(&[("2", "1"), ("2", "3")]);
    assert_eq!(separated(&a, 0.05), expected);
    assert_eq!(separated(&a, 0.01), expected);
    assert_eq!(a.order_effect, None);
    assert_eq!(a.subject_scales.len(), 6);
}

/// Scheffé's original design, computed by hand. 3 stimuli a, b, c; every ordered pair judged by
/// n = 2 subjects of its own (12 subjects, one judgment each):
///
/// (a,b): 2, 1   (b,a): −1, −2   (a,c): 2, 3   (c,a): −2, −1   (b,c): 2, 0   (c,b): 0, −1
///
/// d_ab = 3 − (−3) = 6, d_ac = 5 − (−3) = 8, d_bc = 2 − (−1) = 3; X_a = 14, X_b = −3, X_c = −11.
/// α̂ = X / (2 t n) = X / 12 = 7/6, −1/4, −11/12.
/// S_α = Σ X² / 12 = 326 / 12 = 27.1667 (2 df); S_γ = Σ d² / (2n) − S_α = 109/4 − 326/12 =
/// 1/12 = 0.0833 (1 df); S_δ = Σ_{i<j} (x_ij + x_ji)² / (2n) = (0 + 4 + 1) / 4 = 1.25 (3 df);
/// S_T = 33 (12 df); S_e = 33 − 27.1667 − 0.0833 − 1.25 = 4.5 (6 df), which is also the
/// within-cell sum of squares 0.5 + 0.5 + 0.5 + 0.5 + 2 + 0.5. MS_e = 0.75.
/// F_α = 13.5833 / 0.75 = 18.1111, F_γ = 0.1111, F_δ = 0.4167 / 0.75 = 0.5556.
/// δ̂ = Σx / (t (t − 1) n) = 3 / 12 = 0.25. Y = q sqrt(0.75 / 12) = q / 4.
fn scheffe_hand_case() -> Vec<Judgment> {
    let cells = [
        ("a", "b", [2.0, 1.0]),
        ("b", "a", [-1.0, -2.0]),
        ("a", "c", [2.0, 3.0]),
        ("c", "a", [-2.0, -1.0]),
        ("b", "c", [2.0, 0.0]),
        ("c", "b", [0.0, -1.0]),
    ];
    let mut judgments = Vec::new();
    for (first, second, scores) in cells {
        for (r, score) in scores.into_iter().enumerate() {
            judgments.push(judgment(
                &format!("{first}{second}{r}"),
                first,
                second,
                score,
            ));
        }
    }
    judgments
}

#[test]
fn scheffe_original_matches_the_hand_computed_case() {
    let judgments = scheffe_hand_case();
    assert_eq!(infer_variant(&judgments), Ok(Variant::Scheffe));
    let a = analyze(&judgments, None).unwrap();
    assert_eq!(a.replications, 2);
    let expected_scale = [7.0 / 6.0, -0.25, -11.0 / 12.0];
    for (ours, expected) in a.scale.iter().zip(expected_scale) {
        assert!((ours - expected).abs() < 1e-12, "{ours} vs {expected}");
    }
    assert_eq!(
        sources(&a),
        [
            Source::MainEffect,
            Source::Combination,
            Source::Order,
            Source::Error,
            Source::Total
        ]
    );
    let exact = [
        (
            Source::MainEffect,
            326.0 / 12.0,
            2.0,
            Some(326.0 / 24.0 / 0.75),
        ),
        (
            Source::Combination,
            1.0 / 12.0,
            1.0,
            Some(1.0 / 12.0 / 0.75),
        ),
        (Source::Order, 1.25, 3.0, Some(1.25 / 3.0 / 0.75)),
        (Source::Error, 4.5, 6.0, None),
        (Source::Total, 33.0, 12.0, None),
    ];
    for (source, ss, df, f) in exact {
        let r = row(&a, source);
        assert!((r.ss - ss).abs() < 1e-12, "SS {source:?}: {} vs {ss}", r.ss);
        assert_eq!(r.df, df);
        match f {
            Some(f) => assert!((r.f.unwrap() - f).abs() < 1e-9, "F {source:?}"),
            None => assert_eq!(r.f, None),
        }
    }
    assert!((a.order_effect.unwrap() - 0.25).abs() < 1e-12);
    for y in &a.yardstick {
        assert!(
            (y.y - y.q / 4.0).abs() < 1e-12,
            "Y = q sqrt(MS_e / (2 t n))"
        );
    }
}

/// Haga's variant, computed by hand. 3 stimuli; each unordered pair judged by m = 2 subjects, in
/// either order (6 subjects, one judgment each):
///
/// s1 (a,b) 2; s2 (b,a) −1; s3 (a,c) 3; s4 (a,c) 1; s5 (b,c) 1; s6 (c,b) 1
///
/// Oriented towards the first-named of each pair: ab 2, 1; ac 3, 1; bc 1, −1, so d_ab = 3,
/// d_ac = 4, d_bc = 0; X_a = 7, X_b = −3, X_c = −4; α̂ = X / (t m) = X / 6 = 7/6, −1/2, −2/3.
/// S_α = Σ X² / 6 = 74 / 6 = 12.3333 (2 df); S_γ = Σ d² / m − S_α = 25/2 − 74/6 = 1/6 (1 df);
/// S_T = 17 (6 df); S_e = 17 − 74/6 − 1/6 = 4.5 (3 df), also the within-pair sum of squares of
/// the oriented scores 0.5 + 2 + 2. MS_e = 1.5; Y = q sqrt(1.5 / 6) = q / 2.
fn haga_hand_case() -> Vec<Judgment> {
    vec![
        judgment("s1", "a", "b", 2.0),
        judgment("s2", "b", "a", -1.0),
        judgment("s3", "a", "c", 3.0),
        judgment("s4", "a", "c", 1.0),
        judgment("s5", "b", "c", 1.0),
        judgment("s6", "c", "b", 1.0),
    ]
}

#[test]
fn haga_matches_the_hand_computed_case() {
    let judgments = haga_hand_case();
    assert_eq!(infer_variant(&judgments), Ok(Variant::Haga));
    let a = analyze(&judgments, None).unwrap();
    assert_eq!(a.replications, 2);
    for (ours, expected) in a.scale.iter().zip([7.0 / 6.0, -0.5, -2.0 / 3.0]) {
        assert!((ours - expected).abs() < 1e-12, "{ours} vs {expected}");
    }
    assert_eq!(
        sources(&a),
        [
            Source::MainEffect,
            Source::Combination,
            Source::Error,
            Source::Total
        ]
    );
    for (source, ss, df) in [
        (Source::MainEffect, 74.0 / 6.0, 2.0),
        (Source::Combination, 1.0 / 6.0, 1.0),
        (Source::Error, 4.5, 3.0),
        (Source::Total, 17.0, 6.0),
    ] {
        let r = row(&a, source);
        assert!((r.ss - ss).abs() < 1e-12, "SS {source:?}: {} vs {ss}", r.ss);
        assert_eq!(r.df, df);
    }
    assert!((row(&a, Source::MainEffect).f.unwrap() - 37.0 / 6.0 / 1.5).abs() < 1e-9);
    assert_eq!(a.order_effect, None);
    for y in &a.yardstick {
        assert!((y.y - y.q / 2.0).abs() < 1e-12, "Y = q sqrt(MS_e / (t m))");
    }
}

/// Each of the published examples' judgments given to a subject of its own is a design of Scheffé's
/// (Ura's data: every ordered pair by 3) or Haga's (Nakaya's: every pair by 6). Their scale, main
/// effect and combination are the same functions of the pair totals, so they must print as the
/// published ones; Haga's error must be Nakaya's main × subject and error pooled, 11.2222 + 2.9444.
#[test]
fn scheffe_and_haga_share_the_published_pair_totals() {
    let relabel = |judgments: Vec<Judgment>| -> Vec<Judgment> {
        judgments
            .into_iter()
            .enumerate()
            .map(|(r, j)| Judgment {
                subject: format!("judge{r}"),
                ..j
            })
            .collect()
    };
    let scheffe = analyze(&relabel(ura_example()), None).unwrap();
    let haga = analyze(&relabel(nakaya_example()), None).unwrap();
    assert_eq!(scheffe.variant, Variant::Scheffe);
    assert_eq!(haga.variant, Variant::Haga);
    for a in [&scheffe, &haga] {
        for (ours, printed) in a.scale.iter().zip(["-0.9444", "1.3333", "-0.3889"]) {
            assert_printed("α̂", *ours, printed);
        }
        assert_printed("S_α", row(a, Source::MainEffect).ss, "50.7778");
        assert_printed("S_γ", row(a, Source::Combination).ss, "0.0556");
        assert_printed("S_T", row(a, Source::Total).ss, "65.0000");
    }
    let pooled = row(&haga, Source::Error).ss;
    assert!((pooled - (11.2222 + 2.9444)).abs() <= 1e-4, "{pooled}");
    assert_eq!(row(&haga, Source::Error).df, 15.0);
}

/// The invariants every variant keeps, on each variant's example.
#[test]
fn every_variant_keeps_the_invariants() {
    for (variant, judgments) in [
        (Variant::Scheffe, scheffe_hand_case()),
        (Variant::Haga, haga_hand_case()),
        (Variant::Ura, ura_example()),
        (Variant::Nakaya, nakaya_example()),
    ] {
        let a = analyze(&judgments, Some(variant)).unwrap();
        // The scale sums to 0.
        assert!(
            a.scale.iter().sum::<f64>().abs() < 1e-12,
            "{variant:?} scale sum"
        );
        // The components add up to the total, in sums of squares and degrees of freedom.
        let parts = &a.anova[..a.anova.len() - 1];
        let total = row(&a, Source::Total);
        let ss: f64 = parts.iter().map(|r| r.ss).sum();
        let df: f64 = parts.iter().map(|r| r.df).sum();
        assert!(
            (ss - total.ss).abs() < 1e-9,
            "{variant:?}: Σ SS {ss} vs {}",
            total.ss
        );
        assert_eq!(df, total.df, "{variant:?} df");

        // Swapping first and second and negating the score says the same thing.
        let swapped: Vec<Judgment> = judgments
            .iter()
            .map(|j| Judgment {
                first: j.second.clone(),
                second: j.first.clone(),
                score: -j.score,
                ..j.clone()
            })
            .collect();
        let b = analyze(&swapped, Some(variant)).unwrap();
        for name in &a.stimuli {
            let at =
                |x: &PairedAnalysis| x.scale[x.stimuli.iter().position(|s| s == name).unwrap()];
            assert!(
                (at(&a) - at(&b)).abs() < 1e-12,
                "{variant:?} swapped scale of {name}"
            );
        }
        for (ra, rb) in a.anova.iter().zip(&b.anova) {
            assert!(
                (ra.ss - rb.ss).abs() < 1e-9,
                "{variant:?} swapped SS {:?}",
                ra.source
            );
        }
        // The order effect, where there is one, changes sign: the first is now the second.
        if let (Some(da), Some(db)) = (a.order_effect, b.order_effect) {
            assert!((da + db).abs() < 1e-12, "{variant:?} order effect");
        }

        // A design where every judgment is 0: scale 0, nothing to test.
        let zeros: Vec<Judgment> = judgments
            .iter()
            .map(|j| Judgment {
                score: 0.0,
                ..j.clone()
            })
            .collect();
        let z = analyze(&zeros, Some(variant)).unwrap();
        assert!(z.scale.iter().all(|&s| s == 0.0), "{variant:?} zero scale");
        assert!(
            z.anova.iter().all(|r| r.ss == 0.0 && r.f.is_none()),
            "{variant:?} zero ANOVA"
        );
        assert!(z
            .yardstick
            .iter()
            .all(|y| y.y == 0.0 && y.separated.is_empty()));
    }
}

/// The seed paper's design: 4 stimuli, 5 subjects, each judging every ordered pair (12 judgments
/// each). A fabricated data set with a clear ordering: the grade is the difference of the true
/// roughnesses, plus an order bias and seeded noise, rounded and clipped to ±3.
#[test]
fn seed_design_is_inferred_as_ura_and_recovers_a_clear_ordering() {
    use rand::{Rng, SeedableRng};
    let stimuli = ["20 Hz", "40 Hz", "80 Hz", "160 Hz"];
    let roughness = [-1.5, -0.5, 0.5, 1.5];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(34);
    let mut judgments = Vec::new();
    for subject in 1..=5 {
        for (i, first) in stimuli.iter().enumerate() {
            for (j, second) in stimuli.iter().enumerate() {
                if i == j {
                    continue;
                }
                let noise: f64 = rng.random_range(-0.8..0.8);
                let grade = (roughness[i] - roughness[j] + 0.3 + noise)
                    .round()
                    .clamp(-3.0, 3.0);
                judgments.push(judgment(&format!("s{subject}"), first, second, grade));
            }
        }
    }
    assert_eq!(judgments.len(), 60);
    assert_eq!(infer_variant(&judgments), Ok(Variant::Ura));
    let a = analyze(&judgments, None).unwrap();
    assert_eq!(a.variant, Variant::Ura);
    assert_eq!(a.stimuli, stimuli);
    assert!(
        a.scale.windows(2).all(|w| w[0] < w[1]),
        "scale {:?}",
        a.scale
    );
    assert_eq!(a.subjects.len(), 5);
    // The bias was positive: the first presented judged rougher.
    assert!(a.order_effect.unwrap() > 0.0);
    // Neighbours 1 unit of roughness apart are well beyond the yardstick at 1 %.
    assert_eq!(separated(&a, 0.01).len(), 6);
    assert!(row(&a, Source::MainEffect).p.unwrap() < 1e-6);
}

#[test]
fn refusals_are_sentences_naming_what_is_wrong() {
    assert_eq!(analyze(&[], None).unwrap_err(), PairedError::NoJudgments);
    assert_eq!(
        analyze(&[], None).unwrap_err().to_string(),
        "there are no judgments to analyse"
    );

    let mut self_compared = haga_hand_case();
    self_compared[2].second = "a".to_string();
    assert_eq!(
        analyze(&self_compared, None).unwrap_err().to_string(),
        "stimulus \"a\" is compared with itself in row 3"
    );

    let mut nan = haga_hand_case();
    nan[1].score = f64::NAN;
    assert_eq!(
        analyze(&nan, None).unwrap_err().to_string(),
        "the score in row 2 is NaN, not a number of grades"
    );

    let mut unnamed = haga_hand_case();
    unnamed[4].subject.clear();
    assert_eq!(
        analyze(&unnamed, None).unwrap_err().to_string(),
        "the subject name in row 5 is empty"
    );

    // Ura's data analysed by Nakaya's variant: each subject judged each pair in both orders.
    assert_eq!(
        analyze(&ura_example(), Some(Variant::Nakaya))
            .unwrap_err()
            .to_string(),
        "subject s1 judged pair (1, 2) twice, which Nakaya's variant does not allow"
    );

    // Nakaya's data analysed by Ura's variant: the reversed orders are missing.
    assert_eq!(
        analyze(&nakaya_example(), Some(Variant::Ura))
            .unwrap_err()
            .to_string(),
        "the design is unbalanced: subject s1 did not judge (2, 1), and Ura's variant needs \
         every ordered pair from every subject"
    );

    // One judgment missing from Ura's data: neither Ura's nor Nakaya's design.
    let mut short = ura_example();
    short.remove(7);
    let error = infer_variant(&short).unwrap_err();
    assert!(matches!(error, PairedError::Unbalanced { .. }), "{error:?}");
    assert!(error
        .to_string()
        .starts_with("the design is unbalanced: subject s2 did not judge"));

    // A pair judged more often than the others in a one-judgment-per-subject design.
    let mut extra = haga_hand_case();
    extra.push(judgment("s7", "a", "b", 1.0));
    assert_eq!(
        infer_variant(&extra).unwrap_err().to_string(),
        "the design is unbalanced: pair (a, b) was judged 3 times and (a, c) twice, but Haga's \
         variant needs every pair judged equally often"
    );

    // Scheffé's design forced on subjects who judged several pairs.
    assert_eq!(
        analyze(&ura_example(), Some(Variant::Scheffe))
            .unwrap_err()
            .to_string(),
        "the design is unbalanced: subject s1 made 6 judgments, but in Scheffé's original design \
         each subject judges one pair (Ura's and Nakaya's variants take subjects who judge every \
         pair)"
    );
}

#[test]
fn lines_without_degrees_of_freedom_have_no_test() {
    // Ura's variant from one subject: main × subject and order × subject have no df.
    let one: Vec<Judgment> = ura_example()
        .into_iter()
        .filter(|j| j.subject == "s1")
        .collect();
    let a = analyze(&one, None).unwrap();
    assert_eq!(a.variant, Variant::Ura);
    for source in [Source::MainBySubject, Source::OrderBySubject] {
        let r = row(&a, source);
        assert_eq!(
            (r.df, r.ms, r.f, r.p),
            (0.0, None, None, None),
            "{source:?}"
        );
    }
    // t (t − 1) − (t − 1) − (t − 1)(t − 2)/2 − 1 = 2 df left for the error, so the main effect
    // is tested.
    assert_eq!(row(&a, Source::Error).df, 2.0);
    assert!(row(&a, Source::MainEffect).f.is_some());

    // Nakaya's variant from one subject: the error has no df, nothing is tested, no yardstick.
    let one: Vec<Judgment> = nakaya_example()
        .into_iter()
        .filter(|j| j.subject == "s1")
        .collect();
    let a = analyze(&one, Some(Variant::Nakaya)).unwrap();
    assert_eq!(row(&a, Source::Error).df, 0.0);
    assert_eq!(row(&a, Source::Error).ms, None);
    assert!(a.anova.iter().all(|r| r.f.is_none() && r.p.is_none()));
    assert!(a.yardstick.is_empty());
}

#[test]
fn results_serialise_as_data() {
    let a = analyze(&ura_example(), None).unwrap();
    let json = serde_json::to_value(&a).unwrap();
    assert_eq!(json["variant"], "ura");
    assert_eq!(json["anova"][0]["source"], "main_effect");
    assert_eq!(json["anova"][6]["ms"], serde_json::Value::Null);
    assert_eq!(json["yardstick"][0]["alpha"], 0.05);
}

/// Arbitrary judgments — any names, repeats, missing pairs, self comparisons, NaN and huge
/// scores — are analysed or refused, never a panic.
#[test]
fn arbitrary_judgments_never_panic() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let names = ["a", "b", "c", ""];
    for _ in 0..300 {
        let rows = rng.random_range(0..14);
        let judgments: Vec<Judgment> = (0..rows)
            .map(|_| {
                let score = match rng.random_range(0..20) {
                    0 => f64::NAN,
                    1 => 1e300,
                    _ => f64::from(rng.random_range(-3..=3)),
                };
                judgment(
                    ["s1", "s2", "s3", ""][rng.random_range(0..4)],
                    names[rng.random_range(0..4)],
                    names[rng.random_range(0..4)],
                    score,
                )
            })
            .collect();
        let _ = infer_variant(&judgments);
        for variant in [
            None,
            Some(Variant::Scheffe),
            Some(Variant::Haga),
            Some(Variant::Ura),
            Some(Variant::Nakaya),
        ] {
            if let Err(e) = analyze(&judgments, variant) {
                assert!(!e.to_string().is_empty());
            }
        }
    }
}
