//! Grooved tile → grating region of a scene.
//!
//! λ = G + L (Konyo et al., eq. 1: f = V/λ with λ = ridge width + groove width). The drive
//! amplitude follows the skin model's A (Taylor & Lederman's preferred "stimulus for roughness"),
//! normalised to the largest A over the paper's tile sets and forces ([`paper_tiles`], k = 0.08
//! mm/g, μ = 0.5): amplitude_permille = round(1000 · A/A_max), clamped to 1…1000 (the core
//! rejects 0). This assumes the felt roughness the display should reproduce scales linearly with
//! drive amplitude, which no source paper establishes; it is a placeholder to be calibrated.

use super::grooved::{grooved, GroovedError, GroovedInput, SolveOptions, Solver};

/// 1 oz in g, as the paper rounds it.
pub const OZ_G: f64 = 28.0;

/// The four finger forces of the paper's pad measurements: 1, 4, 9 and 16 oz.
pub const PAPER_FORCES_G: [f64; 4] = [OZ_G, 4.0 * OZ_G, 9.0 * OZ_G, 16.0 * OZ_G];

/// One tile of the paper's sets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile {
    /// Set name: "G (L=0.25)", "L (G=0.25)" or "L (G=0.625)".
    pub set: &'static str,
    /// Tile label (G1…G8, L1…L8).
    pub label: &'static str,
    /// Groove width G, mm.
    pub groove_mm: f64,
    /// Land width L, mm.
    pub land_mm: f64,
}

const G_LABELS: [&str; 8] = ["G1", "G2", "G3", "G4", "G5", "G6", "G7", "G8"];
const L_LABELS: [&str; 8] = ["L1", "L2", "L3", "L4", "L5", "L6", "L7", "L8"];
/// Land widths L1…L8: 0.007 in, then 0.010…0.040 in by 0.005 in (paper's mm values).
const LANDS: [f64; 8] = [0.18, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0];

/// The tile sets of Taylor & Lederman figs. 2–4 (Lederman 1974, Exps. IV and III):
/// G-set L = 0.25 mm, G = 0.125…1.0 mm by 0.125; L-sets with G = 0.25 and 0.625 mm,
/// L = 0.18, 0.25…1.0 mm by 0.125.
pub fn paper_tiles() -> Vec<Tile> {
    let mut v = Vec::new();
    for (i, label) in G_LABELS.iter().enumerate() {
        v.push(Tile {
            set: "G (L=0.25)",
            label,
            groove_mm: 0.125 * (i + 1) as f64,
            land_mm: 0.25,
        });
    }
    for (set, g) in [("L (G=0.25)", 0.25), ("L (G=0.625)", 0.625)] {
        for (label, l) in L_LABELS.iter().zip(LANDS) {
            v.push(Tile {
                set,
                label,
                groove_mm: g,
                land_mm: l,
            });
        }
    }
    v
}

/// Largest A over [`paper_tiles`] × [`PAPER_FORCES_G`] with the paper's k and μ, mm².
pub fn a_max_mm2() -> Result<f64, GroovedError> {
    let mut m: f64 = 0.0;
    for t in paper_tiles() {
        for f in PAPER_FORCES_G {
            let r = grooved(
                &GroovedInput::paper(t.groove_mm, t.land_mm, f),
                Solver::Safeguarded,
                &SolveOptions::default(),
            )?;
            m = m.max(r.a_mm2);
        }
    }
    Ok(m)
}

/// A grating region made from a tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GratingRegion {
    /// λ = G + L, µm.
    pub wavelength_um: u32,
    /// 1…1000.
    pub amplitude_permille: u16,
    /// The model's A, mm².
    pub a_mm2: f64,
    /// The normaliser A_max, mm².
    pub a_max_mm2: f64,
}

/// Tile (G, L, F) → grating region, with `inp.k_mm_per_g`, `inp.mu`, `inp.pad` as given.
pub fn tile_to_region(inp: &GroovedInput) -> Result<GratingRegion, GroovedError> {
    let r = grooved(inp, Solver::Safeguarded, &SolveOptions::default())?;
    let a_max = a_max_mm2()?;
    let wl = ((inp.groove_mm + inp.land_mm) * 1000.0).round();
    if !(1.0..=u32::MAX as f64).contains(&wl) {
        return Err(GroovedError::InvalidInput(
            "wavelength G + L must be between 1 um and u32::MAX um",
        ));
    }
    let amp = (1000.0 * r.a_mm2 / a_max).round().clamp(1.0, 1000.0) as u16;
    Ok(GratingRegion {
        wavelength_um: wl as u32,
        amplitude_permille: amp,
        a_mm2: r.a_mm2,
        a_max_mm2: a_max,
    })
}

impl GratingRegion {
    /// The same region with the keys `scenes/*.toml` files use (saw_core::scene_file):
    /// `wavelength_mm` and `amplitude_percent` (one decimal, so the ‰ value is kept exactly).
    pub fn to_scene_file_toml(&self) -> String {
        format!(
            "[[region]]\nkind = \"grating\"\nwavelength_mm = {}\namplitude_percent = {}\n",
            self.wavelength_um as f64 / 1000.0,
            self.amplitude_permille as f64 / 10.0
        )
    }
}

/// One tile of the paper's sets at one force, with the paper's k and μ.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TileRow {
    /// The tile.
    pub tile: Tile,
    /// Finger force, g.
    pub force_g: f64,
    /// θ of eq. 4, rad.
    pub theta_rad: f64,
    /// D of eq. 1, mm.
    pub d_mm: f64,
    /// A_c summed over the pad, mm².
    pub a_c_mm2: f64,
    /// A summed over the pad, mm².
    pub a_mm2: f64,
    /// λ = G + L of the grating region, µm.
    pub wavelength_um: u32,
    /// Drive amplitude of the grating region, ‰ (1000·A/A_max).
    pub amplitude_permille: u16,
}

/// [`paper_tiles`] × [`PAPER_FORCES_G`] (tile-major), solved with safeguarded Newton.
pub fn tile_rows() -> Result<Vec<TileRow>, String> {
    let mut v = Vec::new();
    for t in paper_tiles() {
        for f in PAPER_FORCES_G {
            let inp = GroovedInput::paper(t.groove_mm, t.land_mm, f);
            let r = grooved(&inp, Solver::Safeguarded, &SolveOptions::default())
                .map_err(|e| e.to_string())?;
            let reg = tile_to_region(&inp).map_err(|e| e.to_string())?;
            v.push(TileRow {
                tile: t,
                force_g: f,
                theta_rad: r.theta_rad,
                d_mm: r.d_mm,
                a_c_mm2: r.a_c_mm2,
                a_mm2: r.a_mm2,
                wavelength_um: reg.wavelength_um,
                amplitude_permille: reg.amplitude_permille,
            });
        }
    }
    Ok(v)
}
