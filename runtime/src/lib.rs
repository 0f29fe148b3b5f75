//! x

#[cfg(feature = "gpu")]
pub mod gpu;
