//! The report's SVG plots, drawn with plotters' SVG backend into strings that the page inlines.
//!
//! Each function returns the SVG text of one figure, or a [`PlotError`] saying what could not
//! be drawn. Data is thinned before drawing so that a page stays a few megabytes at most.

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::fit::{Mat3, Vec3};
use crate::session::coverage::{region_directions, region_name, Coverage};

/// Why a plot could not be drawn.
#[derive(Debug, thiserror::Error)]
#[error("the {figure} plot could not be drawn: {detail}")]
pub struct PlotError {
    /// Which figure.
    pub figure: &'static str,
    /// The plotting library's message.
    pub detail: String,
}

pub(crate) fn plot_error<E: std::fmt::Display>(figure: &'static str) -> impl Fn(E) -> PlotError {
    move |e| PlotError {
        figure,
        detail: e.to_string(),
    }
}

/// Colour of the data before calibration.
const BEFORE: RGBColor = RGBColor(214, 96, 77);
/// Colour of the data after calibration.
const AFTER: RGBColor = RGBColor(33, 102, 172);
/// Colour of fitted shapes (ellipse, sphere, zero line).
const SHAPE: RGBColor = RGBColor(30, 30, 30);

/// Points drawn per scatter at most.
pub const MAX_POINTS: usize = 1500;

/// A residual plot's finish: a thin zero line across `x` and the legend in the upper right.
fn zero_line_and_legend<'a>(
    chart: &mut ChartContext<'a, SVGBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    x: std::ops::Range<f64>,
    figure: &'static str,
) -> Result<(), PlotError> {
    chart
        .draw_series(LineSeries::new(
            [(x.start, 0.0), (x.end, 0.0)],
            SHAPE.stroke_width(1),
        ))
        .map_err(plot_error(figure))?;
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(plot_error(figure))
}

/// Every `n`-th item so that at most `max` remain.
pub fn thinned<T: Copy>(items: &[T], max: usize) -> Vec<T> {
    let step = items.len().div_ceil(max.max(1)).max(1);
    items.iter().step_by(step).copied().collect()
}

/// A range padded by 8 % on each side (and widened when empty or degenerate).
pub(crate) fn padded(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return -1.0..1.0;
    }
    let span = (hi - lo).max(1e-9 * hi.abs().max(1.0));
    (lo - 0.08 * span)..(hi + 0.08 * span)
}

/// Same span on both axes around each axis' centre, so circles look round.
fn square(points: &[(f64, f64)]) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let x = padded(points.iter().map(|p| p.0));
    let y = padded(points.iter().map(|p| p.1));
    let half = (x.end - x.start).max(y.end - y.start) / 2.0;
    let (cx, cy) = ((x.start + x.end) / 2.0, (y.start + y.end) / 2.0);
    ((cx - half)..(cx + half), (cy - half)..(cy + half))
}

/// The axis pairs of the three projections and their names.
pub const PROJECTIONS: [(usize, usize, &str, &str); 3] =
    [(0, 1, "x", "y"), (0, 2, "x", "z"), (1, 2, "y", "z")];

/// Outline of the projection of the ellipsoid `{b + M·u : |u| = 1}` onto axes `(i, j)`: the
/// ellipse `P·b + (S·Sᵀ)^½·v`, `S = P·M`, `|v| = 1`, as a closed polyline.
pub fn ellipse_outline(centre: &Vec3, shape: &Mat3, i: usize, j: usize) -> Vec<(f64, f64)> {
    let s_i = shape.row(i);
    let s_j = shape.row(j);
    let (c11, c12, c22) = (s_i.dot(&s_i), s_i.dot(&s_j), s_j.dot(&s_j));
    // Square root of the symmetric 2×2 matrix by its eigen-decomposition.
    let mean = (c11 + c22) / 2.0;
    let radius = (((c11 - c22) / 2.0).powi(2) + c12 * c12).sqrt();
    let (l1, l2) = ((mean + radius).max(0.0), (mean - radius).max(0.0));
    let angle = 0.5 * (2.0 * c12).atan2(c11 - c22);
    let (sin, cos) = angle.sin_cos();
    (0..=96)
        .map(|k| {
            let t = std::f64::consts::TAU * f64::from(k) / 96.0;
            let (a, b) = (l1.sqrt() * t.cos(), l2.sqrt() * t.sin());
            (centre[i] + cos * a - sin * b, centre[j] + sin * a + cos * b)
        })
        .collect()
}

/// One projection of magnetometer samples with a closed outline (fitted ellipse or sphere),
/// the legend naming both (`outline_label`, e.g. "fitted ellipsoid").
pub fn projection(
    title: &str,
    unit: &str,
    points: &[Vec3],
    (outline, outline_label): (&[(f64, f64)], &str),
    axes: (usize, usize, &str, &str),
    after: bool,
) -> Result<String, PlotError> {
    const FIGURE: &str = "magnetometer projection";
    let (i, j, xname, yname) = axes;
    let pairs: Vec<(f64, f64)> = thinned(points, MAX_POINTS)
        .iter()
        .map(|p| (p[i], p[j]))
        .collect();
    let all: Vec<(f64, f64)> = pairs.iter().chain(outline).copied().collect();
    let (xr, yr) = square(&all);
    let colour = if after { AFTER } else { BEFORE };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (340, 340)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error(FIGURE))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 15))
            .margin(8)
            .margin_right(20)
            .x_label_area_size(32)
            .y_label_area_size(48)
            .build_cartesian_2d(xr, yr)
            .map_err(plot_error(FIGURE))?;
        chart
            .configure_mesh()
            .x_desc(format!("{xname} ({unit})"))
            .y_desc(format!("{yname} ({unit})"))
            .x_labels(5)
            .y_labels(5)
            .draw()
            .map_err(plot_error(FIGURE))?;
        chart
            .draw_series(
                pairs
                    .iter()
                    .map(|p| Circle::new(*p, 2, colour.mix(0.45).filled())),
            )
            .map_err(plot_error(FIGURE))?
            .label(if after {
                "calibrated samples"
            } else {
                "raw samples"
            })
            .legend(move |(x, y)| Circle::new((x + 5, y), 3, colour.filled()));
        if !outline.is_empty() {
            chart
                .draw_series(LineSeries::new(
                    outline.iter().copied(),
                    SHAPE.stroke_width(2),
                ))
                .map_err(plot_error(FIGURE))?
                .label(outline_label)
                .legend(|(x, y)| PathElement::new([(x, y), (x + 12, y)], SHAPE.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 11))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(plot_error(FIGURE))?;
        root.present().map_err(plot_error(FIGURE))?;
    }
    Ok(svg)
}

/// Above this many poses the pose labels stand vertical, so neighbouring labels never overlap.
pub const VERTICAL_LABELS_ABOVE: usize = 16;

/// Width of a per-pose plot's drawing, px.
const BARS_WIDTH: u32 = 1020;

/// Whether the pose labels stand vertical: above [`VERTICAL_LABELS_ABOVE`] poses, or when the
/// longest label (about 7 px a character at 12 px) is wider than its bar's slot.
pub fn labels_vertical(labels: &[String]) -> bool {
    let longest = labels.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    let slot = f64::from(BARS_WIDTH - 100) / labels.len().max(1) as f64;
    labels.len() > VERTICAL_LABELS_ABOVE || longest as f64 * 7.0 > slot * 0.9
}

/// Height of the label area under a per-pose plot: room for the longest label when they stand
/// vertical.
fn pose_label_area(labels: &[String]) -> u32 {
    if labels_vertical(labels) {
        let longest = labels.iter().map(|l| l.chars().count()).max().unwrap_or(4);
        (longest as u32 * 7 + 40).clamp(60, 200)
    } else {
        48
    }
}

/// Draws each pose's label under its bar: horizontal for a few short labels, vertical (reading
/// top to bottom) otherwise ([`labels_vertical`]).
fn pose_labels<'a>(
    root: &DrawingArea<SVGBackend<'a>, plotters::coord::Shift>,
    chart: &ChartContext<'a, SVGBackend<'a>, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    labels: &[String],
    y_bottom: f64,
    figure: &'static str,
) -> Result<(), PlotError> {
    use plotters::style::text_anchor::{HPos, Pos, VPos};
    let vertical = labels_vertical(labels);
    for (k, label) in labels.iter().enumerate() {
        let (px, py) = chart.backend_coord(&(k as f64, y_bottom));
        let font = ("sans-serif", 12).into_font();
        let style = if vertical {
            TextStyle::from(font.transform(FontTransform::Rotate90))
                .pos(Pos::new(HPos::Left, VPos::Center))
        } else {
            TextStyle::from(font).pos(Pos::new(HPos::Center, VPos::Top))
        };
        root.draw(&Text::new(label.clone(), (px, py + 4), style))
            .map_err(plot_error(figure))?;
    }
    Ok(())
}

/// Per-pose bars on their own scale (so small "after" values are as readable as large "before"
/// ones), each bar labelled with its pose's orientation; `y_desc` names the value and unit.
pub fn pose_bars(
    title: &str,
    y_desc: &str,
    values: &[f64],
    labels: &[String],
    after: bool,
) -> Result<String, PlotError> {
    let series = [(
        values.to_vec(),
        if after { AFTER } else { BEFORE },
        if after {
            "after calibration"
        } else {
            "before calibration"
        },
    )];
    grouped_bars(title, y_desc, &series, labels, "residual per pose")
}

/// Colours of the x, y and z axes in the per-axis plots.
const AXIS_COLOURS: [RGBColor; 3] = [
    RGBColor(228, 26, 28),
    RGBColor(77, 175, 74),
    RGBColor(55, 126, 184),
];

/// One value per pose and axis (e.g. the gyroscope's rate at rest, °/s) as three bars per pose
/// in the axes' colours, with a legend, on the plot's own scale.
pub fn axis_bars(
    title: &str,
    y_desc: &str,
    values: &[[f64; 3]],
    labels: &[String],
) -> Result<String, PlotError> {
    let series: Vec<(Vec<f64>, RGBColor, &str)> = ["x axis", "y axis", "z axis"]
        .iter()
        .enumerate()
        .map(|(i, name)| {
            (
                values.iter().map(|v| v[i]).collect(),
                AXIS_COLOURS[i],
                *name,
            )
        })
        .collect();
    grouped_bars(title, y_desc, &series, labels, "per-axis value per pose")
}

/// Bars of one or more series side by side at each pose, with a zero line, a legend and the
/// poses' labels.
fn grouped_bars(
    title: &str,
    y_desc: &str,
    series: &[(Vec<f64>, RGBColor, &str)],
    labels: &[String],
    figure: &'static str,
) -> Result<String, PlotError> {
    let n = series.iter().map(|s| s.0.len()).max().unwrap_or(0);
    let data = padded(series.iter().flat_map(|s| s.0.iter().copied()).chain([0.0]));
    // Headroom above the tallest bar for the legend in the upper right.
    let yr = data.start..(data.end + 0.12 * series.len() as f64 * (data.end - data.start));
    let bottom = yr.start;
    let xr = -0.5..(n as f64 - 0.5);
    let width = 0.7 / series.len().max(1) as f64;
    let label_area = pose_label_area(labels);
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (BARS_WIDTH, 250 + label_area)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error(figure))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(label_area)
            .y_label_area_size(64)
            .build_cartesian_2d(xr.clone(), yr)
            .map_err(plot_error(figure))?;
        chart
            .configure_mesh()
            .x_desc("pose (the side that points up)")
            .y_desc(y_desc)
            .disable_x_mesh()
            .x_labels(0)
            .draw()
            .map_err(plot_error(figure))?;
        for (s, (values, colour, label)) in series.iter().enumerate() {
            let colour = *colour;
            let left = -0.35 + s as f64 * width;
            chart
                .draw_series(values.iter().enumerate().map(|(k, v)| {
                    let x = k as f64 + left;
                    Rectangle::new([(x, 0.0), (x + width * 0.9, *v)], colour.filled())
                }))
                .map_err(plot_error(figure))?
                .label(*label)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 10, y + 5)], colour.filled())
                });
        }
        zero_line_and_legend(&mut chart, xr, figure)?;
        pose_labels(&root, &chart, labels, bottom, figure)?;
        root.present().map_err(plot_error(figure))?;
    }
    Ok(svg)
}

/// Histogram of values (percent) with `bins` equal bins.
pub fn histogram(
    title: &str,
    x_desc: &str,
    values: &[f64],
    after: bool,
) -> Result<String, PlotError> {
    const FIGURE: &str = "norm-error histogram";
    const BINS: usize = 40;
    let range = padded(values.iter().copied());
    let width = (range.end - range.start) / BINS as f64;
    let mut counts = [0u32; BINS];
    for v in values.iter().filter(|v| v.is_finite()) {
        let k = ((v - range.start) / width).floor() as usize;
        if let Some(c) = counts.get_mut(k.min(BINS - 1)) {
            *c += 1;
        }
    }
    let top = counts.iter().copied().max().unwrap_or(1).max(1);
    let colour = if after { AFTER } else { BEFORE };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (500, 300)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error(FIGURE))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(48)
            .build_cartesian_2d(range.clone(), 0u32..(top + top / 10 + 1))
            .map_err(plot_error(FIGURE))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc("samples")
            .x_labels(6)
            .draw()
            .map_err(plot_error(FIGURE))?;
        chart
            .draw_series(counts.iter().enumerate().map(|(k, c)| {
                let x0 = range.start + k as f64 * width;
                Rectangle::new([(x0, 0), (x0 + width, *c)], colour.mix(0.8).filled())
            }))
            .map_err(plot_error(FIGURE))?
            .label(if after {
                "after calibration"
            } else {
                "before calibration"
            })
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], colour.filled()));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(plot_error(FIGURE))?;
        root.present().map_err(plot_error(FIGURE))?;
    }
    Ok(svg)
}

/// Residual against a variable (time, temperature): "before" in the upper panel and "after" in
/// the lower one, each on its own vertical scale so the small calibrated residual stays
/// readable; both share the horizontal axis.
pub fn residual_against(
    title: &str,
    x_desc: &str,
    y_desc: &str,
    before: &[(f64, f64)],
    after: &[(f64, f64)],
) -> Result<String, PlotError> {
    const FIGURE: &str = "residual against a variable";
    let before = thinned(before, MAX_POINTS);
    let after = thinned(after, MAX_POINTS);
    let xr = padded(before.iter().chain(&after).map(|p| p.0));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (500, 440)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error(FIGURE))?;
        let root = root
            .titled(title, ("sans-serif", 15))
            .map_err(plot_error(FIGURE))?;
        let panels = root.split_evenly((2, 1));
        for (area, points, colour, label) in [
            (&panels[0], &before, BEFORE, "before calibration"),
            (&panels[1], &after, AFTER, "after calibration"),
        ] {
            let yr = padded(points.iter().map(|p| p.1).chain([0.0]));
            let mut chart = ChartBuilder::on(area)
                .margin(6)
                .x_label_area_size(30)
                .y_label_area_size(56)
                .build_cartesian_2d(xr.clone(), yr)
                .map_err(plot_error(FIGURE))?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(y_desc)
                .x_labels(6)
                .y_labels(5)
                .draw()
                .map_err(plot_error(FIGURE))?;
            chart
                .draw_series(
                    points
                        .iter()
                        .map(|p| Circle::new(*p, 2, colour.mix(0.5).filled())),
                )
                .map_err(plot_error(FIGURE))?
                .label(label)
                .legend(move |(x, y)| Circle::new((x + 5, y), 3, colour.filled()));
            zero_line_and_legend(&mut chart, xr.clone(), FIGURE)?;
        }
        root.present().map_err(plot_error(FIGURE))?;
    }
    Ok(svg)
}

/// Tile size of the coverage map, degrees: fine enough that the regions' borders show.
const TILE_DEG: f64 = 5.0;

/// Azimuth and elevation of `d`, degrees.
fn azimuth_elevation(d: &Vec3) -> (f64, f64) {
    let n = d.norm();
    (
        d.y.atan2(d.x).to_degrees(),
        (d.z / n).clamp(-1.0, 1.0).asin().to_degrees(),
    )
}

/// Map of the field directions in the session's 26 regions ([`crate::session::coverage`]): the
/// same cells, centre and minimum per region as the session's screen. Each 5° tile of the
/// azimuth–elevation plane takes the colour of the region its direction falls in; regions
/// with fewer than `min_samples` samples stay white with a red label.
pub fn coverage_map(cover: &Coverage, min_samples: usize) -> Result<String, PlotError> {
    const FIGURE: &str = "sphere coverage";
    let directions = region_directions();
    let top = cover.counts.iter().copied().max().unwrap_or(1).max(1);
    let region_of = |d: &Vec3| {
        directions
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.dot(d).total_cmp(&b.1.dot(d)))
            .map_or(0, |(i, _)| i)
    };
    let colour_of = |count: usize| {
        if count < min_samples {
            WHITE
        } else {
            // Square-root shading so that sparsely sampled regions stay visible.
            let shade = (count as f64 / top as f64).sqrt();
            let fade = |full: u8| (255.0 - (255.0 - f64::from(full)) * (0.25 + 0.75 * shade)) as u8;
            RGBColor(fade(AFTER.0), fade(AFTER.1), fade(AFTER.2))
        }
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1020, 380)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_error(FIGURE))?;
        let caption = format!(
            "field directions in the session's 26 regions (reading less its sphere centre, as \
             counted on screen); white: fewer than {min_samples} samples"
        );
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(32)
            .y_label_area_size(48)
            .build_cartesian_2d(-180.0..180.0, -90.0..90.0)
            .map_err(plot_error(FIGURE))?;
        chart
            .configure_mesh()
            .x_desc("azimuth atan2(y, x) of the field in the board frame (°)")
            .y_desc("elevation (°)")
            .x_labels(13)
            .y_labels(7)
            .draw()
            .map_err(plot_error(FIGURE))?;
        let columns = (360.0 / TILE_DEG) as usize;
        let rows = (180.0 / TILE_DEG) as usize;
        let tiles = (0..columns).flat_map(|a| (0..rows).map(move |e| (a, e)));
        chart
            .draw_series(tiles.map(|(a, e)| {
                let x0 = -180.0 + TILE_DEG * a as f64;
                let y0 = -90.0 + TILE_DEG * e as f64;
                let (az, el) = (
                    (x0 + TILE_DEG / 2.0).to_radians(),
                    (y0 + TILE_DEG / 2.0).to_radians(),
                );
                let d = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
                let count = cover.counts.get(region_of(&d)).copied().unwrap_or(0);
                Rectangle::new(
                    [(x0, y0), (x0 + TILE_DEG, y0 + TILE_DEG)],
                    colour_of(count).filled(),
                )
            }))
            .map_err(plot_error(FIGURE))?;
        let labels = directions.iter().zip(&cover.counts).map(|(d, &count)| {
            let (az, el) = azimuth_elevation(d);
            // Keep the labels of the ±X column and of the poles inside the frame.
            let az = if az > 170.0 { -170.0 } else { az };
            let el = el.clamp(-84.0, 84.0);
            let colour: &'static RGBColor = if count < min_samples { &BEFORE } else { &SHAPE };
            let style = TextStyle::from(("sans-serif", 12).into_font())
                .color(colour)
                .pos(plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Center,
                    plotters::style::text_anchor::VPos::Center,
                ));
            Text::new(format!("{} {count}", region_name(d)), (az, el), style)
        });
        chart.draw_series(labels).map_err(plot_error(FIGURE))?;
        root.present().map_err(plot_error(FIGURE))?;
    }
    Ok(svg)
}
