//! The plane's fuzz corpora (issue #36: `fuzz/corpus/{link_bytes_2d,scene_file_2d,controller2d}/`,
//! kept in the repository) replayed through the very bodies the fuzz targets run
//! (`fuzz/bodies/plane.rs`, included here by path as the targets include it), on the stable
//! toolchain: every input a fuzzer kept passes its target's checks on every `cargo test`, as
//! `saw-link`'s `fuzz_corpus` replays the 1D corpora.
//!
//! `cargo test -p saw-tests --test fuzz_corpus_2d -- --ignored write_the_seed_inputs` (re)writes
//! the seeds of `link_bytes_2d` (every request kind through both doors) and `scene_file_2d` (the
//! shipped 2D scenes).

#[path = "../../fuzz/bodies/plane.rs"]
mod plane;

use std::path::{Path, PathBuf};

use saw_link::frame::{self, Receiver, MAX_ENCODED};
use saw_link::msg::{Header, PROTOCOL_VERSION};

fn corpus(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/corpus")
        .join(target)
}

/// Every input kept for `target`, sorted by name (an absent corpus is an empty one: a target's
/// corpus is only what its runs kept).
fn inputs(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let Ok(dir) = std::fs::read_dir(corpus(target)) else {
        return Vec::new();
    };
    let mut v: Vec<(PathBuf, Vec<u8>)> = dir
        .map(|e| e.unwrap().path())
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect();
    v.sort();
    v
}

/// Replays `target`'s corpus through `body`; a panic names the input.
fn replay(target: &str, body: impl Fn(&[u8])) -> usize {
    let all = inputs(target);
    for (path, bytes) in &all {
        let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| body(bytes)));
        if run.is_err() {
            panic!("{}: the {target} fuzz body panicked on it", path.display());
        }
    }
    all.len()
}

#[test]
fn every_link_bytes_2d_input_kept_is_answered() {
    let n = replay("link_bytes_2d", |b| {
        plane::link_bytes_2d(b);
    });
    assert!(
        n >= 28,
        "{n} inputs: the seeds are every request through both doors"
    );
    // The seeds reach the session: each frame through the odd door is one reply.
    let (_, frame) = inputs("link_bytes_2d")
        .into_iter()
        .find(|(p, _)| p.ends_with("seed-frame-0"))
        .expect("the Hello seed");
    assert_eq!(plane::link_bytes_2d(&frame).replies, 1);
}

#[test]
fn every_scene_file_2d_input_kept_is_read() {
    let n = replay("scene_file_2d", |b| {
        plane::scene_file_2d(b);
    });
    assert!(n >= 2, "{n} inputs");
    // The seeds are the shipped 2D scenes: each is accepted.
    for (path, bytes) in inputs("scene_file_2d") {
        if path
            .file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("seed-")
        {
            assert!(plane::scene_file_2d(&bytes), "{} refused", path.display());
        }
    }
}

#[test]
fn every_controller2d_input_kept_passes_its_checks() {
    replay("controller2d", plane::controller2d);
}

/// The bodies check what they claim: a refusal that changed the scene, or a reply that does not
/// encode, would panic. Shown on a frame the 2D board refuses (a 1D scene): the body answers it
/// as refused, the scene as it was.
#[test]
fn a_1d_scene_on_the_overlay_is_refused_and_changes_nothing() {
    let req = saw_link::msg::Request::LoadScene(saw_core::scene::default_config());
    let mut wire = [0u8; MAX_ENCODED];
    let h = Header {
        version: PROTOCOL_VERSION,
        seq: 7,
    };
    let n = frame::encode(&h, &req, &mut wire).unwrap();
    let mut line = vec![0u8];
    line.extend_from_slice(&wire[..n]);
    let fed = plane::link_bytes_2d(&line);
    assert_eq!((fed.replies, fed.refused), (1, 1));
}

#[test]
#[ignore = "writes fuzz/corpus: run by hand when the requests or the 2D scenes change"]
fn write_the_seed_inputs() {
    let dir = corpus("link_bytes_2d");
    std::fs::create_dir_all(&dir).unwrap();
    for (i, req) in saw_link::testing::every_request().iter().enumerate() {
        let mut wire = [0u8; MAX_ENCODED];
        let h = Header {
            version: PROTOCOL_VERSION,
            seq: i as u32,
        };
        let n = frame::encode(&h, req, &mut wire).unwrap();
        // Door 0: the line's bytes.
        let mut line = vec![0u8];
        line.extend_from_slice(&wire[..n]);
        std::fs::write(dir.join(format!("seed-line-{i}")), &line).unwrap();
        // Door 1: the frame's header and body, as the receiver hands them on.
        let mut rx = Receiver::<MAX_ENCODED>::default();
        let len = wire[..n].iter().find_map(|&b| rx.push(b)).unwrap().unwrap();
        let mut payload = vec![1u8];
        payload.extend_from_slice(rx.payload(len));
        std::fs::write(dir.join(format!("seed-frame-{i}")), &payload).unwrap();
    }
    let dir = corpus("scene_file_2d");
    std::fs::create_dir_all(&dir).unwrap();
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for e in std::fs::read_dir(scenes).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        let text = std::fs::read_to_string(&p).unwrap();
        if saw_core::scene_file::sensor_of(&name, &text)
            == Ok(saw_core::scene_file::SensorKind::FourWire)
        {
            std::fs::copy(&p, dir.join(format!("seed-{name}"))).unwrap();
        }
    }
}

/// The 2D test board (`saw_link::testing`, which the fuzz bodies and the session tests read
/// scenes for) reads at the F446's touch frame as host-sim's schedule gives it: a change to the
/// schedule (conversions, discards, margins) fails here, not as scenes compiled for a stale rate.
#[test]
fn the_test_boards_frame_is_the_f446_schedules() {
    assert_eq!(
        Some(saw_link::testing::FRAME_US),
        host_sim::sim2d::board_frame_period_us(&saw_boards::NUCLEO_F446RE)
    );
}
