//! The fuzz corpora (`fuzz/corpus/<target>/`, kept in the repository) replayed through the same
//! entry points the fuzz targets call (`saw_link::testing`), on the stable toolchain: every
//! input a fuzzer ever kept is answered without a panic, on every `cargo test`. A `scene_struct`
//! input is the fuzzer's choices: it is replayed as the TOML text they build, read as
//! `scene_file` reads a file.
//!
//! `cargo test -p saw-link --test fuzz_corpus -- --ignored write_the_seed_inputs` (re)writes the
//! seed inputs: every request kind framed as the host sends it, through both doors of
//! `link_bytes`, and the repository's scene files.

use std::path::{Path, PathBuf};

use saw_link::frame::{self, Receiver, MAX_ENCODED};
use saw_link::msg::{Header, PROTOCOL_VERSION};
use saw_link::testing::{link_bytes, scene_file_bytes, scene_struct_bytes, scene_toml};

fn corpus(target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../fuzz/corpus")
        .join(target)
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

fn seed() {
    let dir = corpus("link_bytes");
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
    let dir = corpus("scene_file");
    std::fs::create_dir_all(&dir).unwrap();
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for e in std::fs::read_dir(scenes).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap().to_string_lossy().to_string();
        // A seed must load (`every_scene_file_input_kept_is_read`), and the target reads 1D
        // scenes: issue #36's `scenes/2d-*.toml` are not seeds.
        let text = std::fs::read_to_string(&p).unwrap();
        let sensor = saw_core::scene_file::sensor_of(&name, &text);
        if sensor != Ok(saw_core::scene_file::SensorKind::Rheostat) {
            continue;
        }
        std::fs::copy(&p, dir.join(format!("seed-{name}"))).unwrap();
    }
}

#[test]
#[ignore = "writes fuzz/corpus: run by hand when the requests or the scenes change"]
fn write_the_seed_inputs() {
    seed();
}

#[test]
fn every_link_input_kept_is_answered() {
    let all = inputs("link_bytes");
    assert!(all.len() >= 18, "{} inputs", all.len());
    let mut answered = 0;
    for (p, bytes) in &all {
        let fed = link_bytes(bytes);
        answered += fed.replies;
        // A seed is one whole request: exactly one reply, and not an error.
        if p.file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("seed-")
        {
            assert_eq!((fed.replies, fed.refused), (1, 0), "{}", p.display());
        }
    }
    assert!(answered as usize >= all.len() / 2, "{answered} replies");
}

#[test]
fn every_scene_file_input_kept_is_read() {
    let all = inputs("scene_file");
    let accepted = all.iter().filter(|(_, b)| scene_file_bytes(b)).count();
    // The repository's scenes are among them, and they load.
    for (p, b) in &all {
        if p.file_name()
            .unwrap()
            .to_string_lossy()
            .starts_with("seed-")
        {
            assert!(scene_file_bytes(b), "{}", p.display());
        }
    }
    assert!(accepted >= 5, "{accepted} of {} accepted", all.len());
}

#[test]
fn every_scene_struct_input_kept_is_read() {
    let all = inputs("scene_struct");
    assert!(all.len() >= 100, "{} inputs", all.len());
    let accepted = all.iter().filter(|(_, b)| scene_struct_bytes(b)).count();
    // The corpus keeps what reached new code, past the reader into the controller's checks:
    // many of its scenes are accepted, and among them the shapes the planted panics need.
    assert!(
        accepted >= all.len() / 10,
        "{accepted} of {} accepted",
        all.len()
    );
    let read = |b: &[u8]| {
        saw_core::scene_file::load_for_board(
            "s.toml",
            &scene_toml(b),
            saw_link::testing::TIMER,
            100,
        )
    };
    let six_lines = all
        .iter()
        .filter_map(|(_, b)| read(b).ok())
        .filter(|c| c.scene.lines.positions_um.len() >= 6)
        .count();
    assert!(six_lines >= 1, "no accepted scene with 6 or more lines");
}
