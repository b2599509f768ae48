//! The base model extended by a set of effects (see [`super::effects`]), fitted jointly by the
//! generic Levenberg–Marquardt solver (`fit::lm`) on noise-weighted residuals.
//!
//! Norm model (accelerometer, magnetometer; seed 003's iteration on `|A(v)| = g`, seed 000
//! eq. 17–29 for the ellipsoid): `rᵢ = (|yᵢ|/ref − 1)/σ'ᵢ`, `A` upper-triangular (the gauge of
//! `fit::norm_lm`), or diagonal for the axis-aligned base (seed 004). Gyroscope at rest (seed
//! 000 eq. 9): `rᵢ = yᵢ/σᵢ` per axis, since the true rate is zero. The unknowns are solved for in centred, scaled data (`x̃ = (x − c)/s`,
//! `τ = (T − T₀)/s_T`, `θ = (t − t₀)/s_t`, `f̃ = f/g`) where every parameter is of order one, and
//! are mapped back to physical units afterwards. The weights `1/σ'ᵢ` are fixed once (from the
//! base fit) so that the losses of nested models are comparable. The Jacobian is by central
//! differences: the models are small and smooth, and a single code path serves every effect.

use nalgebra::{DMatrix, DVector};

use super::effects::{EffectKind, BINS};
use crate::fit::lm::{levenberg_marquardt, LeastSquaresProblem, LmOptions};
use crate::fit::validate::{count_distinct, DISTINCT_DEG};
use crate::fit::{Calibration, Mat3, Vec3};
use crate::pipeline::observations::Observation;

/// Which kind of base model a sensor has.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BaseKind {
    /// `|A(x − b)| = reference` (accelerometer, magnetometer).
    Norm {
        /// Reference magnitude (g or the field strength, or 1).
        reference: f64,
        /// `A` diagonal (6 unknowns: the axis-aligned models of seed 004) instead of upper
        /// triangular (9): the base when the poses cannot determine the full model.
        axis_aligned: bool,
    },
    /// `A(x − b) = 0` at rest with `A = scale·I` (gyroscope).
    Rest {
        /// Data unit to rad/s.
        scale: f64,
    },
}

/// The observations in the scaled coordinates the solver works in.
#[derive(Debug, Clone)]
pub struct Problem {
    /// Base model.
    pub base: BaseKind,
    /// Centred, scaled readings `x̃ᵢ`.
    pub points: Vec<Vec3>,
    /// Per-observation weights: norm model one per observation, rest model one per axis.
    pub weights: Vec<Vec3>,
    /// `τᵢ`, or `None` when temperature is not recorded (or does not vary).
    pub tau: Option<Vec<f64>>,
    /// `θᵢ`.
    pub theta: Vec<f64>,
    /// `f̃ᵢ` (specific force over g), when known.
    pub force: Option<Vec<Vec3>>,
    /// Centre `c` (data units).
    pub centre: Vec3,
    /// Scale `s` (data units).
    pub scale: f64,
    /// Reference temperature `T₀` and temperature scale `s_T` (°C).
    pub temp_ref: (f64, f64),
    /// Reference time `t₀` and time scale `s_t` (s).
    pub time_ref: (f64, f64),
    /// Gravity used to scale `f` (m/s²).
    pub force_scale: f64,
    /// Quantile bin (0..BINS) of each observation's time.
    pub time_bins: Vec<usize>,
    /// Quantile bin of each observation's temperature, when recorded.
    pub temp_bins: Option<Vec<usize>>,
}

/// Quantile bin of each value (ties share a bin).
fn quantile_bins(values: &[f64]) -> Vec<usize> {
    let mut sorted: Vec<f64> = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let n = sorted.len().max(1);
    values
        .iter()
        .map(|v| {
            let rank = sorted.partition_point(|s| s < v);
            (rank * BINS / n).min(BINS - 1)
        })
        .collect()
}

fn mean_std(values: &[f64]) -> (f64, f64) {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

impl Problem {
    /// Build the scaled problem. `start` is the base fit (its offset is the centre, and for the
    /// norm model its gain turns each pose's axis noise into the noise of the calibrated norm).
    /// `force` is the calibrated specific force of each observation in m/s², when known.
    pub fn new(
        obs: &[Observation],
        base: BaseKind,
        start: &Calibration,
        force: Option<Vec<Vec3>>,
        gravity: f64,
    ) -> Self {
        let centre = start.b;
        let scale = match base {
            BaseKind::Norm { .. } => {
                let n = obs.len().max(1) as f64;
                (obs.iter()
                    .map(|o| (o.mean - centre).norm_squared())
                    .sum::<f64>()
                    / n)
                    .sqrt()
                    .max(f64::MIN_POSITIVE)
            }
            BaseKind::Rest { .. } => {
                let n = obs.len().max(1) as f64;
                (obs.iter().map(|o| o.sigma_mean.norm_squared()).sum::<f64>() / n)
                    .sqrt()
                    .max(f64::MIN_POSITIVE)
            }
        };
        let points = obs.iter().map(|o| (o.mean - centre) / scale).collect();
        let weights = obs
            .iter()
            .map(|o| match base {
                BaseKind::Norm { reference, .. } => {
                    let y = start.apply(&o.mean);
                    let grad = y
                        .try_normalize(0.0)
                        .map(|v| start.a.transpose() * v / reference)
                        .unwrap_or_else(Vec3::zeros);
                    let sigma = grad.component_mul(&o.sigma_mean).norm();
                    Vec3::repeat(if sigma > 0.0 { 1.0 / sigma } else { 0.0 })
                }
                BaseKind::Rest { .. } => {
                    o.sigma_mean.map(|s| if s > 0.0 { scale / s } else { 0.0 })
                }
            })
            .collect();
        let temps: Option<Vec<f64>> = obs.iter().map(|o| o.temp_c).collect();
        let (tau, temp_ref) = match temps {
            Some(t) => {
                let (m, s) = mean_std(&t);
                if s > 0.0 {
                    (Some(t.iter().map(|v| (v - m) / s).collect()), (m, s))
                } else {
                    (None, (m, 1.0))
                }
            }
            None => (None, (0.0, 1.0)),
        };
        let times: Vec<f64> = obs.iter().map(|o| o.time_s).collect();
        let (t_mean, t_std) = mean_std(&times);
        let t_std = if t_std > 0.0 { t_std } else { 1.0 };
        let theta = times.iter().map(|t| (t - t_mean) / t_std).collect();
        let force_scale = if gravity > 0.0 { gravity } else { 1.0 };
        let force = force.map(|f| f.iter().map(|v| v / force_scale).collect());
        let time_bins = quantile_bins(&times);
        let temp_bins = obs
            .iter()
            .map(|o| o.temp_c)
            .collect::<Option<Vec<f64>>>()
            .map(|t| quantile_bins(&t));
        Self {
            time_bins,
            temp_bins,
            base,
            points,
            weights,
            tau,
            theta,
            force,
            centre,
            scale,
            temp_ref,
            time_ref: (t_mean, t_std),
            force_scale,
        }
    }

    /// Distinct orientations (within [`DISTINCT_DEG`]) among the observations `rows`.
    pub fn distinct_orientations(&self, rows: &[usize]) -> usize {
        let directions: Vec<Vec3> = rows
            .iter()
            .filter_map(|&i| self.points.get(i)?.try_normalize(0.0))
            .collect();
        count_distinct(&directions, DISTINCT_DEG)
    }

    /// Whether the observations `rows` can determine the base model. A norm model's residual is
    /// one equation per orientation, however often it is repeated, so it needs at least as
    /// many distinct orientations as unknowns; with fewer the solver still returns parameters,
    /// but a held-out pose is predicted from a direction they do not constrain. The rest model
    /// is determined by any observation.
    pub fn determines_base(&self, rows: &[usize]) -> bool {
        match self.base {
            BaseKind::Norm { .. } => self.distinct_orientations(rows) >= self.base_params(),
            BaseKind::Rest { .. } => !rows.is_empty(),
        }
    }

    /// Number of base-model parameters.
    pub fn base_params(&self) -> usize {
        match self.base {
            BaseKind::Norm {
                axis_aligned: true, ..
            } => 6,
            BaseKind::Norm { .. } => 9,
            BaseKind::Rest { .. } => 3,
        }
    }

    /// Residual components per observation.
    pub fn components(&self) -> usize {
        match self.base {
            BaseKind::Norm { .. } => 1,
            BaseKind::Rest { .. } => 3,
        }
    }

    /// Whether the data carry what `effect` is a function of.
    pub fn supports(&self, effect: EffectKind) -> bool {
        match effect {
            EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature => {
                self.tau.is_some()
                    && !(effect == EffectKind::ScaleTemperature
                        && matches!(self.base, BaseKind::Rest { .. }))
            }
            EffectKind::BiasDrift => self.theta.iter().any(|t| *t != 0.0),
            EffectKind::ScaleNonlinearity => matches!(self.base, BaseKind::Norm { .. }),
            EffectKind::GSensitivity => {
                self.force.is_some() && matches!(self.base, BaseKind::Rest { .. })
            }
            EffectKind::BinnedBias(temp) => !temp || self.tau.is_some(),
        }
    }

    /// Weighted residual components of observation `i` under `params` for the `effects`.
    pub fn residual(&self, i: usize, effects: &[EffectKind], p: &[f64]) -> Vec3 {
        let x = self.points[i];
        let tau = self.tau.as_ref().map_or(0.0, |t| t[i]);
        let mut offset = 0;
        let (r, b) = match self.base {
            BaseKind::Norm {
                axis_aligned: true, ..
            } => {
                offset = 6;
                (
                    Mat3::from_diagonal(&Vec3::new(p[0], p[1], p[2])),
                    Vec3::new(p[3], p[4], p[5]),
                )
            }
            BaseKind::Norm { .. } => {
                offset = 9;
                (
                    Mat3::new(p[0], p[1], p[2], 0.0, p[3], p[4], 0.0, 0.0, p[5]),
                    Vec3::new(p[6], p[7], p[8]),
                )
            }
            BaseKind::Rest { .. } => {
                offset += 3;
                (Mat3::identity(), Vec3::new(p[0], p[1], p[2]))
            }
        };
        let mut bias = b;
        let mut out_scale = Vec3::repeat(1.0);
        let mut quad = Vec3::zeros();
        let mut cubic = Vec3::zeros();
        let mut g_term = Vec3::zeros();
        for e in effects {
            let q = &p[offset..offset + e.param_count()];
            match *e {
                EffectKind::BiasTemperature(d) => {
                    for k in 0..usize::from(d.clamp(1, 3)) {
                        bias += Vec3::new(q[3 * k], q[3 * k + 1], q[3 * k + 2])
                            * tau.powi(k as i32 + 1);
                    }
                }
                EffectKind::ScaleTemperature => out_scale += Vec3::new(q[0], q[1], q[2]) * tau,
                EffectKind::BiasDrift => bias += Vec3::new(q[0], q[1], q[2]) * self.theta[i],
                EffectKind::ScaleNonlinearity => {
                    quad = Vec3::new(q[0], q[1], q[2]);
                    cubic = Vec3::new(q[3], q[4], q[5]);
                }
                EffectKind::BinnedBias(temp) => {
                    let bin = if temp {
                        self.temp_bins.as_ref().map_or(0, |b| b[i])
                    } else {
                        self.time_bins[i]
                    };
                    if bin > 0 {
                        bias +=
                            Vec3::new(q[3 * (bin - 1)], q[3 * (bin - 1) + 1], q[3 * (bin - 1) + 2]);
                    }
                }
                EffectKind::GSensitivity => {
                    if let Some(f) = &self.force {
                        let k = Mat3::from_row_slice(q);
                        g_term = k * f[i];
                    }
                }
            }
            offset += e.param_count();
        }
        let u = x - bias;
        let u2 = u
            + quad.component_mul(&u.component_mul(&u))
            + cubic.component_mul(&u.component_mul(&u).component_mul(&u));
        let w = self.weights[i];
        match self.base {
            BaseKind::Norm { .. } => {
                let y = out_scale.component_mul(&(r * u2));
                Vec3::new(w[0] * (y.norm() - 1.0), 0.0, 0.0)
            }
            BaseKind::Rest { .. } => (u2 - g_term).component_mul(&w),
        }
    }
}

/// Least-squares view of a [`Problem`] restricted to some observations.
struct Subset<'a> {
    problem: &'a Problem,
    effects: &'a [EffectKind],
    rows: &'a [usize],
}

impl LeastSquaresProblem for Subset<'_> {
    fn residuals(&self, p: &DVector<f64>) -> DVector<f64> {
        let c = self.problem.components();
        let mut out = DVector::zeros(self.rows.len() * c);
        for (j, &i) in self.rows.iter().enumerate() {
            let r = self.problem.residual(i, self.effects, p.as_slice());
            for k in 0..c {
                out[j * c + k] = r[k];
            }
        }
        out
    }

    fn jacobian(&self, p: &DVector<f64>) -> DMatrix<f64> {
        let m = self.rows.len() * self.problem.components();
        let mut jac = DMatrix::zeros(m, p.len());
        let mut q = p.clone();
        for col in 0..p.len() {
            let h = 1e-6 * (1.0 + p[col].abs());
            q[col] = p[col] + h;
            let plus = self.residuals(&q);
            q[col] = p[col] - h;
            let minus = self.residuals(&q);
            q[col] = p[col];
            jac.set_column(col, &((plus - minus) / (2.0 * h)));
        }
        jac
    }
}

/// A fitted extended model in scaled coordinates.
#[derive(Debug, Clone)]
pub struct ExtendedFit {
    /// Effects included, in parameter order.
    pub effects: Vec<EffectKind>,
    /// Parameters (scaled coordinates).
    pub params: DVector<f64>,
    /// Weighted cost `Σ r²` over the fitted observations.
    pub cost: f64,
    /// Covariance of the scaled parameters, `(JᵀJ)⁻¹` (noise known), when not singular.
    pub covariance: Option<DMatrix<f64>>,
}

/// The starting parameter vector: the base calibration (in scaled coordinates) and zeros.
pub fn start_params(
    problem: &Problem,
    start: &Calibration,
    effects: &[EffectKind],
) -> DVector<f64> {
    let mut p = match problem.base {
        BaseKind::Norm {
            reference,
            axis_aligned: true,
        } => {
            // The start's diagonal: exact for the axis-aligned models it comes from.
            let d = start.a.diagonal() * (problem.scale / reference);
            vec![d[0], d[1], d[2], 0.0, 0.0, 0.0]
        }
        BaseKind::Norm { reference, .. } => {
            let r =
                crate::fit::linalg::upper_triangular_gauge(&start.a) * (problem.scale / reference);
            vec![
                r[(0, 0)],
                r[(0, 1)],
                r[(0, 2)],
                r[(1, 1)],
                r[(1, 2)],
                r[(2, 2)],
                0.0,
                0.0,
                0.0,
            ]
        }
        BaseKind::Rest { .. } => vec![0.0; 3],
    };
    for e in effects {
        p.extend(std::iter::repeat_n(0.0, e.param_count()));
    }
    DVector::from_vec(p)
}

/// Fit `effects` on the observations `rows`, starting from `start` (a parameter vector of the
/// same layout). `None` when the solver fails or there are not more residuals than unknowns.
pub fn fit_rows(
    problem: &Problem,
    effects: &[EffectKind],
    rows: &[usize],
    start: &DVector<f64>,
) -> Option<ExtendedFit> {
    if rows.len() * problem.components() <= start.len() {
        return None;
    }
    let subset = Subset {
        problem,
        effects,
        rows,
    };
    let opts = LmOptions {
        max_iterations: 300,
        step_tolerance: 1e-9,
        cost_tolerance: 1e-12,
        ..LmOptions::default()
    };
    let sol = levenberg_marquardt(&subset, start.clone(), &opts).ok()?;
    if !sol.params.iter().all(|v| v.is_finite()) {
        return None;
    }
    let covariance = sol
        .jtj
        .clone()
        .try_inverse()
        .filter(|c| c.iter().all(|v| v.is_finite()));
    Some(ExtendedFit {
        effects: effects.to_vec(),
        params: sol.params,
        cost: sol.cost,
        covariance,
    })
}

/// Physical value of scaled parameter `index` of `fit`, and the factor that converts it.
pub fn physical_factor(problem: &Problem, effects: &[EffectKind], index: usize) -> f64 {
    let mut offset = problem.base_params();
    let s = problem.scale;
    let s_t = problem.temp_ref.1;
    for e in effects {
        let n = e.param_count();
        if index < offset + n {
            let j = index - offset;
            return match *e {
                EffectKind::BiasTemperature(_) => s / s_t.powi(j as i32 / 3 + 1),
                EffectKind::ScaleTemperature => 1.0 / s_t,
                EffectKind::BiasDrift => s / problem.time_ref.1,
                EffectKind::BinnedBias(_) => s,
                EffectKind::ScaleNonlinearity => {
                    if j < 3 {
                        1.0 / s
                    } else {
                        1.0 / (s * s)
                    }
                }
                EffectKind::GSensitivity => match problem.base {
                    BaseKind::Rest { scale } => s * scale / problem.force_scale,
                    BaseKind::Norm { .. } => s / problem.force_scale,
                },
            };
        }
        offset += n;
    }
    1.0
}

/// The base calibration `A`, `b` of a fitted parameter vector, in data units.
pub fn base_calibration(problem: &Problem, params: &DVector<f64>) -> Calibration {
    match problem.base {
        BaseKind::Norm {
            reference,
            axis_aligned: true,
        } => Calibration {
            a: Mat3::from_diagonal(&Vec3::new(params[0], params[1], params[2]))
                * (reference / problem.scale),
            b: problem.centre + Vec3::new(params[3], params[4], params[5]) * problem.scale,
        },
        BaseKind::Norm { reference, .. } => {
            let r = Mat3::new(
                params[0], params[1], params[2], 0.0, params[3], params[4], 0.0, 0.0, params[5],
            );
            Calibration {
                a: r * (reference / problem.scale),
                b: problem.centre + Vec3::new(params[6], params[7], params[8]) * problem.scale,
            }
        }
        BaseKind::Rest { scale } => Calibration {
            a: Mat3::identity() * scale,
            b: problem.centre + Vec3::new(params[0], params[1], params[2]) * problem.scale,
        },
    }
}

/// Unweighted residual of observation `i` in the units of `imucal fit`: relative norm error for
/// the norm model, `|y|` in rad/s (signed by nothing) for the gyroscope; plus the signed
/// per-axis components for correlation (norm model: the relative error on axis 0 only).
pub fn physical_residual(
    problem: &Problem,
    i: usize,
    effects: &[EffectKind],
    params: &DVector<f64>,
) -> (f64, Vec3) {
    let r = problem.residual(i, effects, params.as_slice());
    let w = problem.weights[i];
    let unweighted = Vec3::from_fn(|k, _| if w[k] > 0.0 { r[k] / w[k] } else { 0.0 });
    match problem.base {
        BaseKind::Norm { .. } => (unweighted[0], Vec3::new(unweighted[0], 0.0, 0.0)),
        BaseKind::Rest { scale } => {
            let v = unweighted * problem.scale * scale;
            (v.norm(), v)
        }
    }
}
