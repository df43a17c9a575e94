//! `host-sim soak --plane`: a short plane soak keeps every rule and does what it says (2D scenes,
//! every finger move and touch fault, lift-offs, edge pulses, reloads, refusals); each defect
//! planted in the harness is caught under its rule, with a line that reruns its episode alone;
//! the checksum is the seed's whatever the thread count; the core's µs wrap is crossed.

use host_sim::soak::{self, Plant, Rule, SoakOptions, Summary, EPISODE_SAMPLES};

fn soak(seed: u64, from: u64, samples: u64, threads: usize, plant: Plant) -> Summary {
    soak::run(&SoakOptions {
        seed,
        from,
        samples,
        threads: Some(threads),
        plant,
        plane: true,
    })
}

/// 2 × 10^5 frames on each of three seeds: no violation, and every kind of move, fault and
/// event happened.
#[test]
fn a_short_plane_soak_keeps_every_rule() {
    let mut kinds = std::collections::BTreeMap::new();
    for seed in [1, 2, 0xC0FFEE] {
        let s = soak(seed, 0, 200_000, 2, Plant::None);
        eprint!("{}", soak::render(&s));
        assert_eq!(s.violations, 0, "seed {seed}: {:#?}", s.found);
        assert!(s.plane && s.samples == 200_000);
        assert!(s.pulses > 1_000, "seed {seed}: {} pulses", s.pulses);
        assert!(
            s.edge_pulses > 100,
            "seed {seed}: {} edge pulses",
            s.edge_pulses
        );
        assert!(s.ridge_pulses > 0 && s.lifts > 20, "seed {seed}");
        for (kind, n) in s.faults.iter().chain(&s.moves) {
            *kinds.entry(*kind).or_insert(0) += n;
        }
        assert!(s.off_samples > 1_000, "seed {seed}");
        assert!(
            s.reloads > 0 && s.boundary_moves > 0 && s.broken > 0,
            "seed {seed}"
        );
        assert!(s.refusal_samples > 200, "seed {seed}");
    }
    // Every fault kind and finger move, over the three seeds.
    assert_eq!(kinds.len(), 15);
    for (kind, n) in kinds {
        assert!(n > 0, "no {kind}");
    }
}

/// Each planted defect is caught under the rule it breaks, and the first violation's line reruns
/// its episode alone (with `--plane`) and finds the same violation at the same sample.
#[test]
fn planted_defects_are_caught_and_reproduce() {
    let cases = [
        (Plant::CarrierOnLift, Rule::OnWhileLifted),
        (Plant::CarrierOnFault, Rule::OnDuringFault),
        (Plant::DutyCap, Rule::Duty),
        (Plant::DoubledPulse, Rule::Doubled),
        (Plant::ResetOnRefusal, Rule::RefusalChangedScene),
    ];
    for (plant, rule) in cases {
        let s = soak(7, 0, 300_000, 2, plant);
        assert!(
            s.by_rule[rule.name()] > 0,
            "{plant:?}: no {rule:?}: {:?}",
            s.by_rule
        );
        let f = s
            .found
            .iter()
            .find(|f| f.violation.rule == rule)
            .unwrap_or(&s.found[0]);
        eprintln!(
            "{plant:?}: {} at sample {}: {}\n  {}",
            f.violation.rule.name(),
            f.violation.sample,
            f.violation.detail,
            f.reproduce
        );
        let from = f.episode * EPISODE_SAMPLES;
        assert!(
            f.reproduce
                .starts_with(&format!("host-sim soak --plane --seed 7 --from {from} ")),
            "{}",
            f.reproduce
        );
        let again = soak(7, from, EPISODE_SAMPLES, 1, plant);
        assert!(
            again.found.iter().any(|g| g.violation == f.violation),
            "{plant:?}: rerun of episode {} found {:#?}",
            f.episode,
            again.found
        );
    }
}

/// One thread or two, the same checksum and counts; another seed another checksum; the plane's
/// episodes are not the 1D soak's.
#[test]
fn plane_checksum_follows_the_seed() {
    let a = soak(3, 0, 60_000, 1, Plant::None);
    let b = soak(3, 0, 60_000, 2, Plant::None);
    let c = soak(4, 0, 60_000, 2, Plant::None);
    assert_eq!(a.checksum, b.checksum);
    assert_eq!(
        (a.pulses, a.edge_pulses, a.faults_total),
        (b.pulses, b.edge_pulses, b.faults_total)
    );
    assert_ne!(a.checksum, c.checksum);
    let one_d = soak::run(&SoakOptions {
        seed: 3,
        from: 0,
        samples: 60_000,
        threads: Some(2),
        plant: Plant::None,
        plane: false,
    });
    assert_ne!(a.checksum, one_d.checksum);
}

/// Episodes around 2^32 µs of each board's frame period: the core's clock wraps inside one of
/// them with a live scene, and every rule holds.
#[test]
fn the_microsecond_wrap_is_crossed_in_2d() {
    let (mut wraps, mut violations) = (0, 0);
    for board in saw_boards::ALL.iter() {
        let p = host_sim::sim2d::board_frame_period_us(board).expect("a frame period") as u64;
        let e = (1u64 << 32) / p / EPISODE_SAMPLES;
        let s = soak(5, e * EPISODE_SAMPLES, EPISODE_SAMPLES, 2, Plant::None);
        wraps += s.wraps_in_episode;
        violations += s.violations;
    }
    assert!(wraps >= 1);
    assert_eq!(violations, 0);
}
