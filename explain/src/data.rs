//! Measured steady-state data: one row per test point, read from CSV with SI column names.
//!
//! Required columns: `omega_n_rad_s` (cam speed), `tau_rot_nm` (load torque on the output),
//! `i_in_a` (mean vibrator current). Optional: `t_s` (time of the test), `v_in_v` (vibrator
//! voltage), `temp_c` (motor temperature), `backdriven` (0/1: whether the output moved).
//! Other columns are ignored. Header names are matched without regard to case or surrounding
//! spaces; lines starting with `#` are comments. A row whose `backdriven` is 0 may leave
//! `i_in_a` empty (the paper has no current where the load did not move).

use std::io::Read;
use std::path::Path;

use crate::ExplainError;

/// Required columns, in the order of the error messages.
pub const REQUIRED_COLUMNS: [&str; 3] = ["omega_n_rad_s", "tau_rot_nm", "i_in_a"];
/// Optional columns the analysis uses.
pub const OPTIONAL_COLUMNS: [&str; 4] = ["t_s", "v_in_v", "temp_c", "backdriven"];
/// Fewest rows with a current that `rig explain` works with.
pub const MIN_ROWS: usize = 10;

/// One test point.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MeasuredRow {
    /// Cam speed w_n, rad/s.
    pub omega_n: f64,
    /// Load torque on the output tau_rot, N m.
    pub tau_rot: f64,
    /// Mean vibrator current, A (`None` only where the load was not backdriven).
    pub i_in: Option<f64>,
    /// Time of the test since the start of the session, s.
    pub t_s: Option<f64>,
    /// Vibrator supply voltage, V.
    pub v_in: Option<f64>,
    /// Motor temperature, deg C.
    pub temp_c: Option<f64>,
    /// Whether the output backdrove.
    pub backdriven: Option<bool>,
}

/// A validated set of test points. An optional column counts as present when every row has
/// it.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    /// Where the data came from (file name), for messages.
    pub name: String,
    /// The rows, in file order.
    pub rows: Vec<MeasuredRow>,
    /// Every row has `t_s`.
    pub has_time: bool,
    /// Every row has `v_in_v`.
    pub has_voltage: bool,
    /// Every row has `temp_c`.
    pub has_temperature: bool,
    /// Every row has `backdriven`.
    pub has_backdriven: bool,
}

fn row_error(file: &str, row: usize, why: String) -> ExplainError {
    ExplainError::MeasuredRow {
        file: file.to_string(),
        row,
        line: row as u64 + 1,
        why,
    }
}

impl Dataset {
    /// Checks plain rows (from a file, the simulator or a test) and builds a data set named
    /// `name`. Every value must be finite, the cam must turn (w_n > 0), an optional value must
    /// be given in every row or in none, and a current is needed wherever the load backdrove.
    pub fn from_rows(name: &str, rows: Vec<MeasuredRow>) -> Result<Self, ExplainError> {
        if rows.is_empty() {
            return Err(ExplainError::EmptyData {
                file: name.to_string(),
                min_rows: MIN_ROWS,
            });
        }
        let all = |f: fn(&MeasuredRow) -> bool| rows.iter().all(f);
        let any = |f: fn(&MeasuredRow) -> bool| rows.iter().any(f);
        for (k, r) in rows.iter().enumerate() {
            let row = k + 1;
            let checks = [
                ("omega_n_rad_s", Some(r.omega_n)),
                ("tau_rot_nm", Some(r.tau_rot)),
                ("i_in_a", r.i_in),
                ("t_s", r.t_s),
                ("v_in_v", r.v_in),
                ("temp_c", r.temp_c),
            ];
            for (column, v) in checks {
                if let Some(v) = v
                    && !v.is_finite()
                {
                    return Err(row_error(
                        name,
                        row,
                        format!("column {column} is not a finite number ({v})"),
                    ));
                }
            }
            if r.omega_n <= 0.0 {
                return Err(row_error(
                    name,
                    row,
                    format!(
                        "column omega_n_rad_s is {}: the cam must turn (give the speed in rad/s, > 0)",
                        r.omega_n
                    ),
                ));
            }
            if r.i_in.is_none() && r.backdriven != Some(false) {
                return Err(row_error(
                    name,
                    row,
                    "column i_in_a is empty: only rows with backdriven = 0 may leave out the current"
                        .into(),
                ));
            }
        }
        let mixed = |has: bool, some: bool, column: &str, missing: fn(&MeasuredRow) -> bool| {
            if some && !has {
                let k = rows.iter().position(missing).unwrap_or(0);
                Err(row_error(
                    name,
                    k + 1,
                    format!(
                        "column {column} is empty while other rows have it: fill it in every row or drop the column"
                    ),
                ))
            } else {
                Ok(has)
            }
        };
        let has_time = mixed(
            all(|r| r.t_s.is_some()),
            any(|r| r.t_s.is_some()),
            "t_s",
            |r| r.t_s.is_none(),
        )?;
        let has_voltage = mixed(
            all(|r| r.v_in.is_some()),
            any(|r| r.v_in.is_some()),
            "v_in_v",
            |r| r.v_in.is_none(),
        )?;
        let has_temperature = mixed(
            all(|r| r.temp_c.is_some()),
            any(|r| r.temp_c.is_some()),
            "temp_c",
            |r| r.temp_c.is_none(),
        )?;
        let has_backdriven = mixed(
            all(|r| r.backdriven.is_some()),
            any(|r| r.backdriven.is_some()),
            "backdriven",
            |r| r.backdriven.is_none(),
        )?;
        let with_current = rows.iter().filter(|r| r.i_in.is_some()).count();
        if with_current < MIN_ROWS {
            return Err(ExplainError::TooFewRows {
                file: name.to_string(),
                rows: with_current,
                min_rows: MIN_ROWS,
            });
        }
        Ok(Self {
            name: name.to_string(),
            rows,
            has_time,
            has_voltage,
            has_temperature,
            has_backdriven,
        })
    }

    /// Reads a CSV file (see the module docs for the columns).
    pub fn read_csv(path: &Path) -> Result<Self, ExplainError> {
        let file = std::fs::File::open(path).map_err(|source| ExplainError::File {
            action: "read",
            path: path.display().to_string(),
            source,
        })?;
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string());
        Self::parse_csv(file, &name)
    }

    /// Parses CSV text from `reader`; `name` names the source in messages.
    pub fn parse_csv<R: Read>(reader: R, name: &str) -> Result<Self, ExplainError> {
        let mut csv = csv::ReaderBuilder::new()
            .trim(csv::Trim::All)
            .comment(Some(b'#'))
            .flexible(true)
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
                found: headers.iter().collect::<Vec<_>>().join(", "),
            })?;
        }
        let [c_omega, c_tau, c_i] = required;
        let c_t = find("t_s")?;
        let c_v = find("v_in_v")?;
        let c_temp = find("temp_c")?;
        let c_bd = find("backdriven")?;

        let mut rows = Vec::new();
        let mut record = csv::ByteRecord::new();
        loop {
            match csv.read_byte_record(&mut record) {
                Ok(false) => break,
                Ok(true) => {}
                Err(e) => {
                    let (row, line) = e
                        .position()
                        .map(|p| (rows.len() + 1, p.line()))
                        .unwrap_or((rows.len() + 1, 0));
                    return Err(ExplainError::MeasuredRow {
                        file: name.to_string(),
                        row,
                        line,
                        why: format!("not readable as CSV: {e}"),
                    });
                }
            }
            let row = rows.len() + 1;
            let line = record
                .position()
                .map(|p| p.line())
                .unwrap_or(row as u64 + 1);
            let bad = |why: String| ExplainError::MeasuredRow {
                file: name.to_string(),
                row,
                line,
                why,
            };
            if record.len() < headers.len() {
                return Err(bad(format!(
                    "has {} fields but the header has {}",
                    record.len(),
                    headers.len()
                )));
            }
            let number = |k: usize, column: &str| -> Result<Option<f64>, ExplainError> {
                let bytes = record.get(k).unwrap_or(b"");
                if bytes.is_empty() {
                    return Ok(None);
                }
                let text = String::from_utf8_lossy(bytes);
                match text.parse::<f64>() {
                    Ok(v) if v.is_finite() => Ok(Some(v)),
                    Ok(_) => Err(bad(format!(
                        "column {column} is not a finite number ('{text}')"
                    ))),
                    Err(_) => Err(bad(format!("column {column} is not a number ('{text}')"))),
                }
            };
            let required_number = |k: usize, column: &str| -> Result<f64, ExplainError> {
                number(k, column)?.ok_or_else(|| bad(format!("column {column} is empty")))
            };
            let backdriven = match c_bd.map(|k| record.get(k).unwrap_or(b"")) {
                None | Some(b"") => None,
                Some(b"1") => Some(true),
                Some(b"0") => Some(false),
                Some(v) if v.eq_ignore_ascii_case(b"true") || v.eq_ignore_ascii_case(b"yes") => {
                    Some(true)
                }
                Some(v) if v.eq_ignore_ascii_case(b"false") || v.eq_ignore_ascii_case(b"no") => {
                    Some(false)
                }
                Some(other) => {
                    return Err(bad(format!(
                        "column backdriven is '{}': give 0 (not backdriven) or 1 (backdriven)",
                        String::from_utf8_lossy(other)
                    )));
                }
            };
            let i_in = number(c_i, "i_in_a")?;
            rows.push(MeasuredRow {
                omega_n: required_number(c_omega, "omega_n_rad_s")?,
                tau_rot: required_number(c_tau, "tau_rot_nm")?,
                i_in,
                t_s: c_t.map(|k| number(k, "t_s")).transpose()?.flatten(),
                v_in: c_v.map(|k| number(k, "v_in_v")).transpose()?.flatten(),
                temp_c: c_temp.map(|k| number(k, "temp_c")).transpose()?.flatten(),
                backdriven,
            });
        }
        Self::from_rows(name, rows)
    }

    /// Writes the data as CSV with the standard column names (optional columns only when
    /// present).
    pub fn write_csv<W: std::io::Write>(&self, out: W) -> Result<(), ExplainError> {
        let mut w = csv::Writer::from_writer(out);
        let mut header = vec!["omega_n_rad_s", "tau_rot_nm", "i_in_a"];
        let flags = [
            (self.has_time, "t_s"),
            (self.has_voltage, "v_in_v"),
            (self.has_temperature, "temp_c"),
            (self.has_backdriven, "backdriven"),
        ];
        header.extend(flags.iter().filter(|(has, _)| *has).map(|(_, c)| *c));
        let io = |e: csv::Error| ExplainError::Output(std::io::Error::other(e));
        w.write_record(&header).map_err(io)?;
        let opt = |v: Option<f64>| v.map(|x| format!("{x}")).unwrap_or_default();
        for r in &self.rows {
            let mut rec = vec![
                format!("{}", r.omega_n),
                format!("{}", r.tau_rot),
                opt(r.i_in),
            ];
            if self.has_time {
                rec.push(opt(r.t_s));
            }
            if self.has_voltage {
                rec.push(opt(r.v_in));
            }
            if self.has_temperature {
                rec.push(opt(r.temp_c));
            }
            if self.has_backdriven {
                rec.push(match r.backdriven {
                    Some(true) => "1".into(),
                    Some(false) => "0".into(),
                    None => String::new(),
                });
            }
            w.write_record(&rec).map_err(io)?;
        }
        w.flush()?;
        Ok(())
    }

    /// Rows with a measured current.
    pub fn current_rows(&self) -> usize {
        self.rows.iter().filter(|r| r.i_in.is_some()).count()
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
        assert_eq!(d.rows.len(), 12);
        assert!(d.has_backdriven && !d.has_time && !d.has_temperature);
        assert_eq!(d.rows[1].backdriven, Some(true));
        assert_eq!(d.rows[0].i_in, Some(2.5));
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
}
