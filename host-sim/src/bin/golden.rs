//! Golden vectors for the Cortex-M4F emulator image (`firmware/emu`), and the check of its report.
//!
//! ```text
//! cargo run --release -p host-sim --features saw-core/scene-file --bin golden -- gen target/golden
//! golden gen   <dir>                 # writes <dir>/golden.bin (+ manifest.txt)
//! golden check <dir> <decoded.log> <cost.md>
//! ```
//!
//! `gen` records, for every scene × trajectory, the ADC input stream (16-bit codes with their
//! timestamps, from the rheostat/ADC model of `host_sim::adc`) and the outputs of the host's own
//! `saw_core::Controller` (NUCLEO-F446RE burst timer, 10 kHz), in the format of
//! `firmware/emu/src/format.rs` (shared source). The scene configs go in as every field of the
//! compiled-from-TOML `Config` (f32 as raw bits); the round trip is checked here.
//!
//! `check` reads the image's defmt log (decoded by defmt-print) and fails unless: every vector
//! was replayed with the host's output CRC (bit-exact) — or, for scenes with f32 inside, every
//! differing record is within the tolerance of `format::within_tolerance`; the expected log
//! lines are there (boot, scene loaded, region change, sensor fault); and every scene and every
//! texture kind costs ≤ 400 instructions per sample on average (each `COST-SCENE` and
//! `COST-TEXTURE` row; the worst single sample, `COST-WORST`, is reported, not bounded), except
//! the kinds [`OVER_BUDGET`] names, which must stay under their ceilings. It writes the cost
//! table (markdown) to `<cost.md>`.
//!
//! 2D (issue #36): `gen` also writes `golden2d.bin` (format in `firmware/emu/src/plane2d.rs`):
//! the 8-window, 16-edge scene, three trajectories' touch frames from host-sim's overlay model,
//! the host sensor's readings and the host `Controller2d`'s outputs; the image replays them as
//! readings (`plane/…`) and as frames through its own sensor (`plane+sensor/…`), and `check`
//! holds both bit-exact and the controller's rows (`plane/…`) at or under [`BUDGET`], as the
//! 1D scenes (issue #36: 200.3–398.5 after its seventh round; the rows' history is beside the
//! check).

#[path = "../../../firmware/emu/src/format.rs"]
#[allow(dead_code)]
mod format;
#[path = "../../../firmware/emu/src/plane2d.rs"]
#[allow(dead_code)]
mod plane2d;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::process::ExitCode;

use format::{encode_config, encode_output, encode_timer, Reader, Sink};
use host_sim::adc::{AdcModel, AdcParams, FaultKind, FaultWindow};
use host_sim::trajectory::Trajectory;
use saw_core::burst::BurstTimer;
use saw_core::texture::{Grating, Texture};
use saw_core::{Config, Controller};

use host_sim::touch::{Finger, Overlay, TouchModel};
use saw_core::plane::{Controller2d, Place};
use saw_core::touch::calibration::CalPoint;
use saw_core::touch::plates::{AdcTiming, PlateRc, Schedule};

/// Samples per vector: 0.5 s at 10 kHz.
const SAMPLES: u64 = 5_000;
/// First timestamp: the u32 µs clock wraps 0.2 s into every vector.
const T0_US: u32 = u32::MAX - 199_999;
/// Per-sample instruction budget (mean over a vector) of every scene and texture kind (the
/// conversion budget's CPU model counts the core at it too).
const BUDGET: u64 = host_sim::budget::SAMPLE_BUDGET_INSTR;
/// Issue #17 not met for these: their rows are over [`BUDGET`] (measured on this commit, see
/// docs/target-cost.md) and fail only above their ceiling here, about 3 % over the worst row
/// measured, so a regression still fails. Remove a line once its kind is under the budget.
/// Empty: every kind is under it. The last one out was the hybrid (its 64-sample line fit on
/// every sample): 552.8 before issue #35, 418.1 after its step's cuts, 392.4 once its line fit
/// made the half's line only where the two ends may disagree, with one fill count, a one-compare
/// clock and no Option tags on its path (rest 357.0); it is now held at 400 like the others.
const OVER_BUDGET: [(&str, f64); 0] = [];

struct VecSink(Vec<u8>);
impl Sink for VecSink {
    fn put(&mut self, b: &[u8]) {
        self.0.extend_from_slice(b);
    }
}

fn scenes(timer: BurstTimer, period: u32) -> Vec<(String, Config)> {
    let dir = std::env::var_os("SAW_SCENES_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes"));
    let mut out = vec![("default".to_string(), saw_core::default_config())];
    for name in ["grating", "material", "random", "lines"] {
        let path = dir.join(format!("{name}.toml"));
        let text =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let cfg =
            saw_core::scene_file::load_for_board(&format!("{name}.toml"), &text, timer, period)
                .unwrap_or_else(|e| panic!("{e}"));
        out.push((name.to_string(), cfg));
    }
    // The default scene with a fourth region, a grating from 60 mm, that no trajectory enters:
    // its cost must equal the default scene's (a scene pays only for the textures it renders).
    let mut cfg = saw_core::default_config();
    cfg.scene.boundaries_um.push(60_000).unwrap();
    cfg.scene
        .textures
        .push(Texture::Grating(Grating::new(1_000)))
        .unwrap();
    out.push(("default+unused-grating".to_string(), cfg));
    out
}

fn trajectories() -> Vec<(&'static str, Trajectory, Vec<FaultWindow>)> {
    vec![
        ("rest", Trajectory::Rest { at_um: 30_000.0 }, vec![]),
        (
            "back-and-forth",
            Trajectory::Triangle {
                a_um: 5_000.0,
                b_um: 55_000.0,
                speed_um_s: 200_000.0,
            },
            vec![],
        ),
        (
            "reversal",
            Trajectory::Reversal {
                from_um: 20_000.0,
                turn_um: 35_000.0,
                speed_um_s: 60_000.0,
            },
            vec![],
        ),
        (
            "rail-fault",
            Trajectory::Constant {
                from_um: 10_000.0,
                speed_um_s: 80_000.0,
            },
            vec![FaultWindow {
                kind: FaultKind::Open,
                start_us: 200_000,
                end_us: 230_000,
            }],
        ),
    ]
}

fn gen(dir: &Path) -> Result<(), String> {
    // The NUCLEO-F446RE's burst timer and sample rate (as host_sim::sim derives them).
    let board = &saw_boards::NUCLEO_F446RE;
    let timer = BurstTimer {
        clock_hz: board.burst_timer_clk_hz,
        counter_bits: board.burst_timer_bits,
        max_burst_hz: board.max_burst_hz,
    };
    let period = 1_000_000 / board.sample_rate_hz;
    let scenes = scenes(timer, period);
    let mut s = VecSink(Vec::new());
    s.put(format::MAGIC);
    s.u32(format::VERSION);
    encode_timer(&mut s, &timer, period);
    s.u8(scenes.len() as u8);
    for (name, cfg) in &scenes {
        s.name(name);
        let mut c = VecSink(Vec::new());
        encode_config(&mut c, cfg);
        let back = format::decode_config(&mut Reader::new(&c.0));
        if &back != cfg {
            return Err(format!(
                "scene {name}: config does not survive the round trip"
            ));
        }
        s.put(&c.0);
    }
    let trajs = trajectories();
    s.u8((scenes.len() * trajs.len()) as u8);
    let mut manifest = String::new();
    for (si, (sname, cfg)) in scenes.iter().enumerate() {
        for (tname, traj, faults) in &trajs {
            let mut adc = AdcModel::new(
                cfg.calibration,
                AdcParams {
                    seed: 7,
                    faults: faults.clone(),
                    ..AdcParams::default()
                },
            )
            .map_err(|e| format!("{e:?}"))?;
            let mut ctl = Controller::new(timer, period).map_err(|e| format!("{e:?}"))?;
            ctl.load(cfg).map_err(|e| format!("{e:?}"))?;
            let mut inputs = VecSink(Vec::new());
            let mut outputs = VecSink(Vec::new());
            let mut n = 0u32;
            for k in 0..SAMPLES {
                let t_sim = k * period as u64;
                let pos = traj.state(t_sim as f64 * 1e-6).position_um;
                let Some(mut sample) = adc.sample(pos, t_sim) else {
                    continue;
                };
                sample.t_us = T0_US.wrapping_add(t_sim as u32);
                inputs.u16(sample.code);
                inputs.u32(sample.t_us);
                encode_output(&mut outputs, &ctl.on_sample(sample));
                n += 1;
            }
            let crc = format::crc32_update(0, &outputs.0);
            let vname = format!("{sname}/{tname}");
            s.name(&vname);
            s.u8(si as u8);
            s.u32(n);
            s.put(&inputs.0);
            s.u32(outputs.0.len() as u32);
            s.put(&outputs.0);
            s.u32(crc);
            writeln!(
                manifest,
                "{vname} n={n} crc={crc:08x} bytes={}",
                outputs.0.len()
            )
            .unwrap();
        }
    }
    gen2d(dir, timer, period, &mut manifest)?;
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    std::fs::write(dir.join("golden.bin"), &s.0).map_err(|e| e.to_string())?;
    std::fs::write(dir.join("manifest.txt"), &manifest).map_err(|e| e.to_string())?;
    println!(
        "golden: {} scenes x {} trajectories, {} bytes -> {}",
        scenes.len(),
        trajs.len(),
        s.0.len(),
        dir.join("golden.bin").display()
    );
    Ok(())
}

/// The 2D vectors' touch plate: the 4.3-inch panel of host-sim's overlay model (95 × 54 mm;
/// finger fractions map to µm by these), read with the F446's 2D acquisition
/// (`saw_boards::touch::touch_adc`, the fields `sim2d::adc_timing` maps).
const PLATE_UM: (f64, f64) = (95_000.0, 54_000.0);
const F446_TOUCH: AdcTiming = {
    let t = saw_boards::touch::touch_adc(&saw_boards::NUCLEO_F446RE);
    AdcTiming {
        conversion_ns: t.conversion_ns,
        conversions_position: t.conversions_position,
        conversions_pressure: t.conversions_pressure,
        discard: t.discard,
    }
};

/// The finger of a 2D vector at `t_s`: where it is (µm), or None when lifted.
type Path2d = fn(f64) -> Option<(f64, f64)>;

/// The 2D trajectories: (name, readings at the controller's 10 kHz, finger).
fn trajectories2d() -> Vec<(&'static str, u32, Path2d)> {
    // 100 mm/s along y = 12 mm through windows 0–3 (window 0's two sides, the free segments),
    // then back on a diagonal up to (30, 27) mm through windows 7 and 6; the first 16 frames
    // are the sensor's landing run.
    fn stroke(t: f64) -> Option<(f64, f64)> {
        let pts = [
            (1_000.0, 12_000.0),
            (60_000.0, 12_000.0),
            (30_000.0, 27_000.0),
        ];
        let mut d = t * 100_000.0;
        for w in pts.windows(2) {
            let (a, b): ((f64, f64), (f64, f64)) = (w[0], w[1]);
            let len = (b.0 - a.0).hypot(b.1 - a.1);
            if d <= len {
                let s = d / len;
                return Some((a.0 + s * (b.0 - a.0), a.1 + s * (b.1 - a.1)));
            }
            d -= len;
        }
        Some(pts[2])
    }
    // At rest on window 0's right side (an edge), 2 LSB a conversion.
    fn rest_on_edge(_t: f64) -> Option<(f64, f64)> {
        Some((14_000.0, 10_000.0))
    }
    // 100 mm/s along y = 25 mm from inside window 5 (off, outline flagged) across its side,
    // into window 6 (oriented grating), lifted from 150 to 170 ms while the hand moves on,
    // landing (16 frames) and on through a free segment and window 7.
    fn lift_landing(t: f64) -> Option<(f64, f64)> {
        let p = (18_000.0 + 100_000.0 * t, 25_000.0);
        (!(0.150..0.170).contains(&t)).then_some(p)
    }
    vec![
        ("stroke", 9_500, stroke),
        ("rest-on-edge", 5_000, rest_on_edge),
        ("lift-landing", 3_500, lift_landing),
    ]
}

/// 2D golden vectors (issue #36): the 8-window, 16-edge scene of `plane2d::config`, each
/// trajectory's frames from host-sim's overlay model (2 LSB a conversion), the readings the
/// host's `TouchSensor` made of them and the host's `Controller2d` outputs. Writes
/// `golden2d.bin` and appends `plane/<name>` and `plane+sensor/<name>` (same outputs) to the
/// manifest.
fn gen2d(dir: &Path, timer: BurstTimer, period: u32, manifest: &mut String) -> Result<(), String> {
    let cfg = plane2d::config();
    let schedule = Schedule::new(&PlateRc::DEFAULT, &F446_TOUCH).map_err(|e| format!("{e:?}"))?;
    // Calibrate on a noiseless model: three targets, as a user touches them.
    let mut quiet = TouchModel::new(
        Overlay {
            noise_lsb: 0.0,
            ..Overlay::default()
        },
        1,
    );
    let cal = [(0.1, 0.1), (0.9, 0.5), (0.5, 0.9)].map(|(x, y)| {
        let f = Finger { x, y, force_n: 1.0 };
        quiet.frame(&schedule, &F446_TOUCH, Some(&f), 0);
        let fr = quiet.frame(&schedule, &F446_TOUCH, Some(&f), 0);
        CalPoint {
            x_code: fr.x_code,
            y_code: fr.y_code,
            x_um: (x * PLATE_UM.0) as i32,
            y_um: (y * PLATE_UM.1) as i32,
        }
    });
    let mut s = VecSink(Vec::new());
    s.put(plane2d::MAGIC);
    s.u32(plane2d::VERSION);
    encode_timer(&mut s, &timer, period);
    s.u32(plane2d::config_crc(&cfg));
    let mut c = plane2d::Rec::new();
    for p in &cal {
        c.len = 0;
        plane2d::encode_cal(&mut c, p);
        s.put(c.as_slice());
    }
    let trajs = trajectories2d();
    s.u8(trajs.len() as u8);
    for (vi, (name, n, path)) in trajs.iter().enumerate() {
        let mut model = TouchModel::new(Overlay::default(), 11 + vi as u64);
        let mut sensor = plane2d::sensor(cal).ok_or("2d: the calibration is refused")?;
        let mut ctl = Controller2d::new(timer, period).map_err(|e| format!("{e:?}"))?;
        ctl.load(&cfg).map_err(|e| format!("{e:?}"))?;
        let (mut inputs, mut outputs) = (VecSink(Vec::new()), VecSink(Vec::new()));
        let mut windows = std::collections::BTreeSet::new();
        for k in 0..*n {
            let t_us = T0_US.wrapping_add(k * period);
            let finger = path(k as f64 * period as f64 * 1e-6).map(|(x, y)| Finger {
                x: x / PLATE_UM.0,
                y: y / PLATE_UM.1,
                force_n: 1.0,
            });
            let frame = model.frame(&schedule, &F446_TOUCH, finger.as_ref(), t_us);
            let reading = sensor.on_frame(&frame);
            let out = ctl.on_reading(t_us, reading);
            if let Some(Place::Window(w)) = out.place {
                windows.insert(w);
            }
            let mut r = plane2d::Rec::new();
            plane2d::encode_frame(&mut r, &frame);
            plane2d::encode_reading(&mut r, &reading);
            inputs.put(r.as_slice());
            r.len = 0;
            plane2d::encode_output2d(&mut r, &out);
            let back = plane2d::decode_output2d(&mut Reader::new(r.as_slice()));
            if back != out {
                return Err(format!(
                    "2d {name}: output record does not survive the round trip"
                ));
            }
            outputs.put(r.as_slice());
        }
        let crc = format::crc32_update(0, &outputs.0);
        s.name(name);
        s.u32(*n);
        s.put(&inputs.0);
        s.u32(outputs.0.len() as u32);
        s.put(&outputs.0);
        s.u32(crc);
        let tel = ctl.telemetry();
        for case in ["plane", "plane+sensor"] {
            writeln!(
                manifest,
                "{case}/{name} n={n} crc={crc:08x} bytes={}",
                outputs.0.len()
            )
            .unwrap();
        }
        println!(
            "golden 2d {name}: {n} readings, windows entered {windows:?}, {} switches, {} edge \
             pulses ({} skipped), {} ridge pulses ({} skipped), {} lifts, {} gate actions",
            tel.window_switches,
            tel.edge_pulses,
            tel.edges_skipped,
            tel.ridge_pulses,
            tel.ridges_skipped,
            tel.lifts,
            tel.gate_actions
        );
    }
    std::fs::create_dir_all(dir).map_err(|e| e.to_string())?;
    std::fs::write(dir.join("golden2d.bin"), &s.0).map_err(|e| e.to_string())?;
    Ok(())
}

/// `key=value` fields of a report line.
fn fields(line: &str) -> BTreeMap<&str, &str> {
    line.split_whitespace()
        .filter_map(|w| w.split_once('='))
        .collect()
}

fn num(f: &BTreeMap<&str, &str>, k: &str) -> Result<u64, String> {
    f.get(k)
        .ok_or_else(|| format!("missing {k}"))?
        .parse()
        .map_err(|e| format!("{k}: {e}"))
}

fn check(dir: &Path, log: &Path, cost_md: &Path) -> Result<(), String> {
    let manifest = std::fs::read_to_string(dir.join("manifest.txt")).map_err(|e| e.to_string())?;
    let log = std::fs::read_to_string(log).map_err(|e| e.to_string())?;
    let mut failures = Vec::new();
    // Equivalence.
    let mut seen = 0;
    let f32_scenes = ["grating", "material", "random"];
    for m in manifest.lines() {
        let name = m.split_whitespace().next().unwrap_or("");
        let want = fields(m);
        let Some(line) = log
            .lines()
            .find(|l| l.contains("EQUIV ") && l.contains(&format!("vector={name} ")))
        else {
            failures.push(format!("{name}: not reported by the image"));
            continue;
        };
        seen += 1;
        let got = fields(line);
        let exact = got.get("crc") == want.get("crc") && got.get("n") == want.get("n");
        let diff = num(&got, "diff")?;
        let beyond = num(&got, "beyond_tol")?;
        let f32_inside = f32_scenes
            .iter()
            .any(|s| name.starts_with(&format!("{s}/")));
        if exact && diff == 0 {
            println!(
                "  {name:<40} bit-exact (n={}, crc={})",
                want["n"], want["crc"]
            );
        } else if f32_inside && beyond == 0 {
            println!("  {name:<40} {diff} records differ, all within ±1 tick (f32 scene)");
        } else {
            failures.push(format!(
                "{name}: crc {} vs host {}, {diff} records differ, {beyond} beyond tolerance",
                got.get("crc").unwrap_or(&"?"),
                want["crc"]
            ));
        }
    }
    println!("equivalence: {seen} vectors compared");
    // Logs.
    for (what, needle) in [
        ("boot", "boot: saw-core emulator image"),
        ("scene loaded", "scene loaded: "),
        ("region change", "region "),
        ("sensor fault", "sensor fault RailLow: carrier off"),
        ("sensor recovered", "sensor recovered after RailLow"),
    ] {
        if log.lines().any(|l| l.contains(needle)) {
            println!("  log line present: {what}");
        } else {
            failures.push(format!("log line missing: {what} ('{needle}')"));
        }
    }
    // Costs.
    let mut md = String::new();
    let mut default_cost = None;
    let mut unused_cost = None;
    let sections = [
        ("COST-SCENE", "Whole `on_sample` per scene and trajectory (default estimator med3+lsq32)"),
        ("COST-TEXTURE", "Whole `on_sample`, one-region scene per texture kind (default vectors' back-and-forth and rest inputs)"),
        ("COST-ESTIMATOR", "Velocity estimators: `update` alone, and whole `on_sample` on the default scene (back-and-forth)"),
        ("COST-STAGE", "Stages alone (default scene, back-and-forth inputs)"),
        ("COST-WORST", "Costliest single sample, one-region scene per texture kind (each sample timed alone: ±40; sample 0 announces the scene, the estimator's window fills by sample 34)"),
        ("COST-2D", "2D scene, 8 windows and 16 edges (issue #36): per reading, `Controller2d::on_reading` alone (plane/), `TouchSensor::on_frame` alone (sensor/), both (plane+sensor/)"),
        ("COST-WORST-2D", "2D scene: costliest single reading, `Controller2d::on_reading` (each timed alone: ±40)"),
    ];
    let mut over_budget = Vec::new();
    let mut known_over = Vec::new();
    for (tag, title) in sections {
        let rows: Vec<_> = log
            .lines()
            .filter(|l| l.contains(&format!("{tag} ")))
            .collect();
        if rows.is_empty() {
            failures.push(format!("no {tag} lines in the log"));
            continue;
        }
        writeln!(md, "\n### {title}\n").unwrap();
        if tag == "COST-ESTIMATOR" {
            writeln!(
                md,
                "| estimator | update, instr/sample | on_sample, instr/sample |"
            )
            .unwrap();
            writeln!(md, "|---|---:|---:|").unwrap();
        } else if tag == "COST-WORST" || tag == "COST-WORST-2D" {
            writeln!(
                md,
                "| case | worst sample, instr | at sample | worst from sample 64, instr | at sample |"
            )
            .unwrap();
            writeln!(md, "|---|---:|---:|---:|---:|").unwrap();
        } else {
            writeln!(md, "| case | instr/sample | samples |").unwrap();
            writeln!(md, "|---|---:|---:|").unwrap();
        }
        for l in rows {
            let f = fields(l);
            let name = f.get("case").copied().unwrap_or("?");
            if tag == "COST-ESTIMATOR" {
                writeln!(md, "| {name} | {} | {} |", f["update"], f["on_sample"]).unwrap();
                continue;
            }
            if tag == "COST-WORST" || tag == "COST-WORST-2D" {
                let g = |k| f.get(k).copied().unwrap_or("?");
                writeln!(
                    md,
                    "| {name} | {} | {} | {} | {} |",
                    g("worst"),
                    g("at"),
                    g("steady"),
                    g("steady_at")
                )
                .unwrap();
                continue;
            }
            let per = f.get("per_sample").copied().unwrap_or("?");
            writeln!(md, "| {name} | {per} | {} |", f.get("n").unwrap_or(&"?")).unwrap();
            if tag == "COST-SCENE" || tag == "COST-TEXTURE" {
                let v: f64 = per.parse().unwrap_or(f64::MAX);
                let ceiling = OVER_BUDGET
                    .iter()
                    .find(|(prefix, _)| name.starts_with(prefix))
                    .map(|&(_, c)| c);
                match ceiling {
                    Some(c) if v > BUDGET as f64 && v <= c => {
                        known_over.push(format!("{name} {per} (ceiling {c})"));
                    }
                    Some(c) if v > c => over_budget.push(format!("{name} {per} (ceiling {c})")),
                    _ if v > BUDGET as f64 => over_budget.push(format!("{name} {per}")),
                    _ => {}
                }
            }
            // The 2D controller's rows (`COST-2D case=plane/…`, `Controller2d::on_reading` alone,
            // mean over the vector) on the 8-window, 16-edge scene, worst–best through issue #36's
            // rounds, before they were held at `BUDGET` like every 1D scene: 853.4–862.8 at first;
            // 704.8–761.3 once edges preempt running bursts; 480.7–619.9 after the second round
            // (the lead and the velocity only within the lead's reach, settled distances);
            // 432.8–573.1 after the third (`PlaneLsq`); 329.5–513.4 after the fourth (the edges'
            // quiet distance); 300.6–469.3 after the fifth; 253.0–436.0 after the sixth (the
            // crossing test only where a lead can reach a line, rests on the grid parked);
            // 200.3–398.5 after the seventh (the nearest edge's lead towards its line, an off or
            // constant window's step and a pulse window's answered short; docs/target-cost.md,
            // "Issue #36"). The sensor's rows (`sensor/…`, `plane+sensor/…`) are reported, not
            // bounded: frames come at ~2.9 kHz, not 10.
            if tag == "COST-2D" && name.starts_with("plane/") {
                let v: f64 = per.parse().unwrap_or(f64::MAX);
                if v > BUDGET as f64 {
                    over_budget.push(format!("{name} {per}"));
                }
            }
            if tag == "COST-SCENE" {
                let v: f64 = per.parse().unwrap_or(f64::MAX);
                if name == "default/back-and-forth" {
                    default_cost = Some(v);
                }
                if name == "default+unused-grating/back-and-forth" {
                    unused_cost = Some(v);
                }
            }
        }
    }
    std::fs::write(cost_md, &md).map_err(|e| e.to_string())?;
    print!("{md}");
    if !known_over.is_empty() {
        println!(
            "\nOVER BUDGET (issues #17, #36 not met, under their ceilings): {}",
            known_over.join(", ")
        );
    }
    if over_budget.is_empty() {
        let which = if known_over.is_empty() {
            "every"
        } else {
            "every other"
        };
        println!("\nBUDGET: {which} scene and texture kind ≤ {BUDGET} instructions/sample");
    } else {
        failures.push(format!(
            "over the budget of {BUDGET} instructions/sample: {}",
            over_budget.join(", ")
        ));
    }
    match (default_cost, unused_cost) {
        (Some(d), Some(u)) => {
            println!(
                "\nDEFAULT SCENE: {d:.1} instructions/sample (budget {BUDGET}); with an unused grating region: {u:.1}"
            );
            if d > BUDGET as f64 {
                failures.push(format!("default scene {d:.1} instr/sample > {BUDGET}"));
            }
            if (u - d).abs() > 2.0 {
                failures.push(format!(
                    "an unused grating region changes the cost: {u:.1} vs {d:.1} instr/sample"
                ));
            }
        }
        _ => failures.push("default-scene cost not reported".into()),
    }
    if failures.is_empty() {
        Ok(())
    } else {
        Err(failures.join("\n"))
    }
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().collect();
    let r = match args.get(1).map(String::as_str) {
        Some("gen") if args.len() == 3 => gen(Path::new(&args[2])),
        Some("check") if args.len() == 5 => check(
            Path::new(&args[2]),
            Path::new(&args[3]),
            Path::new(&args[4]),
        ),
        _ => Err("usage: golden gen <dir> | golden check <dir> <decoded.log> <cost.md>".into()),
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("golden: FAIL\n{e}");
            ExitCode::FAILURE
        }
    }
}
