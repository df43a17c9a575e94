//! Test helpers shared by the plane's tests: a seeded Gaussian and the 2D sensor's noise.
//!
//! The 2D sensor (a 4-wire resistive plate, docs/plane.md) is read one axis at a time with the
//! same 16-conversion sum as the 1D rheostat; the touch stage maps each axis's code to µm with
//! an affine calibration. Taking ~1 µm per code on both axes (the rheostat's 63 mm over 96 % of
//! 65 520 codes), k LSB RMS of conversion noise is k·√16 = 4k µm RMS per axis, independent on
//! the two axes.

/// µm RMS per axis for `lsb` LSB RMS of conversion noise (16 conversions summed, 1 µm a code).
pub(crate) fn sigma_um(lsb: f64) -> f64 {
    lsb * 4.0
}

/// A seeded xorshift with Box–Muller Gaussians.
pub(crate) struct Noise(u64);

impl Noise {
    pub(crate) fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1)
    }

    pub(crate) fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    pub(crate) fn gauss(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (core::f64::consts::TAU * v).cos()
    }
}

/// The eight stroke directions, unit vectors: every 45° from +x.
pub(crate) fn directions() -> [(f64, f64); 8] {
    core::array::from_fn(|k| {
        let a = k as f64 * core::f64::consts::FRAC_PI_4;
        (a.cos(), a.sin())
    })
}

/// Sample period of the unit tests' strokes, µs (the controller's 10 kHz).
pub(crate) const PERIOD_US: u32 = 100;
