//! The data rows of a CSV recording turned into columns of numbers, a block of whole lines at a
//! time, the two halves of a long block parsed side by side on two threads.
//!
//! The result is the one a single pass line by line gives, bit for bit and error for error: each
//! half is parsed with the same row rules, the first straight into the output columns, the
//! second into its own; then the second is appended. What one half cannot see of the other is
//! settled at the join: the time check across the seam (the first time of the second half
//! against the last time before it), the line numbers of the second half (counted from its
//! start, then shifted), and the label indices (the second half interns its own labels, the join
//! maps them to the whole file's order of first appearance). The first error in file order wins,
//! as it would line by line.
//!
//! A line is read in one pass over its bytes when it is the usual row (plain decimals, the
//! header's number of fields, no padding): digits eight at a time, no text per field, no UTF-8
//! check for a line of numbers alone (it is ASCII). Any other line is read by the general rules,
//! which give the same values and errors for the usual rows too.

use std::collections::HashMap;

use super::{LabelKind, Labels, RecordingError, MAX_SENSOR_MAGNITUDE};
use crate::fit::Vec3;
use scan::{scan_row, store_scanned, Plan};

mod scan;

/// Blocks shorter than this are parsed on the calling thread: a second thread costs tens of
/// microseconds to start, about the time of parsing this many bytes.
const PARALLEL_MIN_BYTES: usize = 64 * 1024;

/// Text of a line as the CSV reader sees it: without a byte-order mark or surrounding blanks.
pub(super) fn content(line: &str) -> &str {
    line.trim_start_matches('\u{feff}').trim()
}

/// What a column of the header holds.
#[derive(Debug, Clone, Copy)]
pub(super) enum Role {
    /// `t_s`.
    Time,
    /// `temp_c`.
    Temp,
    /// `pose` or `segment`.
    Label,
    /// A sensor value: index `3·sensor + axis` into one row's readings.
    Reading(usize),
    /// A column not read.
    Ignored,
}

/// The columns of a header as the row parser needs them.
pub(super) struct Layout<'h> {
    /// File name for errors.
    pub path: &'h str,
    /// Column names, for errors.
    pub names: &'h [String],
    /// Role of each column.
    pub roles: Vec<Role>,
    /// Number of sensors (three readings each).
    pub sensors: usize,
    /// Whether a `t_s` column exists.
    pub time: bool,
    /// Whether a `temp_c` column exists.
    pub temp: bool,
    /// Kind of the label column, if there is one.
    pub label: Option<LabelKind>,
}

/// The comma-separated fields of a row (what `str::split(',')` yields), found with a byte
/// search: a comma is one byte in UTF-8, so every piece is itself valid text.
pub(super) fn fields(row: &str) -> impl Iterator<Item = &str> {
    let mut rest = Some(row);
    std::iter::from_fn(move || {
        let text = rest?;
        match memchr::memchr(b',', text.as_bytes()) {
            Some(at) => {
                rest = text.get(at + 1..);
                text.get(..at)
            }
            None => {
                rest = None;
                Some(text)
            }
        }
    })
}

/// Rows read so far, as columns.
pub(super) struct Columns {
    /// `t_s` per row, when the column exists.
    pub time: Option<Vec<f64>>,
    /// `temp_c` per row, when the column exists.
    pub temp: Option<Vec<f64>>,
    /// Labels per row, when a label column exists.
    pub labels: Option<LabelInterner>,
    /// Readings per sensor, in the order of the header's sensors.
    pub sensors: Vec<Vec<Vec3>>,
    /// Number of rows.
    pub rows: usize,
}

impl Columns {
    /// No rows yet, with the columns of `layout`.
    pub fn new(layout: &Layout<'_>) -> Self {
        Self {
            time: layout.time.then(Vec::new),
            temp: layout.temp.then(Vec::new),
            labels: layout.label.map(LabelInterner::new),
            sensors: vec![Vec::new(); layout.sensors],
            rows: 0,
        }
    }

    /// Room for `more` rows in every column.
    pub fn reserve(&mut self, more: usize) {
        for v in self.time.iter_mut().chain(self.temp.iter_mut()) {
            v.reserve(more);
        }
        for v in &mut self.sensors {
            v.reserve(more);
        }
        if let Some(l) = &mut self.labels {
            l.per_row.reserve(more);
        }
    }

    fn clear(&mut self) {
        for v in self.time.iter_mut().chain(self.temp.iter_mut()) {
            v.clear();
        }
        for v in &mut self.sensors {
            v.clear();
        }
        if let Some(l) = &mut self.labels {
            l.clear();
        }
        self.rows = 0;
    }

    /// Append the rows of `part`, which come next in the file.
    fn append(&mut self, part: &Columns) {
        for (to, from) in self.time.iter_mut().zip(&part.time) {
            to.extend_from_slice(from);
        }
        for (to, from) in self.temp.iter_mut().zip(&part.temp) {
            to.extend_from_slice(from);
        }
        for (to, from) in self.sensors.iter_mut().zip(&part.sensors) {
            to.extend_from_slice(from);
        }
        if let (Some(to), Some(from)) = (&mut self.labels, &part.labels) {
            to.append(from);
        }
        self.rows += part.rows;
    }
}

/// One stretch of lines parsed on its own: its rows, how far it got and what stopped it.
pub(super) struct Part {
    columns: Columns,
    /// Lines seen (the line an error stopped on included).
    lines: usize,
    /// The first time value of the stretch, with its line (counted from the stretch's start):
    /// the check against the time before the stretch is made when the stretches are joined.
    first_time: Option<(usize, f64)>,
    /// The first error, its line counted from the stretch's start.
    error: Option<RecordingError>,
}

impl Part {
    /// An empty part for the columns of `layout`.
    pub fn new(layout: &Layout<'_>) -> Self {
        Self {
            columns: Columns::new(layout),
            lines: 0,
            first_time: None,
            error: None,
        }
    }

    fn reset(&mut self) {
        self.columns.clear();
        self.lines = 0;
        self.first_time = None;
        self.error = None;
    }
}

/// A run of whole lines: its bytes, the number of its first line and the input offset of its
/// first byte.
pub(super) struct Block<'b> {
    /// The lines, each ended by a line break except perhaps the last one of the input.
    pub bytes: &'b [u8],
    /// 1-based number of the first line.
    pub first_line: usize,
    /// Offset of the first byte in the input.
    pub offset: u64,
}

/// Parse the rows of `block` into `out`, on two threads when the block is long; `parts` are
/// scratch space reused across blocks. Returns the number of lines of the block, or the first
/// error in file order.
pub(super) fn parse_block(
    layout: &Layout<'_>,
    block: &Block<'_>,
    parts: &mut [Part; 2],
    out: &mut Columns,
) -> Result<usize, RecordingError> {
    let [first, second] = parts;
    first.reset();
    second.reset();
    // The first part reads straight into `out`, its rows being the next ones of the file: the
    // time check across the seam is then made as its first row is read, and only the second
    // part's rows are copied.
    std::mem::swap(&mut first.columns, out);
    let split = (block.bytes.len() >= PARALLEL_MIN_BYTES)
        .then(|| memchr::memchr(b'\n', &block.bytes[block.bytes.len() / 2..]))
        .flatten()
        .map(|at| block.bytes.len() / 2 + at + 1);
    match split {
        Some(mid) => {
            let (a, b) = block.bytes.split_at(mid);
            std::thread::scope(|scope| {
                let later =
                    scope.spawn(|| parse_lines(layout, b, block.offset + mid as u64, second));
                parse_lines(layout, a, block.offset, first);
                later
                    .join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
            });
        }
        None => parse_lines(layout, block.bytes, block.offset, first),
    }
    std::mem::swap(&mut first.columns, out);
    if let Some(mut err) = first.error.take() {
        err.shift_line(block.first_line - 1);
        return Err(err);
    }
    join(layout.path, block.first_line + first.lines, second, out)?;
    Ok(first.lines + second.lines)
}

/// Append `part`, whose first line is number `first_line`, to `out`: the time check across the
/// seam first, then the part's own error (both as line by line reading would report them).
fn join(
    path: &str,
    first_line: usize,
    part: &mut Part,
    out: &mut Columns,
) -> Result<(), RecordingError> {
    // A first row cut short is named by its field count, as within a part.
    let first_row_short = matches!(
        (&part.error, part.first_time),
        (Some(RecordingError::FieldCount { line, .. }), Some((first, _))) if *line == first
    );
    if let (Some((line, time)), Some(&previous), false) = (
        part.first_time,
        out.time.as_ref().and_then(|t| t.last()),
        first_row_short,
    ) {
        if time < previous {
            return Err(RecordingError::TimeBackwards {
                path: path.to_string(),
                line: first_line - 1 + line,
                time,
                previous,
            });
        }
    }
    if let Some(mut err) = part.error.take() {
        err.shift_line(first_line - 1);
        return Err(err);
    }
    out.append(&part.columns);
    Ok(())
}

/// Parse the lines of `text` (input offset `offset`) into `part`, stopping at the first error.
///
/// Each line is first read by [`scan_row`], in one pass over its bytes; a line that pass does
/// not take whole (anything but plain decimals and text fields, or the wrong number of fields)
/// is read again by [`parse_row`], the general rules, after the text check. Both give the same
/// values and the same first error, so which one read a line never shows.
fn parse_lines(layout: &Layout<'_>, text: &[u8], offset: u64, part: &mut Part) {
    let plan = Plan::new(layout);
    let mut values = vec![0.0; layout.roles.len()];
    let mut start = 0;
    while start < text.len() {
        part.lines += 1;
        let line_no = part.lines;
        let result = match scan_row(layout, text, start, &mut values) {
            Some(row) => {
                start = row.next;
                store_scanned(layout, &plan, text, offset, &row, &values, line_no, part)
            }
            None => {
                let end = memchr::memchr(b'\n', &text[start..]).map_or(text.len(), |at| start + at);
                let mut line = &text[start..end];
                if let [rest @ .., b'\r'] = line {
                    line = rest;
                }
                let line_offset = offset + start as u64;
                start = end + 1;
                line_text(layout.path, line, line_offset)
                    .and_then(|line| parse_row(layout, line, line_no, part))
            }
        };
        if let Err(e) = result {
            part.error = Some(e);
            return;
        }
    }
}

/// A line as text, refused as [`super::lines::LineReader`] refuses it: a zero byte first, then
/// bytes that are not UTF-8 (`offset` is the input offset of the line's first byte).
fn line_text<'t>(path: &str, line: &'t [u8], offset: u64) -> Result<&'t str, RecordingError> {
    if let Some(at) = memchr::memchr(0, line) {
        return Err(RecordingError::NotText {
            path: path.to_string(),
            detail: format!(
                "it holds binary data (a zero byte at offset {})",
                offset + at as u64
            ),
        });
    }
    std::str::from_utf8(line).map_err(|e| {
        let at = e.valid_up_to();
        RecordingError::NotText {
            path: path.to_string(),
            detail: format!(
                "it holds bytes that are not UTF-8 text (byte 0x{:02X} at offset {})",
                line.get(at).copied().unwrap_or(0),
                offset + at as u64
            ),
        }
    })
}

/// The advice for a value that is not a number, until the rest of its column is known.
pub(super) const ONE_ROW_ADVICE: &str = "correct or delete that row";

/// Rows of `text` (skipped lines left out), and how many of them hold no finite number in
/// field `column` (or have no such field), for at most `limit` rows.
pub(super) fn rows_without_a_number(text: &[u8], column: usize, limit: usize) -> (usize, usize) {
    let (mut rows, mut bad) = (0, 0);
    for line in text.split(|&b| b == b'\n') {
        if rows >= limit {
            break;
        }
        let line = String::from_utf8_lossy(line);
        let body = content(&line);
        if body.is_empty() || body.starts_with('#') {
            continue;
        }
        rows += 1;
        let number = fields(body).nth(column).and_then(|text| {
            parse_number(text.trim()).or_else(|| parse_number(text.trim().trim_matches('"').trim()))
        });
        bad += usize::from(number.is_none());
    }
    (rows, bad)
}

/// A field as a finite number.
fn parse_number(text: &str) -> Option<f64> {
    super::decimal::parse_finite(text)
}

/// Parse one line (number `line_no` within its part) into `part`; skipped lines add nothing.
fn parse_row(
    layout: &Layout<'_>,
    line: &str,
    line_no: usize,
    part: &mut Part,
) -> Result<(), RecordingError> {
    let body = content(line);
    if body.is_empty() || body.starts_with('#') {
        return Ok(());
    }
    // One row's sensor values, in the order of the header's sensors (at most three sensors).
    let mut readings = [0.0; 9];
    let mut found = 0;
    for (col, text) in fields(body).enumerate() {
        found += 1;
        let Some(role) = layout.roles.get(col) else {
            continue;
        };
        if let Role::Label = role {
            if let Some(l) = part.columns.labels.as_mut() {
                l.push(text.trim());
            }
            continue;
        }
        if let Role::Ignored = role {
            continue;
        }
        // ASCII blanks are the usual padding; other Unicode spaces take the slower trim, and a
        // number in quotes (spreadsheet exports quote every field) is still a number.
        let value = parse_number(text.trim_ascii())
            .or_else(|| parse_number(text.trim()))
            .or_else(|| parse_number(text.trim().trim_matches('"').trim()))
            .ok_or_else(|| RecordingError::BadNumber {
                path: layout.path.to_string(),
                line: line_no,
                column: layout.names[col].clone(),
                text: text.trim().to_string(),
                advice: ONE_ROW_ADVICE.to_string(),
            });
        // A row cut short (a truncated last line, `55.`) is named as such, not by what its
        // first fields happen to say.
        let stored =
            value.and_then(|v| store_value(layout, *role, col, v, line_no, &mut readings, part));
        if let Err(error) = stored {
            let count = fields(body).count();
            return Err(field_count_error(layout, line_no, count).unwrap_or(error));
        }
    }
    if let Some(error) = field_count_error(layout, line_no, found) {
        return Err(error);
    }
    finish_row(&readings, part);
    Ok(())
}

/// The error for a row of `found` fields, when the header names another number of columns.
fn field_count_error(layout: &Layout<'_>, line_no: usize, found: usize) -> Option<RecordingError> {
    (found != layout.names.len()).then(|| RecordingError::FieldCount {
        path: layout.path.to_string(),
        line: line_no,
        expected: layout.names.len(),
        found,
    })
}

/// Keep `value`, read from column `col` (of role `role`) of line `line_no`: a time (checked
/// against the time before it) or temperature into its column, a sensor value (checked against
/// [`MAX_SENSOR_MAGNITUDE`]) into the row's `readings`.
#[inline]
fn store_value(
    layout: &Layout<'_>,
    role: Role,
    col: usize,
    value: f64,
    line_no: usize,
    readings: &mut [f64; 9],
    part: &mut Part,
) -> Result<(), RecordingError> {
    let columns = &mut part.columns;
    match role {
        Role::Time => {
            let t = columns.time.get_or_insert_with(Vec::new);
            match t.last() {
                Some(&previous) if value < previous => {
                    return Err(RecordingError::TimeBackwards {
                        path: layout.path.to_string(),
                        line: line_no,
                        time: value,
                        previous,
                    });
                }
                Some(_) => {}
                None => part.first_time = Some((line_no, value)),
            }
            t.push(value);
        }
        Role::Temp => columns.temp.get_or_insert_with(Vec::new).push(value),
        Role::Reading(slot) => {
            if value.abs() > MAX_SENSOR_MAGNITUDE {
                return Err(RecordingError::OutOfRange {
                    path: layout.path.to_string(),
                    line: line_no,
                    column: layout.names[col].clone(),
                    value,
                    limit: MAX_SENSOR_MAGNITUDE,
                });
            }
            if let Some(r) = readings.get_mut(slot) {
                *r = value;
            }
        }
        Role::Label | Role::Ignored => {}
    }
    Ok(())
}

/// End a row whose values are stored: its sensor readings into their columns.
#[inline]
fn finish_row(readings: &[f64; 9], part: &mut Part) {
    let columns = &mut part.columns;
    for (out, r) in columns.sensors.iter_mut().zip(readings.chunks_exact(3)) {
        out.push(Vec3::new(r[0], r[1], r[2]));
    }
    columns.rows += 1;
}

/// Builds [`Labels`] row by row, storing each distinct text once.
pub(super) struct LabelInterner {
    kind: LabelKind,
    names: Vec<String>,
    index: HashMap<String, usize>,
    per_row: Vec<Option<usize>>,
}

impl LabelInterner {
    /// No labels yet, of `kind`.
    pub(super) fn new(kind: LabelKind) -> Self {
        Self {
            kind,
            names: Vec::new(),
            index: HashMap::new(),
            per_row: Vec::new(),
        }
    }

    fn clear(&mut self) {
        self.names.clear();
        self.index.clear();
        self.per_row.clear();
    }

    /// Index of `text`, adding it when it is new.
    fn intern(&mut self, text: &str) -> usize {
        if let Some(&i) = self.index.get(text) {
            return i;
        }
        self.names.push(text.to_string());
        self.index.insert(text.to_string(), self.names.len() - 1);
        self.names.len() - 1
    }

    /// The next row's label (`-` or empty: none).
    pub(super) fn push(&mut self, text: &str) {
        // A label in quotes (spreadsheet exports quote every field) is the same label.
        let text = text.trim_matches('"').trim();
        let label = (!(text.is_empty() || text == "-")).then(|| self.intern(text));
        self.per_row.push(label);
    }

    /// Append the rows of `later`, whose names are new to this one in their order of first
    /// appearance there, so the joined order of first appearance is the whole file's.
    fn append(&mut self, later: &LabelInterner) {
        let map: Vec<usize> = later.names.iter().map(|n| self.intern(n)).collect();
        self.per_row.extend(
            later
                .per_row
                .iter()
                .map(|l| l.and_then(|i| map.get(i).copied())),
        );
    }

    /// The labels read.
    pub fn finish(self) -> Labels {
        Labels {
            kind: self.kind,
            names: self.names,
            per_row: self.per_row,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NAMES: [&str; 5] = ["t_s", "ax", "ay", "az", "pose"];

    fn layout(names: &[String]) -> Layout<'_> {
        Layout {
            path: "test.csv",
            names,
            roles: vec![
                Role::Time,
                Role::Reading(0),
                Role::Reading(1),
                Role::Reading(2),
                Role::Label,
            ],
            sensors: 1,
            time: true,
            temp: false,
            label: Some(LabelKind::Pose),
        }
    }

    /// Rows `0..n` (time `i`, label `a`), and the index of the first row of the second half.
    fn rows(n: usize) -> (Vec<String>, usize) {
        let lines: Vec<String> = (0..n).map(|i| format!("{i},1.5,-2,3,a")).collect();
        let text = lines.join("\n") + "\n";
        let mid = text.len() / 2 + text[text.len() / 2..].find('\n').unwrap_or(0) + 1;
        let second = text[..mid].matches('\n').count();
        (lines, second)
    }

    fn parse(lines: &[String]) -> Result<Columns, RecordingError> {
        let names: Vec<String> = NAMES.iter().map(|n| n.to_string()).collect();
        let layout = layout(&names);
        let text = lines.join("\n") + "\n";
        let block = Block {
            bytes: text.as_bytes(),
            first_line: 2,
            offset: 0,
        };
        let mut parts = [Part::new(&layout), Part::new(&layout)];
        let mut out = Columns::new(&layout);
        let count = parse_block(&layout, &block, &mut parts, &mut out)?;
        assert_eq!(count, lines.len());
        Ok(out)
    }

    /// The error `parse` gives for `lines`, as text (empty when they parse).
    fn error_of(lines: &[String]) -> String {
        parse(lines)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    }

    #[test]
    fn time_going_back_at_the_first_row_of_the_second_half_is_refused_there() {
        let (mut lines, second) = rows(8000);
        assert!(second > 1000, "the block is parsed in two halves");
        lines[second] = format!("{},1.5,-2,3,a", second - 2);
        let err = error_of(&lines);
        // Line numbers count from the block's first line, 2.
        let expected = format!(
            "line {}: time {} s is earlier than the previous row's {} s",
            second + 2,
            second - 2,
            second - 1
        );
        assert!(err.contains(&expected), "{err}");
    }

    #[test]
    fn a_row_cut_short_is_named_by_its_field_count_not_by_its_time() {
        let (mut lines, _) = rows(20);
        // A truncated last line whose time reads as earlier than the row before it.
        lines.push("1.".into());
        let err = error_of(&lines);
        assert!(
            err.contains("line 22: 1 fields but the header names"),
            "{err}"
        );
        lines.pop();
        lines.push("25,1.5,x".into());
        let err = error_of(&lines);
        assert!(err.contains("line 22: 3 fields"), "{err}");
    }

    #[test]
    fn a_row_cut_short_at_the_start_of_the_second_half_is_named_by_its_field_count() {
        let (mut lines, second) = rows(8000);
        lines[second] = "1.".into();
        let err = error_of(&lines);
        assert!(
            err.contains(&format!("line {}: 1 fields", second + 2)),
            "{err}"
        );
    }

    #[test]
    fn errors_of_the_second_half_name_their_line_in_the_whole_file() {
        let (mut lines, second) = rows(8000);
        lines[second + 10] = format!("{},1.5,oops,3,a", second + 10);
        let err = error_of(&lines);
        assert!(
            err.contains(&format!("line {}, column `ay`: `oops`", second + 12)),
            "{err}"
        );
        // An error in the first half comes first, whatever the second half holds.
        lines[second - 3] = format!("{},1.5,-2,3", second - 3);
        let err = error_of(&lines);
        assert!(
            err.contains(&format!("line {}: 4 fields", second - 1)),
            "{err}"
        );
    }

    #[test]
    fn labels_first_seen_in_the_second_half_follow_those_of_the_first() {
        let (mut lines, second) = rows(8000);
        lines[1] = "1,1.5,-2,3,c".to_string();
        lines[second] = format!("{second},1.5,-2,3,b");
        lines[second + 1] = format!("{},1.5,-2,3,c", second + 1);
        lines[second + 2] = format!("{},1.5,-2,3,-", second + 2);
        let out = parse(&lines).expect("valid rows");
        let labels = out.labels.expect("a label column").finish();
        assert_eq!(labels.names, ["a", "c", "b"]);
        assert_eq!(labels.per_row[1], Some(1));
        assert_eq!(labels.per_row[second], Some(2));
        assert_eq!(labels.per_row[second + 1], Some(1));
        assert_eq!(labels.per_row[second + 2], None);
        assert_eq!(labels.per_row[second + 3], Some(0));
        assert_eq!(out.rows, 8000);
        assert_eq!(out.time.expect("time")[second], second as f64);
    }

    /// The block's rows by the general rules alone, line by line (the text check, then
    /// [`parse_row`]), with line numbers and offsets counted from the block's start.
    fn line_by_line(layout: &Layout<'_>, text: &[u8]) -> Result<Columns, RecordingError> {
        let mut part = Part::new(layout);
        let mut offset = 0;
        for (i, line) in text.split_inclusive(|&b| b == b'\n').enumerate() {
            let mut body = line.strip_suffix(b"\n").unwrap_or(line);
            if let [rest @ .., b'\r'] = body {
                body = rest;
            }
            let body = line_text(layout.path, body, offset)?;
            parse_row(layout, body, i + 1, &mut part)?;
            offset += line.len() as u64;
        }
        Ok(part.columns)
    }

    /// Everything a block's parse gives, as comparable text (values as bits).
    fn outcome(result: Result<Columns, RecordingError>) -> String {
        match result {
            Err(e) => format!("error: {e}"),
            Ok(c) => {
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                let sensors: Vec<Vec<u64>> = c
                    .sensors
                    .iter()
                    .map(|s| {
                        s.iter()
                            .flat_map(|v| [v.x, v.y, v.z])
                            .map(f64::to_bits)
                            .collect()
                    })
                    .collect();
                let labels = c.labels.map(|l| {
                    let l = l.finish();
                    (l.names, l.per_row)
                });
                format!(
                    "{} rows, time {:?}, temp {:?}, sensors {sensors:?}, labels {labels:?}",
                    c.rows,
                    c.time.as_deref().map(bits),
                    c.temp.as_deref().map(bits),
                )
            }
        }
    }

    #[test]
    fn rows_read_in_one_pass_match_the_general_rules_value_for_value_and_error_for_error() {
        let names: Vec<String> = ["t_s", "ax", "ay", "az", "pose", "note", "temp_c"]
            .iter()
            .map(|n| n.to_string())
            .collect();
        let with_text = Layout {
            path: "test.csv",
            names: &names,
            roles: vec![
                Role::Time,
                Role::Reading(0),
                Role::Reading(1),
                Role::Reading(2),
                Role::Label,
                Role::Ignored,
                Role::Temp,
            ],
            sensors: 1,
            time: true,
            temp: true,
            label: Some(LabelKind::Pose),
        };
        let numbers = Layout {
            path: "test.csv",
            names: &names[..4],
            roles: vec![
                Role::Time,
                Role::Reading(0),
                Role::Reading(1),
                Role::Reading(2),
            ],
            sensors: 1,
            time: true,
            temp: false,
            label: None,
        };
        let odd_numbers = [
            " 1.5",
            "1.5 ",
            "1e3",
            "+2",
            "1.",
            ".5",
            "-.5",
            "-",
            "",
            "abc",
            "1234567890123456.5",
            "0000000000000000007",
            "-0.0",
            "2e10",
            "-3e10",
            "\u{a0}4.25",
            "1.5\r",
            "inf",
            "1\u{0}",
        ];
        let odd_texts = ["", "-", " a ", "\u{e9}t\u{e9}", "b\r", "#", "x y"];
        let odd_lines = ["", "# comment", "\u{feff}", "  ", "\r", "1,2,3"];
        let mut state: u64 = 0x1234_5678_9ABC_DEF1;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for round in 0..3000 {
            let layout = if round % 2 == 0 { &with_text } else { &numbers };
            // Mostly short blocks (an error early on hides nothing); some long enough to be
            // parsed in two halves.
            let lines = if round % 50 == 0 {
                4000
            } else {
                1 + next() as usize % 30
            };
            let rare = if round % 50 == 0 { 20_000 } else { 60 };
            let mut text = String::new();
            let mut time = 0.0;
            for _ in 0..lines {
                if next() % rare == 0 {
                    text += odd_lines[next() as usize % odd_lines.len()];
                    text += "\n";
                    continue;
                }
                let mut fields = Vec::new();
                for role in &layout.roles {
                    let r = next();
                    let field = if r % rare == 0 {
                        match role {
                            Role::Label | Role::Ignored => {
                                odd_texts[(r >> 20) as usize % odd_texts.len()].to_string()
                            }
                            _ => odd_numbers[(r >> 20) as usize % odd_numbers.len()].to_string(),
                        }
                    } else {
                        match role {
                            Role::Time => {
                                time += if r % 997 == 1 { -0.5 } else { 0.01 };
                                format!("{time:.2}")
                            }
                            Role::Label => {
                                ["a", "b", "c\u{e9}", ""][(r >> 8) as usize % 4].to_string()
                            }
                            Role::Ignored => "n".to_string(),
                            _ => {
                                let digits = (r >> 8) % 9;
                                let v = ((r >> 16) % 2_000_000) as f64 / 1000.0 - 1000.0;
                                format!("{v:.*}", digits as usize)
                            }
                        }
                    };
                    fields.push(field);
                }
                if next() % rare == 1 {
                    fields.pop();
                }
                if next() % rare == 2 {
                    fields.push("1".into());
                }
                text += &fields.join(",");
                text += if next() % 7 == 0 { "\r\n" } else { "\n" };
            }
            if next() % 3 == 0 {
                text.pop();
            }
            let block = Block {
                bytes: text.as_bytes(),
                first_line: 1,
                offset: 0,
            };
            let mut parts = [Part::new(layout), Part::new(layout)];
            let mut out = Columns::new(layout);
            let fast = parse_block(layout, &block, &mut parts, &mut out).map(|_| out);
            assert_eq!(
                outcome(fast),
                outcome(line_by_line(layout, text.as_bytes())),
                "{text:?}"
            );
        }
    }

    #[test]
    fn fields_split_a_row_exactly_as_str_split_on_commas() {
        for row in [
            "",
            ",",
            "1,2,3",
            ",a,,b,",
            " 1.5 , -2 ,\u{e9}t\u{e9},x",
            "no commas",
        ] {
            let expected: Vec<&str> = row.split(',').collect();
            assert_eq!(fields(row).collect::<Vec<_>>(), expected, "{row:?}");
        }
    }
}
