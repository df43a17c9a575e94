//! Strokes the guards' tests share (`gate`, `clamp`): a clean one, and the check that a guard
//! hands its inner estimator such a stroke untouched.

use super::VelocityEstimator;

/// 20 mm/s with a small deterministic dither (±3 µm), as a clean stroke, µm at sample `i`.
pub(crate) fn ramp(i: u32) -> i32 {
    10_000 + 2 * i as i32 + [0, 3, -2, 1, -3, 2][i as usize % 6]
}

/// On a clean stroke (20 mm/s accelerating to 300 mm/s: steps up to 30 µm) `guarded` answers
/// what `bare` answers, sample by sample, with the same group delay.
pub(crate) fn assert_a_clean_ramp_is_untouched<G: VelocityEstimator, B: VelocityEstimator>(
    mut guarded: G,
    mut bare: B,
    period_us: u32,
) {
    for i in 0..2_000u32 {
        let x = ramp(i) + (i * i / 1_400) as i32;
        let t = i * period_us;
        assert_eq!(guarded.update(x, t), bare.update(x, t), "sample {i}");
    }
    assert_eq!(guarded.group_delay_us(), bare.group_delay_us());
}
