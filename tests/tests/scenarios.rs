//! Runs every `tests/scenarios/*.toml`: each file's steps through the closed loop, each file's
//! expectations checked. Adding a scenario is adding a file.

use std::path::PathBuf;

use host_sim::scenario::Scenario;

#[test]
fn every_scenario_file_meets_its_expectations() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    assert!(files.len() >= 3, "only {} scenario files", files.len());
    let mut failures = Vec::new();
    for f in &files {
        let sc = Scenario::from_file(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let (r, m) = sc.run().unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let fails = sc.check(&r, &m);
        eprintln!(
            "{:<28} {} samples, {} switches, {} fault onsets, {} pulses: {}",
            sc.name,
            m.samples,
            m.switches.len(),
            m.fault_onsets,
            m.pulses,
            if fails.is_empty() { "ok" } else { "FAIL" }
        );
        for x in fails {
            failures.push(format!("{}: {x}", f.display()));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The expectation checker can fail: a wrong region sequence and an impossible switch count on
/// the default sweep are reported.
#[test]
fn a_wrong_expectation_is_reported() {
    let text = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenarios/default_sweep.toml"),
    )
    .unwrap()
    .replace("[0, 1, 2, 1, 0, 1, 2]", "[0, 1, 2]")
    .replace("max_switches = 6", "max_switches = 5");
    let sc = Scenario::from_toml(&text).unwrap();
    let (r, m) = sc.run().unwrap();
    let fails = sc.check(&r, &m);
    assert_eq!(fails.len(), 2, "{fails:?}");
}
