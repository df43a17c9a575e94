//! Logging shim: the core logs through defmt on target, through `log` on the host, or not at all;
//! and the rate limit of its repeated lines.
//!
//! Same idea as embassy's `fmt.rs`: callers write `info!("…", x)` with `{}` for integers and
//! `{:?}` for enums, which defmt, `log` and `core::format_args!` all accept, so every log line
//! type-checks in all three builds. With neither feature the arguments are still borrowed (no
//! unused warnings) but nothing is formatted.
#![allow(unused_macros)]

macro_rules! trace {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")] ::defmt::trace!($($t)*);
        #[cfg(all(feature = "log", not(feature = "defmt")))] ::log::trace!($($t)*);
        #[cfg(not(any(feature = "defmt", feature = "log")))] { let _ = ::core::format_args!($($t)*); }
    }};
}
macro_rules! debug {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")] ::defmt::debug!($($t)*);
        #[cfg(all(feature = "log", not(feature = "defmt")))] ::log::debug!($($t)*);
        #[cfg(not(any(feature = "defmt", feature = "log")))] { let _ = ::core::format_args!($($t)*); }
    }};
}
macro_rules! info {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")] ::defmt::info!($($t)*);
        #[cfg(all(feature = "log", not(feature = "defmt")))] ::log::info!($($t)*);
        #[cfg(not(any(feature = "defmt", feature = "log")))] { let _ = ::core::format_args!($($t)*); }
    }};
}
macro_rules! warn {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")] ::defmt::warn!($($t)*);
        #[cfg(all(feature = "log", not(feature = "defmt")))] ::log::warn!($($t)*);
        #[cfg(not(any(feature = "defmt", feature = "log")))] { let _ = ::core::format_args!($($t)*); }
    }};
}
macro_rules! error {
    ($($t:tt)*) => {{
        #[cfg(feature = "defmt")] ::defmt::error!($($t)*);
        #[cfg(all(feature = "log", not(feature = "defmt")))] ::log::error!($($t)*);
        #[cfg(not(any(feature = "defmt", feature = "log")))] { let _ = ::core::format_args!($($t)*); }
    }};
}

/// A count of thousandths shown in the unit the user wrote: 63 000 µm as `63` mm, 42 mHz as
/// `0.042` Hz, 1 500 µs as `1.5` ms (trailing zeros dropped, so `20` rather than `20.000`).
/// For the error sentences' `Display`, which only the host formats (the firmware logs errors
/// through defmt), so on target it is never linked.
pub(crate) struct Milli(pub u64);

impl core::fmt::Display for Milli {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        frac(f, self.0, 1000)
    }
}

/// A count of tenths shown in the unit the user wrote: 505 ‰ as `50.5` %.
pub(crate) struct Deci(pub u64);

impl core::fmt::Display for Deci {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        frac(f, self.0, 10)
    }
}

/// `x / scale` in decimal, the fraction's trailing zeros dropped (`scale` a power of ten).
fn frac(f: &mut core::fmt::Formatter<'_>, x: u64, scale: u64) -> core::fmt::Result {
    write!(f, "{}", x / scale)?;
    let (mut rest, mut digit) = (x % scale, scale / 10);
    if rest != 0 {
        f.write_str(".")?;
        while rest != 0 {
            write!(f, "{}", rest / digit)?;
            rest %= digit;
            digit /= 10;
        }
    }
    Ok(())
}

/// Region changes and clamps are logged at most this often; the rest are counted.
pub const LOG_INTERVAL_US: u32 = 100_000;

/// A rate limit for log lines, on the sample clock (the core reads no clock of its own).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct LogLimit {
    last_us: Option<u32>,
    suppressed: u32,
}

impl LogLimit {
    /// True when a line may be logged now; otherwise counts it as suppressed.
    pub(crate) fn due(&mut self, t_us: u32) -> bool {
        let due = self
            .last_us
            .is_none_or(|last| t_us.wrapping_sub(last) >= LOG_INTERVAL_US);
        if due {
            self.last_us = Some(t_us);
        } else {
            self.suppressed += 1;
        }
        due
    }

    /// Lines suppressed since the last logged one; resets the count.
    pub(crate) fn take_suppressed(&mut self) -> u32 {
        core::mem::take(&mut self.suppressed)
    }
}
