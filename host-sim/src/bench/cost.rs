//! Cost per sample, counted deterministically: instructions executed inside the estimator, as
//! counted by valgrind's callgrind (`Ir`), not wall time.
//!
//! The bench re-runs its own executable under
//! `valgrind --tool=callgrind --toggle-collect=*cost_kernel*` with `SAW_BENCH_COST=<method>` set;
//! in that mode it only feeds the method a fixed, pre-made stream inside [`cost_kernel`], so the
//! count covers exactly the `update` calls (plus one indirect call and the loop, ≈ 8
//! instructions per sample, the same for every method). The figures are x86-64 instructions of
//! the release build: a faithful *ranking* of the arithmetic and memory work, not Cortex-M4
//! cycles (there an f32 multiply is one cycle like an integer one, a 64-bit multiply-accumulate
//! one or two, sqrt 14; on a core without FPU the f32 methods would cost tens of times more).

use std::path::Path;
use std::process::Command;

use saw_core::velocity::VelocityEstimator;

use super::methods::Method;
use super::scenario::{reference_spec, Input};

/// Environment variable that switches the executable into cost-kernel mode.
pub const COST_ENV: &str = "SAW_BENCH_COST";
/// Samples fed in the cost run.
pub const COST_SAMPLES: usize = 20_000;

/// Feeds the stream to the estimator; the only code callgrind counts.
#[inline(never)]
pub fn cost_kernel(e: &mut dyn VelocityEstimator, xs: &[(i32, u32)]) -> i64 {
    let mut acc = 0i64;
    for &(x, t) in xs {
        if let Some(v) = e.update(x, t) {
            acc = acc.wrapping_add(v as i64);
        }
    }
    acc
}

/// Cost-kernel mode: run `method` over the reference stream once.
pub fn run_kernel(method: &Method, seed: u64) {
    let spec = reference_spec(seed);
    let period = spec.period_us();
    let xs: Vec<(i32, u32)> = spec
        .generate()
        .into_iter()
        .filter_map(|o| match o.input {
            Input::Position(x) => Some((x, o.t_us)),
            _ => None,
        })
        .take(COST_SAMPLES)
        .collect();
    let mut e = (method.build)(period);
    let acc = cost_kernel(e.as_mut(), std::hint::black_box(&xs));
    println!("{} {} {}", method.name, xs.len(), acc);
}

/// True when valgrind can be run.
pub fn valgrind_available() -> bool {
    Command::new("valgrind")
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Instructions per sample of `method`, from a callgrind run of this executable.
pub fn measure(method: &Method, seed: u64, work_dir: &Path) -> Result<f64, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let out_file = work_dir.join(format!("callgrind.{}.out", method.name));
    let args: Vec<String> = std::env::args().skip(1).collect();
    let status = Command::new("valgrind")
        .arg("--tool=callgrind")
        .arg("--toggle-collect=*cost_kernel*")
        .arg(format!("--callgrind-out-file={}", out_file.display()))
        .arg(&exe)
        .args(&args)
        .env(COST_ENV, method.name)
        .env("SAW_BENCH_COST_SEED", seed.to_string())
        .output()
        .map_err(|e| format!("valgrind: {e}"))?;
    if !status.status.success() {
        return Err(format!(
            "valgrind failed for {}: {}",
            method.name,
            String::from_utf8_lossy(&status.stderr)
        ));
    }
    let text = std::fs::read_to_string(&out_file).map_err(|e| e.to_string())?;
    let _ = std::fs::remove_file(&out_file);
    let total = text
        .lines()
        .find_map(|l| {
            l.strip_prefix("summary:")
                .or_else(|| l.strip_prefix("totals:"))
        })
        .and_then(|s| s.split_whitespace().next())
        .and_then(|s| s.parse::<u64>().ok())
        .ok_or_else(|| format!("no summary in {}", out_file.display()))?;
    let stdout = String::from_utf8_lossy(&status.stdout);
    let n: usize = stdout
        .lines()
        .find_map(|l| {
            let mut it = l.split_whitespace();
            (it.next() == Some(method.name)).then(|| it.next()?.parse().ok())?
        })
        .ok_or_else(|| format!("kernel printed no count: {stdout}"))?;
    Ok(total as f64 / n as f64)
}
