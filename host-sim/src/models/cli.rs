//! Command-line front end of the models: `host-sim model <name> [--flags]` and
//! `host-sim tile-to-scene [--flags]`. Arguments are plain strings so that any CLI parser can
//! forward them; output is returned as text (the caller prints it).

use super::atan::{atan_curve, atan_errors, run_bench, AtanImpl};
use super::charts::{write_charts, AtanCostSource, Chart};
use super::grooved::{grooved, Eq4, GroovedInput, Pad, SolveOptions, Solver};
use super::sandpaper;
use super::solvers::solver_sweep;
use super::stick_slip::{fig5_curve, stick_slip, Material, StickSlipParams};
use super::tile::{a_max_mm2, tile_rows, tile_to_region};
use std::collections::BTreeMap;
use std::fmt::Write as _;

/// Usage of `model`.
pub const MODEL_USAGE: &str = "\
usage: host-sim model <name> [flags]
  stick-slip   (--delta-mu X | --e-object-pa --nu-object --e-skin-pa --nu-skin --sigma-um --beta-um
                --shear-strength-diff-pa) [--normal-force-n 1] [--mass-g 1] [--stiffness-n-per-m 500]
                [--speed-mm-s 40] [--json]
  fig5         [--points 200] : CSV of f_ss against mu_s - mu_c with fig. 5's P, m, k, U
  grooved      --groove-mm G --land-mm L --force-g F [--k-mm-per-g 0.08] [--mu 0.5]
               [--solver newton|bisection|safeguarded] [--rtol 1e-13] [--theta0 0.785]
               [--pad-area-mm2 150] [--pad-ref-force-g 112] [--pad-exponent 0.15] [--json]
  theta-solvers : CSV of iterations against accuracy for the three solvers
  tiles        : CSV of the paper's tile sets (D, A_c, A, grating region)
  sandpaper    (--grit N | --f-b-hz F) [--json]
  atan         [--curve] : CSV of atan / f_ss errors (micromath, libm, f64); --curve: against R
  atan-bench   --impl none|micromath|libm|f64|fss-micromath|fss-libm [--n 100000]
  charts       [--out docs/charts] [--only fig5|solvers|tiles|atan] [--no-cost] : writes the
               models-*.png charts and prints the tables of docs/models.md; the atan cost axis
               runs this binary under valgrind (callgrind), skipped if valgrind is missing
usage: host-sim tile-to-scene --groove-mm G --land-mm L --force-g F [--k-mm-per-g 0.08] [--mu 0.5]
               [--pad-area-mm2 150] [--pad-ref-force-g 112] [--pad-exponent 0.15] [--speed-mm-s V]
               [--scene-file]  (keys of scenes/*.toml: wavelength_mm, amplitude_percent)";

/// Parsed `--name value` / `--flag` arguments; every flag must be consumed.
struct Flags {
    values: BTreeMap<String, String>,
    switches: Vec<String>,
    used: Vec<String>,
}

const SWITCHES: [&str; 6] = ["json", "csv", "help", "curve", "scene-file", "no-cost"];

impl Flags {
    fn parse(args: &[String]) -> Result<Self, String> {
        let mut values = BTreeMap::new();
        let mut switches = Vec::new();
        let mut i = 0;
        while i < args.len() {
            let a = &args[i];
            let name = a
                .strip_prefix("--")
                .ok_or_else(|| format!("unexpected argument {a:?}"))?;
            if let Some((k, v)) = name.split_once('=') {
                values.insert(k.to_string(), v.to_string());
            } else if SWITCHES.contains(&name) {
                switches.push(name.to_string());
            } else {
                let v = args
                    .get(i + 1)
                    .ok_or_else(|| format!("--{name} needs a value"))?;
                values.insert(name.to_string(), v.clone());
                i += 1;
            }
            i += 1;
        }
        Ok(Self {
            values,
            switches,
            used: Vec::new(),
        })
    }

    fn switch(&mut self, name: &str) -> bool {
        self.used.push(name.to_string());
        self.switches.iter().any(|s| s == name)
    }

    fn opt_str(&mut self, name: &str) -> Option<String> {
        self.used.push(name.to_string());
        self.values.get(name).cloned()
    }

    fn opt_f64(&mut self, name: &str) -> Result<Option<f64>, String> {
        match self.opt_str(name) {
            None => Ok(None),
            Some(s) => {
                let v: f64 = s
                    .parse()
                    .map_err(|_| format!("--{name}: not a number: {s:?}"))?;
                if v.is_finite() {
                    Ok(Some(v))
                } else {
                    Err(format!("--{name}: must be finite"))
                }
            }
        }
    }

    fn f64_or(&mut self, name: &str, default: f64) -> Result<f64, String> {
        Ok(self.opt_f64(name)?.unwrap_or(default))
    }

    fn req_f64(&mut self, name: &str) -> Result<f64, String> {
        self.opt_f64(name)?
            .ok_or_else(|| format!("--{name} is required"))
    }

    fn finish(&self) -> Result<(), String> {
        for k in self.values.keys().chain(self.switches.iter()) {
            if !self.used.contains(k) {
                return Err(format!("unknown flag --{k}"));
            }
        }
        Ok(())
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
/// otherwise returns `None` and the caller parses its own CLI.
pub fn run_from_env() -> Option<std::process::ExitCode> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = match args.split_first() {
        Some((c, rest)) if c == "model" => run_model(rest),
        Some((c, rest)) if c == "tile-to-scene" => run_tile_to_scene(rest),
        _ => return None,
    };
    Some(match out {
        Ok(s) => {
            println!("{}", s.trim_end());
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
    })
}

/// `host-sim model <args>`; returns the text to print.
pub fn run_model(args: &[String]) -> Result<String, String> {
    let Some((name, rest)) = args.split_first() else {
        return Err(MODEL_USAGE.into());
    };
    let mut fl = Flags::parse(rest)?;
    if fl.switch("help") {
        return Ok(MODEL_USAGE.into());
    }
    let out = match name.as_str() {
        "stick-slip" => cmd_stick_slip(&mut fl)?,
        "fig5" => cmd_fig5(&mut fl)?,
        "grooved" => cmd_grooved(&mut fl)?,
        "theta-solvers" => cmd_theta_solvers(&mut fl)?,
        "tiles" => cmd_tiles(&mut fl)?,
        "sandpaper" => cmd_sandpaper(&mut fl)?,
        "atan" => cmd_atan(&mut fl)?,
        "charts" => cmd_charts(&mut fl)?,
        "atan-bench" => {
            let what = fl.opt_str("impl").ok_or("--impl is required")?;
            let n = fl.f64_or("n", 100_000.0)? as usize;
            fl.finish()?;
            let s = run_bench(&what, n)?;
            format!("{what} n={n} sum={s}")
        }
        "help" | "--help" => MODEL_USAGE.into(),
        other => return Err(format!("unknown model {other:?}\n{MODEL_USAGE}")),
    };
    fl.finish()?;
    Ok(out)
}

fn cmd_stick_slip(fl: &mut Flags) -> Result<String, String> {
    let as_json = fl.switch("json");
    let delta = fl.opt_f64("delta-mu")?;
    let names = [
        "e-object-pa",
        "nu-object",
        "e-skin-pa",
        "nu-skin",
        "sigma-um",
        "beta-um",
        "shear-strength-diff-pa",
    ];
    let mut mat = Vec::new();
    for n in names {
        mat.push(fl.opt_f64(n)?);
    }
    let given = mat.iter().filter(|m| m.is_some()).count();
    let (delta_mu, material) = match (delta, given) {
        (Some(_), g) if g > 0 => {
            return Err("give either --delta-mu or the material parameters, not both".into())
        }
        (Some(d), _) => (d, None),
        (None, 7) => {
            let m = Material {
                e_object_pa: mat[0].unwrap_or_default(),
                nu_object: mat[1].unwrap_or_default(),
                e_skin_pa: mat[2].unwrap_or_default(),
                nu_skin: mat[3].unwrap_or_default(),
                sigma_m: mat[4].unwrap_or_default() * 1e-6,
                beta_m: mat[5].unwrap_or_default() * 1e-6,
                shear_strength_diff_pa: mat[6].unwrap_or_default(),
            };
            (m.delta_mu().map_err(|e| e.to_string())?, Some(m))
        }
        (None, _) => {
            return Err(format!(
                "give --delta-mu, or all of --{}",
                names.join(" --")
            ));
        }
    };
    let p = StickSlipParams {
        delta_mu,
        normal_force_n: fl.f64_or("normal-force-n", 1.0)?,
        mass_kg: fl.f64_or("mass-g", 1.0)? * 1e-3,
        stiffness_n_per_m: fl.f64_or("stiffness-n-per-m", 500.0)?,
        speed_m_s: fl.f64_or("speed-mm-s", 40.0)? * 1e-3,
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

fn cmd_fig5(fl: &mut Flags) -> Result<String, String> {
    let n = fl.f64_or("points", 200.0)? as usize;
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

fn grooved_input(fl: &mut Flags) -> Result<GroovedInput, String> {
    Ok(GroovedInput {
        groove_mm: fl.req_f64("groove-mm")?,
        land_mm: fl.req_f64("land-mm")?,
        force_g: fl.req_f64("force-g")?,
        k_mm_per_g: fl.f64_or("k-mm-per-g", 0.08)?,
        mu: fl.f64_or("mu", 0.5)?,
        pad: Pad {
            area_ref_mm2: fl.f64_or("pad-area-mm2", 150.0)?,
            force_ref_g: fl.f64_or("pad-ref-force-g", 112.0)?,
            exponent: fl.f64_or("pad-exponent", 0.15)?,
        },
    })
}

fn cmd_grooved(fl: &mut Flags) -> Result<String, String> {
    let as_json = fl.switch("json");
    let inp = grooved_input(fl)?;
    let solver_name = fl.opt_str("solver").unwrap_or_else(|| "safeguarded".into());
    let solver =
        Solver::parse(&solver_name).ok_or_else(|| format!("unknown solver {solver_name:?}"))?;
    let d = SolveOptions::default();
    let opt = SolveOptions {
        rtol: fl.f64_or("rtol", d.rtol)?,
        max_iter: d.max_iter,
        theta0: fl.f64_or("theta0", d.theta0)?,
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

fn cmd_theta_solvers(fl: &mut Flags) -> Result<String, String> {
    fl.switch("csv");
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
    Ok(s)
}

fn cmd_tiles(fl: &mut Flags) -> Result<String, String> {
    fl.switch("csv");
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

fn cmd_sandpaper(fl: &mut Flags) -> Result<String, String> {
    let as_json = fl.switch("json");
    let r = match (fl.opt_f64("grit")?, fl.opt_f64("f-b-hz")?) {
        (Some(g), None) => sandpaper::from_grit(g)?,
        (None, Some(f)) => sandpaper::from_f_b(f)?,
        _ => return Err("give exactly one of --grit or --f-b-hz".into()),
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

fn cmd_atan(fl: &mut Flags) -> Result<String, String> {
    fl.switch("csv");
    if fl.switch("curve") {
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
        return Ok(s);
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
    Ok(s)
}

fn cmd_charts(fl: &mut Flags) -> Result<String, String> {
    let out = fl.opt_str("out").unwrap_or_else(|| "docs/charts".into());
    let only = match fl.opt_str("only") {
        None => None,
        Some(s) => Some(
            Chart::parse(&s)
                .ok_or_else(|| format!("--only: unknown chart {s:?} (fig5|solvers|tiles|atan)"))?,
        ),
    };
    let cost = if fl.switch("no-cost") {
        AtanCostSource::Skip
    } else {
        let exe = std::env::current_exe().map_err(|e| format!("current executable: {e}"))?;
        AtanCostSource::Callgrind { exe }
    };
    fl.finish()?;
    write_charts(std::path::Path::new(&out), only, &cost)
}

/// `host-sim tile-to-scene <args>`; returns the TOML snippet.
pub fn run_tile_to_scene(args: &[String]) -> Result<String, String> {
    let mut fl = Flags::parse(args)?;
    if fl.switch("help") {
        return Ok(MODEL_USAGE.into());
    }
    let inp = grooved_input(&mut fl)?;
    let speed = fl.opt_f64("speed-mm-s")?;
    let scene_file = fl.switch("scene-file");
    fl.finish()?;
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
    if scene_file {
        s.push_str(&reg.to_scene_file_toml());
    } else {
        s.push_str(&reg.to_toml());
    }
    Ok(s)
}
