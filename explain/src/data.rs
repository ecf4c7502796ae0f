//! Measured steady-state data: one row per test point, read from CSV with SI column names.
//!
//! Required columns: `omega_n_rad_s` (cam speed), `tau_rot_nm` (load torque on the output),
//! `i_in_a` (mean vibrator current). Optional: `t_s` (time of the test), `v_in_v` (vibrator
//! voltage), `temp_c` (motor temperature), `backdriven` (0/1: whether the output moved).
//! Other columns are ignored. Header names are matched without regard to case or surrounding
//! spaces; lines starting with `#` are comments. A row whose `backdriven` is 0 may leave
//! `i_in_a` empty (the paper has no current where the load did not move).
//!
//! The rows are kept as columns (one `Vec<f64>` per quantity, no per-row allocation), so a
//! million rows take about 60 MB; the CSV is parsed as it streams in.

use std::io::Read;
use std::path::Path;

use rigfile::row::Column;

use crate::ExplainError;

/// Required columns, in the order of the error messages.
pub const REQUIRED_COLUMNS: [&str; 3] = [
    Column::CamSpeed.name(),
    Column::Load.name(),
    Column::Current.name(),
];
/// Optional columns the analysis uses.
pub const OPTIONAL_COLUMNS: [&str; 4] = [
    Column::Time.name(),
    Column::Supply.name(),
    Column::Temperature.name(),
    Column::Backdriven.name(),
];
/// Fewest rows with a current that `rig explain` works with.
pub const MIN_ROWS: usize = 10;
/// Longest line of a measured file, bytes: a header of every column the tools write is
/// about 100 bytes, so a longer line is not a table (a file without line ends, `/dev/zero`,
/// a sparse file); reading stops there instead of buffering it whole.
pub const MAX_LINE_BYTES: usize = 64 * 1024;
/// Most rows the column buffers reserve up front from the file's size (they grow beyond).
const MAX_RESERVED_ROWS: u64 = 4_000_000;

/// `text` cut to at most `max` characters, with how much was left out.
fn shortened(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        None => text.to_string(),
        Some((cut, _)) => format!(
            "{} ... ({} more bytes not shown)",
            &text[..cut],
            text.len() - cut
        ),
    }
}

/// A reader that fails once a line grows beyond `limit` bytes, so a file without line ends
/// is refused after a bounded read (the CSV reader would otherwise buffer the line whole).
struct LineBounded<R> {
    inner: R,
    since_newline: usize,
    line: u64,
    limit: usize,
}

impl<R: Read> Read for LineBounded<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        let chunk = &buf[..n];
        match chunk.iter().rposition(|&b| b == b'\n') {
            Some(last) => {
                self.line += chunk.iter().filter(|&&b| b == b'\n').count() as u64;
                self.since_newline = n - last - 1;
            }
            None => self.since_newline += n,
        }
        if self.since_newline > self.limit {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "line {} is longer than {} KiB: not a CSV table of test points (a file without line ends?); reading stopped there",
                    self.line + 1,
                    self.limit / 1024
                ),
            ));
        }
        Ok(n)
    }
}

/// One test point: the rig tools' one measured-row type ([`rigfile::row`]), which every
/// sweep CSV writes; explain uses its cam speed, load, current, time, supply, temperature
/// and backdrive observation.
pub use rigfile::row::MeasuredRow;

/// A validated set of test points, stored as columns. An optional column counts as present
/// when every row has it.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// Where the data came from (file name), for messages.
    pub name: String,
    /// Every row has `t_s`.
    pub has_time: bool,
    /// Every row has `v_in_v`.
    pub has_voltage: bool,
    /// Every row has `temp_c`.
    pub has_temperature: bool,
    /// Every row has `backdriven`.
    pub has_backdriven: bool,
    omega_n: Vec<f64>,
    tau_rot: Vec<f64>,
    /// NaN where the current is missing.
    i_in: Vec<f64>,
    /// Empty when the column is absent (likewise the other optional columns).
    t_s: Vec<f64>,
    v_in: Vec<f64>,
    temp_c: Vec<f64>,
    backdriven: Vec<bool>,
    /// Line of each row in its file (1-based); empty when the rows did not come from a file
    /// (then row k sits on line k + 1, after a header).
    lines: Vec<u32>,
}

impl PartialEq for Dataset {
    /// Same name, columns and values (file lines aside).
    fn eq(&self, other: &Self) -> bool {
        self.name == other.name
            && self.has_time == other.has_time
            && self.has_voltage == other.has_voltage
            && self.has_temperature == other.has_temperature
            && self.has_backdriven == other.has_backdriven
            && self.len() == other.len()
            && self.rows().eq(other.rows())
    }
}

fn row_error(file: &str, row: usize, line: u64, why: String) -> ExplainError {
    ExplainError::MeasuredRow {
        file: file.to_string(),
        row,
        line,
        why,
    }
}

/// Columns as read, optional values NaN (or 2 for `backdriven`) where a row leaves them empty.
#[derive(Default)]
struct RawColumns {
    omega_n: Vec<f64>,
    tau_rot: Vec<f64>,
    i_in: Vec<f64>,
    t_s: Vec<f64>,
    v_in: Vec<f64>,
    temp_c: Vec<f64>,
    backdriven: Vec<u8>,
    lines: Vec<u32>,
}

const MISSING_FLAG: u8 = 2;

impl RawColumns {
    fn with_capacity(n: usize) -> Self {
        Self {
            omega_n: Vec::with_capacity(n),
            tau_rot: Vec::with_capacity(n),
            i_in: Vec::with_capacity(n),
            t_s: Vec::with_capacity(n),
            v_in: Vec::with_capacity(n),
            temp_c: Vec::with_capacity(n),
            backdriven: Vec::with_capacity(n),
            lines: Vec::new(),
        }
    }

    fn push(&mut self, r: &MeasuredRow) {
        let opt = |v: Option<f64>| v.unwrap_or(f64::NAN);
        self.omega_n.push(r.omega_n);
        self.tau_rot.push(r.tau_rot);
        self.i_in.push(opt(r.i_in));
        self.t_s.push(opt(r.t_s));
        self.v_in.push(opt(r.v_in));
        self.temp_c.push(opt(r.temp_c));
        self.backdriven.push(match r.backdriven {
            Some(true) => 1,
            Some(false) => 0,
            None => MISSING_FLAG,
        });
    }

    fn len(&self) -> usize {
        self.omega_n.len()
    }

    fn line(&self, k: usize) -> u64 {
        self.lines.get(k).map_or(k as u64 + 2, |&l| u64::from(l))
    }

    /// Checks the columns (see [`Dataset::from_rows`]) and builds the data set.
    fn validate(self, name: &str) -> Result<Dataset, ExplainError> {
        let n = self.len();
        if n == 0 {
            return Err(ExplainError::EmptyData {
                file: name.to_string(),
                min_rows: MIN_ROWS,
            });
        }
        let bad = |k: usize, why: String| row_error(name, k + 1, self.line(k), why);
        for k in 0..n {
            for (column, v) in [
                ("omega_n_rad_s", self.omega_n[k]),
                ("tau_rot_nm", self.tau_rot[k]),
            ] {
                if !v.is_finite() {
                    return Err(bad(
                        k,
                        format!("column {column} is not a finite number ({v})"),
                    ));
                }
            }
            for (column, v) in [
                ("i_in_a", self.i_in[k]),
                ("t_s", self.t_s[k]),
                ("v_in_v", self.v_in[k]),
                ("temp_c", self.temp_c[k]),
            ] {
                if v.is_infinite() {
                    return Err(bad(
                        k,
                        format!("column {column} is not a finite number ({v})"),
                    ));
                }
            }
            if self.omega_n[k] <= 0.0 {
                return Err(bad(
                    k,
                    format!(
                        "column omega_n_rad_s is {}: the cam must turn (give the speed in rad/s, > 0)",
                        self.omega_n[k]
                    ),
                ));
            }
            if self.i_in[k].is_nan() && self.backdriven[k] != 0 {
                return Err(bad(
                    k,
                    "column i_in_a is empty: only rows with backdriven = 0 may leave out the current"
                        .into(),
                ));
            }
        }
        // An optional column: present in every row, in none, or an error at the first gap.
        let presence = |missing: &dyn Fn(usize) -> bool, column: &str| {
            let gaps = (0..n).filter(|&k| missing(k)).count();
            if gaps == 0 {
                Ok(true)
            } else if gaps == n {
                Ok(false)
            } else {
                let k = (0..n).find(|&k| missing(k)).unwrap_or(0);
                Err(bad(
                    k,
                    format!(
                        "column {column} is empty while other rows have it: fill it in every row or drop the column"
                    ),
                ))
            }
        };
        let has_time = presence(&|k| self.t_s[k].is_nan(), "t_s")?;
        let has_voltage = presence(&|k| self.v_in[k].is_nan(), "v_in_v")?;
        let has_temperature = presence(&|k| self.temp_c[k].is_nan(), "temp_c")?;
        let has_backdriven = presence(&|k| self.backdriven[k] == MISSING_FLAG, "backdriven")?;
        let with_current = self.i_in.iter().filter(|v| !v.is_nan()).count();
        if with_current < MIN_ROWS {
            return Err(ExplainError::TooFewRows {
                file: name.to_string(),
                rows: with_current,
                min_rows: MIN_ROWS,
            });
        }
        let keep = |has: bool, v: Vec<f64>| if has { v } else { Vec::new() };
        let lines_needed = self
            .lines
            .iter()
            .enumerate()
            .any(|(k, &l)| u64::from(l) != k as u64 + 2);
        Ok(Dataset {
            name: name.to_string(),
            has_time,
            has_voltage,
            has_temperature,
            has_backdriven,
            omega_n: self.omega_n,
            tau_rot: self.tau_rot,
            i_in: self.i_in,
            t_s: keep(has_time, self.t_s),
            v_in: keep(has_voltage, self.v_in),
            temp_c: keep(has_temperature, self.temp_c),
            backdriven: if has_backdriven {
                self.backdriven.into_iter().map(|b| b == 1).collect()
            } else {
                Vec::new()
            },
            lines: if lines_needed { self.lines } else { Vec::new() },
        })
    }
}

/// Parses one CSV field as a finite number; `Ok(None)` when it is empty.
fn parse_number(bytes: &[u8]) -> Result<Option<f64>, String> {
    if bytes.is_empty() {
        return Ok(None);
    }
    match std::str::from_utf8(bytes).ok().map(str::parse::<f64>) {
        Some(Ok(v)) if v.is_finite() => Ok(Some(v)),
        Some(Ok(_)) => Err("is not a finite number".into()),
        _ => Err("is not a number".into()),
    }
}

impl Dataset {
    /// Checks plain rows (from a file, the simulator or a test) and builds a data set named
    /// `name`. Every value must be finite, the cam must turn (w_n > 0), an optional value must
    /// be given in every row or in none, and a current is needed wherever the load backdrove.
    pub fn from_rows(name: &str, rows: Vec<MeasuredRow>) -> Result<Self, ExplainError> {
        let mut raw = RawColumns::with_capacity(rows.len());
        for (k, r) in rows.iter().enumerate() {
            for (column, v) in [
                ("i_in_a", r.i_in),
                ("t_s", r.t_s),
                ("v_in_v", r.v_in),
                ("temp_c", r.temp_c),
            ] {
                if let Some(v) = v
                    && !v.is_finite()
                {
                    return Err(row_error(
                        name,
                        k + 1,
                        k as u64 + 2,
                        format!("column {column} is not a finite number ({v})"),
                    ));
                }
            }
            raw.push(r);
        }
        raw.validate(name)
    }

    /// Reads a CSV file (see the module docs for the columns).
    pub fn read_csv(path: &Path) -> Result<Self, ExplainError> {
        // A FIFO or a device would block or never end: only regular files are read.
        if let Ok(meta) = std::fs::metadata(path)
            && !meta.is_file()
        {
            return Err(ExplainError::MeasuredFile {
                file: path.display().to_string(),
                why: format!(
                    "is not a regular file ({}): save the measurement to a file first",
                    if meta.is_dir() {
                        "a folder"
                    } else {
                        "a pipe, socket or device"
                    }
                ),
            });
        }
        let file = std::fs::File::open(path).map_err(|source| ExplainError::File {
            action: "read",
            path: path.display().to_string(),
            source,
        })?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string());
        let size = file.metadata().map(|m| m.len()).unwrap_or(0);
        Self::parse_csv_sized(
            std::io::BufReader::with_capacity(1 << 16, file),
            &name,
            size,
        )
    }

    /// Parses CSV text from `reader`; `name` names the source in messages.
    pub fn parse_csv<R: Read>(reader: R, name: &str) -> Result<Self, ExplainError> {
        Self::parse_csv_sized(reader, name, 0)
    }

    /// [`Dataset::parse_csv`] with the size of the input in bytes, if known, to reserve the
    /// columns once.
    fn parse_csv_sized<R: Read>(reader: R, name: &str, bytes: u64) -> Result<Self, ExplainError> {
        // Fields are trimmed as they are parsed (cheaper than trimming every record).
        let reader = LineBounded {
            inner: reader,
            since_newline: 0,
            line: 0,
            limit: MAX_LINE_BYTES,
        };
        let mut csv = csv::ReaderBuilder::new()
            .trim(csv::Trim::Headers)
            .comment(Some(b'#'))
            .flexible(true)
            .buffer_capacity(1 << 16)
            .from_reader(reader);
        let file_err = |why: String| ExplainError::MeasuredFile {
            file: name.to_string(),
            why,
        };
        let headers = csv
            .headers()
            .map_err(|e| file_err(format!("cannot read the header: {e}")))?
            .clone();
        if headers.is_empty() || headers.iter().all(str::is_empty) {
            return Err(ExplainError::EmptyData {
                file: name.to_string(),
                min_rows: MIN_ROWS,
            });
        }
        let lower: Vec<String> = headers.iter().map(|h| h.to_ascii_lowercase()).collect();
        let find = |column: &str| -> Result<Option<usize>, ExplainError> {
            let hits: Vec<usize> = lower
                .iter()
                .enumerate()
                .filter(|(_, h)| h.as_str() == column)
                .map(|(k, _)| k)
                .collect();
            match hits.len() {
                0 => Ok(None),
                1 => Ok(Some(hits[0])),
                _ => Err(file_err(format!(
                    "column {column} appears {} times in the header: keep one",
                    hits.len()
                ))),
            }
        };
        let mut required = [0usize; 3];
        for (slot, column) in required.iter_mut().zip(REQUIRED_COLUMNS) {
            *slot = find(column)?.ok_or_else(|| ExplainError::MissingColumn {
                file: name.to_string(),
                column: column.to_string(),
                found: shortened(&headers.iter().collect::<Vec<_>>().join(", "), 240),
            })?;
        }
        let [c_omega, c_tau, c_i] = required;
        let optional = [find("t_s")?, find("v_in_v")?, find("temp_c")?];
        let c_bd = find("backdriven")?;
        let columns = headers.len();

        // About 60 bytes a row in the usual files: reserve once instead of doubling.
        let mut raw = RawColumns::with_capacity((bytes / 48).min(MAX_RESERVED_ROWS) as usize);
        let mut record = csv::ByteRecord::new();
        loop {
            let row = raw.len() + 1;
            match csv.read_byte_record(&mut record) {
                Ok(false) => break,
                Ok(true) => {}
                Err(e) => {
                    let line = e.position().map_or(0, |p| p.line());
                    return Err(row_error(
                        name,
                        row,
                        line,
                        format!("not readable as CSV: {e}"),
                    ));
                }
            }
            let line = record.position().map_or(row as u64 + 1, |p| p.line());
            let bad = |why: String| row_error(name, row, line, why);
            if record.len() < columns {
                return Err(bad(format!(
                    "has {} fields but the header has {columns}",
                    record.len()
                )));
            }
            let field = |k: usize| record.get(k).unwrap_or(b"").trim_ascii();
            let number = |k: usize, column: &str| -> Result<f64, ExplainError> {
                parse_number(field(k))
                    .map(|v| v.unwrap_or(f64::NAN))
                    .map_err(|why| {
                        bad(format!(
                            "column {column} {why} ('{}')",
                            String::from_utf8_lossy(field(k))
                        ))
                    })
            };
            let required_number = |k: usize, column: &str| -> Result<f64, ExplainError> {
                let v = number(k, column)?;
                if v.is_nan() {
                    Err(bad(format!("column {column} is empty")))
                } else {
                    Ok(v)
                }
            };
            let backdriven = match c_bd.map(field) {
                None | Some(b"") => MISSING_FLAG,
                Some(b"1") => 1,
                Some(b"0") => 0,
                Some(v) if v.eq_ignore_ascii_case(b"true") || v.eq_ignore_ascii_case(b"yes") => 1,
                Some(v) if v.eq_ignore_ascii_case(b"false") || v.eq_ignore_ascii_case(b"no") => 0,
                Some(other) => {
                    return Err(bad(format!(
                        "column backdriven is '{}': give 0 (not backdriven) or 1 (backdriven)",
                        String::from_utf8_lossy(other)
                    )));
                }
            };
            raw.omega_n.push(required_number(c_omega, "omega_n_rad_s")?);
            raw.tau_rot.push(required_number(c_tau, "tau_rot_nm")?);
            raw.i_in.push(number(c_i, "i_in_a")?);
            let opt =
                |c: Option<usize>, column: &str| c.map_or(Ok(f64::NAN), |k| number(k, column));
            raw.t_s.push(opt(optional[0], "t_s")?);
            raw.v_in.push(opt(optional[1], "v_in_v")?);
            raw.temp_c.push(opt(optional[2], "temp_c")?);
            raw.backdriven.push(backdriven);
            let line32 = u32::try_from(line).unwrap_or(u32::MAX);
            if !raw.lines.is_empty() || line != row as u64 + 1 {
                if raw.lines.is_empty() {
                    // Every earlier row sat right after the header.
                    raw.lines.reserve(raw.omega_n.capacity());
                    raw.lines.extend((1..row).map(|r| r as u32 + 1));
                }
                raw.lines.push(line32);
            }
        }
        raw.validate(name)
    }

    /// Writes the data as CSV with the standard column names (optional columns only when
    /// present), numbers as Rust prints them.
    pub fn write_csv<W: std::io::Write>(&self, out: W) -> Result<(), ExplainError> {
        use rigfile::row::{EXPLAIN_COLUMNS, Numbers};
        let present = |c: &Column| match c {
            Column::Time => self.has_time,
            Column::Supply => self.has_voltage,
            Column::Temperature => self.has_temperature,
            Column::Backdriven => self.has_backdriven,
            _ => true,
        };
        let columns: Vec<Column> = EXPLAIN_COLUMNS.into_iter().filter(present).collect();
        rigfile::row::write_columns(out, &columns, Numbers::Plain, true, self.rows())
            .map_err(|e| ExplainError::Output(std::io::Error::other(e)))
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.omega_n.len()
    }

    /// Whether there are no rows (never, for a validated data set).
    pub fn is_empty(&self) -> bool {
        self.omega_n.is_empty()
    }

    /// Row `k` (0-based).
    pub fn row(&self, k: usize) -> MeasuredRow {
        let opt = |v: &[f64]| v.get(k).copied().filter(|x| !x.is_nan());
        MeasuredRow {
            omega_n: self.omega_n[k],
            tau_rot: self.tau_rot[k],
            i_in: opt(&self.i_in),
            t_s: opt(&self.t_s),
            v_in: opt(&self.v_in),
            temp_c: opt(&self.temp_c),
            backdriven: self.backdriven.get(k).copied(),
            ..MeasuredRow::default()
        }
    }

    /// Every row, in file order.
    pub fn rows(&self) -> impl Iterator<Item = MeasuredRow> + '_ {
        (0..self.len()).map(|k| self.row(k))
    }

    /// The file line of row `k` (0-based index; the header is line 1).
    pub fn line(&self, k: usize) -> u64 {
        self.lines.get(k).map_or(k as u64 + 2, |&l| u64::from(l))
    }

    /// Cam speeds, rad/s.
    pub fn omega_n(&self) -> &[f64] {
        &self.omega_n
    }

    /// Load torques, N m.
    pub fn tau_rot(&self) -> &[f64] {
        &self.tau_rot
    }

    /// Currents, A (NaN where a non-backdriven row has none).
    pub fn i_in(&self) -> &[f64] {
        &self.i_in
    }

    /// Times, s, when the data has them.
    pub fn t_s(&self) -> Option<&[f64]> {
        self.has_time.then_some(self.t_s.as_slice())
    }

    /// Vibrator voltages, V, when the data has them.
    pub fn v_in(&self) -> Option<&[f64]> {
        self.has_voltage.then_some(self.v_in.as_slice())
    }

    /// Motor temperatures, deg C, when the data has them.
    pub fn temp_c(&self) -> Option<&[f64]> {
        self.has_temperature.then_some(self.temp_c.as_slice())
    }

    /// Backdrive observations, when the data has them.
    pub fn backdriven(&self) -> Option<&[bool]> {
        self.has_backdriven.then_some(self.backdriven.as_slice())
    }

    /// Rows with a measured current.
    pub fn current_rows(&self) -> usize {
        self.i_in.iter().filter(|v| !v.is_nan()).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Dataset, ExplainError> {
        Dataset::parse_csv(text.as_bytes(), "measured.csv")
    }

    fn body(rows: usize) -> String {
        (0..rows)
            .map(|k| {
                format!(
                    "{},{},{}\n",
                    31.4 + k as f64,
                    0.368 * (1 + k % 10) as f64,
                    2.5
                )
            })
            .collect()
    }

    #[test]
    fn reads_required_and_optional_columns_in_any_order() {
        let mut text =
            String::from("# comment\nI_IN_A, tau_rot_nm ,extra,omega_n_rad_s,backdriven\n");
        for k in 0..12 {
            text.push_str(&format!(
                "2.5,{},x,{},{}\n",
                0.368 * (k + 1) as f64,
                31.4,
                k % 2
            ));
        }
        let d = parse(&text).unwrap();
        assert_eq!(d.len(), 12);
        assert!(d.has_backdriven && !d.has_time && !d.has_temperature);
        assert_eq!(d.row(1).backdriven, Some(true));
        assert_eq!(d.row(0).i_in, Some(2.5));
    }

    #[test]
    fn bad_values_name_the_row_and_column() {
        let text = format!("omega_n_rad_s,tau_rot_nm,i_in_a\n{}31.4,1.0,abc\n", body(6));
        let e = parse(&text).unwrap_err().to_string();
        assert!(
            e.contains("measured.csv row 7") && e.contains("column i_in_a is not a number ('abc')"),
            "{e}"
        );
        let text = format!("omega_n_rad_s,tau_rot_nm,i_in_a\n{}31.4,NaN,2.0\n", body(3));
        let e = parse(&text).unwrap_err().to_string();
        assert!(
            e.contains("row 4") && e.contains("tau_rot_nm") && e.contains("finite"),
            "{e}"
        );
        let text = format!("omega_n_rad_s,tau_rot_nm,i_in_a\n{}0,1.0,2.0\n", body(3));
        assert!(
            parse(&text)
                .unwrap_err()
                .to_string()
                .contains("cam must turn")
        );
    }

    #[test]
    fn missing_columns_and_empty_files_say_what_is_needed() {
        let e = parse("omega_n_rad_s,i_in_a\n31.4,2.5\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("measured.csv: missing required column tau_rot_nm"),
            "{e}"
        );
        let e = parse("").unwrap_err().to_string();
        assert!(
            e.contains("measured.csv is empty: it needs a header and at least"),
            "{e}"
        );
        let e = parse("omega_n_rad_s,tau_rot_nm,i_in_a\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("is empty"), "{e}");
        let text = format!("omega_n_rad_s,tau_rot_nm,i_in_a\n{}", body(4));
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains("only 4 rows"), "{e}");
    }

    #[test]
    fn current_may_be_missing_only_where_the_load_held() {
        let mut text = String::from("omega_n_rad_s,tau_rot_nm,i_in_a,backdriven\n");
        for k in 0..12 {
            text.push_str(&format!("31.4,{},2.5,1\n", 0.368 * (k + 1) as f64));
        }
        text.push_str("31.4,0.368,,0\n");
        let d = parse(&text).unwrap();
        assert_eq!(d.current_rows(), 12);
        text.push_str("31.4,0.368,,1\n");
        let e = parse(&text).unwrap_err().to_string();
        assert!(e.contains("row 14") && e.contains("i_in_a is empty"), "{e}");
    }

    #[test]
    fn csv_round_trip() {
        let mut text = String::from("omega_n_rad_s,tau_rot_nm,i_in_a,t_s,temp_c\n");
        for k in 0..12 {
            text.push_str(&format!(
                "31.4,{},2.5,{},{}\n",
                0.368 * (k + 1) as f64,
                k * 20,
                25 + k
            ));
        }
        let d = parse(&text).unwrap();
        let mut out = Vec::new();
        d.write_csv(&mut out).unwrap();
        let back = Dataset::parse_csv(out.as_slice(), "measured.csv").unwrap();
        assert_eq!(back, d);
    }

    #[test]
    fn saved_csv_keeps_its_bytes() {
        // Numbers as Rust prints them (`1`, not `1.0`; no exponent), a held row's current
        // empty, the optional columns only when present, in their fixed order.
        let mut text = String::from("backdriven,tau_rot_nm,omega_n_rad_s,i_in_a,v_in_v\n");
        for k in 0..11 {
            text.push_str(&format!("1,{},31.4,2.5,{}\n", 0.1 + 0.2 * k as f64, 3.6));
        }
        text.push_str("0,0.0000001,1e2,,8.8\n");
        let d = parse(&text).unwrap();
        let mut out = Vec::new();
        d.write_csv(&mut out).unwrap();
        let out = String::from_utf8(out).unwrap();
        let mut lines = out.lines();
        assert_eq!(
            lines.next(),
            Some("omega_n_rad_s,tau_rot_nm,i_in_a,v_in_v,backdriven")
        );
        assert_eq!(lines.next(), Some("31.4,0.1,2.5,3.6,1"));
        assert_eq!(lines.next(), Some("31.4,0.30000000000000004,2.5,3.6,1"));
        assert_eq!(lines.last(), Some("100,0.0000001,,8.8,0"));
        assert!(out.ends_with('\n') && !out.contains('\r'));
    }
}
