//! What `imucal calibrate` shows: pictures and prompts, indicatif bars for stillness, hold
//! progress and coverage (plain lines with `--yes` or when stderr is not a terminal), the fitted
//! result and the before/after table.

use std::time::{Duration, Instant};

use super::write_policy::{WriteDecision, WritePolicy};
use imucal::device::PoseProgress;
use imucal::report::gain::{gain, gain_text};
use imucal::session::mag_guidance::MagGuidance;
use imucal::session::rest::REST_QUANTITIES;
use imucal::session::{
    RestErrors, SessionEvent, SessionFit, SessionObserver, SessionOutcome, VerdictLevel,
};
use imucal_protocol::StreamKind;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The terminal interface of a session.
pub(super) struct Terminal {
    plain: bool,
    policy: WritePolicy,
    /// What became of the offer to write the fitted set (`None` before it is made).
    pub(super) decision: Option<WriteDecision>,
    port: String,
    pub(super) bar: ProgressBar,
    last_line: Option<Instant>,
    last_coverage: usize,
    /// Also write the magnetometer's coverage updates as JSON lines (`--json`).
    json: bool,
}

impl Terminal {
    pub(super) fn new(plain: bool, policy: WritePolicy, port: String) -> Self {
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
            policy,
            decision: None,
            port,
            bar,
            last_line: None,
            last_coverage: usize::MAX,
            json: false,
        }
    }

    /// With `on`, coverage updates of the magnetometer phase are also written to stderr as one
    /// JSON object a line (`"event": "mag_coverage"`, with the guidance), for scripts that run
    /// `--json`; the prose line is then left out in plain mode.
    pub(super) fn with_json_events(mut self, on: bool) -> Self {
        self.json = on;
        self
    }

    fn line(&self, text: &str) {
        if self.plain {
            say!("{text}");
        } else {
            self.bar.println(text);
        }
    }

    /// At most one progress line every two seconds (plain mode's bars, `--json` events).
    fn throttled(&mut self, text: &str) {
        if self
            .last_line
            .is_none_or(|t| t.elapsed() >= Duration::from_secs(2))
        {
            self.last_line = Some(Instant::now());
            self.line(text);
        }
    }

    /// Empties the bar so a finished step's message does not linger under the next prompt.
    fn clear_bar(&self) {
        if !self.plain {
            self.bar.set_position(0);
            self.bar.set_prefix("");
            self.bar.set_message("");
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

/// What a person does to fill the coverage region named `region` (e.g. `+X-Z`): the field must
/// point along that direction of the board, and the Earth's field points north and, away from
/// the equator, steeply down in the northern hemisphere (up in the southern).
fn pointing_hint(region: &str) -> String {
    let parts: Vec<String> = region
        .as_bytes()
        .chunks(2)
        .filter_map(|pair| match pair {
            [b'+', b'Z'] => Some("the top face (+Z)".to_string()),
            [b'-', b'Z'] => Some("the bottom face (-Z)".to_string()),
            [sign, axis] => Some(format!("the {}{} end", *sign as char, *axis as char)),
            _ => None,
        })
        .collect();
    let side = match parts.as_slice() {
        [one] => one.clone(),
        [first @ .., last] => format!("{} and {last}", first.join(", ")),
        [] => region.to_string(),
    };
    format!("turn the board so {side} points north and down (south of the equator: north and up)")
}

/// The coverage bar's message: the counts and the instruction towards the nearest empty region.
/// On a terminal the instruction is the message's second line, so both are redrawn in place and
/// no earlier hint lingers; plain mode joins them on one line.
fn coverage_message(
    covered: usize,
    regions: usize,
    samples: usize,
    empty: &[String],
    guidance: Option<&MagGuidance>,
    plain: bool,
) -> String {
    let next = match (guidance, empty.first()) {
        (_, None) => "every direction reached".to_string(),
        (Some(g), Some(_)) => format!("next: {}", g.text),
        (None, Some(region)) => format!("next: {}", pointing_hint(region)),
    };
    let counts = format!(
        "{covered}/{regions} directions, {samples} samples, {} empty",
        empty.len()
    );
    if plain {
        format!("{counts}; {next}")
    } else {
        format!("{counts}\n{:>12}{next}", "")
    }
}

/// Stillness in the units of the summary: accelerometer σ in mg, gyroscope σ in °/s.
fn stillness_text(still: bool, accel_std_mps2: f64, gyro_std_rads: f64) -> String {
    let mg = 1000.0 / imucal::session::solve::STANDARD_GRAVITY;
    format!(
        "{} (accel σ {:.1} mg, gyro σ {:.3} °/s)",
        if still { "still " } else { "moving" },
        accel_std_mps2 * mg,
        gyro_std_rads.to_degrees()
    )
}

/// Bar position (0–99, the capture ends the bar) and message of a hold: still time toward the
/// `hold_s` seconds this capture averages. The time since the request bounds the still time the
/// board has gathered from above, so the bar never runs ahead of the capture.
fn hold_progress(name: &str, progress: &PoseProgress, hold_s: f64) -> (u64, String) {
    let held_s = progress.elapsed.as_secs_f64().min(hold_s);
    let fraction = if hold_s > 0.0 { held_s / hold_s } else { 0.0 };
    let state = match progress.still {
        Some(true) | None => "keep it there",
        Some(false) => "moving: hold it steady, the average restarts",
    };
    (
        ((fraction * 100.0) as u64).min(99),
        format!("averaging {name}: {held_s:.1} of {hold_s:.1} s; {state}"),
    )
}

/// What the screen shows for a figure the fit could not estimate (instead of `NaN`).
const NOT_ESTIMATED: &str = imucal::report::NOT_ESTIMATED;

/// `value` with `precision` decimals (signed when `signed`), or [`NOT_ESTIMATED`].
fn figure(value: f64, precision: usize, signed: bool) -> String {
    match (value.is_finite(), signed) {
        (false, _) => NOT_ESTIMATED.to_string(),
        (true, true) => format!("{value:>+.precision$}"),
        (true, false) => format!("{value:.precision$}"),
    }
}

fn triple(values: [f64; 3], precision: usize) -> String {
    let parts: Vec<String> = values.iter().map(|v| figure(*v, precision, true)).collect();
    format!("[{}]", parts.join(", "))
}

fn sigmas(values: [f64; 3], precision: usize) -> String {
    let parts: Vec<String> = values
        .iter()
        .map(|v| figure(*v, precision, false))
        .collect();
    format!("[{}]", parts.join(", "))
}

/// The fit summary's first line: which method fitted each sensor, the gyroscope's scale named
/// when the moves between holds calibrated it.
fn fit_headline(accel: imucal::fit::Method, gyro: imucal::fit::Method) -> String {
    let gyro = if gyro == imucal::fit::Method::GyroScale {
        "gyro bias from the holds, scale and misalignment from the moves between them"
    } else {
        "gyro bias from the holds (scale not calibrated)"
    };
    format!(
        "Fit (accelerometer {}, {gyro}, magnetometer LM ellipsoid + dip alignment):",
        accel.name()
    )
}

/// The sensor's gain error against nominal per axis, ppm, as the gyroscope's line, `fit` and
/// the report give it: a correction `A = 1.02` is a sensor that reads 1/1.02 of the truth,
/// −1.96 %. Its σ relative to the gain is that of `A`'s diagonal to first order.
fn scale_error_ppm(a: &imucal::fit::Mat3) -> [f64; 3] {
    gain(a, 1.0).map_or([f64::NAN; 3], |g| g.scale.map(|s| (s - 1.0) * 1e6))
}

/// The gyroscope's scale and axis angles, or that they were not calibrated: the identity
/// written in their place is no measurement of a perfect gyroscope.
fn gyro_gain_line(fit: &SessionFit) -> String {
    if fit.gyro.method != imucal::fit::Method::GyroScale {
        return "scale and axis angles not calibrated (identity written)".to_string();
    }
    gain(&fit.gyro.cal.a, 1.0).map_or_else(
        || "scale: the fitted matrix is singular".to_string(),
        |g| gain_text(&g, 3),
    )
}

pub(super) fn describe_fit(fit: &SessionFit) -> Vec<String> {
    let u = &fit.uncertainties;
    let mg = 1000.0 / imucal::session::solve::STANDARD_GRAVITY;
    let accel_b = [0, 1, 2].map(|i| fit.accel.cal.b[i] * mg);
    let accel_scale = scale_error_ppm(&fit.accel.cal.a);
    let gyro_b = [0, 1, 2].map(|i| fit.gyro.cal.b[i].to_degrees());
    let mag_b = [0, 1, 2].map(|i| fit.mag.cal.b[i]);
    let source = match fit.field_source {
        imucal::session::FieldSource::Given => "reference",
        imucal::session::FieldSource::SimulatedSite => "the simulated site's",
        imucal::session::FieldSource::MeanRadius => "the sensor's mean radius",
    };
    let mut lines = vec![
        fit_headline(fit.accel.method, fit.gyro.method),
        format!("  accelerometer model: {}", fit.accel_choice.reason),
        format!(
            "  accelerometer  offset {} mg ± {}",
            triple(accel_b, 2),
            sigmas(u.accel_bias_mg, 3)
        ),
        format!(
            "                 scale error {} ppm ± {}",
            triple(accel_scale, 0),
            sigmas(u.accel_scale_ppm, 0)
        ),
        format!(
            "                 expected |a| error ± {} mg (1σ, worst direction)",
            figure(u.accel_norm_mg, 3, false)
        ),
        format!(
            "  gyroscope      bias   {} °/s ± {}",
            triple(gyro_b, 3),
            sigmas(u.gyro_bias_dps, 4)
        ),
        format!("                 {}", gyro_gain_line(fit)),
        format!(
            "  magnetometer   offset {} µT ± {}",
            triple(mag_b, 2),
            sigmas(u.mag_bias_ut, 3)
        ),
        format!(
            "                 expected |m| error ± {} % (1σ); field {:.2} µT ({source}); {}",
            figure(u.mag_norm_pct, 3, false),
            fit.field_ut,
            match &fit.alignment {
                Ok(_) => format!(
                    "aligned to the accelerometer ± {}°",
                    figure(u.alignment_deg, 3, false)
                ),
                Err(e) => format!("NOT aligned to the accelerometer ({e})"),
            }
        ),
    ];
    lines.extend(fit.notes.iter().map(|n| format!("  note: {n}")));
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
                self.clear_bar();
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
            SessionEvent::Capturing {
                target,
                progress,
                hold_s,
            } => {
                let (position, message) = hold_progress(target.name.as_str(), progress, *hold_s);
                self.bar("holding", 100, position, message);
            }
            SessionEvent::Captured {
                target,
                samples,
                captured,
                total,
            } => {
                self.clear_bar();
                self.line(&format!(
                    "  captured {} ({samples} samples) — {captured}/{total}",
                    target.name
                ));
            }
            SessionEvent::CaptureFailed { target, reason } => {
                self.clear_bar();
                self.line(&format!("  {} not captured: {reason}", target.name));
            }
            SessionEvent::Note(text) => self.line(&format!("Note: {text}")),
            SessionEvent::MagPrompt => {
                self.last_line = None;
                self.clear_bar();
                self.line(
                    "\nMagnetometer: turn the board slowly through all directions (roll, pitch \
                     and yaw), away from steel, magnets and cables. The hint below names the \
                     board's ends (+X, -Y, …) and faces (components +Z, underside -Z) as the \
                     position pictures do; a turn about the vertical moves only the field's \
                     horizontal part, so some directions need a tilt first.",
                );
            }
            SessionEvent::MagCoverage {
                covered,
                regions,
                samples,
                empty,
                guidance,
            } => {
                if *covered != self.last_coverage {
                    self.last_coverage = *covered;
                    self.last_line = None;
                }
                if self.json {
                    let line = serde_json::json!({
                        "event": "mag_coverage",
                        "covered": covered,
                        "regions": regions,
                        "samples": samples,
                        "empty": empty,
                        "guidance": guidance,
                    });
                    self.throttled(&line.to_string());
                }
                let message =
                    coverage_message(*covered, *regions, *samples, empty, guidance.as_ref(), self.plain);
                if !(self.json && self.plain) {
                    self.bar("coverage", *regions as u64, *covered as u64, message);
                }
            }
            SessionEvent::RestPrompt => {
                self.last_line = None;
                self.clear_bar();
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
        let question = format!("Write these parameters to the board on {}", self.port);
        let decision = self.policy.decide(fit.verdict.level, &question);
        self.decision = Some(decision);
        decision == WriteDecision::Write
    }
}

/// The at-rest errors before and after. With `extended` (the set `--analyze` wrote) the
/// "after" column is that set, the one on the board now, and the base set's column sits
/// beside it for comparison.
pub(super) fn before_after_table(
    outcome: &SessionOutcome,
    extended: Option<&RestErrors>,
) -> String {
    let show = |value: Option<f64>, unit: &str, precision: usize| match value {
        Some(v) if v.is_finite() => format!("{v:.precision$} {unit}"),
        Some(_) => "unknown".to_string(),
        None => "—".to_string(),
    };
    let mut columns: Vec<(&str, Option<&RestErrors>)> = vec![("before", Some(&outcome.before))];
    match extended {
        Some(set) => {
            columns.push(("base set", outcome.after.as_ref()));
            columns.push(("on the board", Some(set)));
        }
        None => columns.push(("after", outcome.after.as_ref())),
    }
    let mut text = format!("{:<16}", "at rest");
    for (name, _) in &columns {
        text.push_str(&format!("{name:>14}"));
    }
    text.push_str(&format!("{:>12}\n", "target"));
    for (k, quantity) in REST_QUANTITIES.iter().enumerate() {
        text.push_str(&format!("{:<16}", quantity.label));
        for (column, (_, errors)) in columns.iter().enumerate() {
            // Uncalibrated values are large: one decimal fewer.
            let digits = quantity.digits - usize::from(column == 0);
            let value = errors.map(|e| e.values()[k]);
            text.push_str(&format!("{:>14}", show(value, quantity.unit, digits)));
        }
        text.push_str(&format!("{:>12}\n", quantity.target));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hold_bar_counts_toward_this_capture_and_never_completes_before_it() {
        let progress = |elapsed_s: f64| PoseProgress {
            elapsed: Duration::from_secs_f64(elapsed_s),
            timeout: Duration::from_secs(20),
            still: Some(true),
        };
        // Half of a 1.2 s hold is half the bar, whatever the 20 s timeout.
        let (half, text) = hold_progress("+Z up", &progress(0.6), 1.2);
        assert_eq!(half, 50);
        assert!(text.contains("0.6 of 1.2 s"), "{text}");
        // Past the hold the bar waits at 99 % for the board's answer.
        assert_eq!(hold_progress("+Z up", &progress(5.0), 1.2).0, 99);
    }

    #[test]
    fn the_fit_headline_names_the_gyroscope_scale_when_the_moves_calibrated_it() {
        use imucal::fit::Method;
        let scaled = fit_headline(Method::Lm, Method::GyroScale);
        assert!(
            scaled.contains("scale and misalignment from the moves"),
            "{scaled}"
        );
        let bias_only = fit_headline(Method::Lm, Method::GyroBias);
        assert!(bias_only.contains("scale not calibrated"), "{bias_only}");
    }

    #[test]
    fn the_accelerometer_scale_error_has_the_sign_of_the_gyroscope_line_and_the_report() {
        // A correction of 1.02 on x: the sensor reads 1/1.02 of the truth, −19 608 ppm.
        let a = imucal::fit::Mat3::from_diagonal(&imucal::fit::Vec3::new(1.02, 1.0, 0.99));
        let ppm = scale_error_ppm(&a);
        assert!((ppm[0] - (1.0 / 1.02 - 1.0) * 1e6).abs() < 1e-6, "{ppm:?}");
        assert!(ppm[1].abs() < 1e-9, "{ppm:?}");
        assert!(ppm[2] > 10_000.0, "{ppm:?}");
        // The same convention as the gain text the gyroscope's line prints.
        let text = gain_text(&gain(&a, 1.0).expect("regular"), 3);
        assert!(text.contains("-1.961 %"), "{text}");
    }

    #[test]
    fn figures_not_estimated_are_written_in_words() {
        assert_eq!(figure(f64::NAN, 3, false), "unknown / not estimated");
        assert_eq!(
            sigmas([0.1, f64::NAN, 0.2], 2),
            "[0.10, unknown / not estimated, 0.20]"
        );
        assert_eq!(triple([1.0, -2.0, 0.5], 1), "[+1.0, -2.0, +0.5]");
    }

    #[test]
    fn stillness_is_shown_in_the_summary_units() {
        let text = stillness_text(true, 0.0098_0665, 1.0_f64.to_radians());
        assert!(text.contains("accel σ 1.0 mg"), "{text}");
        assert!(text.contains("gyro σ 1.000 °/s"), "{text}");
    }

    #[test]
    fn the_coverage_message_gives_the_attitude_instruction_on_its_own_line() {
        use imucal::fit::Vec3;
        // Flat, the field along +X and dipping: -Z needs a tilt.
        let g = imucal::session::mag_guidance::guidance(
            &Vec3::z(),
            &Vec3::new(0.5, 0.0, -0.866),
            &-Vec3::z(),
        )
        .expect("guidance");
        let empty = vec!["-Z".to_string()];
        let bar = coverage_message(25, 26, 1800, &empty, Some(&g), false);
        let lines: Vec<&str> = bar.lines().collect();
        assert_eq!(lines.len(), 2, "{bar}");
        assert!(lines[0].starts_with("25/26 directions, 1800 samples, 1 empty"));
        assert!(lines[1].contains(&g.text), "{bar}");
        let plain = coverage_message(25, 26, 1800, &empty, Some(&g), true);
        assert_eq!(plain.lines().count(), 1);
        // Without an attitude the hint falls back to the field's direction in the room.
        assert!(coverage_message(25, 26, 1800, &empty, None, true).contains("points north"));
        assert!(coverage_message(26, 26, 1800, &[], Some(&g), true).contains("every direction"));
    }

    #[test]
    fn coverage_hints_name_sides_of_the_board() {
        assert!(pointing_hint("-Z").contains("the bottom face (-Z) points north and down"));
        assert!(pointing_hint("+X-Z").contains("the +X end and the bottom face (-Z)"));
    }
}
