//! Log macros: forwarded to defmt with the `defmt` feature, compiled away without it (host and
//! simulator builds), so the arguments cost nothing there.

macro_rules! log_warn {
    ($($arg:tt)*) => {{
        #[cfg(feature = "defmt")]
        defmt::warn!($($arg)*);
    }};
}

macro_rules! log_info {
    ($($arg:tt)*) => {{
        #[cfg(feature = "defmt")]
        defmt::info!($($arg)*);
    }};
}

macro_rules! log_error {
    ($($arg:tt)*) => {{
        #[cfg(feature = "defmt")]
        defmt::error!($($arg)*);
    }};
}

pub(crate) use {log_error, log_info, log_warn};
