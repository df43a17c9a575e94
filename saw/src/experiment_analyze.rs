//! `saw experiment analyze`: reads the CSV files (and the sessions' sidecars beside them, for
//! each block's stimuli in the protocol's order), runs the analysis, prints it as text or JSON
//! and draws the chart. The analysis itself is `saw_experiment::analysis`.

use std::path::Path;

use saw_experiment::analysis::paired::Variant;
use saw_experiment::analysis::report::{self, Options, Report};
use serde_json::{json, Value};

use crate::experiment::Method;
use crate::{significant, Done, Failure};

/// Reads, analyses, prints (and charts).
pub fn analyze(
    files: &[std::path::PathBuf],
    method: Option<Method>,
    output: Option<&Path>,
) -> Result<Done, Failure> {
    let mut opts = Options {
        method: method.map(|m| match m {
            Method::Scheffe => Variant::Scheffe,
            Method::Ura => Variant::Ura,
            Method::Haga => Variant::Haga,
            Method::Nakaya => Variant::Nakaya,
        }),
        ..Options::default()
    };
    let data =
        saw_experiment::session::read_for_analysis(files, &mut opts).map_err(Failure::input)?;
    let r = report::analyze(&data, &opts).map_err(|e| Failure::input(e.to_string()))?;
    // Every block refused: the refusals are the answer (exit 2); some refused: reported with
    // the rest.
    if r.paired.is_empty() && r.tracks.is_empty() && r.constant.is_empty() && !r.refused.is_empty()
    {
        return Err(Failure::input(
            r.refused
                .iter()
                .map(|e| e.to_string())
                .collect::<Vec<_>>()
                .join("; "),
        ));
    }
    let mut text = render(&r);
    if let Some(png) = output {
        chart(&r, png)?;
        text += &format!("\nchart: {}", png.display());
    }
    Ok(Done {
        text,
        json: serde_json::to_value(&r).unwrap_or(Value::Null),
    })
}

/// Draws the report's chart.
#[cfg(feature = "chart")]
fn chart(r: &Report, png: &Path) -> Result<(), Failure> {
    if let Some(dir) = png.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.is_dir() {
            return Err(Failure::input(format!(
                "-o {}: the directory {} does not exist",
                png.display(),
                dir.display()
            )));
        }
    }
    saw_experiment::chart::draw(r, png)
        .map_err(|e| Failure::input(format!("-o {}: {e}", png.display())))
}

/// Without the chart feature there is no chart.
#[cfg(not(feature = "chart"))]
fn chart(_: &Report, png: &Path) -> Result<(), Failure> {
    Err(Failure::input(format!(
        "-o {}: this saw was built without charts (cargo feature `chart`)",
        png.display()
    )))
}

fn num(v: f64) -> String {
    significant(v, 4)
}

/// The report as text.
fn render(r: &Report) -> String {
    let mut out = String::new();
    for b in &r.paired {
        let a = &b.scheffe;
        out += &format!(
            "block \"{}\": paired comparisons, {} subjects, {} judgments, Scheffé's method ({} variant)\n",
            b.block,
            b.subjects,
            b.judgments,
            json!(a.variant).as_str().unwrap_or("?")
        );
        let mut order: Vec<usize> = (0..a.stimuli.len()).collect();
        order.sort_by(|&i, &j| a.scale[i].total_cmp(&a.scale[j]));
        out += "  stimulus            scale    thurstone  bradley-terry\n";
        for i in order {
            let s = &a.stimuli[i];
            let t = b
                .thurstone
                .as_ref()
                .and_then(|m| m.get(s))
                .map_or("-".into(), |v| num(*v));
            let bt = b
                .bradley_terry
                .as_ref()
                .and_then(|m| m.get(s))
                .map_or("-".into(), |v| num(*v));
            out += &format!("  {:<18} {:>7}  {:>9}  {:>13}\n", s, num(a.scale[i]), t, bt);
        }
        out += "  source                    SS      df        MS         F        p\n";
        for row in &a.anova {
            out += &format!(
                "  {:<18} {:>10} {:>7} {:>9} {:>9} {:>8}\n",
                json!(row.source).as_str().unwrap_or("?"),
                num(row.ss),
                num(row.df),
                row.ms.map_or("".into(), num),
                row.f.map_or("".into(), num),
                row.p.map_or("".into(), |p| if p < 1e-4 {
                    "<0.0001".to_string()
                } else {
                    format!("{p:.4}")
                }),
            );
        }
        for y in &a.yardstick {
            out += &format!(
                "  yardstick at {} %: q = {}, Y = {}; pairs it separates: {}\n",
                y.alpha * 100.0,
                num(y.q),
                num(y.y),
                if y.separated.is_empty() {
                    "none".to_string()
                } else {
                    y.separated
                        .iter()
                        .map(|(p, q)| format!("{p}–{q}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            );
        }
    }
    for c in &r.correlations {
        out += &format!(
            "scales of \"{}\" and \"{}\" ({}): Pearson r = {}, Spearman ρ = {}\n",
            c.blocks.0,
            c.blocks.1,
            c.pairs
                .iter()
                .map(|(a, b)| format!("{a}~{b}"))
                .collect::<Vec<_>>()
                .join(", "),
            c.pearson.map_or("-".into(), |v| format!("{v:.3}")),
            c.spearman.map_or("-".into(), |v| format!("{v:.3}")),
        );
    }
    for t in &r.tracks {
        out += &format!(
            "staircase \"{}\" of {} in block \"{}\": {} trials, {} reversals, threshold {} (mean of the last {} reversals)\n",
            t.track,
            t.subject,
            t.block,
            t.levels.len(),
            t.reversal_levels.len(),
            t.threshold.map_or("- (too few reversals)".into(), num),
            t.threshold_reversals
        );
    }
    let fitted = r.constant.iter().map(|c| (c, "constant stimuli")).chain(
        r.staircase_fits
            .iter()
            .map(|c| (c, "the staircases' trials")),
    );
    for (c, what) in fitted {
        out += &format!(
            "block \"{}\": psychometric fit of {what}, {} levels, {} trials\n",
            c.block,
            c.points.len(),
            c.points.iter().map(|p| p.n_trials).sum::<u32>()
        );
        for f in &c.fits {
            match &f.result {
                Ok(ci) => {
                    let level_ci = ci.level_at_target.map_or(String::new(), |i| {
                        format!(" [{}, {}]", num(i.lower), num(i.upper))
                    });
                    out += &format!(
                        "  {:?}: level at {:.1} % = {}{}; α = {} [{}, {}], β = {} [{}, {}] (95 % bootstrap, {} resamples)\n",
                        f.model,
                        ci.fit.target * 100.0,
                        ci.fit.level_at_target.map_or("-".into(), num),
                        level_ci,
                        num(ci.fit.alpha),
                        num(ci.alpha.lower),
                        num(ci.alpha.upper),
                        num(ci.fit.beta),
                        num(ci.beta.lower),
                        num(ci.beta.upper),
                        ci.n_resamples
                    );
                    // Resamples with no maximum (all right at every level, say) pile up at the
                    // search's bounds: an interval built on many of them says little.
                    if ci.n_degenerate * 10 > ci.n_resamples {
                        out += &format!(
                            "    caution: {} of {} resamples had no maximum-likelihood fit, so these intervals are unreliable; levels nearer the threshold or more trials would steady them\n",
                            ci.n_degenerate, ci.n_resamples
                        );
                    }
                }
                Err(e) => out += &format!("  {:?}: no fit: {e}\n", f.model),
            }
        }
    }
    for e in &r.refused {
        out += &format!("not analysed: {e}\n");
    }
    out.trim_end().to_string()
}
