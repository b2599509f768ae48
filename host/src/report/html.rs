//! The report page: sections, tables and figures assembled into one self-contained HTML page.

use super::format::{
    constant_temperature_text, escape, norm_error_mg, norm_error_pct, parameter_table,
    region_coverage, region_min_samples, rms, session_regions_text, temperature_varies,
    NOT_ESTIMATED,
};
use super::{plots, GyroPoses, ReportData, ReportError, RestCheck};
use crate::fit::{Mat3, Vec3};
use crate::session::rest::REST_QUANTITIES;

/// "1 pose", "12 poses".
fn poses(count: usize) -> String {
    format!("{count} pose{}", if count == 1 { "" } else { "s" })
}

pub(super) fn figure(svg: &str) -> String {
    format!("<div class=fig>{svg}</div>")
}

/// Renders the report page.
pub fn render_html(data: &ReportData) -> Result<String, ReportError> {
    if data.accel.is_none() && data.mag.is_none() && data.gyro.is_none() {
        // The verdict holds the reasons no sensor was fitted: they are the cause to name.
        let because = if data.verdict.is_empty() {
            String::new()
        } else {
            format!(": {}", data.verdict.join("; "))
        };
        return Err(ReportError::NoData { because });
    }
    let mut summary_rows = Vec::new();
    let mut body = String::new();

    if let Some(mag) = &data.mag {
        body.push_str("<h2>Magnetometer</h2><p>Raw samples with the outline of the fitted ellipsoid (top) and calibrated samples with the reference sphere (bottom).</p><div class=row>");
        for axes in plots::PROJECTIONS {
            let outline = mag
                .ellipsoid
                .map(|(centre, shape)| plots::ellipse_outline(&centre, &shape, axes.0, axes.1))
                .unwrap_or_default();
            body.push_str(&figure(&plots::projection(
                &format!("raw {}{}", axes.2, axes.3),
                &mag.raw_unit,
                &mag.raw,
                (&outline, "fitted ellipsoid"),
                axes,
                false,
            )?));
        }
        body.push_str("</div><div class=row>");
        let sphere = plots::ellipse_outline(&Vec3::zeros(), &(Mat3::identity() * mag.field), 0, 1);
        for axes in plots::PROJECTIONS {
            body.push_str(&figure(&plots::projection(
                &format!("calibrated {}{}", axes.2, axes.3),
                &mag.calibrated_unit,
                &mag.calibrated,
                (&sphere, "reference sphere"),
                axes,
                true,
            )?));
        }
        body.push_str("</div>");
        // Raw norms are compared with their own mean: the raw unit or scale may differ from the
        // reference, and the spread is what calibration removes.
        let raw_mean = mag.raw.iter().map(|v| v.norm()).sum::<f64>() / mag.raw.len() as f64;
        let before: Vec<f64> = mag
            .raw
            .iter()
            .map(|v| norm_error_pct(v, raw_mean))
            .collect();
        let after: Vec<f64> = mag
            .calibrated
            .iter()
            .map(|v| norm_error_pct(v, mag.field))
            .collect();
        // A sample's error after calibration holds its noise: said beside it, so that an RMS
        // above a target that the fit's own uncertainty meets is not read as a bad fit.
        let noise_pct = crate::stats::robust::stream_noise(&mag.calibrated)
            .map(|s| (s.norm_squared() / 3.0).sqrt() / mag.field * 100.0)
            .filter(|v| v.is_finite());
        summary_rows.push((
            "magnetometer |m| error RMS".to_string(),
            format!(
                "{:.2} % before (spread about the raw readings' own mean |m|), {:.3} % after \
                 (against the reference{}) ({} samples)",
                rms(&before),
                rms(&after),
                noise_pct.map_or(String::new(), |n| format!(
                    "; the samples' noise alone leaves about {n:.3} %"
                )),
                after.len()
            ),
        ));
        body.push_str("<h3>Norm error</h3><div class=row>");
        body.push_str(&figure(&plots::histogram(
            "before: |m| / mean raw |m| − 1",
            "norm error (%)",
            &before,
            false,
        )?));
        body.push_str(&figure(&plots::histogram(
            "after: |m| / reference − 1",
            "norm error (%)",
            &after,
            true,
        )?));
        // A recording without times has only its samples' numbers to plot against.
        let (title, axis, heading) = if mag.time_is_index {
            (
                "magnetometer norm error against sample number",
                "sample",
                "sample number",
            )
        } else {
            ("magnetometer norm error against time", "time (s)", "time")
        };
        body.push_str(&format!(
            "</div><h3>Residual against {heading} and temperature</h3><div class=row>"
        ));
        let pairs = |x: &[f64], y: &[f64]| -> Vec<(f64, f64)> {
            x.iter().copied().zip(y.iter().copied()).collect()
        };
        body.push_str(&figure(&plots::residual_against(
            title,
            axis,
            "norm error (%)",
            &pairs(&mag.time_s, &before),
            &pairs(&mag.time_s, &after),
        )?));
        let mut constant = None;
        match mag.temp_c.as_ref() {
            Some(temp) if temperature_varies(temp) => {
                body.push_str(&figure(&plots::residual_against(
                    "magnetometer norm error against temperature",
                    "temperature (°C)",
                    "norm error (%)",
                    &pairs(temp, &before),
                    &pairs(temp, &after),
                )?));
            }
            Some(temp) => constant = Some(constant_temperature_text("magnetometer samples", temp)),
            None => constant = Some(constant_temperature_text("magnetometer samples", &[])),
        }
        body.push_str("</div>");
        for text in constant.iter().chain(&mag.temp_note) {
            body.push_str(&format!("<p class=small>{}</p>", escape(text)));
        }
        body.push_str("<h3>Sphere coverage</h3>");
        let cover = region_coverage(mag);
        if let Some(cover) = &cover {
            body.push_str(&figure(&plots::coverage_map(cover, region_min_samples())?));
        }
        summary_rows.push((
            "sphere coverage".to_string(),
            session_regions_text(cover.as_ref(), data.session_regions_covered),
        ));
    }

    if let Some(accel) = &data.accel {
        let before: Vec<f64> = accel
            .raw_mps2
            .iter()
            .map(|v| norm_error_mg(v, accel.gravity))
            .collect();
        let after: Vec<f64> = accel
            .calibrated
            .iter()
            .map(|v| norm_error_mg(v, accel.gravity))
            .collect();
        summary_rows.push((
            "accelerometer |a| error RMS".to_string(),
            format!(
                "{:.2} mg before, {:.3} mg after ({})",
                rms(&before),
                rms(&after),
                poses(after.len())
            ),
        ));
        body.push_str("<h2>Accelerometer</h2><p>Error of |a| against local gravity per pose, before and after calibration, each on its own scale.</p>");
        let labels = &accel.labels;
        body.push_str(&figure(&plots::pose_bars(
            "accelerometer before calibration: |a| − g per pose",
            "error of |a| (mg)",
            &before,
            labels,
            false,
        )?));
        body.push_str(&figure(&plots::pose_bars(
            "accelerometer after calibration: |a| − g per pose (own scale)",
            "error of |a| (mg)",
            &after,
            labels,
            true,
        )?));
        let with_temp: Vec<(f64, f64, f64)> = accel
            .temp_c
            .iter()
            .zip(before.iter().zip(&after))
            .filter_map(|(t, (b, a))| t.map(|t| (t, *b, *a)))
            .collect();
        let temps: Vec<f64> = with_temp.iter().map(|p| p.0).collect();
        if temperature_varies(&temps) {
            body.push_str(&figure(&plots::residual_against(
                "accelerometer |a| error against pose temperature",
                "temperature (°C)",
                "error of |a| (mg)",
                &with_temp.iter().map(|p| (p.0, p.1)).collect::<Vec<_>>(),
                &with_temp.iter().map(|p| (p.0, p.2)).collect::<Vec<_>>(),
            )?));
        } else {
            body.push_str(&format!(
                "<p class=small>{}</p>",
                escape(&constant_temperature_text("accelerometer poses", &temps))
            ));
        }
    }

    if let Some(gyro) = &data.gyro {
        body.push_str(&gyro_section(gyro, &mut summary_rows)?);
    }

    let mut parameters = String::new();
    for p in &data.parameters {
        parameters.push_str(&parameter_table(p));
    }
    if !data.extended_terms.is_empty() {
        parameters.push_str(
            "<h3>Extended terms on the board</h3><p class=small>Terms beyond A and b that the \
             firmware applies (written by the residual analysis).</p><table><tr><th>sensor</th>\
             <th>term</th><th>values</th></tr>",
        );
        for (sensor, term, values) in &data.extended_terms {
            parameters.push_str(&format!(
                "<tr><td>{}</td><td>{}</td><td>{}</td></tr>",
                escape(sensor),
                escape(term),
                escape(values)
            ));
        }
        parameters.push_str("</table>");
    }
    if !data.uncertainty_notes.is_empty() {
        parameters.push_str(
            "<h3>How well the parameters are known</h3><p class=small>Each figure is one \
             standard deviation (±): the true value lies within it about two times in three, \
             and within three times it almost always.</p><table class=text>",
        );
        for (name, value) in &data.uncertainty_notes {
            parameters.push_str(&format!(
                "<tr><th>{}</th><td>{}</td></tr>",
                escape(name),
                escape(value)
            ));
        }
        parameters.push_str("</table>");
    }

    let level_class = badge_class(&data.verdict_level);
    let mut verdict = format!(
        "<p class=\"verdict {level_class}\">Verdict: {}</p>",
        escape(&data.verdict_level)
    );
    if !data.verdict.is_empty() {
        verdict.push_str("<ul>");
        for reason in &data.verdict {
            verdict.push_str(&format!("<li>{}</li>", escape(reason)));
        }
        verdict.push_str("</ul>");
    }
    let mut summary = String::from("<table class=text>");
    for (name, value) in &summary_rows {
        summary.push_str(&format!(
            "<tr><th>{}</th><td>{}</td></tr>",
            escape(name),
            escape(value)
        ));
    }
    summary.push_str("</table>");
    summary.push_str(&rest_check_table(&data.rest_checks));
    let notes: String = data
        .notes
        .iter()
        .map(|n| format!("<li>{}</li>", escape(n)))
        .collect();
    let notes = if notes.is_empty() {
        String::new()
    } else {
        format!("<h3>Notes</h3><ul>{notes}</ul>")
    };
    if let Some(analysis) = &data.analysis {
        body.push_str(&format!(
            "<h2>Residual analysis and extended terms</h2><p>What the residuals of the poses \
             show beyond the base model, and the terms written for it (the parameter tables \
             below are the set on the board).</p><pre>{}</pre>",
            escape(analysis)
        ));
    }
    if !data.history.is_empty() {
        body.push_str("<h2>Calibration history</h2><p>This board's parameters in every recorded calibration.</p><div class=row>");
        for (_, svg) in &data.history {
            body.push_str(&figure(svg));
        }
        body.push_str("</div>");
    }
    Ok(format!(
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>imucal report: {title}</title><style>{STYLE}</style></head><body>\n<h1>IMU calibration report</h1><p class=small>{title}</p>\n{verdict}{summary}{notes}\n{body}\n<h2>Parameters</h2>{parameters}\n</body></html>\n",
        title = escape(&data.source)
    ))
}

const STYLE: &str = "body{font-family:sans-serif;margin:24px;color:#222;max-width:1100px}\
h1{font-size:24px;margin-bottom:4px}h2{border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:32px}\
table{border-collapse:collapse;margin:8px 0}th,td{border:1px solid #ddd;padding:4px 8px;text-align:right;font-size:13px}\
th{background:#f4f4f4;text-align:left}.std{color:#777}.small{color:#666;font-size:13px}\
.row{display:flex;flex-wrap:wrap;gap:8px}.fig{display:inline-block}\
.verdict{font-size:18px;font-weight:bold;padding:8px 12px;display:inline-block;border-radius:4px}\
.good{background:#d9f0d3}.marginal{background:#fee8c8}.poor{background:#f4c7c3}.neutral{background:#e8e8e8}\
pre{white-space:pre-wrap;overflow-wrap:anywhere;font-size:12px;background:#fafafa;padding:8px}\
table.text td{text-align:left}";

/// The badge's colour class for a verdict: green, orange and red only for the session's own
/// levels; anything else (`fitted`: no held-out check) is neutral grey.
pub fn badge_class(level: &str) -> &'static str {
    match level {
        "good" => "good",
        "marginal" => "marginal",
        "poor" | "not fitted" => "poor",
        "partly fitted" | "fitted, with findings" => "marginal",
        _ => "neutral",
    }
}

/// The errors at rest on the board, one column per set.
fn rest_check_table(checks: &[(String, RestCheck)]) -> String {
    if checks.is_empty() {
        return String::new();
    }
    let mut text = String::from("<h3>Checks at rest on the board</h3><table><tr><th></th>");
    for (name, _) in checks {
        text.push_str(&format!("<th>{}</th>", escape(name)));
    }
    text.push_str("<th>target</th></tr>");
    for (k, quantity) in REST_QUANTITIES.iter().enumerate() {
        text.push_str(&format!("<tr><th>{}</th>", quantity.label));
        for (_, check) in checks {
            let (digits, unit) = (quantity.digits, quantity.unit);
            let cell = check.values()[k]
                .filter(|v| v.is_finite())
                .map_or(NOT_ESTIMATED.to_string(), |v| {
                    format!("{v:.digits$} {unit}")
                });
            text.push_str(&format!("<td>{}</td>", escape(&cell)));
        }
        text.push_str(&format!("<td>{}</td></tr>", escape(quantity.target)));
    }
    text.push_str("</table>");
    text
}

/// RMS over poses of each axis.
fn axis_rms(values: &[[f64; 3]]) -> [f64; 3] {
    [0, 1, 2].map(|i| rms(&values.iter().map(|v| v[i]).collect::<Vec<_>>()))
}

/// The gyroscope's section: rate at rest per pose and axis before and after (each on its own
/// scale), the per-axis RMS, and the scale fit from the moves.
fn gyro_section(
    gyro: &GyroPoses,
    summary_rows: &mut Vec<(String, String)>,
) -> Result<String, ReportError> {
    let before = axis_rms(&gyro.raw_dps);
    let after = axis_rms(&gyro.calibrated_dps);
    let per_axis = |v: [f64; 3]| {
        v.iter()
            .map(|r| format!("{r:.4}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    summary_rows.push((
        "gyroscope rate at rest, RMS over poses, x, y, z".to_string(),
        format!(
            "{} °/s before, {} °/s after ({})",
            per_axis(before),
            per_axis(after),
            poses(gyro.raw_dps.len())
        ),
    ));
    let mut body = String::from(
        "<h2>Gyroscope</h2><p>Mean rate in each still pose, per axis, before and after \
         calibration, each on its own scale. Held still the true rate is the Earth's rotation \
         (0.004 °/s at most) plus whatever the hands turned the board during the hold, so what \
         remains after calibration is the bias the fit left and that sway.</p>",
    );
    body.push_str(&figure(&plots::axis_bars(
        "gyroscope before calibration: rate at rest per pose",
        "rate (°/s)",
        &gyro.raw_dps,
        &gyro.labels,
    )?));
    body.push_str(&figure(&plots::axis_bars(
        "gyroscope after calibration: residual rate at rest per pose (own scale)",
        "rate (°/s)",
        &gyro.calibrated_dps,
        &gyro.labels,
    )?));
    body.push_str("<table><tr><th>RMS over poses</th><th>x</th><th>y</th><th>z</th></tr>");
    for (name, values) in [("before, °/s", before), ("after, °/s", after)] {
        body.push_str(&format!("<tr><th>{name}</th>"));
        for v in values {
            body.push_str(&format!("<td>{v:.4}</td>"));
        }
        body.push_str("</tr>");
    }
    body.push_str("</table>");
    if gyro.scale_fit.is_empty() {
        body.push_str(
            "<p class=small>Scale and misalignment: not estimated (only the bias was \
             calibrated).</p>",
        );
    } else {
        body.push_str("<h3>Scale and misalignment from the moves between holds</h3><table>");
        for (name, value) in &gyro.scale_fit {
            body.push_str(&format!(
                "<tr><th>{}</th><td>{}</td></tr>",
                escape(name),
                escape(value)
            ));
        }
        body.push_str("</table>");
    }
    Ok(body)
}
