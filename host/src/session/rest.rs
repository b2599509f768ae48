//! The at-rest check: statistics of samples streamed while the board lies still, as the
//! errors a user sees — `| |ā| − g |` in mg, `| |m̄| − H |` in % of the field, and `|ω̄|` in °/s,
//! each of the window's mean (so the white noise averages out; its contribution is reported as
//! the standard error alongside).

use serde::Serialize;

use super::solve::{Budgets, STANDARD_GRAVITY};
use crate::device::UnitSample;
use crate::fit::Vec3;

/// Errors of the readings at rest.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RestErrors {
    /// Samples averaged.
    pub samples: usize,
    /// Board time spanned, s.
    pub duration_s: f64,
    /// `| |ā| − g |`, mg.
    pub accel_error_mg: f64,
    /// Standard error of `|ā|` from the sample scatter, mg.
    pub accel_noise_mg: f64,
    /// `| |m̄| − H |`, % of `H`.
    pub mag_error_pct: f64,
    /// Standard error of `|m̄|`, % of `H`.
    pub mag_noise_pct: f64,
    /// `|ω̄|`, °/s.
    pub gyro_rate_dps: f64,
    /// Standard error of `|ω̄|` from the sample scatter, °/s.
    pub gyro_noise_dps: f64,
    /// Largest per-axis accelerometer standard deviation of the samples (stillness), m/s².
    pub accel_std_mps2: f64,
}

/// One quantity of the at-rest check, as the screen and the report show it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RestQuantity {
    /// Row label.
    pub label: &'static str,
    /// Unit of the value.
    pub unit: &'static str,
    /// Decimals of a calibrated value (small; an uncalibrated one needs one fewer).
    pub digits: usize,
    /// The session's target, empty when there is none.
    pub target: &'static str,
}

/// The quantities of [`RestErrors::values`], in that order.
pub const REST_QUANTITIES: [RestQuantity; 3] = [
    RestQuantity {
        label: "|a| error",
        unit: "mg",
        digits: 3,
        target: "< 2 mg",
    },
    RestQuantity {
        label: "|m| error",
        unit: "%",
        digits: 3,
        target: "< 0.5 %",
    },
    RestQuantity {
        label: "gyro rate",
        unit: "°/s",
        digits: 4,
        target: "",
    },
];

impl RestErrors {
    /// `| |ā| − g |` (mg), `| |m̄| − H |` (%) and `|ω̄|` (°/s): the rows of [`REST_QUANTITIES`].
    pub fn values(&self) -> [f64; 3] {
        [self.accel_error_mg, self.mag_error_pct, self.gyro_rate_dps]
    }

    /// The targets these errors miss, one sentence each: an error counts as missing its budget
    /// when it lies beyond it by more than three standard errors of its own mean (so the
    /// noise of a short measurement does not fail a good set). Empty when every target is met.
    pub fn missed_targets(&self, budgets: Budgets) -> Vec<String> {
        let mut missed = Vec::new();
        for (what, error, noise, budget, unit) in [
            (
                "|a| error",
                self.accel_error_mg,
                self.accel_noise_mg,
                budgets.accel_mg,
                "mg",
            ),
            (
                "|m| error",
                self.mag_error_pct,
                self.mag_noise_pct,
                budgets.mag_pct,
                "%",
            ),
        ] {
            if error - 3.0 * noise.max(0.0) > budget {
                missed.push(format!(
                    "{what} {error:.3} {unit} (± {noise:.3} {unit}) against its {budget} {unit} \
                     target"
                ));
            }
        }
        missed
    }

    /// The quantities (`|a| error`, `gyro rate`) in which these errors are worse than
    /// `other`'s by more than three standard errors of the difference (so the noise of two
    /// short measurements does not decide), each with whether it is also beyond what the set
    /// measured claims: above three times `stated` (its own one-sigma error of `|a|` in mg and
    /// of the rate in °/s) combined with the measurement's noise. A set can be worse at one
    /// orientation and better over all of them (a base bias measured where the board lies
    /// now), so only a difference beyond the claim condemns it. The magnetometer is not
    /// compared (both sets share it).
    pub fn worse_than(&self, other: &RestErrors, stated: [f64; 2]) -> Vec<WorseAtRest> {
        let mut worse = Vec::new();
        for ((what, unit, mine, my_noise, theirs, their_noise), claim) in [
            (
                "|a| error",
                "mg",
                self.accel_error_mg,
                self.accel_noise_mg,
                other.accel_error_mg,
                other.accel_noise_mg,
            ),
            (
                "gyro rate",
                "°/s",
                self.gyro_rate_dps,
                self.gyro_noise_dps,
                other.gyro_rate_dps,
                other.gyro_noise_dps,
            ),
        ]
        .into_iter()
        .zip(stated)
        {
            let noise = my_noise.max(0.0).hypot(their_noise.max(0.0));
            let stated_sigma = if claim.is_finite() {
                claim.max(0.0)
            } else {
                0.0
            };
            if mine - theirs > 3.0 * noise {
                worse.push(WorseAtRest {
                    what,
                    unit,
                    value: mine,
                    other: theirs,
                    noise,
                    stated_sigma,
                    beyond_claim: mine > 3.0 * stated_sigma.hypot(my_noise.max(0.0)),
                });
            }
        }
        worse
    }
}

/// One quantity in which a set checks worse at rest than another ([`RestErrors::worse_than`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorseAtRest {
    /// `|a| error` or `gyro rate`.
    pub what: &'static str,
    /// Its unit.
    pub unit: &'static str,
    /// The set's value.
    pub value: f64,
    /// The other set's value.
    pub other: f64,
    /// Standard error of the difference.
    pub noise: f64,
    /// The set's own stated one-sigma error of the quantity.
    pub stated_sigma: f64,
    /// Whether the value is beyond three times the stated σ (with the measurement's noise).
    pub beyond_claim: bool,
}

impl std::fmt::Display for WorseAtRest {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let unit = self.unit;
        write!(
            f,
            "{} {:.4} {unit} against {:.4} {unit} (± {:.4} {unit}; its stated σ {:.4} {unit})",
            self.what, self.value, self.other, self.noise, self.stated_sigma
        )
    }
}

fn mean_and_std(values: impl Iterator<Item = Vec3> + Clone) -> (Vec3, Vec3) {
    let n = values.clone().count().max(1) as f64;
    let mean = values.clone().sum::<Vec3>() / n;
    let var = values
        .map(|v| (v - mean).component_mul(&(v - mean)))
        .sum::<Vec3>()
        / n;
    (mean, var.map(|x| x.max(0.0).sqrt()))
}

/// The standard error of `|v̄|` for per-axis sample deviations `std` over `n` samples, along `v̄`.
fn norm_standard_error(mean: &Vec3, std: &Vec3, n: usize) -> f64 {
    let direction = mean.try_normalize(0.0).unwrap_or_else(Vec3::zeros);
    let var = direction
        .component_mul(&direction)
        .dot(&std.component_mul(std));
    (var / n.max(1) as f64).sqrt()
}

/// Errors of `samples` (calibrated, or raw for "before") against gravity `gravity_mps2` and
/// field `field_ut`; `None` without samples.
pub fn rest_errors(samples: &[UnitSample], gravity_mps2: f64, field_ut: f64) -> Option<RestErrors> {
    let first = samples.first()?;
    let last = samples.last()?;
    let n = samples.len();
    let (accel, accel_std) = mean_and_std(samples.iter().map(|s| Vec3::from(s.accel)));
    let (mag, mag_std) = mean_and_std(samples.iter().map(|s| Vec3::from(s.mag)));
    let (gyro, gyro_std) = mean_and_std(samples.iter().map(|s| Vec3::from(s.gyro)));
    let mg = 1000.0 / STANDARD_GRAVITY;
    let pct = 100.0 / field_ut;
    Some(RestErrors {
        samples: n,
        duration_s: last.t_s - first.t_s,
        accel_error_mg: (accel.norm() - gravity_mps2).abs() * mg,
        accel_noise_mg: norm_standard_error(&accel, &accel_std, n) * mg,
        mag_error_pct: (mag.norm() - field_ut).abs() * pct,
        mag_noise_pct: norm_standard_error(&mag, &mag_std, n) * pct,
        gyro_rate_dps: gyro.norm().to_degrees(),
        gyro_noise_dps: norm_standard_error(&gyro, &gyro_std, n).to_degrees(),
        accel_std_mps2: accel_std.max(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_set_is_worse_at_rest_beyond_the_noise_of_both_checks_and_condemned_beyond_its_claim() {
        let check = |gyro_dps: f64| RestErrors {
            samples: 200,
            duration_s: 2.0,
            accel_error_mg: 0.1,
            accel_noise_mg: 0.03,
            mag_error_pct: 0.1,
            mag_noise_pct: 0.01,
            gyro_rate_dps: gyro_dps,
            gyro_noise_dps: 0.005,
            accel_std_mps2: 0.0,
        };
        let base = check(0.015);
        // 0.15 °/s against 0.015: worse beyond the noise (± 0.007 °/s) ...
        let worse = check(0.15).worse_than(&base, [0.2, 0.054]);
        assert_eq!(worse.len(), 1, "{worse:?}");
        assert!(
            worse[0].to_string().starts_with("gyro rate 0.1500 °/s"),
            "{}",
            worse[0]
        );
        assert!(
            worse[0].to_string().contains("its stated σ 0.0540"),
            "{}",
            worse[0]
        );
        // ... but within three times its stated σ of 0.054 °/s: not beyond its claim.
        assert!(!worse[0].beyond_claim);
        assert!(check(0.15).worse_than(&base, [0.2, 0.02])[0].beyond_claim);
        // Within the noise of the two checks: not worse.
        assert!(check(0.030).worse_than(&base, [0.0, 0.0]).is_empty());
    }

    #[test]
    fn a_target_is_missed_only_beyond_three_standard_errors_of_its_measurement() {
        let budgets = Budgets {
            accel_mg: 2.0,
            mag_pct: 0.5,
        };
        let errors = |accel_mg: f64, accel_noise_mg: f64, mag_pct: f64| RestErrors {
            samples: 100,
            duration_s: 1.0,
            accel_error_mg: accel_mg,
            accel_noise_mg,
            mag_error_pct: mag_pct,
            mag_noise_pct: 0.01,
            gyro_rate_dps: 0.0,
            gyro_noise_dps: 0.0,
            accel_std_mps2: 0.0,
        };
        assert!(errors(0.3, 0.05, 0.1).missed_targets(budgets).is_empty());
        // 2.1 mg measured to ± 0.05 mg could be 1.95 mg: within noise of the target.
        assert!(errors(2.1, 0.05, 0.1).missed_targets(budgets).is_empty());
        let missed = errors(6.774, 0.05, 0.9).missed_targets(budgets);
        assert_eq!(missed.len(), 2, "{missed:?}");
        assert!(missed[0].starts_with("|a| error 6.774 mg"), "{missed:?}");
        assert!(missed[1].starts_with("|m| error 0.900 %"), "{missed:?}");
    }

    #[test]
    fn errors_are_those_of_the_means_against_the_references() {
        // Two samples whose means are |a| = 9.81665 (1 mg·1.0197 high), |m| = 48.48 (1 % high)
        // and ω = 0.01 rad/s about Z.
        let make = |t_s: f64, dz: f64| UnitSample {
            t_s,
            accel: [0.0, 0.0, 9.816_65 + dz],
            gyro: [0.0, 0.0, 0.01],
            mag: [48.48, 0.0, 0.0],
            temp_c: 25.0,
        };
        let samples = [make(0.0, -0.01), make(0.5, 0.01)];
        let errors = rest_errors(&samples, 9.806_65, 48.0).expect("samples");
        let expected_mg = 0.01 * 1000.0 / STANDARD_GRAVITY;
        assert!((errors.accel_error_mg - expected_mg).abs() < 1e-9);
        assert!((errors.mag_error_pct - 1.0).abs() < 1e-9);
        assert!((errors.gyro_rate_dps - 0.01f64.to_degrees()).abs() < 1e-12);
        // Sample std 0.01 m/s² along the mean's direction, over 2 samples.
        assert!(
            (errors.accel_noise_mg - 0.01 / 2f64.sqrt() * 1000.0 / STANDARD_GRAVITY).abs() < 1e-9
        );
        assert_eq!(errors.duration_s, 0.5);
    }

    #[test]
    fn no_samples_give_no_errors() {
        assert!(rest_errors(&[], 9.8, 48.0).is_none());
    }
}
