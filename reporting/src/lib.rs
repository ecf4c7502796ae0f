//! Report helpers shared by the rig tools, so every verb writes files the same way:
//! atomic writes (a failed run never destroys an existing file), numbers printed as a person
//! writes them, and the SVG figures of the reports.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use thiserror::Error;

pub mod check;
pub mod figure;
pub mod plot;

/// What can go wrong while writing a report.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum ReportError {
    /// A file or folder that cannot be read or written.
    #[error("cannot {action} {path}: {source}")]
    File {
        /// What was tried ("read", "write", "create folder").
        action: &'static str,
        /// The path.
        path: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// A plot that cannot be drawn.
    #[error("cannot draw {path}: {why}")]
    Plot {
        /// The plot file.
        path: String,
        /// The drawing backend's reason.
        why: String,
    },
}

/// The temporary sibling `path` is written to before the rename: same folder (so the rename
/// stays on one file system), hidden, and named after the process so parallel runs differ.
fn temporary_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "output".into());
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// Writes a file atomically: `write` fills a temporary file beside `path`, which is synced
/// and renamed over `path` only when `write` succeeded. A failed run leaves an existing
/// `path` untouched and no temporary file behind.
pub fn write_atomic_with<E>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), E>
where
    E: From<ReportError>,
{
    let tmp = temporary_path(path);
    let file_err = |action: &'static str, source: std::io::Error| ReportError::File {
        action,
        path: path.display().to_string(),
        source,
    };
    if let Err(e) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    let synced = std::fs::File::open(&tmp).and_then(|f| f.sync_all());
    let renamed = synced.and_then(|()| std::fs::rename(&tmp, path));
    if let Err(source) = renamed {
        let _ = std::fs::remove_file(&tmp);
        return Err(file_err("write", source).into());
    }
    Ok(())
}

/// Writes `bytes` to `path` atomically (see [`write_atomic_with`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), ReportError> {
    write_atomic_with(path, |tmp| {
        std::fs::File::create(tmp)
            .and_then(|mut f| f.write_all(bytes))
            .map_err(|source| ReportError::File {
                action: "write",
                path: path.display().to_string(),
                source,
            })
    })
}

/// Checks before a long measurement that `dir` (an existing folder) takes files: writes and
/// removes a small probe file. Also removes the temporary files ([`write_atomic_with`]'s
/// hidden `.NAME.PID.tmp`) that a killed run left there (their process is gone).
pub fn check_writable_dir(dir: &Path) -> Result<(), ReportError> {
    remove_stale_temporaries(dir);
    let probe = dir.join(format!(".rig-write-check.{}.tmp", std::process::id()));
    let written = std::fs::File::create(&probe)
        .and_then(|mut f| f.write_all(b"rig\n"))
        .and_then(|()| std::fs::remove_file(&probe));
    written.map_err(|source| {
        let _ = std::fs::remove_file(&probe);
        ReportError::File {
            action: "write in folder",
            path: dir.display().to_string(),
            source,
        }
    })
}

/// Removes the temporary files of [`write_atomic_with`] in `dir` whose process no longer
/// runs (a run killed between writing and renaming). Only where the process table can be
/// read (`/proc`); a file of a running process is never touched.
pub fn remove_stale_temporaries(dir: &Path) {
    let proc = Path::new("/proc/self");
    if !proc.exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if let Some(pid) = temporary_pid(&name)
            && pid != std::process::id()
            && !Path::new("/proc").join(pid.to_string()).exists()
        {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// The process id in a temporary file name `.NAME.PID.tmp` ([`temporary_path`]).
fn temporary_pid(name: &str) -> Option<u32> {
    let stem = name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let (base, pid) = stem.rsplit_once('.')?;
    if base.is_empty() {
        return None;
    }
    pid.parse().ok()
}

/// A measured number rounded to `digits` significant digits (a mean of `f32` readings
/// keeps 7: 3.166320013999939 is written 3.16632); non-finite values and zero unchanged.
pub fn significant(value: f64, digits: u8) -> f64 {
    if !value.is_finite() || value == 0.0 || digits == 0 {
        return value;
    }
    format!("{:.*e}", usize::from(digits - 1), value)
        .parse()
        .unwrap_or(value)
}

/// A float as a person writes it: the shortest decimal that reads back to the same `f32`
/// when `value` came from one (62.1, not 62.099998474121094), else the shortest for `f64`.
pub fn human_f64(value: f64) -> f64 {
    let single = value as f32;
    if f64::from(single) == value {
        // Shortest decimal of the f32, parsed as f64: 62.1f32 -> 62.1.
        single.to_string().parse().unwrap_or(value)
    } else {
        value
    }
}

/// A JSON value with every float passed through [`human_f64`].
pub fn human_json(value: serde_json::Value) -> serde_json::Value {
    use serde_json::Value;
    match value {
        Value::Number(n) => match (n.is_f64(), n.as_f64()) {
            (true, Some(f)) => serde_json::Number::from_f64(human_f64(f))
                .map(Value::Number)
                .unwrap_or(Value::Number(n)),
            _ => Value::Number(n),
        },
        Value::Array(items) => Value::Array(items.into_iter().map(human_json).collect()),
        Value::Object(map) => {
            Value::Object(map.into_iter().map(|(k, v)| (k, human_json(v))).collect())
        }
        other => other,
    }
}

/// `value` as pretty JSON with every number as a person writes it (see [`human_json`]).
pub fn json_pretty<T: serde::Serialize + ?Sized>(value: &T) -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(&human_json(serde_json::to_value(value)?))
}

/// `value` as one line of JSON with every number as a person writes it.
pub fn json_line<T: serde::Serialize + ?Sized>(value: &T) -> Result<String, serde_json::Error> {
    serde_json::to_string(&human_json(serde_json::to_value(value)?))
}

/// A number for text output as a person writes it: `62.1` for a value that came from the
/// `f32` 62.1 (see [`human_f64`]), whole numbers without a fraction.
pub fn human(value: f64) -> String {
    human_f64(value).to_string()
}

/// A moment in UTC, split into its civil date and time (proleptic Gregorian), for the
/// timestamps reports and provenance lines carry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UtcTime {
    /// Year.
    pub year: i64,
    /// Month, 1-12.
    pub month: i64,
    /// Day of the month, 1-31.
    pub day: i64,
    /// Hour, 0-23.
    pub hour: u64,
    /// Minute, 0-59.
    pub minute: u64,
    /// Second, 0-59.
    pub second: u64,
}

impl UtcTime {
    /// `time` in UTC (a time before 1970 counts as 1970-01-01T00:00:00Z).
    pub fn of(time: std::time::SystemTime) -> Self {
        let secs = time
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        let (days, rest) = (secs / 86_400, secs % 86_400);
        // Civil date from days since 1970-01-01 (H. Hinnant's algorithm).
        let z = i64::try_from(days).unwrap_or(i64::MAX - 719_468) + 719_468;
        let era = z.div_euclid(146_097);
        let doe = z - era * 146_097;
        let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
        let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
        let mp = (5 * doy + 2) / 153;
        let month = if mp < 10 { mp + 3 } else { mp - 9 };
        Self {
            year: yoe + era * 400 + i64::from(month <= 2),
            month,
            day: doy - (153 * mp + 2) / 5 + 1,
            hour: rest / 3600,
            minute: rest / 60 % 60,
            second: rest % 60,
        }
    }

    /// ISO 8601, `2026-11-22T23:55:00Z`.
    pub fn iso(&self) -> String {
        format!(
            "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}Z",
            self.year, self.month, self.day, self.hour, self.minute, self.second
        )
    }

    /// The compact form for file and folder names, `20261122T235500Z`.
    pub fn compact(&self) -> String {
        format!(
            "{:04}{:02}{:02}T{:02}{:02}{:02}Z",
            self.year, self.month, self.day, self.hour, self.minute, self.second
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measured_means_keep_seven_significant_digits() {
        assert_eq!(significant(3.166320013999939, 7).to_string(), "3.16632");
        assert_eq!(significant(-0.001234567891, 7), -0.001234568);
        assert_eq!(significant(62.1, 7), 62.1);
        assert_eq!(significant(0.0, 7), 0.0);
        assert!(significant(f64::NAN, 7).is_nan());
    }

    #[test]
    fn a_killed_runs_temporaries_are_removed_and_a_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        // No process has id 4294967; this process is alive.
        let stale = dir.path().join(".points.csv.4294967.tmp");
        let live = dir
            .path()
            .join(format!(".points.csv.{}.tmp", std::process::id()));
        let data = dir.path().join("points.csv");
        for p in [&stale, &live, &data] {
            std::fs::write(p, "x").unwrap();
        }
        check_writable_dir(dir.path()).unwrap();
        if Path::new("/proc/self").exists() {
            assert!(!stale.exists());
        }
        assert!(live.exists() && data.exists());
        assert_eq!(temporary_pid(".a.b.12.tmp"), Some(12));
        assert_eq!(temporary_pid("a.12.tmp"), None);
        assert_eq!(temporary_pid(".12.tmp"), None);
        let missing = dir.path().join("no-such-folder");
        let e = check_writable_dir(&missing).unwrap_err().to_string();
        assert!(e.contains("no-such-folder"), "{e}");
    }

    #[test]
    fn utc_dates_and_times() {
        let at = |s| UtcTime::of(std::time::UNIX_EPOCH + std::time::Duration::from_secs(s));
        assert_eq!(at(0).compact(), "19700101T000000Z");
        assert_eq!(at(951_827_696).compact(), "20000229T123456Z");
        assert_eq!(at(1_735_689_599).iso(), "2024-12-31T23:59:59Z");
        assert_eq!(at(1_795_910_400).iso(), "2026-11-29T00:00:00Z");
    }

    #[test]
    fn a_failed_write_leaves_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("model.toml");
        std::fs::write(&path, "old").unwrap();
        let r: Result<(), ReportError> = write_atomic_with(&path, |tmp| {
            std::fs::write(tmp, "half").unwrap();
            Err(ReportError::Plot {
                path: "x".into(),
                why: "failed half-way".into(),
            })
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            1,
            "no temporary left"
        );
        write_atomic(&path, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
    }

    #[test]
    fn floats_print_as_written() {
        assert_eq!(human_f64(f64::from(62.1f32)).to_string(), "62.1");
        assert_eq!(human_f64(f64::from(-0.00378f32)).to_string(), "-0.00378");
        // A true f64 keeps its digits.
        assert_eq!(human_f64(0.1 + 0.2), 0.1 + 0.2);
        let v = human_json(serde_json::json!({"c1": f64::from(62.1f32), "z": [49, 51]}));
        assert_eq!(v.to_string(), r#"{"c1":62.1,"z":[49,51]}"#);
        #[derive(serde::Serialize)]
        struct Device {
            hz: f32,
            ok: bool,
        }
        let d = Device { hz: 62.1, ok: true };
        assert_eq!(json_line(&d).unwrap(), r#"{"hz":62.1,"ok":true}"#);
        assert!(
            json_pretty(&[f64::from(0.235f32)])
                .unwrap()
                .contains("0.235\n")
        );
        assert_eq!(human(f64::from(2.25f32)), "2.25");
        assert_eq!(human(3.0), "3");
    }
}
