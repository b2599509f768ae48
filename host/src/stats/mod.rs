//! Statistics shared by still detection, noise estimation and residual analysis. Each function
//! names its formula and source; none depends on recordings or fits.

pub mod autocorrelation;
pub mod chi_square;
pub mod descriptive;
pub mod distributions;
pub mod threshold;
