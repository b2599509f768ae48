//! Numbers, units, labels and small tables in the words and formats the report uses.

use serde_json::Value;

use super::{gain, MagSamples, SensorParameters};
use crate::device::ParamsFile;
use crate::fit::{Mat3, Vec3};
use crate::session::coverage::{sphere_centre, Coverage, REGIONS};

/// Text for a value that was not estimated (NaN, infinite or absent in the input).
pub const NOT_ESTIMATED: &str = "unknown / not estimated";

/// Rates in rad/s as °/s per axis.
pub(super) fn degrees(v: &Vec3) -> [f64; 3] {
    [v.x, v.y, v.z].map(f64::to_degrees)
}

/// A pose's name from its up direction, e.g. `+X-Y up`.
pub fn up_label(up: &Vec3) -> String {
    match up.try_normalize(0.0) {
        Some(u) => format!("{} up", crate::session::targets::direction_name(&u)),
        None => "pose".to_string(),
    }
}

/// Labels made distinct: a repeated name gets its occurrence (`+Z up`, `+Z up #2`).
pub fn numbered(labels: Vec<String>) -> Vec<String> {
    let mut seen = std::collections::HashMap::<String, usize>::new();
    labels
        .into_iter()
        .map(|label| {
            let count = seen.entry(label.clone()).or_insert(0);
            *count += 1;
            if *count == 1 {
                label
            } else {
                format!("{label} #{count}")
            }
        })
        .collect()
}

/// A summary's uncertainty entry in words: what it is, per axis or worst direction, its unit
/// and that it is one standard deviation.
pub(super) fn uncertainty_in_words(key: &str, value: &Value) -> (String, String) {
    let (name, unit) = match key {
        "accel_bias_mg" => ("accelerometer offset, per axis x, y, z", "mg"),
        "accel_scale_ppm" => ("accelerometer scale factor, per axis x, y, z", "ppm"),
        "accel_norm_mg" => ("expected error of |a| in the worst direction", "mg"),
        "gyro_bias_dps" => ("gyroscope bias, per axis x, y, z", "°/s"),
        "mag_bias_ut" => ("magnetometer offset, per axis x, y, z", "µT"),
        "mag_norm_pct" => (
            "expected error of |m| in the worst direction",
            "% of the field",
        ),
        "alignment_deg" => (
            "angle between the magnetometer's and the accelerometer's frames (RMS of the axes)",
            "°",
        ),
        other => (other, ""),
    };
    let values: Vec<Option<f64>> = match value {
        Value::Array(items) => items.iter().map(Value::as_f64).collect(),
        other => vec![other.as_f64()],
    };
    let known = |v: &Option<f64>| v.is_some_and(f64::is_finite);
    // One "not estimated" for the row rather than one per axis.
    let text = if values.iter().any(known) {
        values
            .iter()
            .map(|v| match v.filter(|v| v.is_finite()) {
                Some(_) => format!("± {}", with_unit(*v, unit)),
                None => NOT_ESTIMATED.to_string(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    } else {
        NOT_ESTIMATED.to_string()
    };
    (name.to_string(), text)
}

/// `value unit` to 3 significant digits, or [`NOT_ESTIMATED`].
fn with_unit(value: Option<f64>, unit: &str) -> String {
    match value.filter(|v| v.is_finite()) {
        // Degrees are written against the number (1.2°), other units after a space.
        Some(v) if unit == "°" => format!("{}°", significant(v, 3)),
        Some(v) => format!("{} {unit}", significant(v, 3))
            .trim_end()
            .to_string(),
        None => NOT_ESTIMATED.to_string(),
    }
}

/// `value` to `digits` significant digits in plain notation (scientific below 1e-4).
fn significant(value: f64, digits: usize) -> String {
    if value == 0.0 {
        return "0".to_string();
    }
    let magnitude = value.abs().log10().floor() as i32;
    if !(-4..6).contains(&magnitude) {
        return format!("{value:.prec$e}", prec = digits.saturating_sub(1));
    }
    let decimals = (digits as i32 - 1 - magnitude).max(0) as usize;
    format!("{value:.decimals$}")
}

/// The summary's gyroscope scale fit (`gyro_scale`) as rows for the report; `a` is the written
/// gyroscope matrix, whose scale errors the parameter table gives, so that both say the same.
pub(super) fn gyro_scale_rows(value: &Value, a: &Mat3) -> Vec<(String, String)> {
    let number = |key: &str| value[key].as_f64();
    let triple = |key: &str| -> Option<[f64; 3]> {
        let a = value[key].as_array()?;
        Some([
            a.first()?.as_f64()?,
            a.get(1)?.as_f64()?,
            a.get(2)?.as_f64()?,
        ])
    };
    let Some(scale) = triple("scale") else {
        return Vec::new();
    };
    let sigma = triple("scale_sigma_pct").unwrap_or([f64::NAN; 3]);
    // The sensor's gain against nominal, as the parameter table computes it from the whole
    // matrix (the gyroscope's A also turns it into the accelerometer's frame, so its diagonal
    // alone is not the gain); the diagonal's inverse when the matrix is singular.
    let gains = gain::gain(a, 1.0).map_or(scale.map(|d| 1.0 / d), |g| g.scale);
    let mut rows = vec![(
        "scale error of x, y, z (how far the sensor reads from nominal, ± one standard \
         deviation)"
            .to_string(),
        (0..3)
            .map(|i| {
                format!(
                    "{:+.3} % ± {}",
                    (gains[i] - 1.0) * 100.0,
                    with_unit(Some(sigma[i]), "%")
                )
            })
            .collect::<Vec<_>>()
            .join(", "),
    )];
    rows.push((
        "largest off-diagonal angle A_ij/A_jj, mounting and cross-axis together (not the \
         axes' angles off 90° in the parameter table; ± one standard deviation)"
            .to_string(),
        format!(
            "{} ± {}",
            with_unit(number("misalignment_deg"), "°"),
            with_unit(number("misalignment_sigma_deg"), "°")
        ),
    ));
    if let (Some(used), Some(recorded)) = (number("moves_used"), number("moves_recorded")) {
        rows.push((
            "moves between holds used for the fit".to_string(),
            format!("{used:.0} of {recorded:.0}"),
        ));
    }
    rows.push((
        "angle mismatch of the moves after the fit (RMS)".to_string(),
        with_unit(number("rms_deg"), "°"),
    ));
    if let Some(tilt) = triple("tilt_deg") {
        rows.push((
            "rotation about x, y, z over all moves".to_string(),
            tilt.map(|t| format!("{t:.0}°")).join(", "),
        ));
    }
    rows
}

/// The set's terms beyond `A` and `b` as (sensor, term, values) rows.
pub(super) fn extended_terms(params: &ParamsFile) -> Vec<(String, String, String)> {
    let mut rows = Vec::new();
    for (name, unit, sensor) in [
        ("accelerometer", "m/s²", &params.accel),
        ("gyroscope", "rad/s", &params.gyro),
        ("magnetometer", "µT", &params.mag),
    ] {
        let t_ref = sensor
            .t_ref_c
            .map_or(String::new(), |t| format!(" (T − {t:.2} °C)"));
        if let Some(bias) = &sensor.bias_temp {
            for (k, coeffs) in bias.coeffs.iter().enumerate() {
                if coeffs.iter().any(|c| *c != 0.0) {
                    rows.push((
                        name.to_string(),
                        format!(
                            "offset per {}{t_ref}",
                            crate::analysis::effects::celsius_power(k + 1)
                        ),
                        axes_text(
                            coeffs,
                            &format!("{unit}/{}", crate::analysis::effects::celsius_power(k + 1)),
                        ),
                    ));
                }
            }
        }
        if let Some(scale) = sensor.scale_temp.filter(|s| s.iter().any(|c| *c != 0.0)) {
            rows.push((
                name.to_string(),
                format!("scale change per °C{t_ref}"),
                axes_text(&scale.map(|v| v * 1e6), "ppm/°C"),
            ));
        }
        if let Some(nl) = &sensor.nonlinearity {
            rows.push((
                name.to_string(),
                "quadratic non-linearity".to_string(),
                axes_text(&nl.quadratic, &format!("1/({unit})")),
            ));
            rows.push((
                name.to_string(),
                "cubic non-linearity".to_string(),
                axes_text(&nl.cubic, &format!("1/({unit})²")),
            ));
        }
    }
    if let Some(k) = &params.gyro_g_sensitivity {
        for (r, row) in k.iter().enumerate() {
            rows.push((
                "gyroscope".to_string(),
                format!("g-sensitivity, row {}", ["x", "y", "z"][r]),
                axes_text(&row.map(f64::to_degrees), "°/s per m/s²"),
            ));
        }
    }
    rows
}

/// `x …, y …, z … unit` in one number format.
fn axes_text(values: &[f64; 3], unit: &str) -> String {
    let parts: Vec<String> = ["x", "y", "z"]
        .iter()
        .zip(values)
        .map(|(axis, v)| format!("{axis} {v:+.3e}"))
        .collect();
    format!("{} {unit}", parts.join(", "))
}

/// Text made safe for HTML.
pub fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Error of `|v|` against `reference`, in mg of `reference` (so 1 g = 1000 mg).
pub(super) fn norm_error_mg(v: &Vec3, reference: f64) -> f64 {
    (v.norm() / reference - 1.0) * 1000.0
}

/// Error of `|v|` against `reference`, percent.
pub(super) fn norm_error_pct(v: &Vec3, reference: f64) -> f64 {
    (v.norm() / reference - 1.0) * 100.0
}

pub(super) fn rms(values: &[f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    (values.iter().map(|v| v * v).sum::<f64>() / values.len() as f64).sqrt()
}

/// How one table column writes its numbers: fixed with six decimals when every value of the
/// column is between 1e-4 and 1e5 (or zero) and the largest is at least 0.1, otherwise
/// scientific with four, so a column never mixes the two.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnFormat {
    /// `1.234567`
    Fixed,
    /// `1.2346e-7`
    Scientific,
}

impl ColumnFormat {
    /// The format that suits every finite value of `column`.
    pub fn for_column(column: &[f64]) -> Self {
        // Six decimals keep at least three significant digits down to 1e-4, and the column's
        // largest value (a matrix column's diagonal) to six when it is at least 0.1; a column of
        // small values only (e.g. counts to m/s², 6e-4) would keep just three.
        let fits = |v: &f64| *v == 0.0 || (1e-4..1e5).contains(&v.abs());
        let finite = || column.iter().filter(|v| v.is_finite());
        let largest = finite().fold(0.0_f64, |m, v| m.max(v.abs()));
        if finite().all(fits) && (largest == 0.0 || largest >= 0.1) {
            ColumnFormat::Fixed
        } else {
            ColumnFormat::Scientific
        }
    }

    /// `value` in this format, or [`NOT_ESTIMATED`].
    pub fn show(self, value: f64) -> String {
        if !value.is_finite() {
            return NOT_ESTIMATED.to_string();
        }
        match self {
            ColumnFormat::Fixed => format!("{value:.6}"),
            ColumnFormat::Scientific => format!("{value:.4e}"),
        }
    }
}

pub(super) fn parameter_table(p: &SensorParameters) -> String {
    let cell = |format: ColumnFormat, value: f64, std: Option<f64>| match std {
        Some(s) if s > 0.0 && s.is_finite() => format!(
            "<td>{}<span class=std> ± {s:.2e}</span></td>",
            format.show(value)
        ),
        _ => format!("<td>{}</td>", format.show(value)),
    };
    let columns: [Vec<f64>; 4] = [0, 1, 2, 3].map(|c| {
        (0..3)
            .map(|r| if c < 3 { p.a[(r, c)] } else { p.b[r] })
            .collect()
    });
    let formats = columns.each_ref().map(|c| ColumnFormat::for_column(c));
    let mut rows = String::new();
    for r in 0..3 {
        rows.push_str("<tr>");
        rows.push_str(&format!("<th>row {}</th>", r + 1));
        for (c, format) in formats.iter().enumerate().take(3) {
            rows.push_str(&cell(*format, p.a[(r, c)], p.std.map(|s| s.a[(r, c)])));
        }
        rows.push_str(&cell(formats[3], p.b[r], p.std.map(|s| s.b[r])));
        rows.push_str("</tr>");
    }
    let readable = p
        .to_nominal
        .and_then(|k| gain::gain(&p.a, k).map(|g| (k, g)))
        .map_or(String::new(), |(k, g)| {
            gain_table(&g, gain::Estimated::of(&p.a), k, &p.unit_in, &p.unit_out)
        });
    format!(
        "<h3>{}</h3><p class=small>y = A·(x − b); x in {}, y in {}</p><table><tr><th></th><th colspan=3>A</th><th>b</th></tr>{rows}</table>{readable}",
        escape(&p.name),
        escape(&p.unit_in),
        escape(&p.unit_out)
    )
}

/// The matrix read as a person reads it: scale factor and scale error per axis and the angles
/// between the axes, with the unit conversion (`to_nominal` output units per input unit) apart.
/// Parts the model did not estimate ([`gain::Estimated`]) say so instead of showing zeros.
fn gain_table(
    g: &gain::Gain,
    estimated: gain::Estimated,
    to_nominal: f64,
    unit_in: &str,
    unit_out: &str,
) -> String {
    const FIXED: &str = "<td colspan=3>not estimated by this model</td>";
    let mut rows = String::from(
        "<tr><th></th><th>x</th><th>y</th><th>z</th></tr><tr><th>scale factor against nominal</th>",
    );
    if estimated.scale {
        for s in g.scale {
            rows.push_str(&format!("<td>{s:.5}</td>"));
        }
        rows.push_str("</tr><tr><th>scale error</th>");
        for s in g.scale {
            rows.push_str(&format!("<td>{:+.3} %</td>", (s - 1.0) * 100.0));
        }
    } else {
        rows.push_str(FIXED);
    }
    rows.push_str(
        "</tr><tr><th></th><th>yz</th><th>xz</th><th>xy</th></tr><tr><th>axes off 90° by</th>",
    );
    if estimated.axes {
        for d in g.skew_deg {
            rows.push_str(&format!("<td>{d:+.3}°</td>"));
        }
    } else {
        rows.push_str(FIXED);
    }
    rows.push_str("</tr>");
    let conversion = if (to_nominal - 1.0).abs() < 1e-12 {
        String::new()
    } else {
        format!(
            " The unit conversion, 1 {} = {} {}, is taken out: A alone would hide these \
             errors in it.",
            escape(unit_in),
            significant(to_nominal, 6),
            escape(unit_out)
        )
    };
    format!(
        "<p class=small>Read as scale factors and angles between the sensing axes.{conversion}</p><table>{rows}</table>"
    )
}

/// Samples a region needs to count as reached: the session's own minimum.
pub(super) fn region_min_samples() -> usize {
    crate::session::SessionOptions::default().mag_min_per_region
}

/// Coverage of `mag` in the 26 regions of the session's screen: the samples it counted, their
/// sphere centre and the same region cells ([`crate::session::coverage`]); `None` when the
/// samples fix no centre.
pub fn region_coverage(mag: &MagSamples) -> Option<Coverage> {
    let centre = sphere_centre(&mag.counted)?;
    Some(Coverage::of(&mag.counted, &centre))
}

/// The coverage in words, with the count the session's summary recorded when it differs
/// (a summary written by an older version counted regions with a single sample).
pub(super) fn session_regions_text(cover: Option<&Coverage>, on_screen: Option<u64>) -> String {
    let min = region_min_samples();
    let Some(cover) = cover else {
        return "the samples' directions are not countable (no sphere centre)".to_string();
    };
    let covered = cover.covered(min);
    let empty = cover.empty_regions(min);
    let mut text = format!(
        "{covered} of {REGIONS} directions with at least {min} samples, as the session's \
         screen counts them (moves between positions included)"
    );
    if !empty.is_empty() {
        text.push_str(&format!("; empty: {}", empty.join(" ")));
    }
    if let Some(n) = on_screen.filter(|n| usize::try_from(*n).ok() != Some(covered)) {
        text.push_str(&format!("; the session's summary recorded {n}"));
    }
    text
}

/// Smallest temperature span worth an axis, °C: below it a plot against temperature is a
/// vertical stripe. Die temperature sensors of consumer IMUs resolve 0.003–0.06 °C, and a
/// temperature coefficient only shows over a span many times that.
const MIN_TEMPERATURE_SPAN_C: f64 = 0.5;

/// Whether `temps` span enough to plot against.
pub(super) fn temperature_varies(temps: &[f64]) -> bool {
    let (lo, hi) = temperature_span(temps);
    hi - lo >= MIN_TEMPERATURE_SPAN_C
}

fn temperature_span(temps: &[f64]) -> (f64, f64) {
    temps
        .iter()
        .filter(|t| t.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(*t), hi.max(*t))
        })
}

/// Why there is no plot against temperature: it stayed within [`MIN_TEMPERATURE_SPAN_C`].
pub(super) fn constant_temperature_text(what: &str, temps: &[f64]) -> String {
    let (lo, hi) = temperature_span(temps);
    if !lo.is_finite() {
        return format!(
            "No temperature was recorded with the {what}, so there is no plot against it."
        );
    }
    format!(
        "Temperature constant at {:.1} °C during the {what} (span {:.2} °C, under {MIN_TEMPERATURE_SPAN_C} °C), so there is no plot against it.",
        (lo + hi) / 2.0,
        hi - lo
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_gyroscope_scale_rows_give_the_scale_errors_of_the_parameter_table() {
        // A gain error of 2 % on x, turned by 3° about z into another frame: the diagonal
        // alone is not the gain.
        let turn = nalgebra::Rotation3::from_axis_angle(&Vec3::z_axis(), 3f64.to_radians());
        let a = turn.matrix() * Mat3::from_diagonal(&Vec3::new(1.0 / 1.02, 1.0, 1.0));
        let summary = json!({
            "scale": [a[(0, 0)], a[(1, 1)], a[(2, 2)]],
            "scale_sigma_pct": [0.01, 0.01, 0.01],
            "misalignment_deg": 0.0,
            "misalignment_sigma_deg": 0.01,
        });
        let rows = gyro_scale_rows(&summary, &a);
        let (_, scale) = &rows[0];
        let table = gain::gain(&a, 1.0).expect("regular").scale;
        for (text, g) in scale.split(", ").zip(table) {
            assert!(
                text.starts_with(&format!("{:+.3} %", (g - 1.0) * 100.0)),
                "{text} vs {g}"
            );
        }
        assert!(scale.starts_with("+2.000 %"), "{scale}");
    }
}
