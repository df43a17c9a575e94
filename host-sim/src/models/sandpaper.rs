//! Sandpaper grit ↔ burst frequency f_b through the roughness scales of Nara et al., table 1.
//!
//! | grit | scale (real) | f_b    | scale (virtual) | mean projection radius β |
//! |------|--------------|--------|-----------------|--------------------------|
//! | #60  | −1.125       | 20 Hz  | −1.125          | 180 µm                   |
//! | #120 | −0.375       | 40 Hz  | −0.5            | 80 µm                    |
//! | #240 | 0.375        | 80 Hz  | 0.5             | 48 µm                    |
//! | #320 | 1.125        | 200 Hz | 1.125           | 34 µm                    |
//!
//! Mapping (our choice, documented in docs/models.md): scale is piecewise-linear in ln(grit)
//! between the table points, and ln(f_b) is piecewise-linear in the scale (grit and frequency are
//! ratio quantities, so their steps are logarithmic; the scales are interval scales). Both maps
//! are strictly monotone, so they invert exactly, and clamp to the end points outside the table
//! (#60…#320, 20…200 Hz). At a table point the table value is returned exactly.

/// Table 1 rows: (grit, real scale, f_b Hz, virtual scale, β µm).
pub const TABLE1: [(f64, f64, f64, f64, f64); 4] = [
    (60.0, -1.125, 20.0, -1.125, 180.0),
    (120.0, -0.375, 40.0, -0.5, 80.0),
    (240.0, 0.375, 80.0, 0.5, 48.0),
    (320.0, 1.125, 200.0, 1.125, 34.0),
];

/// Result of a sandpaper lookup.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sandpaper {
    /// Grit (clamped to 60…320).
    pub grit: f64,
    /// Roughness scale (Scheffé, table 1).
    pub scale: f64,
    /// Burst frequency f_b, Hz (clamped to 20…200).
    pub f_b_hz: f64,
    /// Mean projection radius β at this grit, µm (ln β linear in ln grit between table points).
    pub beta_um: f64,
    /// True if the input was outside the table and clamped.
    pub clamped: bool,
}

/// Piecewise-linear interpolation over increasing `xs`, clamped, exact at the knots.
fn interp(xs: &[f64; 4], ys: &[f64; 4], x: f64) -> (f64, bool) {
    if x <= xs[0] {
        return (ys[0], x < xs[0]);
    }
    if x >= xs[3] {
        return (ys[3], x > xs[3]);
    }
    let i = (0..3).find(|&i| x < xs[i + 1]).unwrap_or(2);
    if x == xs[i] {
        return (ys[i], false);
    }
    let t = (x - xs[i]) / (xs[i + 1] - xs[i]);
    (ys[i] + t * (ys[i + 1] - ys[i]), false)
}

fn col(c: usize) -> [f64; 4] {
    TABLE1.map(|r| match c {
        0 => r.0,
        1 => r.1,
        2 => r.2,
        3 => r.3,
        _ => r.4,
    })
}

/// Exact table value when `x` is a knot of `xs` (avoids exp(ln y) ≠ y).
fn knot(xs: &[f64; 4], ys: &[f64; 4], x: f64) -> Option<f64> {
    xs.iter().position(|&k| k == x).map(|i| ys[i])
}

fn scale_to_fb(scale: f64) -> f64 {
    let (sv, fb) = (col(3), col(2));
    knot(&sv, &fb, scale).unwrap_or_else(|| interp(&sv, &fb.map(f64::ln), scale).0.exp())
}

fn grit_beta(grit: f64) -> f64 {
    let (g, b) = (col(0), col(4));
    knot(&g, &b, grit)
        .unwrap_or_else(|| interp(&g.map(f64::ln), &b.map(f64::ln), grit.ln()).0.exp())
}

/// grit → scale → f_b.
pub fn from_grit(grit: f64) -> Result<Sandpaper, String> {
    if !(grit.is_finite() && grit > 0.0) {
        return Err("grit must be finite and > 0".into());
    }
    let (g, sr) = (col(0), col(1));
    let clamped = !(60.0..=320.0).contains(&grit);
    let gc = grit.clamp(60.0, 320.0);
    let scale = knot(&g, &sr, gc).unwrap_or_else(|| interp(&g.map(f64::ln), &sr, gc.ln()).0);
    Ok(Sandpaper {
        grit: gc,
        scale,
        f_b_hz: scale_to_fb(scale),
        beta_um: grit_beta(gc),
        clamped,
    })
}

/// f_b → scale → grit.
pub fn from_f_b(f_b_hz: f64) -> Result<Sandpaper, String> {
    if !(f_b_hz.is_finite() && f_b_hz > 0.0) {
        return Err("f_b must be finite and > 0".into());
    }
    let (fb, sv, g, sr) = (col(2), col(3), col(0), col(1));
    let clamped = !(20.0..=200.0).contains(&f_b_hz);
    let fc = f_b_hz.clamp(20.0, 200.0);
    let scale = knot(&fb, &sv, fc).unwrap_or_else(|| interp(&fb.map(f64::ln), &sv, fc.ln()).0);
    let grit = knot(&sr, &g, scale).unwrap_or_else(|| interp(&sr, &g.map(f64::ln), scale).0.exp());
    Ok(Sandpaper {
        grit,
        scale,
        f_b_hz: fc,
        beta_um: grit_beta(grit),
        clamped,
    })
}
