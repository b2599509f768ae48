//! Reports of a residual analysis: the stable JSON that scripts read, a text summary, and SVG
//! plots (plotters' SVG backend) of the residual against the variable of each accepted effect,
//! before and after.
//!
//! JSON (`imucal analyze --json`), one object per analysed sensor under `"sensors"`:
//! `base_model` (str), `noise_floor`, `consistent_with_noise` (bool, base model, χ² test at
//! 1 %), `rms_before`, `rms_after`, `heldout_rms_before`, `heldout_rms_after` (relative to the
//! reference magnitude for accel/mag, rad/s for gyro), `effects`: `[{name, accepted, score,
//! coefficients: {name: {value, std, unit}}, status, p_value, gain, note}]` (`score` = relative
//! fall of the mean held-out loss; `status` one of accepted, rejected, confounded,
//! not_testable), `unexplained` (bool), and the extras `chi2_before`, `chi2_after` (`{chi2, dof,
//! p_value}`), `n_observations`, `best_correlate` (`{variable, r}` or null),
//! `temp_time_correlation`, `t_ref_c`, `heldout_always_trained` (observations never held out
//! because the base model cannot be refit without them; 0 when every one is), `base_note` (why
//! the base is not the model `fit` chose, or null). A sensor that could not be analysed has `{"error": str}`.

use std::path::Path;

use plotters::prelude::*;
use serde_json::{json, Map, Value};

use super::effects::EffectKind;
use super::{EffectResult, EffectStatus, RecordingAnalysis, SensorAnalysis};
use crate::stats::chi_square::{ChiSquareTest, CONSISTENCY_ALPHA};

/// Why a report could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The directory or a file could not be written.
    #[error("could not write `{path}`: {source}; check that the directory is writable")]
    Io {
        /// Path.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// The plot could not be drawn.
    #[error("could not draw `{path}`: {detail}")]
    Plot {
        /// Path.
        path: String,
        /// Cause.
        detail: String,
    },
}

fn status_name(s: EffectStatus) -> &'static str {
    match s {
        EffectStatus::Accepted => "accepted",
        EffectStatus::Rejected => "rejected",
        EffectStatus::Confounded => "confounded",
        EffectStatus::NotTestable => "not_testable",
        EffectStatus::NotFittable => "not_fittable",
    }
}

fn finite(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

fn test_json(t: &ChiSquareTest) -> Value {
    json!({"chi2": finite(t.chi2), "dof": t.dof, "p_value": finite(t.p_value)})
}

fn effect_json(e: &EffectResult) -> Value {
    let coefficients: Map<String, Value> = e
        .coefficients
        .iter()
        .map(|c| {
            (
                c.name.clone(),
                json!({"value": finite(c.value), "std": finite(c.std), "unit": c.unit}),
            )
        })
        .collect();
    let degree = match e.kind {
        EffectKind::BiasTemperature(d) => Some(d),
        _ => None,
    };
    json!({
        "name": e.kind.name(),
        "accepted": e.status == EffectStatus::Accepted,
        "score": finite(e.score),
        "coefficients": coefficients,
        "status": status_name(e.status),
        "degree": degree,
        "p_value": finite(e.p_value),
        "gain": finite(e.gain),
        "note": e.note,
    })
}

/// JSON of one sensor's analysis.
pub fn sensor_json(a: &SensorAnalysis) -> Value {
    json!({
        "base_model": a.base_model,
        "noise_floor": finite(a.noise_floor),
        "consistent_with_noise": a.consistent_with_noise(),
        "rms_before": finite(a.rms_before),
        "rms_after": finite(a.rms_after),
        "heldout_rms_before": finite(a.heldout_rms_before),
        "heldout_rms_after": finite(a.heldout_rms_after),
        "heldout_always_trained": a.always_trained,
        "base_note": a.base_note,
        "effects": a.effects.iter().map(effect_json).collect::<Vec<_>>(),
        "unexplained": a.unexplained,
        "chi2_before": test_json(&a.test_before),
        "chi2_after": test_json(&a.test_after),
        "n_observations": a.observations.len(),
        "best_correlate": a.best_correlate.as_ref().map(|(v, r)| json!({"variable": v, "r": finite(*r)})),
        "temp_time_correlation": a.temp_time_correlation.map(finite),
        "t_ref_c": finite(a.t_ref_c),
    })
}

/// The JSON document `{"sensors": {...}}`.
pub fn to_json(analysis: &RecordingAnalysis) -> Value {
    let sensors: Map<String, Value> = analysis
        .sensors
        .iter()
        .map(|(s, r)| {
            let v = match r {
                Ok(a) => sensor_json(a),
                Err(e) => json!({"error": e.to_string()}),
            };
            (s.name().to_string(), v)
        })
        .collect();
    json!({ "sensors": sensors })
}

fn rms_unit(a: &SensorAnalysis) -> &'static str {
    a.residual_unit
}

/// Human-readable summary.
pub fn to_text(analysis: &RecordingAnalysis) -> String {
    let mut out = String::new();
    for (sensor, result) in &analysis.sensors {
        let a = match result {
            Err(e) => {
                out.push_str(&format!("{sensor}: not analysed: {e}\n\n"));
                continue;
            }
            Ok(a) => a,
        };
        let u = rms_unit(a);
        out.push_str(&format!(
            "{sensor} — base model {} — {} observations\n",
            a.base_model,
            a.observations.len()
        ));
        out.push_str(&format!(
            "  noise floor {:.3e} {u} (RMS of each observation's own noise, which weighs its \
             residual in χ²); base residual χ² = {:.1} on {} dof ({}): {}\n",
            a.noise_floor,
            a.test_before.chi2,
            a.test_before.dof,
            a.test_before.p_text(),
            if a.consistent_with_noise() {
                "consistent with the noise"
            } else {
                "above the noise"
            }
        ));
        out.push_str(&format!(
            "  RMS {:.3e} → {:.3e} {u}; held-out RMS {:.3e} → {:.3e} {u}\n",
            a.rms_before, a.rms_after, a.heldout_rms_before, a.heldout_rms_after
        ));
        if let Some(note) = &a.base_note {
            out.push_str(&format!("  {note}\n"));
        }
        if a.always_trained > 0 {
            out.push_str(&format!(
                "  held out: each of the {} observations the base model can be refit without, \
                 in turn; the base model cannot be refit without any of the other {} (as a rule \
                 the only pose of its orientation), so they stay in every fit\n",
                a.observations.len() - a.always_trained,
                a.always_trained
            ));
        }
        if let Some(r) = a.temp_time_correlation {
            out.push_str(&format!(
                "  temperature–time correlation of the poses: {r:.3}\n"
            ));
        }
        for e in &a.effects {
            let degree = match e.kind {
                EffectKind::BiasTemperature(d) => format!(" (degree {d})"),
                _ => String::new(),
            };
            out.push_str(&format!(
                "  {:<11} {}{degree}: {}\n",
                status_name(e.status),
                e.kind.name(),
                e.note
            ));
            if e.status == EffectStatus::Accepted {
                for c in &e.coefficients {
                    out.push_str(&format!(
                        "      {:<6} {:>12.4e} ± {:<10.2e} {}\n",
                        c.name, c.value, c.std, c.unit
                    ));
                }
            }
        }
        if a.unexplained {
            let corr = a.best_correlate.as_ref().map_or(String::new(), |(v, r)| {
                format!("; it correlates best with {v} (r = {r:.2})")
            });
            let what = if a.accepted().next().is_some() {
                "partly explained: after the accepted effects the final residual"
            } else {
                "unexplained: the final residual"
            };
            let confounded: Vec<&str> = a
                .effects
                .iter()
                .filter(|e| e.status == EffectStatus::Confounded)
                .map(|e| e.kind.name())
                .collect();
            let candidates = if confounded.is_empty() {
                "no candidate explains it".to_string()
            } else {
                format!(
                    "{} would explain part of it but was set aside as confounded (see above)",
                    confounded.join(" and ")
                )
            };
            out.push_str(&format!(
                "  {what} ({:.3e} {u} RMS) is {:.1}× the noise, each observation weighed by its own (χ²/dof = {:.1}; an RMS below the floor's can be far above the noise of the observations that carry it), and {candidates}{corr}\n",
                a.rms_after,
                a.test_after.reduced().sqrt(),
                a.test_after.reduced()
            ));
        } else {
            out.push_str(&format!(
                "  final residual is consistent with the noise at the {}% level (χ²/dof = {:.2}, {})\n",
                100.0 * CONSISTENCY_ALPHA,
                a.test_after.reduced(),
                a.test_after.p_text()
            ));
        }
        out.push('\n');
    }
    out
}

/// Values of the variable `kind` depends on, per observation.
fn variable_values(a: &SensorAnalysis, kind: EffectKind) -> Option<Vec<f64>> {
    match kind {
        EffectKind::BiasTemperature(_) | EffectKind::ScaleTemperature => {
            a.observations.iter().map(|o| o.temp_c).collect()
        }
        EffectKind::BiasDrift | EffectKind::BinnedBias(false) => {
            Some(a.observations.iter().map(|o| o.time_s).collect())
        }
        EffectKind::BinnedBias(true) => a.observations.iter().map(|o| o.temp_c).collect(),
        EffectKind::ScaleNonlinearity => Some(
            a.observations
                .iter()
                .map(|o| (o.mean - a.calibration.b).norm())
                .collect(),
        ),
        EffectKind::GSensitivity => a
            .observations
            .iter()
            .map(|o| o.accel_mean.map(|f| f.norm()))
            .collect(),
    }
}

/// Draw residual against the variable of `kind`, before (grey) and after (blue).
fn plot_effect(a: &SensorAnalysis, kind: EffectKind, path: &Path) -> Result<(), ReportError> {
    let err = |detail: String| ReportError::Plot {
        path: path.display().to_string(),
        detail,
    };
    let Some(xs) = variable_values(a, kind) else {
        return Ok(());
    };
    let pairs: Vec<(f64, f64, f64)> = xs
        .iter()
        .zip(a.residuals_before.iter().zip(&a.residuals_after))
        .map(|(x, (b, f))| (*x, *b, *f))
        .filter(|(x, b, f)| x.is_finite() && b.is_finite() && f.is_finite())
        .collect();
    if pairs.is_empty() {
        return Ok(());
    }
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, b, f) in &pairs {
        x0 = x0.min(*x);
        x1 = x1.max(*x);
        y0 = y0.min(b.min(*f));
        y1 = y1.max(b.max(*f));
    }
    let pad = |lo: f64, hi: f64| {
        let d = if hi > lo {
            0.05 * (hi - lo)
        } else {
            1e-12_f64.max(lo.abs() * 0.05)
        };
        (lo - d, hi + d)
    };
    let (x0, x1) = pad(x0, x1);
    let (y0, y1) = pad(y0, y1);
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let caption = format!(
        "{}: residual vs {} ({})",
        a.sensor,
        kind.variable(),
        kind.name()
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(caption, ("sans-serif", 20))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(e.to_string()))?;
    chart
        .configure_mesh()
        .x_desc(kind.variable())
        .y_desc(format!("residual ({})", rms_unit(a)))
        .draw()
        .map_err(|e| err(e.to_string()))?;
    chart
        .draw_series(
            pairs
                .iter()
                .map(|(x, b, _)| Circle::new((*x, *b), 3, RGBColor(150, 150, 150).filled())),
        )
        .map_err(|e| err(e.to_string()))?
        .label("base model")
        .legend(|(x, y)| Circle::new((x, y), 3, RGBColor(150, 150, 150).filled()));
    chart
        .draw_series(
            pairs
                .iter()
                .map(|(x, _, f)| Circle::new((*x, *f), 3, BLUE.filled())),
        )
        .map_err(|e| err(e.to_string()))?
        .label("with accepted effects")
        .legend(|(x, y)| Circle::new((x, y), 3, BLUE.filled()));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(e.to_string()))?;
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}

/// Write `analysis.json`, `analysis.txt` and one SVG per accepted effect into `dir`; returns the
/// files written.
pub fn write_report(
    analysis: &RecordingAnalysis,
    dir: &Path,
) -> Result<Vec<std::path::PathBuf>, ReportError> {
    write_report_as(analysis, dir, &to_json(analysis), &to_text(analysis))
}

/// [`write_report`] with the JSON document and text as the command printed them (e.g. with
/// each sensor's base fit), so that the files and the printed output are the same.
pub fn write_report_as(
    analysis: &RecordingAnalysis,
    dir: &Path,
    document: &serde_json::Value,
    text: &str,
) -> Result<Vec<std::path::PathBuf>, ReportError> {
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |source| ReportError::Io { path, source }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let mut written = Vec::new();
    let json_path = dir.join("analysis.json");
    let json = serde_json::to_string_pretty(document).unwrap_or_default();
    std::fs::write(&json_path, json).map_err(io(&json_path))?;
    written.push(json_path);
    let text_path = dir.join("analysis.txt");
    std::fs::write(&text_path, text).map_err(io(&text_path))?;
    written.push(text_path);
    for (_, result) in &analysis.sensors {
        let Ok(a) = result else { continue };
        for e in a.accepted() {
            let path = dir.join(format!("{}_{}.svg", a.sensor.name(), e.kind.name()));
            plot_effect(a, e.kind, &path)?;
            written.push(path);
        }
    }
    Ok(written)
}
