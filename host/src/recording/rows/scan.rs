//! The one-pass reading of the usual row: plain decimals read eight digits at a time straight
//! from the line's bytes, with no text per field and no UTF-8 check for a line of numbers alone.
//! A line this pass does not take whole is left to the general rules ([`super::parse_row`]),
//! which give the same values and errors.

use super::{finish_row, line_text, store_value, Layout, Part, Role};
use crate::recording::{RecordingError, MAX_SENSOR_MAGNITUDE};

/// A line read whole by [`scan_row`].
pub(super) struct Scanned {
    /// Its bytes in the text, line break (and a `\r` before it) excluded.
    line: (usize, usize),
    /// Start of the next line.
    pub(super) next: usize,
    /// Bytes of the label field, if the layout has one.
    label: Option<(usize, usize)>,
    /// Whether the line has text fields (label or ignored columns), which may hold any bytes.
    text_fields: bool,
}

/// The line at `text[start..]` read in one pass when every number field is a plain decimal of
/// the fast path ([`crate::recording::decimal::fast_field`]) ended by the comma or the line break, the
/// line has exactly the header's fields and starts and ends with no blank, byte-order mark or
/// `#`: then `values` holds the value of each number field and the line reads, by the general
/// rules, as the same numbers (a line of number fields alone is ASCII, hence text). `None`
/// otherwise, having changed nothing but `values`.
pub(super) fn scan_row(
    layout: &Layout<'_>,
    text: &[u8],
    start: usize,
    values: &mut [f64],
) -> Option<Scanned> {
    let last = layout.roles.len().checked_sub(1)?;
    let mut i = start;
    let mut label = None;
    let mut text_fields = false;
    for (col, (role, value)) in layout.roles.iter().zip(values.iter_mut()).enumerate() {
        let field = i;
        match role {
            Role::Time | Role::Temp | Role::Reading(_) => {
                let (v, end) = crate::recording::decimal::fast_field(text, i)?;
                *value = v;
                i = end;
            }
            Role::Label | Role::Ignored => {
                text_fields = true;
                let rest = text.get(i..)?;
                i = memchr::memchr2(b',', b'\n', rest).map_or(text.len(), |at| i + at);
                if let Role::Label = role {
                    label = Some((field, i));
                }
            }
        }
        let is_last = col == last;
        match text.get(i) {
            Some(b',') if !is_last => i += 1,
            Some(b'\n') if is_last => break,
            None if is_last => break,
            Some(b'\r') if is_last && matches!(text.get(i + 1), Some(b'\n') | None) => {
                i += 1;
                break;
            }
            _ => return None,
        }
    }
    // Here `i` is at the line break or the end of the text; a text field ending the line holds
    // the `\r` before the line break, which is not part of the line.
    let next = i + 1;
    let mut end = i;
    if end > start && text.get(end - 1) == Some(&b'\r') {
        end -= 1;
    }
    // No byte-order mark, blank or `#` at either end: the line is its own content.
    let plain = |b: Option<&u8>| b.is_some_and(|&b| b.is_ascii() && !char::from(b).is_whitespace());
    let first = text.get(start);
    if end <= start || !plain(first) || first == Some(&b'#') || !plain(text.get(end - 1)) {
        return None;
    }
    let label = label.map(|(from, to)| (from, to.min(end)));
    Some(Scanned {
        line: (start, end),
        next,
        label,
        text_fields,
    })
}

/// Where the values of a row read by [`scan_row`] go.
pub(super) struct Plan {
    /// Column of `t_s`.
    time: Option<usize>,
    /// Column of `temp_c`.
    temp: Option<usize>,
    /// Column of each sensor value, in the order of a row's readings.
    readings: Vec<usize>,
}

impl Plan {
    pub(super) fn new(layout: &Layout<'_>) -> Self {
        let mut plan = Self {
            time: None,
            temp: None,
            readings: vec![usize::MAX; 3 * layout.sensors],
        };
        for (col, role) in layout.roles.iter().enumerate() {
            match *role {
                Role::Time => plan.time = Some(col),
                Role::Temp => plan.temp = Some(col),
                Role::Reading(slot) => {
                    if let Some(r) = plan.readings.get_mut(slot) {
                        *r = col;
                    }
                }
                Role::Label | Role::Ignored => {}
            }
        }
        plan
    }
}

/// Store a line read by [`scan_row`] (number `line_no` within its part, values in `values`).
#[allow(clippy::too_many_arguments)]
pub(super) fn store_scanned(
    layout: &Layout<'_>,
    plan: &Plan,
    text: &[u8],
    offset: u64,
    row: &Scanned,
    values: &[f64],
    line_no: usize,
    part: &mut Part,
) -> Result<(), RecordingError> {
    let (from, to) = row.line;
    // A line with text fields is checked as text first, as the general rules check it.
    let line = if row.text_fields {
        line_text(layout.path, &text[from..to], offset + from as u64)?
    } else {
        ""
    };
    let label = || {
        row.label
            .and_then(|(a, b)| line.get(a - from..b - from))
            .unwrap_or_default()
            .trim()
    };
    // The usual row first: no value refused, each pushed straight to its column.
    let columns = &mut part.columns;
    let time = plan.time.and_then(|c| values.get(c).copied());
    let previous = columns.time.as_ref().and_then(|t| t.last()).copied();
    let time_ok = !matches!((time, previous), (Some(t), Some(p)) if t < p);
    let mut readings = [0.0; 9];
    let mut in_range = true;
    for (r, &col) in readings.iter_mut().zip(&plan.readings) {
        let value = values.get(col).copied().unwrap_or_default();
        in_range &= value.abs() <= MAX_SENSOR_MAGNITUDE;
        *r = value;
    }
    if time_ok && in_range {
        if let Some(t) = time {
            let column = columns.time.get_or_insert_with(Vec::new);
            if column.is_empty() {
                part.first_time = Some((line_no, t));
            }
            column.push(t);
        }
        if let Some(t) = plan.temp.and_then(|c| values.get(c)) {
            columns.temp.get_or_insert_with(Vec::new).push(*t);
        }
        if let (Some(l), Some(_)) = (columns.labels.as_mut(), row.label) {
            l.push(label());
        }
        finish_row(&readings, part);
        return Ok(());
    }
    // A value is refused: the column by column rules name the first one.
    let mut readings = [0.0; 9];
    for (col, (role, &value)) in layout.roles.iter().zip(values).enumerate() {
        match *role {
            Role::Label => {
                if let Some(l) = part.columns.labels.as_mut() {
                    l.push(label());
                }
            }
            Role::Ignored => {}
            role => store_value(layout, role, col, value, line_no, &mut readings, part)?,
        }
    }
    finish_row(&readings, part);
    Ok(())
}
