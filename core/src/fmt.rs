//! Logging shim: the core logs through defmt on target, through `log` on the host, or not at all.
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
