//! The files a `host-sim serve` leaves and takes, with the binary itself: its `--pty` link (and
//! the lock beside it) gone after SIGTERM or SIGINT, a second board refused on a live link
//! (naming the first's pid) and on a flash file another board holds (naming the file), each
//! with one line and exit code 2.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

const EXE: &str = env!("CARGO_BIN_EXE_host-sim");

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "host-sim-serve-files-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `host-sim serve --pty LINK` plus `extra`, for at most 60 s; returns once the link is there.
fn serve(link: &Path, extra: &[&str]) -> Child {
    let mut child = Command::new(EXE)
        .args(["serve", "--pty", link.to_str().unwrap(), "--seconds", "60"])
        .args(extra)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let give_up = Instant::now() + Duration::from_secs(20);
    while std::fs::symlink_metadata(link).is_err() {
        if let Some(s) = child.try_wait().unwrap() {
            panic!("serve ended before making its link: {s}");
        }
        assert!(Instant::now() < give_up, "no link after 20 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    child
}

/// stderr without the board's log lines (`[INFO …]`: serve boots the core, which logs the
/// scene, before it opens the pty).
fn error_lines(stderr: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(stderr)
        .lines()
        .filter(|l| !l.starts_with("[INFO "))
        .map(str::to_string)
        .collect()
}

/// Waits for `child` to end (20 s at most).
fn ended(child: &mut Child) -> std::process::ExitStatus {
    let give_up = Instant::now() + Duration::from_secs(20);
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        assert!(Instant::now() < give_up, "serve did not stop");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A signalled board takes its link and lock file with it: after SIGTERM and after SIGINT the
/// path is free (before, the link stayed and pointed at a pts the next pty would reuse).
#[test]
fn a_signalled_board_removes_its_link() {
    let d = scratch("signal");
    for sig in [Signal::SIGTERM, Signal::SIGINT] {
        let link = d.join(format!("board-{sig}"));
        let mut child = serve(&link, &[]);
        assert!(d.join(format!("board-{sig}.lock")).exists());
        kill(Pid::from_raw(child.id() as i32), sig).unwrap();
        ended(&mut child);
        assert!(
            std::fs::symlink_metadata(&link).is_err(),
            "{sig}: the link outlived its board"
        );
        assert!(
            !d.join(format!("board-{sig}.lock")).exists(),
            "{sig}: the lock file outlived its board"
        );
    }
}

/// A second board on a live link, or on a flash file another board holds, is refused with one
/// line naming what is taken; the first board keeps its link.
#[test]
fn a_second_board_is_refused() {
    let d = scratch("second");
    let link = d.join("board");
    let flash = d.join("flash.bin");
    let mut first = serve(&link, &["--flash", flash.to_str().unwrap()]);
    let target = std::fs::read_link(&link).unwrap();

    let out = Command::new(EXE)
        .args(["serve", "--pty", link.to_str().unwrap(), "--seconds", "1"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert_eq!(
        error_lines(&out.stderr),
        [format!(
            "error: --pty {}: another host-sim serve (pid {}) runs a board on this link; stop it \
             or choose another path",
            link.display(),
            first.id()
        )]
    );
    assert_eq!(std::fs::read_link(&link).unwrap(), target);

    let other = d.join("other");
    let out = Command::new(EXE)
        .args(["serve", "--pty", other.to_str().unwrap(), "--seconds", "1"])
        .args(["--flash", flash.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert_eq!(
        error_lines(&out.stderr),
        [format!(
            "error: --flash {}: another host-sim serve is using this flash file; stop it or \
             choose another file",
            flash.display()
        )]
    );
    assert!(std::fs::symlink_metadata(&other).is_err());

    kill(Pid::from_raw(first.id() as i32), Signal::SIGTERM).unwrap();
    ended(&mut first);
}
