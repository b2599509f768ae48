//! Statistics shared by still detection, noise estimation and residual analysis. Each function
//! names its formula and source; none depends on recordings or fits.

pub mod autocorrelation;
pub mod batch_means;
pub mod chi_square;
pub mod descriptive;
pub mod distributions;
pub mod robust;
pub mod threshold;

/// 3-vector of f64: per-axis statistics (the same type as `crate::fit::Vec3`, named here so that
/// the statistics depend on no other part of the library).
pub type Vec3 = nalgebra::Vector3<f64>;
