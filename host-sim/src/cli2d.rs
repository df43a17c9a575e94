//! The 2D run's command line (issue #36): the flags only a 2D run reads, each checked at the
//! door; which run the flags make (a 4-wire scene file, or with no `--scene` a 2D trajectory on
//! the built-in demo screen, [`crate::sim2d::demo_config`]); the combinations refused (2D flags
//! with a 1D scene, 1D flags with a 2D one, flags the chosen path would ignore); and the run's
//! JSON and human outputs.
//!
//! `host-sim --scene FILE --trajectory line --from-xy X,Y --to-xy X,Y --speed MM_S --json`
//! prints the window switches and edge pulses, each with its (x, y) in mm and its signed
//! distance from the outline or edge it belongs to.

use std::path::PathBuf;

use clap::{ArgMatches, Args as ClapArgs};
use saw_core::plane::Config2d;
use saw_core::scene_file::{self, SensorKind};

use crate::cli::{given, Args, Kind, Refusal};
use crate::door::{fmt_num, Range, Whole};
use crate::sim::burst_timer;
use crate::sim2d::{self, Params2d, Run2d};
use crate::trajectory2d::{PointUm, Trajectory2d};

/// A point's coordinates: the plane's ±1 m (paths may leave the plate; off it the finger reads
/// as lifted).
pub const COORD: Range = Range::new(-1000.0, 1000.0, "mm");
/// A circle's or spiral's radius.
pub const RADIUS: Range = Range::new(0.1, 1000.0, "mm");
/// A spiral's start radius.
pub const R0: Range = Range::new(0.0, 1000.0, "mm");
/// A spiral's turns.
pub const TURNS: Range = Range::new(0.1, 100.0, "turns");
/// A raster's rows.
pub const ROWS: Whole = Whole::new(2, 1000);
/// The press force: the default contact law puts touch-down at 0.2 N, lift-off at 0.1 N.
pub const FORCE: Range = Range::new(0.01, 100.0, "N");
/// When the finger lifts, s from the start.
pub const LIFT_AT: Range = Range::new(0.0, sim2d::MAX_DURATION_S, "s");
/// Simulated time of a 2D run (it keeps its trace), s.
pub const DURATION_2D: Range = Range::new(0.01, sim2d::MAX_DURATION_S, "s");
/// A raster's or spiral's default, and a circle's default run, s.
pub const DEFAULT_TURNS: f64 = 3.0;
/// The rows of a raster without --rows.
pub const DEFAULT_ROWS: u64 = 5;

/// `X,Y` in mm, each within [`COORD`]; a bad coordinate is named (`X`, `Y`) with the rule it
/// breaks, the same rules as every other number at the door (NaN and inf: "finite").
pub fn xy_mm(s: &str) -> Result<(f64, f64), String> {
    let parts: Vec<&str> = s.split(',').collect();
    let [x, y] = parts.as_slice() else {
        return Err(format!(
            "must be two numbers X,Y in mm, each {} (give both, separated by a comma)",
            COORD.span()
        ));
    };
    let x = COORD.check(x).map_err(|rule| format!("X {rule}"))?;
    let y = COORD.check(y).map_err(|rule| format!("Y {rule}"))?;
    Ok((x, y))
}

/// The flags only a 2D run reads.
#[derive(ClapArgs, Debug, Clone, Default)]
pub struct Flags2d {
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true, value_parser = xy_mm,
          help = format!("2D: start of a line, first corner of a raster, X,Y in mm (each {})", COORD.span()))]
    pub from_xy: Option<(f64, f64)>,
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true, value_parser = xy_mm,
          help = format!("2D: end of a line, opposite corner of a raster, X,Y in mm (each {})", COORD.span()))]
    pub to_xy: Option<(f64, f64)>,
    #[arg(long, value_name = "X,Y", allow_hyphen_values = true, value_parser = xy_mm,
          help = format!("2D: centre of a circle or spiral, X,Y in mm (each {})", COORD.span()))]
    pub center_xy: Option<(f64, f64)>,
    #[arg(long, value_name = "MM", allow_hyphen_values = true,
          help = RADIUS.help("2D: radius of a circle, end radius of a spiral"), value_parser = RADIUS.parser())]
    pub radius: Option<f64>,
    #[arg(long, value_name = "MM", allow_hyphen_values = true,
          help = format!("{} [default: 0]", R0.help("2D: start radius of a spiral")), value_parser = R0.parser())]
    pub r0: Option<f64>,
    #[arg(long, value_name = "TURNS", allow_hyphen_values = true,
          help = format!("{} [default: 3]", TURNS.help("2D: turns of a spiral")), value_parser = TURNS.parser())]
    pub turns: Option<f64>,
    #[arg(long, value_name = "ROWS", allow_hyphen_values = true,
          help = format!("{} [default: 5]", ROWS.help("2D: rows of a raster")), value_parser = ROWS.parser())]
    pub rows: Option<u64>,
    /// 2D: a CSV path file, header t_s,x_mm,y_mm, one timed point a line.
    #[arg(long, value_name = "FILE")]
    pub path: Option<PathBuf>,
    #[arg(long, value_name = "N", allow_hyphen_values = true,
          help = format!("{} [default: 1]", FORCE.help("2D: press force (touch-down at 0.2 N with the default contact)")),
          value_parser = FORCE.parser())]
    pub force: Option<f64>,
    #[arg(long, value_name = "S", allow_hyphen_values = true,
          help = LIFT_AT.help("2D: the finger lifts at this time and stays off"), value_parser = LIFT_AT.parser())]
    pub lift_at: Option<f64>,
    /// 2D: print the run as one JSON object (parameters, window_switches, edge_pulses, lifts,
    /// faults, summary) instead of the summary and chart.
    #[arg(long)]
    pub json: bool,
}

/// The 2D flags, by clap id.
const FLAGS_2D: [&str; 11] = [
    "from_xy",
    "to_xy",
    "center_xy",
    "radius",
    "r0",
    "turns",
    "rows",
    "path",
    "force",
    "lift_at",
    "json",
];

/// The flags only a 1D run reads.
const FLAGS_1D: [&str; 7] = [
    "from",
    "to",
    "accel",
    "offset",
    "no_preload",
    "per_conversion",
    "scenario",
];

/// The path-shaping 2D flags each kind reads (the others are refused with it).
fn reads(kind: Kind) -> &'static [&'static str] {
    match kind {
        Kind::Line => &["from_xy", "to_xy", "speed"],
        Kind::Circle => &["center_xy", "radius", "speed"],
        Kind::Spiral => &["center_xy", "radius", "r0", "turns", "speed"],
        Kind::Raster => &["from_xy", "to_xy", "rows", "speed"],
        Kind::Path => &["path"],
        _ => &[],
    }
}

const SHAPING: [&str; 8] = [
    "from_xy",
    "to_xy",
    "center_xy",
    "radius",
    "r0",
    "turns",
    "rows",
    "path",
];

/// Refuses what only a 2D run reads, for a 1D run (the built-in 1D scene or a rheostat file).
pub fn refuse_in_1d(args: &Args, m: &ArgMatches) -> Result<(), Refusal> {
    let scene = crate::cli::scene_label(args);
    if args.trajectory.is_2d() {
        return Err(Refusal::Door(format!(
            "--trajectory {} is a 2D path; {scene} is 1D (a slide rheostat): give a 4-wire \
             scene, or no --scene for the 2D demo screen",
            args.trajectory.name()
        )));
    }
    if let Some(f) = FLAGS_2D.iter().find_map(|id| given(m, id)) {
        return Err(Refusal::Door(format!(
            "{f} is a 2D flag; {scene} with --trajectory {} is a 1D run, which would ignore it",
            args.trajectory.name()
        )));
    }
    Ok(())
}

/// A 2D run the flags describe.
#[derive(Debug)]
pub struct Plan2d {
    /// What to simulate.
    pub params: Params2d,
    /// The scene's name (the file, or the demo screen).
    pub scene: String,
}

/// The 2D run the flags describe (`Ok(None)`: a 1D run; [`crate::cli::plan`] takes it).
pub fn plan(args: &Args, m: &ArgMatches) -> Result<Option<Plan2d>, Refusal> {
    // A scenario sets the scene itself: `cli::plan` refuses what goes with it, before any
    // file is read.
    if args.scenario.is_some() {
        return Ok(None);
    }
    let board = args.board;
    let frame_us = sim2d::board_frame_period_us(board).ok_or_else(|| {
        Refusal::Run(
            format!(
                "board {}: its ADC timing makes no touch schedule",
                board.name
            )
            .into(),
        )
    })?;
    let screen_um = (
        (sim2d::SCREEN_MM.0 * 1e3) as u32,
        (sim2d::SCREEN_MM.1 * 1e3) as u32,
    );
    let (config, scene, plate_um): (Config2d, String, (u32, u32)) = match &args.scene {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| Refusal::Run(format!("--scene {}: {e}", path.display()).into()))?;
            let file = path.display().to_string();
            match scene_file::sensor_of(&file, &text).map_err(Refusal::Scene)? {
                SensorKind::FourWire => (
                    scene_file::load_2d_for_board(&file, &text, burst_timer(board), frame_us)
                        .map_err(Refusal::Scene)?,
                    file.clone(),
                    // The overlay is the scene's plate, as `serve`'s is.
                    scene_file::plate_um_of(&file, &text).map_err(Refusal::Scene)?,
                ),
                // A sensor this simulator does not know yet: the 1D run's reader says why.
                _ => return Ok(None),
            }
        }
        None if args.trajectory.is_2d() => {
            (sim2d::demo_config(), "the 2D demo screen".into(), screen_um)
        }
        None => return Ok(None),
    };
    if let Some(f) = FLAGS_1D.iter().find_map(|id| given(m, id)) {
        return Err(Refusal::Door(format!(
            "{f} is a 1D flag; {scene} is a 2D scene, whose run would ignore it"
        )));
    }
    let kind = args.trajectory;
    if !kind.is_2d() {
        return Err(Refusal::Door(match given(m, "trajectory") {
            Some(t) => format!(
                "{t} is a 1D motion; {scene} is a 2D scene: give --trajectory line, circle, \
                 spiral, raster or path"
            ),
            None => format!(
                "{scene} is a 2D scene: give --trajectory line, circle, spiral, raster or path"
            ),
        }));
    }
    let wants = reads(kind);
    if let Some(f) = SHAPING
        .iter()
        .chain(["speed"].iter())
        .filter(|id| !wants.contains(id))
        .find_map(|id| given(m, id))
    {
        return Err(Refusal::Door(format!(
            "{f} does not shape --trajectory {}, which would ignore it",
            kind.name()
        )));
    }
    let f2 = &args.two_d;
    let need = |v: Option<(f64, f64)>, flag: &str| {
        v.map(|(x, y)| PointUm::new(x * 1e3, y * 1e3))
            .ok_or_else(|| {
                Refusal::Door(format!(
                    "--trajectory {} needs {flag} X,Y (mm)",
                    kind.name()
                ))
            })
    };
    let speed = args.speed * 1e3;
    let refused = |e: crate::trajectory2d::TrajectoryError| {
        Refusal::Door(format!("--trajectory {}: {e}", kind.name()))
    };
    // The shapes' own rules, named by their flags (the trajectory's checks name its fields).
    match kind {
        Kind::Line | Kind::Raster => {
            if let (Some(a), Some(b)) = (f2.from_xy, f2.to_xy) {
                if kind == Kind::Line && a == b {
                    return Err(Refusal::Door(format!(
                        "--from-xy {},{} and --to-xy {},{} are one point: a line needs two",
                        fmt_num(a.0),
                        fmt_num(a.1),
                        fmt_num(b.0),
                        fmt_num(b.1)
                    )));
                }
                if kind == Kind::Raster && (a.0 == b.0 || a.1 == b.1) {
                    return Err(Refusal::Door(format!(
                        "--from-xy {},{} and --to-xy {},{}: a raster's opposite corners must \
                         differ in both x and y",
                        fmt_num(a.0),
                        fmt_num(a.1),
                        fmt_num(b.0),
                        fmt_num(b.1)
                    )));
                }
            }
        }
        Kind::Spiral => {
            if let (Some(r1), r0) = (f2.radius, f2.r0.unwrap_or(0.0)) {
                if r1 <= r0 {
                    return Err(Refusal::Door(format!(
                        "--radius {} mm: must be above --r0 {} mm (the spiral winds out from \
                         --r0 to --radius)",
                        fmt_num(r1),
                        fmt_num(r0)
                    )));
                }
            }
        }
        _ => {}
    }
    let trajectory = match kind {
        Kind::Line => Trajectory2d::line(
            need(f2.from_xy, "--from-xy")?,
            need(f2.to_xy, "--to-xy")?,
            speed,
        ),
        Kind::Circle => Trajectory2d::circle(
            need(f2.center_xy, "--center-xy")?,
            f2.radius
                .ok_or_else(|| Refusal::Door("--trajectory circle needs --radius MM".into()))?
                * 1e3,
            speed,
        ),
        Kind::Spiral => Trajectory2d::spiral(
            need(f2.center_xy, "--center-xy")?,
            f2.r0.unwrap_or(0.0) * 1e3,
            f2.radius
                .ok_or_else(|| Refusal::Door("--trajectory spiral needs --radius MM".into()))?
                * 1e3,
            f2.turns.unwrap_or(DEFAULT_TURNS),
            speed,
        ),
        Kind::Raster => Trajectory2d::raster(
            need(f2.from_xy, "--from-xy")?,
            need(f2.to_xy, "--to-xy")?,
            f2.rows.unwrap_or(DEFAULT_ROWS).min(u32::MAX as u64) as u32,
            speed,
        ),
        Kind::Path => {
            let path = f2.path.as_ref().ok_or_else(|| {
                Refusal::Door("--trajectory path needs --path FILE (CSV t_s,x_mm,y_mm)".into())
            })?;
            let text = std::fs::read_to_string(path)
                .map_err(|e| Refusal::Run(format!("--path {}: {e}", path.display()).into()))?;
            match Trajectory2d::path_from_csv(&text) {
                Ok(t) => Ok(t),
                Err(e) => {
                    return Err(Refusal::Door(format!("--path {}: {e}", path.display())));
                }
            }
        }
        _ => return Ok(None),
    }
    .map_err(refused)?;
    // A path that ends runs to its end and a frame's worth of rest; the circle for 3 s.
    let duration_s = match args.duration {
        Some(d) if d > DURATION_2D.hi => {
            return Err(Refusal::Door(format!(
                "invalid value '{}' for '--duration <S>': a 2D run keeps its trace, so it must \
                 be {}",
                fmt_num(d),
                DURATION_2D.span()
            )))
        }
        Some(d) => d,
        None => trajectory
            .duration_s()
            .map_or(crate::cli::DEFAULT_DURATION_S, |t| t + 0.05)
            .clamp(DURATION_2D.lo, DURATION_2D.hi),
    };
    if let Some(l) = f2.lift_at {
        if l >= duration_s {
            return Err(Refusal::Door(format!(
                "--lift-at {} s: the run ends at {} s (--duration), so the finger would never \
                 lift; give a time before it",
                fmt_num(l),
                fmt_num(duration_s)
            )));
        }
    }
    let mut params = Params2d::new(board, trajectory, duration_s, config);
    params.plate_um = plate_um;
    params.overlay.noise_lsb = args.noise;
    params.seed = args.seed;
    params.force_n = f2.force.unwrap_or(1.0);
    params.lift_at_s = f2.lift_at;
    Ok(Some(Plan2d { params, scene }))
}

/// What a run did that its flags may not have meant, one sentence each: the path off the
/// plate, a finger that never pressed, a path cut by `--duration`. Printed as `warning:` lines
/// (stderr) and listed in the JSON's `warnings`.
pub fn warnings(plan: &Plan2d, run: &Run2d) -> Vec<String> {
    let p = &plan.params;
    let mut w = Vec::new();
    let (pw, ph) = run.plate_mm;
    if let Some(first) = run.first_off_plate_s {
        let off_s = run.off_plate_frames as f64 * run.frame_period_us as f64 * 1e-6;
        w.push(format!(
            "the finger's path is off the {} x {} mm plate for {:.3} s of the {:.3} s ({:.1} % \
             of the frames), first at t = {:.4} s: the overlay reads no finger there",
            fmt_num(pw),
            fmt_num(ph),
            off_s,
            p.duration_s,
            100.0 * run.off_plate_frames as f64 / run.frames.max(1) as f64,
            first
        ));
    }
    if run.pressed_frames == 0 {
        w.push(format!(
            "the finger never pressed the overlay (off the plate, lifted, or --force {} N below \
             the touch-down): nothing rendered",
            fmt_num(p.force_n)
        ));
    }
    if let Some(path_s) = p.trajectory.duration_s() {
        if p.duration_s < path_s {
            w.push(format!(
                "the run ends at {} s (--duration), before the path does ({:.3} s): the rest of \
                 the path is not run",
                fmt_num(p.duration_s),
                path_s
            ));
        }
    }
    w
}

/// The run as one JSON object: its parameters, the events, and the counts.
pub fn json(plan: &Plan2d, run: &Run2d) -> serde_json::Value {
    let p = &plan.params;
    let t = run.telemetry;
    serde_json::json!({
        "scene": plan.scene,
        "board": p.board.name,
        "trajectory": p.trajectory.describe(),
        "duration_s": p.duration_s,
        "noise_lsb": p.overlay.noise_lsb,
        "seed": p.seed,
        "force_n": p.force_n,
        "lift_at_s": p.lift_at_s,
        "plate_mm": [run.plate_mm.0, run.plate_mm.1],
        "frame_period_us": run.frame_period_us,
        "frames": run.frames,
        "pressed_frames": run.pressed_frames,
        "off_plate_frames": run.off_plate_frames,
        "warnings": warnings(plan, run),
        "window_switches": run.window_switches,
        "edge_pulses": run.edge_pulses,
        "lifts": run.lifts,
        "faults": run.faults,
        "summary": {
            "window_switches": run.window_switches.len(),
            "edge_pulses": run.edge_pulses.len(),
            "edges_skipped": t.edges_skipped,
            "ridge_pulses": t.ridge_pulses,
            "ridges_skipped": t.ridges_skipped,
            "lifts": run.lifts.len(),
            "faults": run.faults.len(),
            "gate_actions": t.gate_actions,
        },
    })
}

/// The short human summary.
pub fn summary(plan: &Plan2d, run: &Run2d) -> String {
    let p = &plan.params;
    let t = run.telemetry;
    let mut s = format!(
        "2D run: {} on {}, {}; {:.3} s, {} frames of {} µs, noise {} LSB RMS, {} N\n",
        plan.scene,
        p.board.name,
        p.trajectory.describe(),
        p.duration_s,
        run.frames,
        run.frame_period_us,
        p.overlay.noise_lsb,
        p.force_n
    );
    let place = |w: Option<u8>| w.map_or("background".to_string(), |i| format!("window {i}"));
    s.push_str(&format!("window switches: {}\n", run.window_switches.len()));
    for w in &run.window_switches {
        s.push_str(&format!(
            "  {:8.4} s  ({:7.3}, {:7.3}) mm  {} → {}, {:+.3} mm from window {}'s outline\n",
            w.t_s,
            w.x_mm,
            w.y_mm,
            place(w.from),
            place(w.to),
            w.distance_mm,
            w.outline
        ));
    }
    s.push_str(&format!(
        "edge pulses: {} (skipped to keep the duty cap: {})\n",
        run.edge_pulses.len(),
        t.edges_skipped
    ));
    for e in &run.edge_pulses {
        s.push_str(&format!(
            "  {:8.4} s  ({:7.3}, {:7.3}) mm  edge {}, {:+.3} mm from it\n",
            e.t_s, e.x_mm, e.y_mm, e.edge, e.distance_mm
        ));
    }
    s.push_str(&format!(
        "ridge pulses: {}; lift-offs: {}; faults: {}\n",
        t.ridge_pulses,
        run.lifts.len(),
        run.faults.len()
    ));
    s
}

/// The chart's path: `-o`, else `out/sim2d-<scene file stem>.png` (`out/sim2d-demo.png`).
pub fn chart_path(args: &Args) -> PathBuf {
    if let Some(p) = &args.output {
        return p.clone();
    }
    let stem = args
        .scene
        .as_ref()
        .and_then(|p| p.file_stem())
        .map_or("demo".to_string(), |s| s.to_string_lossy().into_owned());
    PathBuf::from("out").join(format!("sim2d-{stem}.png"))
}

/// Runs `plan`: JSON on stdout with `--json`, else the summary and the chart.
pub fn run(args: &Args, plan: &Plan2d) -> Result<(), Box<dyn std::error::Error>> {
    let r = sim2d::run(&plan.params)?;
    for w in warnings(plan, &r) {
        eprintln!("warning: {w}");
    }
    if args.two_d.json {
        println!("{}", serde_json::to_string_pretty(&json(plan, &r))?);
        return Ok(());
    }
    print!("{}", summary(plan, &r));
    let out = chart_path(args);
    if let Some(dir) = out.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)?;
        }
    }
    let title = format!(
        "{} — {} — {} — noise {} LSB RMS",
        plan.scene,
        plan.params.board.name,
        plan.params.trajectory.describe(),
        plan.params.overlay.noise_lsb
    );
    crate::chart2d::write_png(&plan.params.config, &r, &out, &title)?;
    println!("chart: {}", out.display());
    Ok(())
}
