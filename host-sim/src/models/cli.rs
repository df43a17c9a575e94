//! Command-line front end of the models: `host-sim model <name> [--flags]` and
//! `host-sim tile-to-scene [--flags]`, parsed by clap with every number checked at the door
//! ([`crate::door`]: unit, range, NaN/inf refused, exit code 2). Output is returned as text (the
//! caller prints it).

use super::atan::{atan_curve, atan_errors, run_bench, AtanImpl, BENCH_IMPLS};
use super::charts::{write_charts, AtanCostSource, Chart};
use super::grooved::{grooved, Eq4, GroovedInput, Pad, SolveOptions, Solver};
use super::sandpaper;
use super::solvers::solver_sweep;
use super::stick_slip::{fig5_curve, stick_slip, Material, StickSlipParams};
use super::tile::{a_max_mm2, tile_rows, tile_to_region};
use crate::door::{fmt_num, Range, Whole};
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{ArgGroup, Parser, Subcommand};
use std::fmt::Write as _;
use std::path::PathBuf;

/// Δμ = μs − μc.
const DELTA_MU: Range = Range::new(0.0, 10.0, "");
/// Young's moduli: from a gel (1 kPa) to diamond (about 1 TPa).
const MODULUS: Range = Range::new(1e3, 1e12, "Pa");
/// Poisson's ratios (the model needs −1 < ν ≤ 0.5).
const POISSON: Range = Range::new(-0.99, 0.5, "");
/// RMS roughness of the asperity heights.
const SIGMA: Range = Range::new(0.001, 1000.0, "µm");
/// Mean radius of the asperities.
const BETA: Range = Range::new(0.001, 10_000.0, "µm");
/// s − s′.
const SHEAR_DIFF: Range = Range::new(0.0, 1e9, "Pa");
/// Normal force P.
const NORMAL_FORCE: Range = Range::new(0.0, 100.0, "N");
/// Moving mass m.
const MASS: Range = Range::new(0.001, 1000.0, "g");
/// Spring stiffness k.
const STIFFNESS: Range = Range::new(0.001, 1e6, "N/m");
/// Sliding speed U (and the finger speed of `tile-to-scene`).
const SLIDE_SPEED: Range = Range::new(0.0, 1000.0, "mm/s");
/// Points of fig. 5's curve.
const POINTS: Whole = Whole::new(1, 100_000);
/// Groove width G.
const GROOVE: Range = Range::new(0.01, 10.0, "mm");
/// Land width L.
const LAND: Range = Range::new(0.0, 10.0, "mm");
/// Fingertip force F: up to 10 kg, beyond any touch (the paper's largest is 448 g).
const FORCE: Range = Range::new(0.0, 10_000.0, "g");
/// Skin compliance k.
const COMPLIANCE: Range = Range::new(0.001, 1.0, "mm/g");
/// Friction coefficient μ.
const MU: Range = Range::new(0.0, 10.0, "");
/// Pad area at the reference force.
const PAD_AREA: Range = Range::new(1.0, 10_000.0, "mm²");
/// Pad reference force.
const PAD_FORCE: Range = Range::new(0.1, 10_000.0, "g");
/// Pad power-law exponent.
const PAD_EXPONENT: Range = Range::new(0.0, 1.0, "");
/// Relative tolerance of the θ solvers.
const RTOL: Range = Range::new(1e-16, 0.1, "");
/// Newton's starting θ: inside (0, π/2].
const THETA0: Range = Range::new(0.001, core::f64::consts::FRAC_PI_2, "rad");
/// Grit number of a sandpaper.
const GRIT: Range = Range::new(1.0, 10_000.0, "");
/// Burst frequency: the boards' f_b range.
const F_B: Range = Range::new(
    saw_boards::MIN_BURST_HZ as f64,
    saw_boards::MAX_BURST_HZ as f64,
    "Hz",
);
/// Iterations of one `atan-bench` run.
const BENCH_N: Whole = Whole::new(1, 100_000_000);

/// `host-sim model <name>`.
#[derive(Parser, Debug)]
#[command(
    name = "host-sim model",
    bin_name = "host-sim model",
    about = "Physical models of the display (docs/models.md)",
    arg_required_else_help = true
)]
struct ModelCli {
    #[command(subcommand)]
    model: Model,
}

#[derive(Subcommand, Debug)]
enum Model {
    /// Stick-slip frequency, [N] eqs. 9–12: give --delta-mu, or all seven material parameters.
    StickSlip(StickSlipArgs),
    /// CSV of f_ss against mu_s - mu_c with fig. 5's P, m, k, U.
    Fig5 {
        #[arg(long, value_name = "N", default_value_t = 200, allow_hyphen_values = true,
              help = POINTS.help("Points of the curve"), value_parser = POINTS.parser_usize())]
        points: usize,
    },
    /// Taylor & Lederman's static skin model over a grooved tile, θ solved three ways.
    Grooved(GroovedArgs),
    /// CSV of iterations against accuracy for the three solvers.
    ThetaSolvers {
        /// CSV output (the only output; accepted for symmetry).
        #[arg(long, hide = true)]
        csv: bool,
    },
    /// CSV of the paper's tile sets (D, A_c, A, grating region).
    Tiles {
        /// CSV output (the only output; accepted for symmetry).
        #[arg(long, hide = true)]
        csv: bool,
    },
    /// Table 1's grit ↔ f_b scale: give --grit or --f-b-hz.
    #[command(group(ArgGroup::new("scale").required(true).args(["grit", "f_b_hz"])))]
    Sandpaper {
        #[arg(long, allow_hyphen_values = true, help = GRIT.help("Grit number"),
              value_parser = GRIT.parser())]
        grit: Option<f64>,
        #[arg(long, value_name = "HZ", allow_hyphen_values = true,
              help = F_B.help("Burst frequency"), value_parser = F_B.parser())]
        f_b_hz: Option<f64>,
        /// One JSON object.
        #[arg(long)]
        json: bool,
    },
    /// CSV of atan / f_ss errors (micromath, libm, f64).
    Atan {
        /// Against R instead.
        #[arg(long)]
        curve: bool,
        /// CSV output (the only output; accepted for symmetry).
        #[arg(long, hide = true)]
        csv: bool,
    },
    /// One atan loop, for callgrind (model charts measures the cost with it).
    AtanBench {
        /// The loop.
        #[arg(long = "impl", value_name = "IMPL", value_parser = PossibleValuesParser::new(BENCH_IMPLS))]
        imp: String,
        #[arg(long, default_value_t = 100_000, allow_hyphen_values = true,
              help = BENCH_N.help("Iterations"), value_parser = BENCH_N.parser_usize())]
        n: usize,
    },
    /// Writes the models-*.png charts and prints the tables of docs/models.md; the atan cost
    /// axis runs this binary under valgrind (callgrind), skipped if valgrind is missing.
    Charts {
        /// Output directory (default out/models; `--out docs/charts` refreshes the committed
        /// charts).
        #[arg(long, value_name = "DIR", default_value = "out/models", value_parser = crate::door::out_dir)]
        out: PathBuf,
        /// Only this chart.
        #[arg(long, value_parser = PossibleValuesParser::new(Chart::ALL.map(Chart::name))
              .map(|s| Chart::parse(&s).unwrap_or(Chart::Fig5)))] // listed above
        only: Option<Chart>,
        /// Skip the callgrind cost axis.
        #[arg(long)]
        no_cost: bool,
    },
}

#[derive(clap::Args, Debug)]
struct StickSlipArgs {
    #[arg(long, value_name = "X", allow_hyphen_values = true,
          help = DELTA_MU.help("Friction difference mu_s - mu_c"), value_parser = DELTA_MU.parser())]
    delta_mu: Option<f64>,
    #[command(flatten)]
    material: MaterialArgs,
    #[arg(long, value_name = "N", default_value_t = 1.0, allow_hyphen_values = true,
          help = NORMAL_FORCE.help("Normal force P"), value_parser = NORMAL_FORCE.parser())]
    normal_force_n: f64,
    #[arg(long, value_name = "G", default_value_t = 1.0, allow_hyphen_values = true,
          help = MASS.help("Moving mass m"), value_parser = MASS.parser())]
    mass_g: f64,
    #[arg(long, value_name = "N_PER_M", default_value_t = 500.0, allow_hyphen_values = true,
          help = STIFFNESS.help("Spring stiffness k"), value_parser = STIFFNESS.parser())]
    stiffness_n_per_m: f64,
    #[arg(long, value_name = "MM_S", default_value_t = 40.0, allow_hyphen_values = true,
          help = SLIDE_SPEED.help("Sliding speed U"), value_parser = SLIDE_SPEED.parser())]
    speed_mm_s: f64,
    /// One JSON object.
    #[arg(long)]
    json: bool,
}

/// Eq. 12's material parameters: all seven, or none (then --delta-mu).
#[derive(clap::Args, Debug)]
struct MaterialArgs {
    #[arg(long, value_name = "PA", allow_hyphen_values = true, required_unless_present = "delta_mu",
          conflicts_with = "delta_mu",
          help = MODULUS.help("Young's modulus of the object E_o"), value_parser = MODULUS.parser())]
    e_object_pa: Option<f64>,
    #[arg(long, value_name = "NU", allow_hyphen_values = true, required_unless_present = "delta_mu",
          conflicts_with = "delta_mu",
          help = POISSON.help("Poisson's ratio of the object nu_o"), value_parser = POISSON.parser())]
    nu_object: Option<f64>,
    #[arg(long, value_name = "PA", allow_hyphen_values = true, required_unless_present = "delta_mu",
          conflicts_with = "delta_mu",
          help = MODULUS.help("Young's modulus of the skin E_s"), value_parser = MODULUS.parser())]
    e_skin_pa: Option<f64>,
    #[arg(long, value_name = "NU", allow_hyphen_values = true, required_unless_present = "delta_mu",
          conflicts_with = "delta_mu",
          help = POISSON.help("Poisson's ratio of the skin nu_s"), value_parser = POISSON.parser())]
    nu_skin: Option<f64>,
    #[arg(long, value_name = "UM", allow_hyphen_values = true, required_unless_present = "delta_mu",
          conflicts_with = "delta_mu",
          help = SIGMA.help("RMS asperity height sigma"), value_parser = SIGMA.parser())]
    sigma_um: Option<f64>,
    #[arg(long, value_name = "UM", allow_hyphen_values = true, required_unless_present = "delta_mu",
          conflicts_with = "delta_mu",
          help = BETA.help("Mean asperity radius beta"), value_parser = BETA.parser())]
    beta_um: Option<f64>,
    #[arg(long, value_name = "PA", allow_hyphen_values = true, required_unless_present = "delta_mu",
          conflicts_with = "delta_mu",
          help = SHEAR_DIFF.help("Shear strength difference s - s'"), value_parser = SHEAR_DIFF.parser())]
    shear_strength_diff_pa: Option<f64>,
}

/// The tile and the finger of `grooved` and `tile-to-scene`.
#[derive(clap::Args, Debug)]
struct TileArgs {
    #[arg(long, value_name = "G", allow_hyphen_values = true,
          help = GROOVE.help("Groove width G"), value_parser = GROOVE.parser())]
    groove_mm: f64,
    #[arg(long, value_name = "L", allow_hyphen_values = true,
          help = LAND.help("Land width L"), value_parser = LAND.parser())]
    land_mm: f64,
    #[arg(long, value_name = "F", allow_hyphen_values = true,
          help = FORCE.help("Fingertip force F"), value_parser = FORCE.parser())]
    force_g: f64,
    #[arg(long, value_name = "K", default_value_t = 0.08, allow_hyphen_values = true,
          help = COMPLIANCE.help("Skin compliance k"), value_parser = COMPLIANCE.parser())]
    k_mm_per_g: f64,
    #[arg(long, default_value_t = 0.5, allow_hyphen_values = true,
          help = MU.help("Friction coefficient mu"), value_parser = MU.parser())]
    mu: f64,
    #[arg(long, value_name = "MM2", default_value_t = 150.0, allow_hyphen_values = true,
          help = PAD_AREA.help("Pad area at the reference force"), value_parser = PAD_AREA.parser())]
    pad_area_mm2: f64,
    #[arg(long, value_name = "G", default_value_t = 112.0, allow_hyphen_values = true,
          help = PAD_FORCE.help("Pad reference force"), value_parser = PAD_FORCE.parser())]
    pad_ref_force_g: f64,
    #[arg(long, value_name = "X", default_value_t = 0.15, allow_hyphen_values = true,
          help = PAD_EXPONENT.help("Pad power-law exponent"), value_parser = PAD_EXPONENT.parser())]
    pad_exponent: f64,
}

impl TileArgs {
    fn input(&self) -> GroovedInput {
        GroovedInput {
            groove_mm: self.groove_mm,
            land_mm: self.land_mm,
            force_g: self.force_g,
            k_mm_per_g: self.k_mm_per_g,
            mu: self.mu,
            pad: Pad {
                area_ref_mm2: self.pad_area_mm2,
                force_ref_g: self.pad_ref_force_g,
                exponent: self.pad_exponent,
            },
        }
    }
}

#[derive(clap::Args, Debug)]
struct GroovedArgs {
    #[command(flatten)]
    tile: TileArgs,
    /// Root finder of eq. 4.
    #[arg(long, default_value = "safeguarded",
          value_parser = PossibleValuesParser::new(Solver::ALL.map(Solver::name))
              .map(|s| Solver::parse(&s).unwrap_or(Solver::Safeguarded)))] // listed above
    solver: Solver,
    #[arg(long, default_value_t = SolveOptions::default().rtol, hide_default_value = true,
          allow_hyphen_values = true, value_parser = RTOL.parser(),
          help = format!("{} [default: {}]", RTOL.help("Relative tolerance"),
                         fmt_num(SolveOptions::default().rtol)))]
    rtol: f64,
    #[arg(long, value_name = "RAD", default_value_t = SolveOptions::default().theta0,
          allow_hyphen_values = true, help = THETA0.help("Newton's starting theta"),
          value_parser = THETA0.parser())]
    theta0: f64,
    /// One JSON object.
    #[arg(long)]
    json: bool,
}

/// `host-sim tile-to-scene`.
#[derive(Parser, Debug)]
#[command(
    name = "host-sim tile-to-scene",
    bin_name = "host-sim tile-to-scene",
    about = "A grooved tile as a grating region, printed as a scene file's [[region]] table \
             (wavelength_mm, amplitude_percent): paste it into a file under scenes/"
)]
struct TileToSceneCli {
    #[command(flatten)]
    tile: TileArgs,
    #[arg(long, value_name = "V", allow_hyphen_values = true,
          help = SLIDE_SPEED.help("Finger speed, for the comment f = V/lambda"),
          value_parser = SLIDE_SPEED.parser())]
    speed_mm_s: Option<f64>,
    /// The output is always a scene file's region (this flag is the default, kept so older
    /// scripts run).
    #[arg(long)]
    scene_file: bool,
}

/// Parses `args` (without the program name) as command `name`; help and errors as clap
/// renders them.
fn parse<P: Parser>(name: &str, args: &[String]) -> Result<P, clap::Error> {
    P::try_parse_from(std::iter::once(name.to_string()).chain(args.iter().cloned()))
}

/// A clap refusal as `run_model`'s result: help text is output, anything else an error.
fn rendered(e: clap::Error) -> Result<String, String> {
    let text = e.render().to_string();
    match e.kind() {
        clap::error::ErrorKind::DisplayHelp | clap::error::ErrorKind::DisplayVersion => Ok(text),
        _ => Err(text.trim_end().trim_start_matches("error: ").to_string()),
    }
}

/// A JSON number (non-finite → null).
fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x:?}")
    } else {
        "null".into()
    }
}

/// One JSON object from (key, already-encoded value) pairs.
fn json(fields: &[(&str, String)]) -> String {
    let body: Vec<String> = fields.iter().map(|(k, v)| format!("\"{k}\":{v}")).collect();
    format!("{{{}}}", body.join(","))
}

/// Hook for a binary's `main`: if the process arguments start with `model` or `tile-to-scene`,
/// runs that subcommand, prints its output (or `error: …` on stderr) and returns the exit code;
/// otherwise returns `None` and the caller parses its own CLI. A refused flag exits with clap's
/// one-line error and code 2, like a model's refusal.
pub fn run_from_env() -> Option<std::process::ExitCode> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = match args.split_first() {
        Some((c, rest)) if c == "model" => parse::<ModelCli>("model", rest).map(exec_model),
        Some((c, rest)) if c == "tile-to-scene" => {
            parse::<TileToSceneCli>("tile-to-scene", rest).map(exec_tile_to_scene)
        }
        _ => return None,
    };
    Some(match out {
        Err(e) => e.exit(),
        Ok(Ok(s)) => {
            println!("{}", s.trim_end());
            std::process::ExitCode::SUCCESS
        }
        Ok(Err(e)) => {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
    })
}

/// `host-sim model <args>`; returns the text to print (the help for `--help`).
pub fn run_model(args: &[String]) -> Result<String, String> {
    parse::<ModelCli>("model", args).map_or_else(rendered, exec_model)
}

fn exec_model(cli: ModelCli) -> Result<String, String> {
    match cli.model {
        Model::StickSlip(a) => cmd_stick_slip(&a),
        Model::Fig5 { points } => cmd_fig5(points),
        Model::Grooved(a) => cmd_grooved(&a),
        Model::ThetaSolvers { .. } => Ok(cmd_theta_solvers()),
        Model::Tiles { .. } => cmd_tiles(),
        Model::Sandpaper { grit, f_b_hz, json } => cmd_sandpaper(grit, f_b_hz, json),
        Model::Atan { curve, .. } => Ok(cmd_atan(curve)),
        Model::AtanBench { imp, n } => {
            let s = run_bench(&imp, n)?;
            Ok(format!("{imp} n={n} sum={s}"))
        }
        Model::Charts { out, only, no_cost } => cmd_charts(&out, only, no_cost),
    }
}

fn cmd_stick_slip(a: &StickSlipArgs) -> Result<String, String> {
    let as_json = a.json;
    let m = &a.material;
    let (delta_mu, material) = match a.delta_mu {
        Some(d) => (d, None),
        None => {
            // clap has required all seven when --delta-mu is absent.
            let v = |x: Option<f64>| x.unwrap_or_default();
            let m = Material {
                e_object_pa: v(m.e_object_pa),
                nu_object: v(m.nu_object),
                e_skin_pa: v(m.e_skin_pa),
                nu_skin: v(m.nu_skin),
                sigma_m: v(m.sigma_um) * 1e-6,
                beta_m: v(m.beta_um) * 1e-6,
                shear_strength_diff_pa: v(m.shear_strength_diff_pa),
            };
            (m.delta_mu().map_err(|e| e.to_string())?, Some(m))
        }
    };
    let p = StickSlipParams {
        delta_mu,
        normal_force_n: a.normal_force_n,
        mass_kg: a.mass_g * 1e-3,
        stiffness_n_per_m: a.stiffness_n_per_m,
        speed_m_s: a.speed_mm_s * 1e-3,
    };
    let r = stick_slip(&p).map_err(|e| e.to_string())?;
    if as_json {
        let mut f = vec![
            ("f_ss_hz", num(r.f_ss_hz)),
            ("delta_mu", num(p.delta_mu)),
            ("normal_force_n", num(p.normal_force_n)),
            ("mass_g", num(p.mass_kg * 1e3)),
            ("stiffness_n_per_m", num(p.stiffness_n_per_m)),
            ("speed_mm_s", num(p.speed_m_s * 1e3)),
            ("omega0_rad_s", num(r.omega0_rad_s)),
            ("r", num(r.r)),
            ("a_m_s", num(r.a_m_s)),
        ];
        if let Some(m) = material {
            f.push((
                "contact_modulus_pa",
                num(m.contact_modulus_pa().map_err(|e| e.to_string())?),
            ));
        }
        Ok(json(&f))
    } else {
        Ok(format!(
            "f_ss = {:.6} Hz  (delta_mu = {:.6}, R = {:.6}, omega0 = {:.3} rad/s, f0 = omega0/2pi = {:.3} Hz)",
            r.f_ss_hz,
            p.delta_mu,
            r.r,
            r.omega0_rad_s,
            r.omega0_rad_s / (2.0 * core::f64::consts::PI)
        ))
    }
}

fn cmd_fig5(n: usize) -> Result<String, String> {
    let mut s = String::from("delta_mu,r,f_ss_hz,asymptote_hz,f0_hz\n");
    for p in fig5_curve(n)? {
        let _ = writeln!(
            s,
            "{:e},{:e},{:e},{:e},{:e}",
            p.delta_mu, p.r, p.f_ss_hz, p.asymptote_hz, p.f0_hz
        );
    }
    Ok(s)
}

fn cmd_grooved(a: &GroovedArgs) -> Result<String, String> {
    let as_json = a.json;
    let inp = a.tile.input();
    let solver = a.solver;
    let opt = SolveOptions {
        rtol: a.rtol,
        max_iter: SolveOptions::default().max_iter,
        theta0: a.theta0,
    };
    let r = grooved(&inp, solver, &opt).map_err(|e| e.to_string())?;
    let eq = Eq4::new(inp.groove_mm, inp.land_mm, inp.mu).map_err(|e| e.to_string())?;
    if as_json {
        Ok(json(&[
            ("theta_rad", num(r.theta_rad)),
            ("r_mm", num(r.r_mm)),
            ("d_mm", num(r.d_mm)),
            ("a_cg_mm2", num(r.a_cg_mm2)),
            ("a_g_mm2", num(r.a_g_mm2)),
            ("a_c_mm2", num(r.a_c_mm2)),
            ("a_mm2", num(r.a_mm2)),
            ("mean_depth_mm", num(r.mean_depth_mm)),
            ("x_mm", num(r.x_mm)),
            ("f_g_g_per_mm", num(r.f_g_g_per_mm)),
            ("kfg", num(r.kfg)),
            ("pad_width_mm", num(r.pad_width_mm)),
            ("theta_pole_rad", eq.pole().map_or("null".into(), num)),
            ("groove_mm", num(inp.groove_mm)),
            ("land_mm", num(inp.land_mm)),
            ("force_g", num(inp.force_g)),
            ("k_mm_per_g", num(inp.k_mm_per_g)),
            ("mu", num(inp.mu)),
            ("solver", format!("\"{}\"", solver.name())),
            ("iterations", r.solution.iterations.to_string()),
            ("evaluations", r.solution.evaluations.to_string()),
            (
                "derivative_evaluations",
                r.solution.derivative_evaluations.to_string(),
            ),
            ("rel_residual", num(r.solution.rel_residual)),
        ]))
    } else {
        Ok(format!(
            "theta = {:.9} rad ({:.4} deg)\nr     = {:.6} mm\nD     = {:.6} mm\nA_cg  = {:.6e} mm^2\nA_g   = {:.6e} mm^2\nA_c   = {:.6e} mm^2 (x W/(G+L))\nA     = {:.6e} mm^2 (x W/(G+L))\nk f_g = {:.6e}  (f_g = {:.6} g/mm, W = {:.3} mm)\nsolver {}: {} iterations, {} evaluations, {} derivative evaluations, residual {:.1e}",
            r.theta_rad,
            r.theta_rad.to_degrees(),
            r.r_mm,
            r.d_mm,
            r.a_cg_mm2,
            r.a_g_mm2,
            r.a_c_mm2,
            r.a_mm2,
            r.kfg,
            r.f_g_g_per_mm,
            r.pad_width_mm,
            solver.name(),
            r.solution.iterations,
            r.solution.evaluations,
            r.solution.derivative_evaluations,
            r.solution.rel_residual
        ))
    }
}

fn cmd_theta_solvers() -> String {
    let mut s = String::from("solver,rtol,solved,cases,mean_iterations,max_iterations,mean_evaluations,max_rel_theta_error\n");
    for st in solver_sweep() {
        let _ = writeln!(
            s,
            "{},{:e},{},{},{:.3},{},{:.3},{:e}",
            st.solver.name(),
            st.rtol,
            st.solved,
            st.cases,
            st.mean_iterations,
            st.max_iterations,
            st.mean_evaluations,
            st.max_rel_theta_error
        );
    }
    s
}

fn cmd_tiles() -> Result<String, String> {
    let mut s = String::from("set,label,groove_mm,land_mm,force_g,theta_rad,d_mm,a_c_mm2,a_mm2,wavelength_um,amplitude_permille\n");
    for r in tile_rows()? {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{:e},{:e},{:e},{:e},{},{}",
            r.tile.set,
            r.tile.label,
            r.tile.groove_mm,
            r.tile.land_mm,
            r.force_g,
            r.theta_rad,
            r.d_mm,
            r.a_c_mm2,
            r.a_mm2,
            r.wavelength_um,
            r.amplitude_permille
        );
    }
    Ok(s)
}

fn cmd_sandpaper(grit: Option<f64>, f_b_hz: Option<f64>, as_json: bool) -> Result<String, String> {
    // clap's group has required exactly one of them.
    let r = match (grit, f_b_hz) {
        (Some(g), _) => sandpaper::from_grit(g)?,
        (None, f) => sandpaper::from_f_b(f.unwrap_or_default())?,
    };
    if as_json {
        Ok(json(&[
            ("grit", num(r.grit)),
            ("scale", num(r.scale)),
            ("f_b_hz", num(r.f_b_hz)),
            ("beta_um", num(r.beta_um)),
            ("clamped", r.clamped.to_string()),
        ]))
    } else {
        Ok(format!(
            "grit #{:.1} <-> scale {:.4} <-> f_b = {:.3} Hz (mean projection radius {:.1} um){}",
            r.grit,
            r.scale,
            r.f_b_hz,
            r.beta_um,
            if r.clamped {
                " [clamped to table 1]"
            } else {
                ""
            }
        ))
    }
}

fn cmd_atan(curve: bool) -> String {
    if curve {
        let mut s = String::from("r,impl,abs_err_rad,rel_err_f_ss\n");
        for p in atan_curve() {
            let _ = writeln!(
                s,
                "{:e},{},{:e},{:e}",
                p.r,
                p.imp.name(),
                p.abs_err_rad,
                p.rel_err_f_ss
            );
        }
        return s;
    }
    let mut s = String::from("impl,max_abs_rad,mean_abs_rad,max_rel_f_ss,mean_rel_f_ss\n");
    for imp in AtanImpl::ALL {
        let e = atan_errors(imp);
        let _ = writeln!(
            s,
            "{},{:e},{:e},{:e},{:e}",
            imp.name(),
            e.max_abs_rad,
            e.mean_abs_rad,
            e.max_rel_f_ss,
            e.mean_rel_f_ss
        );
    }
    s
}

fn cmd_charts(out: &std::path::Path, only: Option<Chart>, no_cost: bool) -> Result<String, String> {
    let cost = if no_cost {
        AtanCostSource::Skip
    } else {
        let exe = std::env::current_exe().map_err(|e| format!("current executable: {e}"))?;
        AtanCostSource::Callgrind { exe }
    };
    write_charts(out, only, &cost)
}

/// `host-sim tile-to-scene <args>`; returns the TOML snippet (the help for `--help`).
pub fn run_tile_to_scene(args: &[String]) -> Result<String, String> {
    parse::<TileToSceneCli>("tile-to-scene", args).map_or_else(rendered, exec_tile_to_scene)
}

fn exec_tile_to_scene(cli: TileToSceneCli) -> Result<String, String> {
    let inp = cli.tile.input();
    let speed = cli.speed_mm_s;
    let reg = tile_to_region(&inp).map_err(|e| e.to_string())?;
    let a_max = a_max_mm2().map_err(|e| e.to_string())?;
    let mut s = format!(
        "# tile G = {} mm, L = {} mm, F = {} g, k = {} mm/g, mu = {}: A = {:.6e} mm^2, A_max (paper tile sets) = {:.6e} mm^2\n",
        inp.groove_mm, inp.land_mm, inp.force_g, inp.k_mm_per_g, inp.mu, reg.a_mm2, a_max
    );
    if let Some(v) = speed {
        let _ = writeln!(
            s,
            "# f = V/lambda = {:.3} Hz at V = {v} mm/s",
            v * 1000.0 / reg.wavelength_um as f64
        );
    }
    s.push_str(&reg.to_scene_file_toml());
    Ok(s)
}
