//! Append-only data files whose rows are whole or absent, shared by the verbs that log as
//! they measure (`rig experiment torque-sweep`, `rig monitor --csv`): every row is one
//! `write` of its whole text, so a process killed with SIGKILL leaves whole rows (the
//! kernel keeps what was written when the process dies); a write that fails (a full
//! disk) is cut back to the last whole row; and a file found ending mid-row when it is
//! continued (`--resume`) has that row dropped and reported ([`open_to_continue`]).

use std::io::{Read, Seek, SeekFrom, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use crate::RigError;

/// When an [`Appender`] asks the disk to keep what it wrote (`fsync`): rows reach the
/// file (and survive the process) at every write either way; syncing keeps them through a
/// power cut too.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sync {
    /// After every row (a sweep: a row every few seconds).
    EveryRow,
    /// At most once per this much wall time, and at the end ([`Appender::sync`]): a
    /// monitor logging up to 1,000 rows a second.
    Every(Duration),
}

/// An append-only CSV whose rows are whole or absent: each row is written with one call,
/// and a write that fails (a full disk) is cut back to the last whole row.
#[derive(Debug)]
pub struct Appender {
    file: std::fs::File,
    path: String,
    /// Bytes of whole rows in the file.
    len: u64,
    sync: Sync,
    synced: Instant,
}

impl Appender {
    /// Appends to `file` (opened for writing, positioned at its end), named `path` in
    /// messages.
    pub fn new(file: std::fs::File, path: String, sync: Sync) -> Result<Self, RigError> {
        let len = file
            .metadata()
            .map_err(|source| RigError::File {
                action: "read",
                path: path.clone(),
                source,
            })?
            .len();
        Ok(Self {
            file,
            path,
            len,
            sync,
            synced: Instant::now(),
        })
    }

    /// Bytes of whole rows in the file.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// Whether the file holds nothing.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Appends `text` (whole rows, each ending in a newline) in one write; on failure the
    /// file is cut back to its whole rows and the error names the file.
    pub fn write(&mut self, text: &str) -> Result<(), RigError> {
        let due = match self.sync {
            Sync::EveryRow => true,
            Sync::Every(period) => self.synced.elapsed() >= period,
        };
        let mut written = self.file.write_all(text.as_bytes());
        if due && written.is_ok() {
            written = self.file.sync_data();
            self.synced = Instant::now();
        }
        if let Err(source) = written {
            // No half row stays behind for `--resume` to keep or `explain` to refuse.
            let _ = self.file.set_len(self.len);
            let _ = self.file.sync_data();
            return Err(RigError::File {
                action: "write",
                path: self.path.clone(),
                source,
            });
        }
        self.len += text.len() as u64;
        Ok(())
    }

    /// Asks the disk to keep every row written so far.
    pub fn sync(&mut self) -> Result<(), RigError> {
        self.synced = Instant::now();
        self.file.sync_data().map_err(|source| RigError::File {
            action: "write",
            path: self.path.clone(),
            source,
        })
    }
}

/// Bytes at the end of `text` after its last newline: a row cut short (0 when it ends
/// whole).
pub fn half_row_len(text: &[u8]) -> usize {
    let whole = text.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    text.len() - whole
}

/// Bytes read from the end of a file to find its last whole row (a log may be large).
const TAIL_BYTES: u64 = 64 * 1024;

/// Bytes after the last newline of `path` (a row cut short), reading its end only; an
/// error of kind `InvalidData` when its last 64 KiB hold no line end (not a row file).
pub fn tail_half_row(path: &Path) -> std::io::Result<usize> {
    let mut f = std::fs::File::open(path)?;
    let len = f.metadata()?.len();
    let from = len.saturating_sub(TAIL_BYTES);
    f.seek(SeekFrom::Start(from))?;
    let mut tail = Vec::new();
    f.take(TAIL_BYTES).read_to_end(&mut tail)?;
    let half = half_row_len(&tail);
    if half == tail.len() && from > 0 {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            "no line end in its last 64 KiB: not a file of rows",
        ));
    }
    Ok(half)
}

/// Opens `path` to append, first cutting off a row cut short by a crash, a SIGKILL or a
/// full disk (so appended rows start on their own line and the file stays readable);
/// `said` gets the line that reports it. Returns the file, positioned at its end.
pub fn open_to_continue(
    path: &Path,
    said: &mut dyn FnMut(&str),
) -> Result<std::fs::File, RigError> {
    let name = path.display().to_string();
    let fail = |action, source| RigError::File {
        action,
        path: name.clone(),
        source,
    };
    let half = tail_half_row(path).map_err(|e| {
        if e.kind() == std::io::ErrorKind::InvalidData {
            RigError::BadValue {
                what: format!("--resume {name}"),
                why: format!("{e}; it was left unchanged"),
            }
        } else {
            fail("read", e)
        }
    })?;
    let file = std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .map_err(|e| fail("write", e))?;
    if half > 0 {
        let len = file.metadata().map_err(|e| fail("read", e))?.len();
        file.set_len(len - half as u64)
            .and_then(|()| file.sync_data())
            .map_err(|e| fail("write", e))?;
        said(&format!(
            "dropped an incomplete last row ({half} bytes, cut short by a crash or a full disk) from {name}"
        ));
    }
    Ok(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_half_row_is_dropped_and_reported_and_rows_append_whole() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.csv");
        std::fs::write(&path, "a,b\n1,2\n3,").unwrap();
        assert_eq!(half_row_len(b"a,b\n1,2\n3,"), 2);
        assert_eq!(half_row_len(b"a,b\n"), 0);
        let mut said = Vec::new();
        let file = open_to_continue(&path, &mut |l| said.push(l.to_owned())).unwrap();
        assert_eq!(said.len(), 1);
        assert!(said[0].contains("2 bytes"), "{said:?}");
        let mut out = Appender::new(file, "log.csv".into(), Sync::EveryRow).unwrap();
        assert_eq!(out.len(), 8);
        out.write("5,6\n").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "a,b\n1,2\n5,6\n");
        // A whole file is continued as it is, silently.
        let mut said = Vec::new();
        open_to_continue(&path, &mut |l| said.push(l.to_owned())).unwrap();
        assert!(said.is_empty());
    }

    /// A full disk (Linux's /dev/full): the failed row leaves nothing behind.
    #[cfg(target_os = "linux")]
    #[test]
    fn a_failed_write_names_the_file() {
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open("/dev/full")
            .unwrap();
        let mut out = Appender::new(file, "/dev/full".into(), Sync::EveryRow).unwrap();
        let e = out.write("1,2\n").unwrap_err().to_string();
        assert!(e.contains("/dev/full"), "{e}");
        assert_eq!(out.len(), 0);
    }
}
