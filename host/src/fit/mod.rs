//! Calibration fitting: one file per method, each citing its equations and source.
//!
//! Convention everywhere: a calibrated reading is `y = A·(x − b)`, with `x` in the units the
//! data was read in and `y` in output units (m/s², rad/s, µT, or normalised to the reference
//! magnitude). For the accelerometer and magnetometer the norm model `|A·(x − b)| = ref` does
//! not determine a rotation of the output, so norm-model fits fix the gauge by taking `A`
//! upper-triangular (9 unknowns); see `ARCHITECTURE.md`, "The fitting problems, precisely".

pub mod alignment;
pub mod axis_aligned;
pub mod chen;
pub(crate) mod corrected_score;
pub mod covariance;
pub mod coverage;
pub mod frosio;
pub mod gyro_bias;
pub mod gyro_joint;
pub mod gyro_scale;
pub mod li;
pub mod li_loo;
pub mod li_loo_first_order;
pub mod li_moments;
pub mod linalg;
pub mod lm;
pub mod loo;
pub mod merayo;
pub mod minmax;
pub(crate) mod norm_jacobian;
pub mod norm_lm;
pub mod norm_loo;
pub mod six_position;
pub mod uncertainty;
pub mod validate;

use nalgebra::{DMatrix, Matrix3, Vector3};

/// 3-vector of f64.
pub type Vec3 = Vector3<f64>;
/// 3×3 matrix of f64.
pub type Mat3 = Matrix3<f64>;

/// One static hold: statistics of the samples taken while the board was still.
#[derive(Debug, Clone, PartialEq)]
pub struct Pose {
    /// Mean reading per axis, in the data's units.
    pub mean: Vec3,
    /// Within-pose variance per axis of the individual samples (not of the mean).
    pub var: Vec3,
    /// Number of samples averaged.
    pub n: usize,
    /// Label from the recording (`pose` column), if any.
    pub label: Option<i64>,
}

impl Pose {
    /// One reading as a pose of one sample (no within-pose variance), for pose-based methods
    /// and leave-one-out run on single samples.
    pub fn single(sample: Vec3) -> Self {
        Self {
            mean: sample,
            var: Vec3::zeros(),
            n: 1,
            label: None,
        }
    }

    /// Variance of the pose mean per axis (`var / n`).
    pub fn var_of_mean(&self) -> Vec3 {
        self.var / (self.n.max(1) as f64)
    }
}

/// A calibration of one sensor: `y = A·(x − b)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Calibration {
    /// Scale, cross-axis and (for the magnetometer) soft-iron matrix.
    pub a: Mat3,
    /// Offset (bias / hard iron), in the data's units.
    pub b: Vec3,
}

impl Calibration {
    /// The identity calibration.
    pub fn identity() -> Self {
        Self {
            a: Mat3::identity(),
            b: Vec3::zeros(),
        }
    }

    /// Whether every entry of `A` and `b` is finite.
    pub fn is_finite(&self) -> bool {
        self.a.iter().chain(self.b.iter()).all(|v| v.is_finite())
    }

    /// Apply the calibration to one reading.
    pub fn apply(&self, x: &Vec3) -> Vec3 {
        self.a * (x - self.b)
    }
}

/// One-sigma uncertainties of a calibration's entries (zero where an entry is fixed by the gauge).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationStd {
    /// Standard deviation of each entry of `A`.
    pub a: Mat3,
    /// Standard deviation of each entry of `b`.
    pub b: Vec3,
}

/// The result of a fit.
#[derive(Debug, Clone)]
pub struct Fit {
    /// Which method produced it.
    pub method: Method,
    /// The fitted parameters.
    pub cal: Calibration,
    /// Residual per pose or sample. Accelerometer and magnetometer fits (six-position
    /// included): `(|A(x−b)| − ref) / ref` (relative); gyroscope bias: the norm of the
    /// calibrated rate left at rest, in output units.
    pub residuals: Vec<f64>,
    /// Root mean square of `residuals`.
    pub rms: f64,
    /// Leave-one-pose-out RMS (static-pose fits only): each pose predicted by a fit without it.
    pub loo_rms: Option<f64>,
    /// Parameter covariance from the Gauss–Newton normal matrix, with the noise taken from the
    /// within-pose variance; order documented by `param_names`.
    pub covariance: Option<DMatrix<f64>>,
    /// Names of the parameters in `covariance` order (e.g. `"A11"`, `"b1"`).
    pub param_names: Vec<String>,
    /// One-sigma uncertainties mapped back onto `A` and `b`.
    pub std: Option<CalibrationStd>,
    /// Condition number of the (weighted) Jacobian or design matrix at the solution, with its
    /// columns scaled to unit length so that it does not depend on the parameters' units (Li's
    /// algebraic fit: of its own design, see `fit::li`).
    pub condition_number: f64,
    /// Iterations used (0 for closed-form methods).
    pub iterations: usize,
    /// Why the iterative solver stopped (`None` for closed-form methods and for the methods
    /// with their own Gauss–Newton loop). Always a convergence reason: a solver that stopped
    /// for any other reason makes the fit fail with [`FitError::NotConverged`].
    pub termination: Option<lm::Termination>,
    /// `k` such that `±k·σ` (from `std`) is a 95 % interval: 1.96 with known noise that the
    /// residuals agree with, Student's t when the noise scale was estimated (see
    /// [`uncertainty`]).
    pub coverage_factor: f64,
    /// Reference magnitude the fit was normalised to (g, field strength, or 1).
    pub reference: f64,
}

impl Fit {
    /// A closed-form ellipsoid fit of samples: the relative norm residual of every point, no
    /// covariance (the algebraic methods have none of their own).
    pub(crate) fn closed_form(
        method: Method,
        cal: Calibration,
        points: &[Vec3],
        reference: f64,
        condition_number: f64,
    ) -> Fit {
        let residuals: Vec<f64> = points
            .iter()
            .map(|p| (cal.apply(p).norm() - reference) / reference)
            .collect();
        Fit {
            method,
            cal,
            rms: linalg::rms(&residuals),
            residuals,
            loo_rms: None,
            covariance: None,
            param_names: Vec::new(),
            std: None,
            condition_number,
            iterations: 0,
            termination: None,
            coverage_factor: crate::fit::uncertainty::Z_95,
            reference,
        }
    }
}

/// Every fitting method the library implements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// Gyroscope bias by averaging still data (seed 000 eq. 9; seed 004).
    GyroBias,
    /// Min/max six-face bias and scale (seed 004).
    MinMax,
    /// Axis-aligned ellipsoid by linear least squares (seed 004).
    AxisAligned,
    /// Six-position linear least squares by SVD (seed 000 eq. 11–15).
    SixPosition,
    /// Chen et al.: six-position coarse model, then twelve-position iteration on the norm model (seed 003).
    Chen,
    /// General ellipsoid fit after Li & Griffiths with the `M^½` construction (seed 000 eq. 17–29).
    Li,
    /// Levenberg–Marquardt on the measurement residual `|A(x−b)| − ref` (the default).
    Lm,
    /// Plain Gauss–Newton in the manner of Frosio et al. (seed 000 Table 1–2).
    Frosio,
    /// Merayo's ellipsoid method (seed 000 Table 1–2).
    Merayo,
    /// Gyroscope scale and misalignment from rotations between still poses (Tedaldi et al. 2014).
    GyroScale,
    /// The mean of the min/max and axis-aligned calibrations' outputs: the default accelerometer
    /// chain's model when the data cannot tell those two 6-unknown models apart (not offered as
    /// `--method`).
    MinMaxAxisAlignedMean,
}

impl Method {
    /// Stable name used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Method::GyroBias => "gyro-bias",
            Method::MinMax => "minmax",
            Method::AxisAligned => "axis-aligned",
            Method::SixPosition => "six-position",
            Method::Chen => "chen",
            Method::Li => "li",
            Method::Lm => "lm",
            Method::Frosio => "frosio",
            Method::Merayo => "merayo",
            Method::GyroScale => "gyro-scale",
            Method::MinMaxAxisAlignedMean => "minmax+axis-aligned",
        }
    }
}

/// Why a fit was refused or failed. Every variant reads as a sentence a user can act on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// The data cannot determine the parameters; the message says what is missing
    /// (e.g. "no pose with −Z up", "all poses lie within 20° of a plane").
    #[error("the data cannot determine the calibration: {0}")]
    Underdetermined(String),
    /// Input contained NaN or infinite values.
    #[error("input contains a non-finite value ({0})")]
    NonFinite(String),
    /// An iterative method did not converge.
    #[error("{method} did not converge after {iterations} iterations ({detail})")]
    NotConverged {
        /// Method name.
        method: &'static str,
        /// Iterations spent.
        iterations: usize,
        /// What went wrong.
        detail: String,
    },
}
