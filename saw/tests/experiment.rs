//! `saw experiment` against the virtual board (`host-sim serve`): the seed paper's design run
//! end to end by simulated participants and analysed; a runner killed with SIGKILL and a board
//! pulled mid-session, then resumed: no trial lost, none twice, the order unchanged.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::VirtualBoard;
use serde_json::Value;

/// The shipped study with its virtual set only and short timing (0.2 s explorations): the
/// design as the paper ran it — 4 virtual objects, Ura's variant, 12 comparisons a subject.
fn virtual_study(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../experiments/nara-roughness.toml"),
    )
    .unwrap();
    let cut = text.find("[[block]]\nname = \"real\"").unwrap();
    let text = text[..cut]
        .replace("explore_s = 4.0", "explore_s = 0.2")
        .replace("pause_s = 1.0", "pause_s = 0.02");
    let p = dir.join("virtual.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn saw(port: Option<&Path>, args: &[&str]) -> (i32, String, String) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_saw"));
    if let Some(p) = port {
        c.arg("--port").arg(p);
    }
    let out = c.args(args).stdin(Stdio::null()).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn run_args<'a>(protocol: &'a str, subject: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "experiment",
        "run",
        protocol,
        "--subject",
        subject,
        "--out",
        out,
        "--simulate",
        "default",
    ]
}

/// The (first, second) stimuli of each trial of a session CSV, by trial number; panics on a
/// trial logged twice.
fn trials(csv: &Path) -> BTreeMap<u32, (String, String)> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| head.iter().position(|h| *h == n).unwrap();
    let (t, a, b) = (col("trial"), col("first"), col("second"));
    let mut out = BTreeMap::new();
    for l in lines {
        let f: Vec<&str> = l.split(',').collect();
        let n: u32 = f[t].parse().unwrap();
        let prev = out.insert(n, (f[a].to_string(), f[b].to_string()));
        assert!(
            prev.is_none(),
            "trial {n} logged twice in {}",
            csv.display()
        );
    }
    out
}

/// `saw experiment run` of `protocol` for `subject` into `out`, in the background.
fn spawn_run(
    port: &Path,
    protocol: &str,
    subject: &str,
    out: &str,
    stdout: Stdio,
    stderr: Stdio,
) -> Child {
    Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(port)
        .args(run_args(protocol, subject, out))
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(stderr)
        .spawn()
        .unwrap()
}

/// The order an uninterrupted session of `subject` gives (run into `dir`/whole): what a
/// resumed one must reproduce.
fn uninterrupted(
    port: &Path,
    protocol: &str,
    subject: &str,
    dir: &Path,
) -> BTreeMap<u32, (String, String)> {
    let whole = dir.join("whole");
    let (code, stdout, stderr) = saw(
        Some(port),
        &run_args(protocol, subject, &whole.display().to_string()),
    );
    assert_eq!(code, 0, "{stdout}{stderr}");
    trials(&whole.join(format!("{subject}.csv")))
}

/// Waits until `csv` holds at least `n` trials.
fn wait_for_trials(csv: &Path, n: usize, child: &mut Child) {
    let end = Instant::now() + Duration::from_secs(60);
    loop {
        if csv.exists() && trials(csv).len() >= n {
            return;
        }
        if let Ok(Some(s)) = child.try_wait() {
            panic!("the runner ended ({s}) before {n} trials");
        }
        assert!(Instant::now() < end, "no {n} trials within 60 s");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn the_seed_papers_design_runs_end_to_end_and_recovers_the_observers_order() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let protocol = virtual_study(dir.path());
    let out = dir.path().join("sessions");
    let (p, o) = (protocol.display().to_string(), out.display().to_string());
    for s in 0..5 {
        let subject = format!("s{s}");
        let (code, stdout, stderr) = saw(Some(&vb.port), &run_args(&p, &subject, &o));
        assert_eq!(code, 0, "{stdout}{stderr}");
        let t = trials(&out.join(format!("{subject}.csv")));
        assert_eq!(t.len(), 12, "12 comparisons each");
        // Every ordered pair of the four once: Ura's variant.
        let pairs: std::collections::BTreeSet<_> = t.values().collect();
        assert_eq!(pairs.len(), 12);
        // The sidecar names the board and the subject's index (the sessions before it).
        let side: Value = serde_json::from_str(
            &std::fs::read_to_string(out.join(format!("{subject}.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(side["session"]["subject_index"], s);
        assert_eq!(side["session"]["board"]["board"], "nucleo-f446re", "{side}");
        assert_eq!(side["trials"], 12);
    }
    // Every trial's f_b as the board produced it, and each interval explored.
    let csv = std::fs::read_to_string(out.join("s0.csv")).unwrap();
    let head: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |n: &str| head.iter().position(|h| *h == n).unwrap();
    for l in csv.lines().skip(1) {
        let f: Vec<&str> = l.split(',').collect();
        let want: f64 = f[col("first")].trim_end_matches(" Hz").parse().unwrap();
        assert_eq!(f[col("first_f_b_hz")].parse::<f64>().unwrap(), want, "{l}");
        assert!(
            f[col("first_explored_s")].parse::<f64>().unwrap() > 0.1,
            "{l}"
        );
        assert!(f[col("first_scene_id")].starts_with("0x"), "{l}");
    }

    // The analysis: the scale puts the stimuli in the observer's order (a lower f_b is
    // rougher: judged more).
    let csvs: Vec<String> = (0..5)
        .map(|s| out.join(format!("s{s}.csv")).display().to_string())
        .collect();
    let mut args = vec!["--json", "experiment", "analyze"];
    args.extend(csvs.iter().map(String::as_str));
    let (code, stdout, stderr) = saw(None, &args);
    assert_eq!(code, 0, "{stdout}{stderr}");
    let r: Value = serde_json::from_str(stdout.trim()).unwrap();
    let block = &r["result"]["paired"][0];
    assert_eq!(block["scheffe"]["variant"], "ura", "{block}");
    let scale = &block["scale"];
    let v = |k: &str| scale[k].as_f64().unwrap();
    assert!(
        v("20 Hz") > v("40 Hz") && v("40 Hz") > v("80 Hz") && v("80 Hz") > v("200 Hz"),
        "{scale}"
    );
}

#[test]
fn a_runner_killed_mid_session_resumes_with_no_trial_lost_or_repeated() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let protocol = virtual_study(dir.path());
    let p = protocol.display().to_string();
    // The uninterrupted order, for reference.
    let reference = uninterrupted(&vb.port, &p, "k", dir.path());

    let out = dir.path().join("killed");
    let o = out.display().to_string();
    let mut child = spawn_run(&vb.port, &p, "k", &o, Stdio::null(), Stdio::null());
    wait_for_trials(&out.join("k.csv"), 5, &mut child);
    // SIGKILL: no handler runs, whatever the runner was doing.
    child.kill().unwrap();
    child.wait().unwrap();
    let before = trials(&out.join("k.csv"));
    assert!(before.len() >= 5 && before.len() < 12, "{}", before.len());

    // Without --resume a second session for the subject is refused, and nothing changes.
    let (code, _, stderr) = saw(Some(&vb.port), &run_args(&p, "k", &o));
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--resume continues it"), "{stderr}");
    assert_eq!(trials(&out.join("k.csv")), before);

    let mut args = run_args(&p, "k", &o);
    args.push("--resume");
    let (code, stdout, stderr) = saw(Some(&vb.port), &args);
    assert_eq!(code, 0, "{stdout}{stderr}");
    let after = trials(&out.join("k.csv"));
    assert_eq!(after.len(), 12, "no trial lost");
    assert_eq!(after, reference, "the order unchanged");
    // The log holds each trial once, the resumed ones after the first run's.
    let log = std::fs::read_to_string(out.join("k.log.jsonl")).unwrap();
    let numbers: Vec<u64> = log
        .lines()
        .filter_map(|l| serde_json::from_str::<Value>(l).ok())
        .filter(|v| v["kind"] == "trial")
        .map(|v| v["trial"]["number"].as_u64().unwrap())
        .collect();
    assert_eq!(numbers, (0..12).collect::<Vec<_>>());
}

#[test]
fn a_board_pulled_mid_session_fails_with_a_sentence_and_resumes_where_it_stopped() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let protocol = virtual_study(dir.path());
    let p = protocol.display().to_string();
    let reference = uninterrupted(&vb.port, &p, "u", dir.path());

    let out = dir.path().join("pulled");
    let o = out.display().to_string();
    let mut child = spawn_run(&vb.port, &p, "u", &o, Stdio::piped(), Stdio::piped());
    wait_for_trials(&out.join("u.csv"), 4, &mut child);
    let board_dir = vb.power_off();
    let out_run = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out_run.stderr);
    assert_eq!(out_run.status.code(), Some(3), "a link failure: {stderr}");
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    let before = trials(&out.join("u.csv"));
    assert!(before.len() >= 4 && before.len() < 12);

    // Plugged back in (the same port path), resumed.
    let vb = VirtualBoard::start_in(board_dir, &[]);
    let mut args = run_args(&p, "u", &o);
    args.push("--resume");
    let (code, stdout, stderr) = saw(Some(&vb.port), &args);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert_eq!(trials(&out.join("u.csv")), reference);
}

#[test]
fn protocol_and_command_line_mistakes_are_one_line_each() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(
        &bad,
        "[experiment]\nname = \"x\"\nseed = 1\n[[stimulus]]\nname = \"a\"\nregion = { kind = \"constant\", f_b_hz = 20 }\n[[block]]\nname = \"b\"\ndesign = \"paired\"\nvariant = \"urah\"\nstimuli = [\"a\"]\n",
    )
    .unwrap();
    let b = bad.display().to_string();
    let (code, _, stderr) = saw(None, &["experiment", "check", &b]);
    assert_eq!(code, 2);
    assert_eq!(
        stderr.trim(),
        format!("error: {b}:10:11: block[0].variant: \"urah\" is not a variant; it is one of scheffe, ura, haga, nakaya")
    );
    // run needs a port; a subject id that cannot name a file is refused.
    let protocol = virtual_study(dir.path());
    let p = protocol.display().to_string();
    let (code, _, stderr) = saw(None, &["experiment", "run", &p, "--subject", "s1"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--port: missing"), "{stderr}");
    let (code, _, stderr) = saw(
        Some(Path::new("/nonexistent")),
        &["experiment", "run", &p, "--subject", "../x"],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--subject \"../x\""), "{stderr}");
    let (code, _, stderr) = saw(
        None,
        &[
            "experiment",
            "run",
            &p,
            "--subject",
            "s",
            "--subject-index",
            "-3",
        ],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--subject-index"), "{stderr}");
    // analyze: a file twice, a chart into a directory that is not there.
    let lab = dir.path().join("lab.csv");
    std::fs::write(&lab, "subject,first,second,score\ns1,a,b,1\ns1,b,a,-1\n").unwrap();
    let l = lab.display().to_string();
    let (code, _, stderr) = saw(None, &["experiment", "analyze", &l, &l]);
    assert_eq!(
        (code, stderr.trim()),
        (
            2,
            format!("error: {l} is given twice; each file is read once").as_str()
        )
    );
    let (code, _, stderr) = saw(
        None,
        &["experiment", "analyze", &l, "-o", "/nonexistent/x.png"],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains("the directory /nonexistent does not exist"),
        "{stderr}"
    );
    // check prints the plan.
    let (code, stdout, stderr) = saw(None, &["--json", "experiment", "check", &p]);
    assert_eq!(code, 0, "{stderr}");
    let v: Value = serde_json::from_str(stdout.trim()).unwrap();
    assert_eq!(v["result"]["trials_per_subject"], 12);
}

/// Ctrl-C mid-session: one line on how to go on, exit 130, every answered trial kept.
#[test]
fn an_interrupt_says_how_to_go_on() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let protocol = virtual_study(dir.path());
    let p = protocol.display().to_string();
    let out = dir.path().join("int");
    let o = out.display().to_string();
    let mut child = spawn_run(&vb.port, &p, "i", &o, Stdio::null(), Stdio::piped());
    wait_for_trials(&out.join("i.csv"), 2, &mut child);
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGINT,
    )
    .unwrap();
    let run = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(130), "{stderr}");
    assert_eq!(
        stderr.trim(),
        "saw experiment: interrupted; the log keeps every trial answered (the one in progress is not): --resume continues"
    );
    assert!(trials(&out.join("i.csv")).len() >= 2);
}
