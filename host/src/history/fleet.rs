//! Fleet statistics and the robust outlier test: is a board's calibration far outside the
//! population of boards calibrated before it (or of the other boards of its batch)? The
//! population is the set on each board: an attempt that was not written (refused as an outlier
//! or for a poor verdict) is tested against it and listed, but never counted in it.
//!
//! Method: per parameter, the fleet's centre is the median and its spread the scaled median
//! absolute deviation `s = 1.4826·MAD` (a consistent estimate of σ for normal data). Both have a
//! 50 % breakdown point: up to half the fleet may be faulty without moving them much, unlike a
//! mean and standard deviation that a single gross fault inflates until it hides itself. A
//! board's distance is the robust z `z = (x − median) / √(s²·(1 + π/2n) + σ²)`, where `σ` is the
//! board's own fit uncertainty of that parameter (an uncertain fit is not evidence of a fault)
//! and `π/2n` the variance of the median of `n` boards in units of `s²` (it matters in a small
//! fleet). For `n` below 10 the MAD is corrected by Croux & Rousseeuw's small-sample factors
//! (1992, "Time-efficient algorithms for two highly robust estimators of scale"), above by
//! `n/(n − 0.8)`: the MAD about a sample median is biased low for few values. Noise and
//! residual parameters are positive and multiplicative, so they are compared as logarithms.
//!
//! Threshold: a board is flagged when any `|z|` exceeds `z*`, chosen so that a fault-free board
//! is flagged with probability at most `α` (the false-alarm rate per board, default 0.1 %):
//! Bonferroni over the `m` parameters tested gives a two-sided `α/m` per parameter, and because
//! `s` is itself estimated from `k` values with the MAD's efficiency of 37 %, the quantile is
//! Student's t with `ν = 0.37·k` degrees of freedom instead of the normal's. `z*` thus follows
//! from `α`, `m` and `k`, never from the data's values.
//!
//! Small fleets: every spread must rest on at least [`FleetOptions::min_spread_values`] values
//! (20, ν ≈ 7). A parameter that at least that many boards have gets its own spread. In a
//! smaller fleet (a first batch on an empty history) the MAD of one parameter over a handful of
//! boards is too uncertain (its t tail needs `|z|` of 50–100 at α/m), so the deviations of the
//! axes of one sensor's parameter of one kind (offsets x, y, z; gain diagonal; cross-axis
//! terms; noise) are pooled, each from its own median: the axes of one part share one datasheet
//! tolerance (e.g. the LSM9DS1's ±90 mg zero-g offset for all three axes), so they share a
//! population spread. Seven boards then give 21 values per offset. Parameters without such
//! axes (residuals) are tested only once the fleet is large enough for their own spread.
//!
//! Offset vectors: a magnet by the magnetometer moves all three offsets at once, each by less
//! than its own threshold. So a sensor's offset whose three axes are all tested is also tested
//! as a vector: `d² = Σ z²` over its axes. With the spreads estimated from `ν = 0.37·k` values,
//! `d²/3` follows Snedecor's F with (3, ν) degrees of freedom (the normal theory's χ² with 3
//! degrees of freedom as `ν` grows), and `d` is compared with `√(3·F*)`. The vectors join the
//! Bonferroni count: with `v` of them, each of the `m + v` tests gets `α/(m + v)`. The finding
//! is named `<sensor>.b.length`, its value the offset's length.

use std::collections::BTreeMap;

use serde::Serialize;

use super::record::{BoardWrite, CalibrationRecord};
use super::stats::{median, t_upper_quantile};
use super::store::{HistoryStore, RecordId, StoredRecord};
use super::HistoryError;
use crate::stats::distributions::f_upper_tail;

/// The `f` with `P(F ≥ f) = upper` for `(d1, d2)` degrees of freedom, by bisection on
/// [`f_upper_tail`] (which falls as `f` grows).
fn f_upper_quantile(upper: f64, d1: f64, d2: f64) -> f64 {
    let (mut low, mut high) = (0.0_f64, 1.0_f64);
    while f_upper_tail(high, d1, d2) > upper && high < 1e12 {
        high *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (low + high);
        if f_upper_tail(mid, d1, d2) > upper {
            low = mid;
        } else {
            high = mid;
        }
    }
    high
}

/// Consistency factor of the MAD for the normal distribution: `1/Φ⁻¹(3/4)`.
const MAD_TO_SIGMA: f64 = 1.482_602_218_505_602;

/// Croux & Rousseeuw's small-sample correction of the MAD about the sample median of `n`
/// values (their table for n ≤ 9, `n/(n − 0.8)` above).
fn mad_small_sample_factor(n: usize) -> f64 {
    match n {
        0..=1 => 1.0,
        2 => 1.196,
        3 => 1.495,
        4 => 1.363,
        5 => 1.206,
        6 => 1.200,
        7 => 1.140,
        8 => 1.129,
        9 => 1.107,
        _ => n as f64 / (n as f64 - 0.8),
    }
}

/// Asymptotic efficiency of the MAD relative to the standard deviation (normal data).
const MAD_EFFICIENCY: f64 = 0.367_4;

/// Settings of the outlier test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FleetOptions {
    /// Probability that a fault-free board is flagged.
    pub false_alarm_per_board: f64,
    /// Fewest values a spread may rest on: a parameter's own values (one per board), or in a
    /// small fleet those of its sensor's axes of the same kind, pooled.
    pub min_spread_values: usize,
}

impl Default for FleetOptions {
    fn default() -> Self {
        Self {
            false_alarm_per_board: 1e-3,
            // ν = 0.37·20 ≈ 7 degrees of freedom: below that the spread is too uncertain.
            min_spread_values: 20,
        }
    }
}

/// Population statistics of one parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterStats {
    /// The parameter (see [`CalibrationRecord::parameters`]).
    pub parameter: String,
    /// Boards that have it.
    pub boards: usize,
    /// Median, in the parameter's unit.
    pub median: f64,
    /// Robust standard deviation `1.4826·MAD` (small-sample corrected): in the parameter's unit, or of its natural
    /// logarithm (a relative spread) when `log_scale`.
    pub robust_sd: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Whether the test compares logarithms (noise, residuals).
    pub log_scale: bool,
    /// Values the spread rests on: `boards`, or more when pooled with the sensor's other axes
    /// of the same kind (a small fleet).
    pub spread_values: usize,
    /// The threshold on `|z|` of this parameter (Student's t, `ν = 0.37·spread_values`).
    pub threshold_z: f64,
}

/// One parameter of one board outside the fleet.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Finding {
    /// The parameter.
    pub parameter: String,
    /// The board's value.
    pub value: f64,
    /// The fleet's median.
    pub fleet_median: f64,
    /// Robust distance `z`.
    pub robust_z: f64,
    /// The threshold on `|z|` of this parameter.
    pub threshold_z: f64,
    /// The likely cause, in words.
    pub likely_cause: String,
}

/// One board's result in the fleet.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoardResult {
    /// The board.
    pub device_id: String,
    /// Its newest record.
    pub record_id: RecordId,
    /// Whether any parameter is beyond the threshold.
    pub outlier: bool,
    /// Largest `|z|` over its parameters.
    pub max_abs_z: f64,
    /// The parameters beyond the threshold, farthest first.
    pub findings: Vec<Finding>,
    /// Sensors left out of the comparison with the unit their parameters map from: a set fitted
    /// from raw counts (`input_unit`) has an `A` and `b` in counts, which no board calibrated in
    /// the nominal units can be compared with.
    pub not_compared: Vec<String>,
    /// Why the tested set is not on the board, for an attempt that was not written (tested
    /// against the fleet, not counted in it); `null` for the set on the board.
    pub not_written: Option<String>,
}

/// The fleet's statistics and every board's test.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FleetReport {
    /// Boards in the fleet: the newest set on each board (attempts not written are not counted).
    pub boards: usize,
    /// The method, in words.
    pub method: String,
    /// False-alarm rate per board the threshold was set for.
    pub false_alarm_per_board: f64,
    /// The largest threshold on `|z|` over the parameters (each parameter's own is in
    /// `parameters`; parameters with a pooled spread have smaller ones).
    pub threshold_z: f64,
    /// Per parameter.
    pub parameters: Vec<ParameterStats>,
    /// Parameters too few boards have to be tested.
    pub untested: Vec<Untested>,
    /// Per board, outliers first: the set on each board, and each board's attempt not
    /// written since (`not_written` says why).
    pub results: Vec<BoardResult>,
}

/// The test of one record against the fleet before it is written.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FleetCheck {
    /// Whether a test was possible (enough boards).
    pub tested: bool,
    /// Whether the record is an outlier.
    pub outlier: bool,
    /// Boards it was compared with.
    pub fleet_boards: usize,
    /// The largest threshold on `|z|` over the parameters tested (0 when not tested).
    pub threshold_z: f64,
    /// The parameters beyond it, farthest first.
    pub findings: Vec<Finding>,
    /// Why no test was made, if none was.
    pub note: Option<String>,
}

/// Why no fleet statistics could be made.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    /// The history could not be read.
    #[error(transparent)]
    History(#[from] HistoryError),
    /// Too few boards for a robust spread.
    #[error("the fleet holds {}; the outlier test needs at least {needed} for a trustworthy spread (the three axes of a sensor pooled), so calibrate more boards first", count_boards(*.boards))]
    TooFewBoards {
        /// Boards found.
        boards: usize,
        /// Boards needed.
        needed: usize,
    },
}

/// `1 board`, `7 boards`.
pub fn count_boards(n: usize) -> String {
    format!("{n} board{}", if n == 1 { "" } else { "s" })
}

/// Whether a parameter is compared as a logarithm.
fn is_log_scale(parameter: &str) -> bool {
    parameter.contains(".noise.") || parameter.ends_with(".residual")
}

fn transformed(parameter: &str, value: f64) -> Option<f64> {
    if is_log_scale(parameter) {
        (value > 0.0).then(|| value.ln())
    } else {
        Some(value)
    }
}

/// The parameters whose spreads may be pooled in a small fleet: one sensor's axes of one kind
/// (`accel.b`, `accel.A.diagonal`, `accel.A.cross`, `gyro.noise`, …); a residual is alone.
fn axis_family(parameter: &str) -> String {
    let mut parts = parameter.splitn(3, '.');
    let (sensor, kind, axis) = (
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or_default(),
    );
    match (kind, axis.as_bytes()) {
        ("A", [row, col]) if row == col => format!("{sensor}.A.diagonal"),
        ("A", _) => format!("{sensor}.A.cross"),
        (_, []) => parameter.to_string(),
        _ => format!("{sensor}.{kind}"),
    }
}

/// One parameter's values on the test's scale, their median and absolute deviations.
struct Column {
    name: String,
    raw: Vec<f64>,
    centre: f64,
    deviations: Vec<f64>,
}

impl Column {
    fn new(name: String, raw: Vec<f64>) -> Option<Self> {
        let mut scaled: Vec<f64> = raw.iter().filter_map(|v| transformed(&name, *v)).collect();
        let centre = median(&mut scaled)?;
        let deviations: Vec<f64> = scaled.iter().map(|v| (v - centre).abs()).collect();
        // A parameter every board shares exactly (not fitted) cannot tell boards apart.
        let varies = deviations.iter().any(|d| *d > 0.0);
        varies.then_some(Self {
            name,
            raw,
            centre,
            deviations,
        })
    }

    /// `1.4826·MAD` of `deviations` about medians of `boards` values each, corrected for few
    /// boards; `None` when it is zero.
    fn spread(deviations: &[f64], boards: usize) -> Option<f64> {
        let mad = median(&mut deviations.to_vec())?;
        let spread = MAD_TO_SIGMA * mad_small_sample_factor(boards) * mad;
        (spread > 0.0 && spread.is_finite()).then_some(spread)
    }
}

/// The fitted population: per parameter its median and robust spread.
#[derive(Debug, Clone)]
pub struct FleetModel {
    boards: usize,
    parameters: Vec<ParameterStats>,
    untested: Vec<Untested>,
    /// Offset vectors tested as a whole: the sensor's `b` prefix (`mag.b`) and the threshold on
    /// the length of its axes' `z` vector.
    vectors: Vec<(String, f64)>,
}

/// A parameter some boards have but too few to give the fleet's spread.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Untested {
    /// The parameter, e.g. `mag.b.x`.
    pub parameter: String,
    /// Boards that have it.
    pub boards: usize,
    /// Boards it needs: with its sensor's other axes pooled, or for a parameter without axes
    /// (a residual) [`FleetOptions::min_spread_values`], one value per board.
    pub needed: usize,
}

impl FleetModel {
    /// The model of `records` (one per board), or why none can be made.
    pub fn fit(records: &[&CalibrationRecord], options: &FleetOptions) -> Result<Self, FleetError> {
        let boards = records.len();
        let mut values: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        for record in records {
            for (name, value) in comparable_parameters(record) {
                if value.is_finite() {
                    values.entry(name).or_default().push(value);
                }
            }
        }
        let columns: Vec<Column> = values
            .into_iter()
            .filter_map(|(name, raw)| Column::new(name, raw))
            .collect();
        let mut pooled: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        for column in &columns {
            pooled
                .entry(axis_family(&column.name))
                .or_default()
                .extend(&column.deviations);
        }
        // A pooled spread still needs a median per axis from enough boards: as many as make the
        // smallest pool (three axes) reach the minimum.
        let min_pooled_boards = options.min_spread_values.div_ceil(3).max(3);
        let mut parameters = Vec::new();
        let mut untested = Vec::new();
        for column in columns {
            let own = column.deviations.len();
            let family = pooled
                .get(&axis_family(&column.name))
                .map_or(&[][..], Vec::as_slice);
            let (deviations, spread_values) = if own >= options.min_spread_values {
                (column.deviations.as_slice(), own)
            } else if own >= min_pooled_boards && family.len() >= options.min_spread_values {
                (family, family.len())
            } else {
                // A parameter without axes (a residual) has no pool: it needs its own spread.
                let poolable = axis_family(&column.name) != column.name;
                untested.push(Untested {
                    parameter: column.name,
                    boards: own,
                    needed: if poolable {
                        min_pooled_boards
                    } else {
                        options.min_spread_values
                    },
                });
                continue;
            };
            let Some(spread) = Column::spread(deviations, own) else {
                continue;
            };
            let log_scale = is_log_scale(&column.name);
            parameters.push(ParameterStats {
                boards: own,
                median: if log_scale {
                    column.centre.exp()
                } else {
                    column.centre
                },
                robust_sd: spread,
                min: column.raw.iter().copied().fold(f64::INFINITY, f64::min),
                max: column.raw.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                log_scale,
                spread_values,
                threshold_z: 0.0,
                parameter: column.name,
            });
        }
        if parameters.is_empty() {
            return Err(FleetError::TooFewBoards {
                boards,
                needed: min_pooled_boards,
            });
        }
        // Offsets whose three axes are all tested are also tested as a vector.
        let vector_dofs: Vec<(String, f64)> = ["accel.b", "gyro.b", "mag.b"]
            .into_iter()
            .filter_map(|prefix| {
                let axes: Vec<&ParameterStats> = ["x", "y", "z"]
                    .iter()
                    .filter_map(|axis| {
                        let name = format!("{prefix}.{axis}");
                        parameters.iter().find(|p| p.parameter == name)
                    })
                    .collect();
                let fewest = axes.iter().map(|p| p.spread_values).min()?;
                (axes.len() == 3).then(|| (prefix.to_string(), MAD_EFFICIENCY * fewest as f64))
            })
            .collect();
        let tests = (parameters.len() + vector_dofs.len()) as f64;
        let per_parameter = options.false_alarm_per_board / (2.0 * tests);
        for stats in &mut parameters {
            let dof = MAD_EFFICIENCY * stats.spread_values as f64;
            stats.threshold_z = t_upper_quantile(per_parameter, dof.max(1.0));
        }
        let vectors = vector_dofs
            .into_iter()
            .map(|(prefix, dof)| {
                let f = f_upper_quantile(options.false_alarm_per_board / tests, 3.0, dof.max(1.0));
                (prefix, (3.0 * f).sqrt())
            })
            .collect();
        Ok(Self {
            boards,
            parameters,
            untested,
            vectors,
        })
    }

    /// The largest threshold on `|z|` over the parameters.
    pub fn threshold_z(&self) -> f64 {
        self.parameters
            .iter()
            .map(|p| p.threshold_z)
            .fold(0.0, f64::max)
    }

    /// `|z|` of every parameter of `record` against the fleet, largest first, as findings
    /// (those beyond the threshold are the outlying ones).
    pub fn distances(&self, record: &CalibrationRecord) -> Vec<Finding> {
        let values = comparable_parameters(record);
        let mut out: Vec<Finding> = self
            .parameters
            .iter()
            .filter_map(|stats| {
                let value = *values.get(&stats.parameter)?;
                let x = transformed(&stats.parameter, value)?;
                let centre = transformed(&stats.parameter, stats.median)?;
                // The fit's own σ, moved to the log scale by d(ln x) = dx / x.
                let own = record.sigma.get(&stats.parameter).copied().unwrap_or(0.0);
                let own = if stats.log_scale { own / value } else { own };
                let centre_variance = std::f64::consts::PI / (2.0 * stats.boards as f64);
                let fleet_sd = stats.robust_sd * (1.0 + centre_variance).sqrt();
                let z = (x - centre) / fleet_sd.hypot(own);
                Some(Finding {
                    parameter: stats.parameter.clone(),
                    value,
                    fleet_median: stats.median,
                    robust_z: z,
                    threshold_z: stats.threshold_z,
                    likely_cause: likely_cause_of(record, &stats.parameter),
                })
            })
            .collect();
        let vectors: Vec<Finding> = self
            .vectors
            .iter()
            .filter_map(|(prefix, threshold)| {
                let axes: Vec<&Finding> = ["x", "y", "z"]
                    .iter()
                    .filter_map(|axis| {
                        let name = format!("{prefix}.{axis}");
                        out.iter().find(|f| f.parameter == name)
                    })
                    .collect();
                if axes.len() != 3 {
                    return None;
                }
                let length = |v: &dyn Fn(&Finding) -> f64| {
                    axes.iter().map(|&f| v(f).powi(2)).sum::<f64>().sqrt()
                };
                let parameter = format!("{prefix}.length");
                Some(Finding {
                    value: length(&|f: &Finding| f.value),
                    fleet_median: length(&|f: &Finding| f.fleet_median),
                    robust_z: length(&|f: &Finding| f.robust_z),
                    threshold_z: *threshold,
                    likely_cause: likely_cause_of(record, &parameter),
                    parameter,
                })
            })
            .collect();
        out.extend(vectors);
        out.sort_by(|a, b| b.robust_z.abs().total_cmp(&a.robust_z.abs()));
        out
    }

    /// The findings of `record` beyond the threshold, farthest first.
    pub fn outlying(&self, record: &CalibrationRecord) -> Vec<Finding> {
        let mut findings = self.distances(record);
        findings.retain(|f| f.robust_z.abs() > f.threshold_z);
        // An offset's length adds nothing when one of its axes is beyond its own threshold:
        // that axis names the fault more precisely.
        let axes_beyond: Vec<String> = findings
            .iter()
            .filter(|f| !f.parameter.ends_with(".length"))
            .filter_map(|f| {
                f.parameter
                    .rsplit_once('.')
                    .map(|(prefix, _)| prefix.to_string())
            })
            .collect();
        findings.retain(|f| {
            f.parameter
                .strip_suffix(".length")
                .is_none_or(|prefix| !axes_beyond.iter().any(|p| p == prefix))
        });
        findings
    }
}

/// The likely cause of `record`'s `parameter` being far from the fleet: the hardware cause, and
/// for a set written from a file (`flash`) the file itself, which may have been edited by hand
/// or made for another board.
pub fn likely_cause_of(record: &CalibrationRecord, parameter: &str) -> String {
    let cause = likely_cause(parameter);
    if record.source == super::record::RecordSource::Flash {
        format!("{cause}; or a hand-edited or foreign file (this set was flashed from a file)")
    } else {
        cause
    }
}

/// The likely hardware cause of `parameter` being far from the fleet.
pub fn likely_cause(parameter: &str) -> String {
    let mut parts = parameter.split('.');
    let sensor = parts.next().unwrap_or_default();
    let kind = parts.next().unwrap_or_default();
    let axis = parts.next().unwrap_or_default();
    let on_axis = match axis.len() {
        1 => format!(" on axis {axis}"),
        2 if axis[..1] == axis[1..] => format!(" on axis {}", &axis[..1]),
        _ => String::new(),
    };
    let diagonal = axis.len() == 2 && axis[..1] == axis[1..];
    match (sensor, kind) {
        ("accel", "b") => format!("gross accelerometer offset{on_axis}: cracked or damaged accelerometer axis, or a bad solder joint"),
        ("accel", "A") if diagonal => format!("gross accelerometer gain error{on_axis}: cracked or damaged accelerometer axis, or a bad solder joint"),
        ("accel", "A") => "accelerometer cross-axis coupling far out: the IMU is soldered tilted or the board is bent".into(),
        ("accel", "noise") => format!("excess accelerometer noise{on_axis}: vibration at the fixture, a loose board or a damaged part"),
        ("gyro", "b") => format!("gyroscope zero-rate offset far out{on_axis}: damaged gyroscope or mechanical stress on the part"),
        ("gyro", "A") => format!("gyroscope gain or cross-axis far out{on_axis}: damaged gyroscope or the IMU soldered tilted"),
        ("gyro", "noise") => format!("excess gyroscope noise{on_axis}: damaged MEMS structure, vibration at the fixture or a noisy supply"),
        ("mag", "b") => format!("magnetometer offset far out{on_axis}: a magnet or magnetised steel near the magnetometer (a screw, shield or connector, or a magnet near the board)"),
        ("mag", "A") => "magnetometer scale or soft iron far out: steel or a magnetised part near the sensor".into(),
        ("mag", "noise") => format!("excess magnetometer noise{on_axis}: switching currents or a motor near the board"),
        (_, "residual") => format!("the {sensor} fit leaves a large residual: the board moved during capture or the sensor is damaged"),
        _ => format!("{parameter} far from the fleet"),
    }
}

/// The fleet now: the newest set on the board of every device, and each device's attempts
/// since that were not written (refused sets describe no board, so they are tested against the
/// fleet but never counted in it).
fn fleet_now(
    store: &mut HistoryStore,
) -> Result<(Vec<StoredRecord>, Vec<StoredRecord>), HistoryError> {
    let mut on_board: BTreeMap<String, StoredRecord> = BTreeMap::new();
    let mut not_written: BTreeMap<String, StoredRecord> = BTreeMap::new();
    // Records come oldest first, so the last one seen per device wins.
    for stored in store.records(None)? {
        let device = stored.record.device_id.clone();
        // A recording fitted offline without a board named is tested, not counted.
        if stored.record.board.on_board() && !stored.record.names_no_board() {
            not_written.remove(&device);
            on_board.insert(device, stored);
        } else {
            not_written.insert(device, stored);
        }
    }
    Ok((
        on_board.into_values().collect(),
        not_written.into_values().collect(),
    ))
}

/// The fleet now (the newest set on every board), its statistics and every board's test, with
/// the attempts not written since tested against it and labelled.
pub fn fleet_report(
    store: &mut HistoryStore,
    options: &FleetOptions,
) -> Result<FleetReport, FleetError> {
    let (on_board, not_written) = fleet_now(store)?;
    let records: Vec<&CalibrationRecord> = on_board.iter().map(|s| &s.record).collect();
    let model = FleetModel::fit(&records, options)?;
    let mut results: Vec<BoardResult> = on_board
        .iter()
        .chain(&not_written)
        .map(|s| board_result(&model, s))
        .collect();
    results.sort_by(|a, b| {
        b.outlier
            .cmp(&a.outlier)
            .then(b.max_abs_z.total_cmp(&a.max_abs_z))
    });
    Ok(FleetReport {
        boards: model.boards,
        method: METHOD.into(),
        false_alarm_per_board: options.false_alarm_per_board,
        threshold_z: model.threshold_z(),
        parameters: model.parameters.clone(),
        untested: model.untested.clone(),
        results,
    })
}

/// The method in one sentence, for reports.
pub const METHOD: &str = "per parameter: median and 1.4826·MAD of the fleet (50 % breakdown), \
    robust z = (x − median)/√(s²(1 + π/2n) + σ_fit²), logarithms for noise and residuals; flagged when \
    |z| exceeds the Student-t (ν = 0.37·values) quantile for the false-alarm rate per board \
    split over the parameters tested (Bonferroni); a parameter's own spread when ≥ 20 boards \
    have it, else the deviations of its sensor's axes of the same kind pooled (one datasheet \
    tolerance per part); matrix entries a record's model does not estimate (exactly 0 or 1) are \
    not counted; each sensor's offset is also tested as a vector, its length d = √Σz² against \
    √(3·F) of Snedecor's F(3, ν) at its share of the false-alarm rate";

fn board_result(model: &FleetModel, stored: &StoredRecord) -> BoardResult {
    // The largest |z| of a parameter; an offset's length has its own, larger threshold.
    let max_abs_z = model
        .distances(&stored.record)
        .iter()
        .filter(|f| !f.parameter.ends_with(".length"))
        .map(|f| f.robust_z.abs())
        .fold(0.0, f64::max);
    let findings = model.outlying(&stored.record);
    BoardResult {
        device_id: stored.record.device_id.clone(),
        record_id: stored.id,
        outlier: !findings.is_empty(),
        max_abs_z,
        findings,
        not_compared: stored
            .record
            .params
            .non_nominal_inputs()
            .into_iter()
            .map(|(sensor, unit)| format!("{sensor} (fitted from {unit})"))
            .collect(),
        not_written: match &stored.record.board {
            BoardWrite::NotWritten { reason } => Some(reason.clone()),
            _ if stored.record.names_no_board() => Some(
                "a recording fitted offline, on no board (`fit --params-out --device ID` \
                 records it as that board's)"
                    .into(),
            ),
            _ => None,
        },
    }
}

/// The parameters of `record` the fleet compares: those of the sensors fitted in their nominal
/// units (m/s², rad/s, µT), not of a sensor whose set maps raw counts (see
/// [`BoardResult::not_compared`]).
fn comparable_parameters(record: &CalibrationRecord) -> BTreeMap<String, f64> {
    let foreign: Vec<&str> = record
        .params
        .non_nominal_inputs()
        .into_iter()
        .map(|(sensor, _)| sensor)
        .collect();
    let mut parameters = record.parameters();
    parameters.retain(|name, value| {
        name.split('.')
            .next()
            .is_none_or(|sensor| !foreign.contains(&sensor))
            && !fixed_by_the_model(name, *value)
    });
    parameters
}

/// Whether a matrix entry is one the fitted model does not estimate: exactly 1 or 0, as a
/// model that fits the offset only leaves the whole matrix, and an axis-aligned one the
/// entries off the diagonal. No estimated entry comes out exactly 0 or 1; pooling such
/// placeholders with estimates would make them look like measurements that agree perfectly.
fn fixed_by_the_model(name: &str, value: f64) -> bool {
    name.split('.').nth(1) == Some("A") && (value == 0.0 || value == 1.0)
}

/// Test `record` against the fleet in `store` (the newest set on every other board) before
/// its parameters are written. Too small a fleet gives `tested: false` with the reason.
pub fn is_outlier_against_fleet(
    record: &CalibrationRecord,
    store: &mut HistoryStore,
    options: &FleetOptions,
) -> Result<FleetCheck, HistoryError> {
    let (latest, _) = fleet_now(store)?;
    let others: Vec<&CalibrationRecord> = latest
        .iter()
        .map(|s| &s.record)
        .filter(|r| r.device_id != record.device_id)
        .collect();
    Ok(match FleetModel::fit(&others, options) {
        Ok(model) => {
            let findings = model.outlying(record);
            FleetCheck {
                tested: true,
                outlier: !findings.is_empty(),
                fleet_boards: others.len(),
                threshold_z: model.threshold_z(),
                findings,
                note: None,
            }
        }
        Err(FleetError::History(e)) => return Err(e),
        Err(why) => FleetCheck {
            tested: false,
            outlier: false,
            fleet_boards: others.len(),
            threshold_z: 0.0,
            findings: Vec::new(),
            note: Some(why.to_string()),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_name_the_part_and_axis() {
        assert!(likely_cause("accel.A.yy").contains("gain error on axis y"));
        assert!(likely_cause("mag.b.z").contains("magnet"));
        assert!(likely_cause("gyro.noise.x").contains("excess gyroscope noise on axis x"));
    }
}
