#!/usr/bin/env python3
"""Regenerates docs/charts/models-*.png and prints the tables of docs/models.md.

usage: python3 host-sim/src/models/charts.py --bin target/release/host-sim [--out docs/charts]

The binary is any front end that forwards `model <name> ...` to host_sim::models::cli
(the host-sim CLI or host-sim/src/bin/models.rs). Needs matplotlib (pip install matplotlib) and,
for the atan cost, valgrind. Every number comes from the binary; nothing is typed in here.
"""
import argparse
import csv
import io
import os
import re
import subprocess
import sys
import tempfile

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def run(binary, *args):
    out = subprocess.run([binary, "model", *args], check=True, capture_output=True, text=True).stdout
    return list(csv.DictReader(io.StringIO(out)))


def fig5(binary, out):
    rows = run(binary, "fig5", "--points", "400")
    dm = [float(r["delta_mu"]) for r in rows]
    f = [float(r["f_ss_hz"]) for r in rows]
    asym = [float(r["asymptote_hz"]) for r in rows]
    f0 = float(rows[0]["f0_hz"])
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.loglog(dm, f, lw=2, label=r"$f_{ss}$ (eq. 10, f64)")
    ax.loglog(dm, asym, "--", label=r"large-R asymptote $kU/(2\Delta\mu P)$")
    ax.axhline(f0, color="gray", ls=":", label=r"$\omega_0/2\pi$ = %.1f Hz ($\Delta\mu$ → 0)" % f0)
    ax.set_ylim(f[-1] * 0.5, f0 * 2)
    ax.set_xlabel(r"$\mu_s - \mu_c$")
    ax.set_ylabel(r"stick-slip frequency $f_{ss}$ (Hz)")
    ax.set_title("Nara et al. fig. 5: P = 1 N, m = 1 g, k = 500 N/m, U = 4 cm/s")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "models-stick-slip-fig5.png"), dpi=110)
    plt.close(fig)
    for target in (0.01, 0.1, 1.0, 10.0):
        i = min(range(len(dm)), key=lambda j: abs(dm[j] - target))
        print(f"fig5: delta_mu = {dm[i]:.4g}: f_ss = {f[i]:.4g} Hz")


def solvers(binary, out):
    rows = run(binary, "theta-solvers")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5))
    print("\n| solver | rtol | solved/cases | mean iter | max iter | mean evals (f + f') | max rel θ error |")
    print("|---|---|---|---|---|---|---|")
    for name, mk in (("newton", "o-"), ("bisection", "s-"), ("safeguarded", "^-")):
        rs = [r for r in rows if r["solver"] == name]
        err = [max(float(r["max_rel_theta_error"]), 1e-17) for r in rs]
        it = [float(r["mean_iterations"]) for r in rs]
        ev = [float(r["mean_evaluations"]) for r in rs]
        a1.semilogx(err, it, mk, label=name)
        a2.semilogx(err, ev, mk, label=name)
        for r in rs:
            if r["rtol"] in ("1e-3", "1e-6", "1e-9", "1e-12", "1e-15"):
                print(
                    f"| {name} | {r['rtol']} | {r['solved']}/{r['cases']} | {float(r['mean_iterations']):.2f} | "
                    f"{r['max_iterations']} | {float(r['mean_evaluations']):.2f} | {float(r['max_rel_theta_error']):.1e} |"
                )
    n = rows[0]["cases"]
    for ax, yl in ((a1, "mean iterations"), (a2, "mean evaluations of eq. 4 + derivative")):
        ax.invert_xaxis()
        ax.set_xlabel(r"achieved accuracy: max $|\theta-\theta_{ref}|/\theta_{ref}$")
        ax.set_ylabel(yl)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(
        f"θ solvers on eq. 4: {n} cases (paper tiles × 1,4,9,16 oz × k 0.008/0.08/0.8 × μ 0/0.5/2), rtol 1e-1…1e-15\n"
        "Newton (from π/4) fails on the cases whose pole θ* < π/4 (counted out of its means)",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(os.path.join(out, "models-theta-solvers.png"), dpi=110)
    plt.close(fig)


def tiles(binary, out):
    rows = run(binary, "tiles")
    sets = ["G (L=0.25)", "L (G=0.25)", "L (G=0.625)"]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7), sharey="row")
    forces = sorted({float(r["force_g"]) for r in rows})
    for j, s in enumerate(sets):
        rs = [r for r in rows if r["set"] == s]
        xkey = "groove_mm" if s.startswith("G") else "land_mm"
        for f in forces:
            rf = [r for r in rs if float(r["force_g"]) == f]
            x = [float(r[xkey]) for r in rf]
            axes[0][j].plot(x, [float(r["a_mm2"]) for r in rf], "o-", ms=3, label=f"F = {f:.0f} g ({f / 28:.0f} oz)")
            axes[1][j].plot(x, [float(r["d_mm"]) for r in rf], "o-", ms=3)
            if f == forces[-1] or f == forces[0]:
                for r in rf:
                    axes[0][j].annotate(r["amplitude_permille"], (float(r[xkey]), float(r["a_mm2"])), fontsize=6,
                                        textcoords="offset points", xytext=(0, 4), ha="center")
        axes[0][j].set_title(s)
        axes[1][j].set_xlabel("groove width G (mm)" if xkey == "groove_mm" else "land width L (mm)")
        for i in range(2):
            axes[i][j].grid(True, alpha=0.3)
    axes[0][0].set_ylabel("A (mm², summed over pad)  [labels: amplitude ‰]")
    axes[1][0].set_ylabel("D (mm)")
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Taylor & Lederman tile sets (figs. 2–4): k = 0.08 mm/g, μ = 0.5, pad 150 mm² at 112 g ∝ F^0.15; "
                 "amplitude ‰ = 1000·A/A_max", fontsize=9)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "models-tiles.png"), dpi=110)
    plt.close(fig)


def callgrind_ir(binary, what, n, sym):
    with tempfile.TemporaryDirectory() as d:
        cg = os.path.join(d, "cg.out")
        subprocess.run(
            ["valgrind", "--tool=callgrind", f"--callgrind-out-file={cg}", f"--toggle-collect=*{sym}*",
             binary, "model", "atan-bench", "--impl", what, "--n", str(n)],
            check=True, capture_output=True,
        )
        with open(cg) as fh:
            m = re.search(r"^(?:summary|totals):\s+(\d+)", fh.read(), re.M)
        return int(m.group(1))


def atan(binary, out):
    err = {r["impl"]: r for r in run(binary, "atan")}
    n1, n2 = 10_000, 20_000
    cost = {}
    for what, sym in (("none", "bench_atan_none"), ("micromath", "bench_atan_micromath"), ("libm", "bench_atan_libm"),
                      ("f64", "bench_atan_f64"), ("fss-micromath", "bench_fss_micromath"), ("fss-libm", "bench_fss_libm")):
        a, b = callgrind_ir(binary, what, n1, sym), callgrind_ir(binary, what, n2, sym)
        cost[what] = (b - a) / (n2 - n1)
    loop = cost["none"]
    print("\n| atan | max abs err (rad) | mean abs err (rad) | max rel f_ss err | mean rel f_ss err | x86-64 instr/call (net of loop) | f_ss per sample, instr |")
    print("|---|---|---|---|---|---|---|")
    for imp in ("micromath", "libm", "f64"):
        e = err[imp]
        fss = cost.get("fss-" + imp)
        print(f"| {imp} | {float(e['max_abs_rad']):.2e} | {float(e['mean_abs_rad']):.2e} | {float(e['max_rel_f_ss']):.2e} | "
              f"{float(e['mean_rel_f_ss']):.2e} | {cost[imp] - loop:.1f} | {'%.1f' % (fss - loop) if fss else '—'} |")
    print(f"(loop overhead {loop:.1f} instr/iteration, subtracted)")
    curve = run(binary, "atan", "--curve")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.5))
    for imp, mk in (("micromath", "o"), ("libm", "s"), ("f64", "^")):
        e = err[imp]
        c = cost[imp] - loop
        a1.loglog(c, float(e["max_abs_rad"]), mk, ms=9, label=f"{imp}: max |atan err|")
        a1.loglog(c, float(e["max_rel_f_ss"]), mk, ms=9, mfc="none", label=f"{imp}: max rel f_ss err")
        rs = [r for r in curve if r["impl"] == imp]
        a2.loglog([float(r["r"]) for r in rs], [max(float(r["abs_err_rad"]), 1e-12) for r in rs], lw=1, label=imp)
    a1.set_xlabel("cost: x86-64 instructions per call (callgrind, loop overhead subtracted)")
    a1.set_ylabel("error")
    a1.grid(True, which="both", alpha=0.3)
    a1.legend(fontsize=7)
    a1.set_title("error against cost, R ∈ [0, 1000]")
    a2.set_xlabel("R = Δμ P/(m ω0 U)")
    a2.set_ylabel("|atan(R) − atan_f64(R)| (rad), floored at 1e-12")
    a2.grid(True, which="both", alpha=0.3)
    a2.legend(fontsize=7)
    a2.set_title("atan error over the R range")
    fig.tight_layout()
    fig.savefig(os.path.join(out, "models-atan.png"), dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--bin", required=True)
    ap.add_argument("--out", default="docs/charts")
    ap.add_argument("--only", choices=["fig5", "solvers", "tiles", "atan"])
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    for name, fn in (("fig5", fig5), ("solvers", solvers), ("tiles", tiles), ("atan", atan)):
        if a.only in (None, name):
            fn(a.bin, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
