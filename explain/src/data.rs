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
//! million rows take about 60 MB; the CSV is parsed as it streams in, a block of whole lines
//! (512 KiB) per core at a time.

use rigfile::text_input::LineBounded;
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
pub use rigfile::text_input::MAX_LINE_BYTES;
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

/// What a measured file's line should be, for the bounded reader's refusal.
const MEASURED_TEXT: &str = "a CSV table of test points";

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

/// Bytes of whole lines parsed as one block on one thread.
const BLOCK_BYTES: usize = 1 << 19;

/// Where a measured file's columns sit.
#[derive(Debug, Clone, Copy)]
struct Layout {
    omega_n: usize,
    tau_rot: usize,
    i_in: usize,
    /// `t_s`, `v_in_v`, `temp_c`.
    optional: [Option<usize>; 3],
    backdriven: Option<usize>,
    /// Fields of the header.
    columns: usize,
}

/// The CSV reader's settings: headers trimmed (fields are trimmed as they are parsed,
/// cheaper than trimming every record), `#` comments, records of any length.
fn csv_reader<R: Read>(reader: R, has_headers: bool) -> csv::Reader<R> {
    csv::ReaderBuilder::new()
        .trim(csv::Trim::Headers)
        .comment(Some(b'#'))
        .flexible(true)
        .has_headers(has_headers)
        .buffer_capacity(1 << 16)
        .from_reader(reader)
}

impl Layout {
    /// The columns of `headers`: an error for a missing or repeated required column.
    fn of(headers: &csv::StringRecord, name: &str) -> Result<Self, ExplainError> {
        let file_err = |why: String| ExplainError::MeasuredFile {
            file: name.to_string(),
            why,
        };
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
        let [omega_n, tau_rot, i_in] = required;
        Ok(Self {
            omega_n,
            tau_rot,
            i_in,
            optional: [find("t_s")?, find("v_in_v")?, find("temp_c")?],
            backdriven: find("backdriven")?,
            columns: headers.len(),
        })
    }

    /// Appends the values of `record` to `raw`; the reason when a field is not readable.
    fn push(&self, record: &csv::ByteRecord, raw: &mut RawColumns) -> Result<(), String> {
        let columns = self.columns;
        if record.len() < columns {
            return Err(format!(
                "has {} fields but the header has {columns}",
                record.len()
            ));
        }
        let field = |k: usize| record.get(k).unwrap_or(b"").trim_ascii();
        let number = |k: usize, column: &str| -> Result<f64, String> {
            parse_number(field(k))
                .map(|v| v.unwrap_or(f64::NAN))
                .map_err(|why| {
                    format!(
                        "column {column} {why} ('{}')",
                        shortened(&String::from_utf8_lossy(field(k)), 40)
                    )
                })
        };
        let required_number = |k: usize, column: &str| -> Result<f64, String> {
            let v = number(k, column)?;
            if v.is_nan() {
                Err(format!("column {column} is empty"))
            } else {
                Ok(v)
            }
        };
        let backdriven = match self.backdriven.map(field) {
            None | Some(b"") => MISSING_FLAG,
            Some(b"1") => 1,
            Some(b"0") => 0,
            Some(v) if v.eq_ignore_ascii_case(b"true") || v.eq_ignore_ascii_case(b"yes") => 1,
            Some(v) if v.eq_ignore_ascii_case(b"false") || v.eq_ignore_ascii_case(b"no") => 0,
            Some(other) => {
                return Err(format!(
                    "column backdriven is '{}': give 0 (not backdriven) or 1 (backdriven)",
                    String::from_utf8_lossy(other)
                ));
            }
        };
        raw.omega_n
            .push(required_number(self.omega_n, "omega_n_rad_s")?);
        raw.tau_rot
            .push(required_number(self.tau_rot, "tau_rot_nm")?);
        raw.i_in.push(number(self.i_in, "i_in_a")?);
        let opt = |c: Option<usize>, column: &str| c.map_or(Ok(f64::NAN), |k| number(k, column));
        raw.t_s.push(opt(self.optional[0], "t_s")?);
        raw.v_in.push(opt(self.optional[1], "v_in_v")?);
        raw.temp_c.push(opt(self.optional[2], "temp_c")?);
        raw.backdriven.push(backdriven);
        Ok(())
    }
}

impl RawColumns {
    /// Records that data row `row` (1-based, just pushed) sits on file line `line`: the
    /// lines are kept only once some row is not on the line after its predecessor's.
    fn note_line(&mut self, row: usize, line: u64) {
        if !self.lines.is_empty() || line != row as u64 + 1 {
            if self.lines.is_empty() {
                // Every earlier row sat right after the header.
                self.lines.reserve(self.omega_n.capacity());
                self.lines.extend((1..row).map(|r| r as u32 + 1));
            }
            self.lines.push(u32::try_from(line).unwrap_or(u32::MAX));
        }
    }

    /// Appends the rows of `block`, whose first byte is on file line `first_line`.
    fn append(&mut self, block: Block, first_line: u64) {
        let before = self.len();
        let b = block.raw;
        self.omega_n.extend_from_slice(&b.omega_n);
        self.tau_rot.extend_from_slice(&b.tau_rot);
        self.i_in.extend_from_slice(&b.i_in);
        self.t_s.extend_from_slice(&b.t_s);
        self.v_in.extend_from_slice(&b.v_in);
        self.temp_c.extend_from_slice(&b.temp_c);
        self.backdriven.extend_from_slice(&b.backdriven);
        for (i, &local) in block.lines.iter().enumerate() {
            let row = before + i + 1;
            self.note_line(row, block_line(local, row, first_line));
        }
    }
}

/// The file line of a block's line `local` (1-based within the block; 0: unknown, then the
/// line after the header's that row `row` would have).
fn block_line(local: u64, row: usize, first_line: u64) -> u64 {
    if local == 0 {
        row as u64 + 1
    } else {
        first_line + local - 1
    }
}

/// Rows parsed from one block of whole lines, with the line of each within the block.
struct Block {
    raw: RawColumns,
    lines: Vec<u64>,
}

/// Why a block failed: its row (1-based within the block), its line within the block and
/// the reason.
type BlockError = (usize, u64, String);

/// Parses a block of whole lines (no header, no quotes).
fn parse_block(bytes: &[u8], layout: &Layout) -> Result<Block, BlockError> {
    let mut csv = csv_reader(bytes, false);
    let rows = bytes.len() / 48;
    let mut block = Block {
        raw: RawColumns::with_capacity(rows),
        lines: Vec::with_capacity(rows),
    };
    let mut record = csv::ByteRecord::new();
    loop {
        let row = block.raw.len() + 1;
        match csv.read_byte_record(&mut record) {
            Ok(false) => return Ok(block),
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map_or(0, |p| p.line());
                return Err((row, line, format!("not readable as CSV: {e}")));
            }
        }
        let line = record.position().map_or(0, |p| p.line());
        layout
            .push(&record, &mut block.raw)
            .map_err(|why| (row, line, why))?;
        block.lines.push(line);
    }
}

/// Reads the records of `csv` (positioned after the header) into `raw`, its line `k` being
/// the file's line `k + line_offset`.
fn read_records<R: Read>(
    csv: &mut csv::Reader<R>,
    layout: &Layout,
    name: &str,
    raw: &mut RawColumns,
    line_offset: u64,
) -> Result<(), ExplainError> {
    let mut record = csv::ByteRecord::new();
    loop {
        let row = raw.len() + 1;
        match csv.read_byte_record(&mut record) {
            Ok(false) => return Ok(()),
            Ok(true) => {}
            Err(e) => {
                let line = e.position().map_or(0, |p| p.line() + line_offset);
                return Err(row_error(
                    name,
                    row,
                    line,
                    format!("not readable as CSV: {e}"),
                ));
            }
        }
        let line = record
            .position()
            .map_or(row as u64 + 1, |p| p.line() + line_offset);
        layout
            .push(&record, raw)
            .map_err(|why| row_error(name, row, line, why))?;
        raw.note_line(row, line);
    }
}

/// Reads from `reader` until `buf` holds `size` bytes or the input ends (then `true`).
fn fill(reader: &mut impl Read, buf: &mut Vec<u8>, size: usize) -> std::io::Result<bool> {
    let mut filled = buf.len();
    buf.resize(size, 0);
    while filled < size {
        match reader.read(&mut buf[filled..]) {
            Ok(0) => {
                buf.truncate(filled);
                return Ok(true);
            }
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => {
                buf.truncate(filled);
                return Err(e);
            }
        }
    }
    Ok(false)
}

/// Parses a measured CSV from `reader` (`bytes` long, if known, to reserve the columns
/// once), in blocks of about `block_bytes` of whole lines parsed on as many threads as the
/// machine has cores, with the file's row and line numbers in every message. A block with a
/// quote or a carriage return ([`needs_stream`]) and everything after it are read in one
/// stream, as is a file whose header is not in its first block. Every line stays bounded
/// ([`MAX_LINE_BYTES`]), so a file without line ends is refused after a bounded read.
fn parse_blocks<R: Read>(
    reader: R,
    name: &str,
    bytes: u64,
    block_bytes: usize,
) -> Result<Dataset, ExplainError> {
    let mut reader = LineBounded::new(reader, MEASURED_TEXT);
    let mut raw = RawColumns::with_capacity((bytes / 48).min(MAX_RESERVED_ROWS) as usize);
    // Whole lines of the next block, and the part line after them.
    // Whole lines of the next block, whether the input ended there, and whether the read
    // failed (a line beyond the limit): then the block is what was read, and the one stream
    // reads it and meets the error again, with the row it is in.
    let next_block = |reader: &mut LineBounded<R>, carry: &mut Vec<u8>| {
        let mut buf = std::mem::take(carry);
        // A part line as long as a block (the reader stops it at the line limit) grows by
        // a block.
        let size = if buf.len() < block_bytes {
            block_bytes
        } else {
            buf.len() + block_bytes
        };
        match fill(reader, &mut buf, size) {
            Err(_) => (buf, false, true),
            Ok(true) => (buf, true, false),
            Ok(false) => {
                match memchr::memrchr(b'\n', &buf) {
                    Some(last) => *carry = buf.split_off(last + 1),
                    None => *carry = std::mem::take(&mut buf),
                }
                (buf, false, false)
            }
        }
    };
    let mut carry = Vec::new();
    let (first, mut end, failed) = next_block(&mut reader, &mut carry);
    // The header from the first block.
    let mut header = csv_reader(first.as_slice(), true);
    let headers = header.headers().cloned();
    let body = header.position().clone();
    drop(header);
    let in_first = body.byte() > 0 && (body.byte() as usize) < first.len() || end;
    if failed || !in_first || needs_stream(&first) {
        // One stream: the first block, the part line and the rest.
        let rest = std::io::Cursor::new(first).chain(std::io::Cursor::new(carry));
        let mut csv = csv_reader(rest.chain(reader), true);
        let headers = csv
            .headers()
            .map_err(|e| ExplainError::MeasuredFile {
                file: name.to_string(),
                why: format!("cannot read the header: {e}"),
            })?
            .clone();
        let layout = Layout::of(&headers, name)?;
        read_records(&mut csv, &layout, name, &mut raw, 0)?;
        return raw.validate(name);
    }
    let headers = headers.map_err(|e| ExplainError::MeasuredFile {
        file: name.to_string(),
        why: format!("cannot read the header: {e}"),
    })?;
    let layout = Layout::of(&headers, name)?;
    let mut first = first;
    first.drain(..body.byte() as usize);
    let mut pending = vec![(first, body.line())];
    // The line the next block starts on: a block ends at its last line end, and the reader
    // has counted every line end so far.
    let mut line = reader.lines_read() + 1;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    loop {
        // Gather a block per thread, parse them together, append in file order.
        let mut stream = None;
        while !end && pending.len() < threads {
            let (block, last, failed) = next_block(&mut reader, &mut carry);
            end = last;
            if failed || needs_stream(&block) {
                stream = Some((block, line));
                break;
            }
            pending.push((block, line));
            line = reader.lines_read() + 1;
        }
        let parsed = crate::parallel::par_map(&pending, |(block, _)| parse_block(block, &layout));
        for ((_, first_line), block) in pending.drain(..).zip(parsed) {
            match block {
                Ok(block) => raw.append(block, first_line),
                Err((row, local, why)) => {
                    let row = raw.len() + row;
                    return Err(row_error(
                        name,
                        row,
                        block_line(local, row, first_line),
                        why,
                    ));
                }
            }
        }
        if let Some((block, first_line)) = stream {
            // A quote, a carriage return or a read error: the rest in one stream.
            let rest = std::io::Cursor::new(block).chain(std::io::Cursor::new(carry));
            let mut csv = csv_reader(rest.chain(reader), false);
            read_records(&mut csv, &layout, name, &mut raw, first_line - 1)?;
            break;
        }
        if end {
            break;
        }
    }
    raw.validate(name)
}

/// Whether `block` must be read in one stream with the rest: a quote (a field could hold a
/// line end) or a carriage return (the CSV reader counts the lines of CR LF text its own
/// way, so a block's line numbers would not add up).
fn needs_stream(block: &[u8]) -> bool {
    block.contains(&b'"') || block.contains(&b'\r')
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
        if let Some(why) = rigfile::text_input::not_a_regular_file(path) {
            return Err(ExplainError::MeasuredFile {
                file: path.display().to_string(),
                why,
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
        parse_blocks(reader, name, bytes, BLOCK_BYTES)
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

    /// The file read as one stream (the reader before blocks): the oracle of the blocks.
    fn parse_stream(text: &str) -> Result<Dataset, ExplainError> {
        let bounded = LineBounded::new(text.as_bytes(), MEASURED_TEXT);
        let mut csv = csv_reader(bounded, true);
        let headers = csv.headers().unwrap().clone();
        let layout = Layout::of(&headers, "measured.csv")?;
        let mut raw = RawColumns::default();
        read_records(&mut csv, &layout, "measured.csv", &mut raw, 0)?;
        raw.validate("measured.csv")
    }

    #[test]
    fn blocks_read_as_one_stream_reads() {
        let header = "omega_n_rad_s,tau_rot_nm,i_in_a,t_s,backdriven";
        let rows: Vec<String> = (0..40)
            .map(|k| format!("{},{},{},{k},1", 31.4 + k as f64, 0.1 * k as f64, 2.5))
            .collect();
        let plain = format!("{header}\n{}\n", rows.join("\n"));
        let commented = format!(
            "# rig A\n\n{header}\n{}\n# a rest\n\n{}\n",
            rows[..15].join("\n"),
            rows[15..].join("\r\n")
        );
        let quoted = format!("{header}\n{}\n\"31.4\",1.0,2.5,99,1\n", rows.join("\n"));
        let no_end = format!("{header}\n{}", rows.join("\n"));
        let mut bad_late = rows.clone();
        bad_late[33] = "31.4,1.0,abc,33,1".into();
        let bad_late = format!("# x\n{header}\n{}\n", bad_late.join("\n"));
        let mut short = rows.clone();
        short[21] = "31.4,1.0".into();
        let short = format!("{header}\n\n{}\n", short.join("\n"));
        let mut long = rows.clone();
        long[30] = format!("31.4,1.0,2.5,{},1", "7".repeat(3 * MAX_LINE_BYTES));
        let long = format!("{header}\n{}\n", long.join("\n"));
        for text in [plain, commented, quoted, no_end, bad_late, short, long] {
            let stream = parse_stream(&text);
            for block in [1, 7, 40, 100, 1 << 20] {
                let got = parse_blocks(text.as_bytes(), "measured.csv", 0, block);
                match (&stream, &got) {
                    (Ok(a), Ok(b)) => {
                        assert_eq!(a, b, "block {block}: {text}");
                        for k in 0..a.len() {
                            assert_eq!(a.line(k), b.line(k), "block {block}, row {k}: {text}");
                        }
                    }
                    // Where a read stops decides how many rows come before a refused line;
                    // the line itself is named exactly.
                    (Err(a), Err(b)) if a.to_string().contains("longer than") => {
                        let tail = |e: &ExplainError| {
                            e.to_string()
                                .split_off(e.to_string().find("line 32").unwrap())
                        };
                        assert_eq!(tail(a), tail(b), "block {block}")
                    }
                    (Err(a), Err(b)) => {
                        assert_eq!(a.to_string(), b.to_string(), "block {block}")
                    }
                    _ => panic!("block {block}: {stream:?} against {got:?}"),
                }
            }
        }
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
