//! Parameters of one board over time, for the report: one SVG figure per group (offsets and
//! gains per sensor), the x, y and z parameters as lines against days since the first record.

use plotters::prelude::*;

use super::record::AXES;
use super::store::StoredRecord;
use crate::report::plots::{padded, plot_error, PlotError};

/// A figure: which parameters, titled how, in which unit and scaled by what for display.
struct Group {
    title: &'static str,
    unit: &'static str,
    /// Parameter name with `{}` for the axis letter.
    pattern: &'static str,
    scale: f64,
}

const GROUPS: [Group; 5] = [
    Group {
        title: "Accelerometer offset",
        unit: "m/s²",
        pattern: "accel.b.{}",
        scale: 1.0,
    },
    Group {
        title: "Accelerometer gain (diagonal of A)",
        unit: "",
        pattern: "accel.A.{}{}",
        scale: 1.0,
    },
    Group {
        title: "Gyroscope offset",
        unit: "°/s",
        pattern: "gyro.b.{}",
        scale: 180.0 / std::f64::consts::PI,
    },
    Group {
        title: "Magnetometer offset",
        unit: "µT",
        pattern: "mag.b.{}",
        scale: 1.0,
    },
    Group {
        title: "Magnetometer gain (diagonal of A)",
        unit: "",
        pattern: "mag.A.{}{}",
        scale: 1.0,
    },
];

const AXIS_COLOURS: [RGBColor; 3] = [
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(31, 119, 180),
];

/// `(days since the first record, value)` of `parameter` in `records` (oldest first).
pub fn parameter_series(records: &[StoredRecord], parameter: &str) -> Vec<(f64, f64)> {
    let start = records.first().map_or(0, |s| s.record.recorded_unix_ms);
    records
        .iter()
        .filter_map(|s| {
            let value = *s.record.parameters().get(parameter)?;
            let days = (s.record.recorded_unix_ms - start) as f64 / 86_400_000.0;
            Some((days, value))
        })
        .collect()
}

/// One `(title, SVG)` per parameter group of one board's `records` (oldest first).
pub fn parameters_over_time(records: &[StoredRecord]) -> Result<Vec<(String, String)>, PlotError> {
    const FIGURE: &str = "parameters over time";
    let mut figures = Vec::new();
    for group in &GROUPS {
        let series: Vec<Vec<(f64, f64)>> = AXES
            .iter()
            .map(|axis| {
                let name = group.pattern.replace("{}", axis);
                parameter_series(records, &name)
                    .into_iter()
                    .map(|(t, v)| (t, v * group.scale))
                    .collect()
            })
            .collect();
        let xr = padded(series.iter().flatten().map(|p| p.0));
        let yr = padded(series.iter().flatten().map(|p| p.1));
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (500, 260)).into_drawing_area();
            root.fill(&WHITE).map_err(plot_error(FIGURE))?;
            let mut chart = ChartBuilder::on(&root)
                .caption(group.title, ("sans-serif", 15))
                .margin(8)
                .x_label_area_size(32)
                .y_label_area_size(64)
                .build_cartesian_2d(xr, yr)
                .map_err(plot_error(FIGURE))?;
            chart
                .configure_mesh()
                .x_desc("days since the first calibration")
                .y_desc(group.unit)
                .x_labels(6)
                .draw()
                .map_err(plot_error(FIGURE))?;
            for ((points, colour), axis) in series.iter().zip(AXIS_COLOURS).zip(AXES) {
                chart
                    .draw_series(LineSeries::new(points.iter().copied(), colour))
                    .map_err(plot_error(FIGURE))?
                    .label(axis)
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 14, y)], colour.stroke_width(2))
                    });
                chart
                    .draw_series(points.iter().map(|p| Circle::new(*p, 3, colour.filled())))
                    .map_err(plot_error(FIGURE))?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(plot_error(FIGURE))?;
            root.present().map_err(plot_error(FIGURE))?;
        }
        figures.push((group.title.to_string(), svg));
    }
    Ok(figures)
}
