//! What `imucal calibrate` shows: pictures and prompts, indicatif bars for stillness, hold
//! progress and coverage (plain lines with `--yes` or when stderr is not a terminal), the fitted
//! result and the before/after table.

use std::io::{BufRead, IsTerminal, Write};
use std::time::{Duration, Instant};

use imucal::session::{SessionEvent, SessionFit, SessionObserver, SessionOutcome, VerdictLevel};
use imucal_protocol::StreamKind;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The terminal interface of a session.
pub(super) struct Terminal {
    plain: bool,
    yes: bool,
    port: String,
    pub(super) bar: ProgressBar,
    last_line: Option<Instant>,
    last_coverage: usize,
}

impl Terminal {
    pub(super) fn new(plain: bool, yes: bool, port: String) -> Self {
        let bar = if plain {
            ProgressBar::hidden()
        } else {
            let bar = ProgressBar::with_draw_target(Some(100), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template("{prefix:>10} [{bar:30}] {msg}")
                    .unwrap_or_else(|_| ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
            bar
        };
        Self {
            plain,
            yes,
            port,
            bar,
            last_line: None,
            last_coverage: usize::MAX,
        }
    }

    fn line(&self, text: &str) {
        if self.plain {
            eprintln!("{text}");
        } else {
            self.bar.println(text);
        }
    }

    /// Plain mode: at most one progress line every two seconds.
    fn throttled(&mut self, text: &str) {
        if self
            .last_line
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(2))
        {
            self.last_line = Some(Instant::now());
            eprintln!("{text}");
        }
    }

    fn bar(&mut self, prefix: &str, length: u64, position: u64, message: String) {
        if self.plain {
            self.throttled(&format!("  {prefix}: {message}"));
        } else {
            self.bar.set_prefix(prefix.to_string());
            self.bar.set_length(length.max(1));
            self.bar.set_position(position.min(length));
            self.bar.set_message(message);
        }
    }
}

fn stillness_text(still: bool, accel_std: f64, gyro_std: f64) -> String {
    format!(
        "{} (accel σ {:.3} m/s², gyro σ {:.4} rad/s)",
        if still { "still " } else { "moving" },
        accel_std,
        gyro_std
    )
}

fn triple(values: [f64; 3], precision: usize) -> String {
    let parts: Vec<String> = values
        .iter()
        .map(|v| format!("{v:>+.precision$}"))
        .collect();
    format!("[{}]", parts.join(", "))
}

fn sigmas(values: [f64; 3], precision: usize) -> String {
    let parts: Vec<String> = values.iter().map(|v| format!("{v:.precision$}")).collect();
    format!("[{}]", parts.join(", "))
}

pub(super) fn describe_fit(fit: &SessionFit) -> Vec<String> {
    let u = &fit.uncertainties;
    let mg = 1000.0 / imucal::session::solve::STANDARD_GRAVITY;
    let accel_b = [0, 1, 2].map(|i| fit.accel.cal.b[i] * mg);
    let accel_scale = [0, 1, 2].map(|i| (fit.accel.cal.a[(i, i)] - 1.0) * 1e6);
    let gyro_b = [0, 1, 2].map(|i| fit.gyro.cal.b[i].to_degrees());
    let mag_b = [0, 1, 2].map(|i| fit.mag.cal.b[i]);
    let source = match fit.field_source {
        imucal::session::FieldSource::Given => "given",
        imucal::session::FieldSource::MeanRadius => "the sensor's mean radius",
    };
    let mut lines = vec![
        format!(
            "Fit (accelerometer {}, gyro bias from the holds, LM ellipsoid + dip alignment):",
            fit.accel.method.name()
        ),
        format!("  accelerometer model: {}", fit.accel_choice.reason),
        format!(
            "  accelerometer  offset {} mg ± {}",
            triple(accel_b, 2),
            sigmas(u.accel_bias_mg, 3)
        ),
        format!(
            "                 scale  {} ppm ± {}",
            triple(accel_scale, 0),
            sigmas(u.accel_scale_ppm, 0)
        ),
        format!(
            "                 expected |a| error ± {:.3} mg (1σ, worst direction)",
            u.accel_norm_mg
        ),
        format!(
            "  gyroscope      bias   {} °/s ± {}",
            triple(gyro_b, 3),
            sigmas(u.gyro_bias_dps, 4)
        ),
        format!(
            "                 scale  {} (diagonal of A; 1 = nominal)",
            triple([0, 1, 2].map(|i| fit.gyro.cal.a[(i, i)]), 4)
        ),
        format!(
            "  magnetometer   offset {} µT ± {}",
            triple(mag_b, 2),
            sigmas(u.mag_bias_ut, 3)
        ),
        format!(
            "                 expected |m| error ± {:.3} % (1σ); field {:.2} µT ({source}); \
             aligned to the accelerometer ± {:.3}°",
            u.mag_norm_pct, fit.field_ut, u.alignment_deg
        ),
    ];
    let verdict = match fit.verdict.level {
        VerdictLevel::Good => "good",
        VerdictLevel::Marginal => "marginal",
        VerdictLevel::Poor => "poor",
    };
    lines.push(format!("  verdict: {verdict}"));
    lines.extend(fit.verdict.reasons.iter().map(|r| format!("    - {r}")));
    lines
}

impl SessionObserver for Terminal {
    fn event(&mut self, event: &SessionEvent<'_>) {
        match event {
            SessionEvent::Prompt {
                target,
                captured,
                total,
            } => {
                self.last_line = None;
                self.line(&format!(
                    "\nPosition {}/{total}: hold the board {} (any order is fine)",
                    captured + 1,
                    target.name
                ));
                for row in target.picture() {
                    if !row.is_empty() {
                        self.line(&row);
                    }
                }
            }
            SessionEvent::Motion {
                state,
                at,
                needed,
                settle_s,
            } => {
                let place = match (at, needed) {
                    (Some(t), true) => format!("in {}", t.name),
                    (Some(t), false) => format!("in {} (already captured)", t.name),
                    (None, _) => "between positions".to_string(),
                };
                let progress = (state.still_for_s / settle_s * 100.0) as u64;
                self.bar(
                    "stillness",
                    100,
                    if *needed { progress } else { 0 },
                    format!(
                        "{} {place}",
                        stillness_text(state.still, state.accel_std_mps2, state.gyro_std_rads)
                    ),
                );
            }
            SessionEvent::Capturing { target, progress } => {
                let fraction = progress.elapsed.as_secs_f64() / progress.timeout.as_secs_f64();
                let still = match progress.still {
                    Some(true) => "still",
                    Some(false) => "moving",
                    None => "waiting",
                };
                self.bar(
                    "holding",
                    100,
                    (fraction * 100.0) as u64,
                    format!("averaging {} ({still}), keep it there", target.name),
                );
            }
            SessionEvent::Captured {
                target,
                samples,
                captured,
                total,
            } => self.line(&format!(
                "  captured {} ({samples} samples) — {captured}/{total}",
                target.name
            )),
            SessionEvent::CaptureFailed { target, reason } => {
                self.line(&format!("  {} not captured: {reason}", target.name));
            }
            SessionEvent::Note(text) => self.line(&format!("Note: {text}")),
            SessionEvent::MagPrompt => {
                self.last_line = None;
                self.line(
                    "\nMagnetometer: turn the board slowly through all directions (roll, pitch \
                     and yaw), away from steel, magnets and cables.",
                );
            }
            SessionEvent::MagCoverage {
                covered,
                regions,
                samples,
                empty,
            } => {
                let shown: Vec<&str> = empty.iter().take(6).map(String::as_str).collect();
                let more = empty.len().saturating_sub(shown.len());
                let missing = if empty.is_empty() {
                    "every direction reached".to_string()
                } else if more > 0 {
                    format!("still empty: {} and {more} more", shown.join(" "))
                } else {
                    format!("still empty: {}", shown.join(" "))
                };
                let message = format!("{covered}/{regions} directions, {samples} samples; {missing}");
                if self.plain && *covered != self.last_coverage {
                    self.last_coverage = *covered;
                    self.last_line = None;
                }
                self.bar("coverage", *regions as u64, *covered as u64, message);
            }
            SessionEvent::RestPrompt => {
                self.last_line = None;
                self.line("\nPut the board down and leave it still for the final check.");
            }
            SessionEvent::Resting {
                still_for_s,
                needed_s,
            } => self.bar(
                "rest",
                100,
                (still_for_s / needed_s * 100.0) as u64,
                format!("still for {still_for_s:.1} of {needed_s:.1} s"),
            ),
            SessionEvent::Measuring { kind } => {
                let what = match kind {
                    StreamKind::Raw => "raw readings at rest (before)",
                    StreamKind::Calibrated => "calibrated readings at rest (after)",
                };
                self.line(&format!("Measuring {what}…"));
            }
            SessionEvent::Fitted(fit) => {
                self.bar.finish_and_clear();
                for line in describe_fit(fit) {
                    self.line(&line);
                }
            }
            SessionEvent::Verified(status) => self.line(&format!(
                "Written to {}, committed, read back and compared: CRC {:#010x} (store sequence {})",
                self.port, status.active_crc, status.active_seq
            )),
        }
    }

    fn confirm_write(&mut self, fit: &SessionFit) -> bool {
        if self.yes || !std::io::stdin().is_terminal() {
            return true;
        }
        let advice = if fit.verdict.level == VerdictLevel::Poor {
            " (the verdict is poor)"
        } else {
            ""
        };
        eprint!(
            "Write these parameters to the board on {}{advice}? [Y/n] ",
            self.port
        );
        let _ = std::io::stderr().flush();
        let mut answer = String::new();
        if std::io::stdin().lock().read_line(&mut answer).is_err() {
            return false;
        }
        !matches!(answer.trim().to_lowercase().as_str(), "n" | "no")
    }
}

pub(super) fn before_after_table(outcome: &SessionOutcome) -> String {
    let before = &outcome.before;
    let after = outcome.after.as_ref();
    let show = |value: Option<f64>, unit: &str, precision: usize| {
        value.map_or("—".to_string(), |v| format!("{v:.precision$} {unit}"))
    };
    let mut text = String::new();
    text.push_str(&format!(
        "{:<16}{:>14}{:>14}{:>12}\n",
        "at rest", "before", "after", "target"
    ));
    let rows = [
        (
            "|a| error",
            Some(before.accel_error_mg),
            after.map(|a| a.accel_error_mg),
            "mg",
            2,
            "< 2 mg",
        ),
        (
            "|m| error",
            Some(before.mag_error_pct),
            after.map(|a| a.mag_error_pct),
            "%",
            2,
            "< 0.5 %",
        ),
        (
            "gyro rate",
            Some(before.gyro_rate_dps),
            after.map(|a| a.gyro_rate_dps),
            "°/s",
            3,
            "",
        ),
    ];
    for (name, was, now, unit, precision, target) in rows {
        text.push_str(&format!(
            "{name:<16}{:>14}{:>14}{target:>12}\n",
            show(was, unit, precision),
            show(now, unit, precision + 1),
        ));
    }
    text
}
