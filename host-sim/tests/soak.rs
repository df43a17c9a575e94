//! `host-sim soak`: a short soak keeps every rule; each defect planted in the harness (a port
//! that ignores the duty cap, one that keeps the carrier on through a sensor fault, one that
//! restarts the counter on every update, a device that resets its scene on a refused upload) is
//! caught with the seed and sample that reproduce it, and rerunning the episode named reproduces
//! it; the checksum is the seed's, whatever the thread count.

use host_sim::soak::{self, Plant, Rule, SoakOptions, Summary, EPISODE_SAMPLES};

fn soak(seed: u64, from: u64, samples: u64, threads: usize, plant: Plant) -> Summary {
    soak::run(&SoakOptions {
        seed,
        from,
        samples,
        threads: Some(threads),
        plant,
        plane: false,
    })
}

/// 2 × 10^5 samples on each of three seeds: no violation, and the soak did what it says (pulses,
/// every fault kind, reloads, boundary moves, refusals compared).
#[test]
fn a_short_soak_keeps_every_rule() {
    for seed in [1, 2, 0xC0FFEE] {
        let s = soak(seed, 0, 200_000, 2, Plant::None);
        eprint!("{}", soak::render(&s));
        assert_eq!(s.violations, 0, "seed {seed}: {:#?}", s.found);
        assert_eq!(s.samples, 200_000);
        assert!(s.pulses > 500, "seed {seed}: {} pulses", s.pulses);
        for (kind, n) in &s.faults {
            assert!(*n > 0, "seed {seed}: no {kind} fault injected");
        }
        assert!(s.off_samples > 100, "seed {seed}");
        assert!(
            s.reloads > 0 && s.boundary_moves > 0 && s.broken > 0,
            "seed {seed}"
        );
        assert!(s.refusal_samples > 200, "seed {seed}");
    }
}

/// Each planted defect is caught, under the rule it breaks, and the line printed with it reruns
/// its episode alone and finds the same violation at the same sample.
#[test]
fn planted_defects_are_caught_and_reproduce() {
    let cases = [
        (Plant::DutyCap, Rule::Duty),
        (Plant::CarrierOnFault, Rule::OnDuringFault),
        (Plant::DoubledPulse, Rule::Doubled),
        (Plant::ResetOnRefusal, Rule::RefusalChangedScene),
    ];
    for (plant, rule) in cases {
        let s = soak(7, 0, 300_000, 2, plant);
        assert!(s.violations > 0, "{plant:?} not caught");
        // Counted under its rule (the first 20 printed may all be of other rules: with the
        // duty windows reaching back before an episode's start judged at their full length,
        // `duty-cap`'s first 20 are runts and on-times).
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
        // The line names the seed, the episode's first sample and the plant.
        let from = f.episode * EPISODE_SAMPLES;
        assert!(f.reproduce.contains("--seed 7 "), "{}", f.reproduce);
        assert!(
            f.reproduce.contains(&format!("--from {from} ")),
            "{}",
            f.reproduce
        );
        assert!(f.violation.sample >= from && f.violation.sample < from + EPISODE_SAMPLES);
        // Its episode alone, one thread: the same violation at the same sample.
        let again = soak(7, from, EPISODE_SAMPLES, 1, plant);
        assert!(
            again.found.iter().any(|g| g.violation == f.violation),
            "{plant:?}: rerun of episode {} found {:#?}",
            f.episode,
            again.found
        );
    }
}

/// The same seed gives the same checksum (and counts) on one thread or two; another seed
/// another checksum; a sub-range reruns its episodes' results exactly.
#[test]
fn checksum_follows_the_seed() {
    let a = soak(3, 0, 60_000, 1, Plant::None);
    let b = soak(3, 0, 60_000, 2, Plant::None);
    let c = soak(4, 0, 60_000, 2, Plant::None);
    assert_eq!(a.checksum, b.checksum);
    assert_eq!((a.pulses, a.faults_total), (b.pulses, b.faults_total));
    assert_ne!(a.checksum, c.checksum);
    // Episodes 3..6 of seed 3 run by themselves: the same pulses as inside the whole run.
    let whole = soak(3, 30_000, 30_000, 2, Plant::None);
    let parts: u64 = (3..6)
        .map(|e| soak(3, e * EPISODE_SAMPLES, EPISODE_SAMPLES, 1, Plant::None).pulses)
        .sum();
    assert_eq!(whole.pulses, parts);
}

/// The soak crosses the core's µs wrap: an episode around 2^32 µs (global sample 42 949 672)
/// runs with the wrap inside it and keeps every rule.
#[test]
fn the_microsecond_wrap_is_crossed() {
    let from = (1u64 << 32) / 100 / EPISODE_SAMPLES * EPISODE_SAMPLES;
    let s = soak(5, from, 3 * EPISODE_SAMPLES, 2, Plant::None);
    assert_eq!(s.wraps, 1);
    assert_eq!(s.wraps_in_episode, 1);
    assert_eq!(s.violations, 0, "{:#?}", s.found);
}
