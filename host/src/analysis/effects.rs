//! The candidate effects: physical hypotheses about what the base model `y = A·(x − b)` misses,
//! each an extension of the model with its own parameters and units. The parameterisation is
//! the one the firmware applies (`imucal_protocol::CalibrationSet`):
//!
//! ```text
//! ΔT = T − T₀,  Δt = t − t₀
//! u  = x − b − Σₖ cₖ·ΔTᵏ − r·Δt          bias_temperature (degree 1–3), bias_drift
//! u' = u + q∘u² + k∘u³                    scale_nonlinearity (per axis)
//! y  = (1 + s·ΔT)∘(A·u')                  scale_temperature (per output axis)
//! y −= K·f                                g_sensitivity (gyroscope; f = calibrated specific force)
//! ```
//!
//! `bias_drift` has no firmware term (a device does not know the time since its calibration);
//! it is reported so that a drifting sensor is not mistaken for a temperature effect.

use serde::Serialize;

/// One candidate effect family (stable names in [`EffectKind::name`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
pub enum EffectKind {
    /// Bias as a polynomial in `T − T₀` of the given degree (1–3); data units per °Cᵏ.
    BiasTemperature(u8),
    /// Scale factor linear in `T − T₀`, per output axis; 1/°C.
    ScaleTemperature,
    /// Bias linear in time; data units per second.
    BiasDrift,
    /// Per-axis quadratic and cubic terms of the offset-corrected reading; 1/unit, 1/unit².
    ScaleNonlinearity,
    /// Gyroscope bias linear in specific force (3×3); rad/s per m/s².
    GSensitivity,
    /// Not a candidate but a check of one: a bias constant within each of [`BINS`] quantile
    /// bins of time (`false`) or temperature (`true`), free in shape. A time or temperature
    /// effect whose residual this beats has the wrong form (a step, a hysteresis loop).
    BinnedBias(bool),
}

/// Number of quantile bins of [`EffectKind::BinnedBias`].
pub const BINS: usize = 8;

impl EffectKind {
    /// Stable name used in JSON and reports.
    pub fn name(self) -> &'static str {
        match self {
            EffectKind::BiasTemperature(_) => "bias_temperature",
            EffectKind::ScaleTemperature => "scale_temperature",
            EffectKind::BiasDrift => "bias_drift",
            EffectKind::ScaleNonlinearity => "scale_nonlinearity",
            EffectKind::GSensitivity => "g_sensitivity",
            EffectKind::BinnedBias(_) => "binned_bias",
        }
    }

    /// Number of extra parameters.
    pub fn param_count(self) -> usize {
        match self {
            EffectKind::BiasTemperature(d) => 3 * usize::from(d.clamp(1, 3)),
            EffectKind::ScaleTemperature | EffectKind::BiasDrift => 3,
            EffectKind::ScaleNonlinearity => 6,
            EffectKind::GSensitivity => 9,
            EffectKind::BinnedBias(_) => 3 * (BINS - 1),
        }
    }

    /// Whether the effect needs the temperature of each observation.
    pub fn needs_temperature(self) -> bool {
        matches!(
            self,
            EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature
        )
    }

    /// The recorded variable the effect is a function of (for plots and reports).
    pub fn variable(self) -> &'static str {
        match self {
            EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature => "temperature (°C)",
            EffectKind::BiasDrift => "time (s)",
            EffectKind::ScaleNonlinearity => "reading magnitude (data units)",
            EffectKind::GSensitivity => "specific force (m/s²)",
            EffectKind::BinnedBias(true) => "temperature (°C)",
            EffectKind::BinnedBias(false) => "time (s)",
        }
    }

    /// Names of the extra parameters, in parameter order, with their unit (`unit` is the
    /// sensor's data unit).
    pub fn param_labels(self, unit: &str) -> Vec<(String, String)> {
        let axes = ["x", "y", "z"];
        match self {
            EffectKind::BiasTemperature(d) => (1..=d.clamp(1, 3))
                .flat_map(|k| {
                    axes.iter().map(move |a| {
                        (
                            format!("c{k}_{a}"),
                            format!("{unit}/{}", celsius_power(usize::from(k))),
                        )
                    })
                })
                .collect(),
            EffectKind::ScaleTemperature => axes
                .iter()
                .map(|a| (format!("s_{a}"), "1/°C".to_string()))
                .collect(),
            EffectKind::BiasDrift => axes
                .iter()
                .map(|a| (format!("r_{a}"), format!("{unit}/s")))
                .collect(),
            EffectKind::ScaleNonlinearity => axes
                .iter()
                .map(|a| (format!("q_{a}"), format!("1/({unit})")))
                .chain(
                    axes.iter()
                        .map(|a| (format!("k_{a}"), format!("1/({unit})²"))),
                )
                .collect(),
            EffectKind::GSensitivity => axes
                .iter()
                .flat_map(|r| {
                    axes.iter()
                        .map(move |c| (format!("K_{r}{c}"), "(rad/s)/(m/s²)".to_string()))
                })
                .collect(),
            EffectKind::BinnedBias(_) => (1..BINS)
                .flat_map(|b| {
                    axes.iter()
                        .map(move |a| (format!("bin{b}_{a}"), unit.to_string()))
                })
                .collect(),
        }
    }
}

/// The families tested for a norm-model sensor (accelerometer, magnetometer).
pub const NORM_FAMILIES: [EffectKind; 4] = [
    EffectKind::BiasTemperature(1),
    EffectKind::ScaleTemperature,
    EffectKind::BiasDrift,
    EffectKind::ScaleNonlinearity,
];

/// The families tested for the gyroscope at rest. Scale terms act on the rate, which is zero
/// at rest, so still data cannot see them.
pub const GYRO_FAMILIES: [EffectKind; 3] = [
    EffectKind::BiasTemperature(1),
    EffectKind::BiasDrift,
    EffectKind::GSensitivity,
];

/// `°C`, `°C²` or `°C³`: the unit of a temperature power, written as people write it.
pub fn celsius_power(power: usize) -> String {
    match power {
        1 => "°C".to_string(),
        2 => "°C²".to_string(),
        3 => "°C³".to_string(),
        k => format!("°C^{k}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_linearity_coefficients_are_labelled_per_unit_of_the_reading_unambiguously() {
        let labels = EffectKind::ScaleNonlinearity.param_labels("m/s²");
        assert!(
            labels.contains(&("q_x".into(), "1/(m/s²)".into())),
            "{labels:?}"
        );
        assert!(
            labels.contains(&("k_z".into(), "1/(m/s²)²".into())),
            "{labels:?}"
        );
    }

    #[test]
    fn temperature_powers_are_written_with_superscripts() {
        let labels = EffectKind::BiasTemperature(3).param_labels("mg");
        let units: Vec<&str> = labels.iter().map(|(_, u)| u.as_str()).collect();
        assert!(units.contains(&"mg/°C"));
        assert!(units.contains(&"mg/°C²"));
        assert!(units.contains(&"mg/°C³"));
        assert!(units
            .iter()
            .all(|u| !u.ends_with("°C2") && !u.ends_with("°C3")));
    }
}
