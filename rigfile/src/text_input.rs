//! One bounded reader for every text file the tools read (rig files, plans, measured and
//! calibration CSVs): only regular files (a FIFO or a device would block or never end),
//! at most a stated size, and no line longer than [`MAX_LINE_BYTES`] (a file without line
//! ends is refused after a bounded read). Every refusal says what was found and what to
//! give; the caller names the file.

use std::io::Read;
use std::path::Path;

/// Longest line of any text input, bytes: a header of every column the tools write is
/// about 100 bytes, so a longer line is not a table (a file without line ends, `/dev/zero`,
/// a sparse file); reading stops there instead of buffering it whole.
pub const MAX_LINE_BYTES: usize = 64 * 1024;
/// Largest table (a sweep or calibration CSV) read whole, bytes: a plan's 100,000 runs at
/// about 100 bytes a row is 10 MB.
pub const MAX_TABLE_BYTES: u64 = 64 << 20;
/// Largest plan file, bytes (10,000 points of a few lines each).
pub const MAX_PLAN_BYTES: u64 = 4 << 20;

/// Why `path` is not a regular file, or `None` when it is one (or does not exist: opening
/// it then says so). A FIFO or a device would block or never end.
pub fn not_a_regular_file(path: &Path) -> Option<String> {
    let meta = std::fs::metadata(path).ok()?;
    (!meta.is_file()).then(|| {
        format!(
            "is not a regular file ({}): save it to a file first",
            if meta.is_dir() {
                "a folder"
            } else {
                "a pipe, socket or device"
            }
        )
    })
}

/// The text of regular file `path` of at most `max_bytes` bytes with lines of at most
/// [`MAX_LINE_BYTES`]; `what` says what a line should be (`"a plan file (TOML)"`). `Err`
/// is the reason, for the caller to put after the file's name.
pub fn read_text(path: &Path, max_bytes: u64, what: &'static str) -> Result<String, String> {
    if let Some(why) = not_a_regular_file(path) {
        return Err(why);
    }
    let file = std::fs::File::open(path).map_err(|e| format!("cannot read it ({e})"))?;
    if let Ok(meta) = file.metadata()
        && meta.len() > max_bytes
    {
        return Err(too_big(meta.len(), max_bytes, what));
    }
    // The read stays bounded too (a file can grow, or its size be unknown).
    let mut bytes = Vec::new();
    LineBounded::new(file.take(max_bytes + 1), what)
        .read_to_end(&mut bytes)
        .map_err(|e| {
            if e.kind() == std::io::ErrorKind::InvalidData {
                e.to_string()
            } else {
                format!("cannot read it ({e})")
            }
        })?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_big(bytes.len() as u64, max_bytes, what));
    }
    String::from_utf8(bytes).map_err(|e| {
        format!(
            "is not UTF-8 text (byte {}): give {what}",
            e.utf8_error().valid_up_to()
        )
    })
}

fn too_big(len: u64, max: u64, what: &str) -> String {
    format!(
        "is {len} bytes or more, more than the {} KiB {what} can need",
        max / 1024
    )
}

/// A reader that fails once a line grows beyond [`MAX_LINE_BYTES`], so a file without line
/// ends is refused after a bounded read (a CSV reader would otherwise buffer the line
/// whole).
pub struct LineBounded<R> {
    inner: R,
    since_newline: usize,
    line: u64,
    limit: usize,
    what: &'static str,
    /// The line found too long: every later read fails with it too.
    refused: Option<u64>,
}

impl<R> LineBounded<R> {
    /// `inner` with lines of at most [`MAX_LINE_BYTES`]; `what` says what the text should
    /// be, for the refusal (`"a CSV table of test points"`).
    pub fn new(inner: R, what: &'static str) -> Self {
        Self {
            inner,
            since_newline: 0,
            line: 0,
            limit: MAX_LINE_BYTES,
            what,
            refused: None,
        }
    }

    /// Line ends read so far.
    pub fn lines_read(&self) -> u64 {
        self.line
    }

    /// The refusal of line `line`.
    fn too_long(&self, line: u64) -> std::io::Error {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!(
                "line {line} is longer than {} KiB: not {} (a file without line ends?); reading stopped there",
                self.limit / 1024,
                self.what
            ),
        )
    }
}

impl<R: Read> Read for LineBounded<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if let Some(line) = self.refused {
            return Err(self.too_long(line));
        }
        let n = self.inner.read(buf)?;
        // Every line of the chunk is measured, not only its last: how the reads fall must
        // not decide which lines pass.
        let mut run = self.since_newline;
        let mut too_long = None;
        let mut start = 0;
        for end in memchr::memchr_iter(b'\n', &buf[..n]) {
            self.line += 1;
            if run + end - start > self.limit && too_long.is_none() {
                too_long = Some(self.line);
            }
            run = 0;
            start = end + 1;
        }
        run += n - start;
        if run > self.limit && too_long.is_none() {
            too_long = Some(self.line + 1);
        }
        self.since_newline = run;
        if let Some(line) = too_long {
            self.refused = Some(line);
            return Err(self.too_long(line));
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_fifos_long_lines_and_big_files_are_refused() {
        let e = read_text(Path::new("/dev/zero"), 1 << 20, "a plan file").unwrap_err();
        assert!(e.contains("a pipe, socket or device"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        let long = dir.path().join("long");
        std::fs::write(&long, vec![b'x'; MAX_LINE_BYTES + 10]).unwrap();
        let e = read_text(&long, 1 << 20, "a plan file").unwrap_err();
        assert!(
            e.starts_with("line 1 is longer than 64 KiB: not a plan file"),
            "{e}"
        );
        let big = dir.path().join("big");
        std::fs::write(&big, "a\n".repeat(1000)).unwrap();
        let e = read_text(&big, 1000, "a plan file").unwrap_err();
        assert!(e.contains("2000 bytes or more, more than the 0 KiB"), "{e}");
        assert_eq!(read_text(&big, 2000, "x").unwrap().len(), 2000);
        let e = read_text(dir.path(), 10, "x").unwrap_err();
        assert!(e.contains("a folder"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_is_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if !made.is_ok_and(|s| s.success()) {
            eprintln!("skipped: no mkfifo");
            return;
        }
        let e = read_text(&fifo, 1 << 20, "x").unwrap_err();
        assert!(e.contains("a pipe, socket or device"), "{e}");
    }
}
