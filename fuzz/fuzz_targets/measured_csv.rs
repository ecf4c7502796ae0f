//! Measured data for `rig explain` (`explain::Dataset::parse_csv`): arbitrary bytes as CSV,
//! read in arbitrary chunks. Parsing may never panic; accepted data has only finite values
//! and enough rows with a current, and written back as CSV it reads back the same.
#![no_main]

use std::io::Read;

use explain::Dataset;
use explain::data::MIN_ROWS;
use libfuzzer_sys::fuzz_target;

/// A reader that hands out at most `chunk` bytes per read, as a pipe or a slow disk does.
struct Chunked<'a> {
    data: &'a [u8],
    chunk: usize,
}

impl Read for Chunked<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.data.len().min(self.chunk).min(buf.len());
        buf[..n].copy_from_slice(&self.data[..n]);
        self.data = &self.data[n..];
        Ok(n)
    }
}

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, bytes)) = data.split_first() else {
        return;
    };
    let reader = Chunked {
        data: bytes,
        chunk: usize::from(chunk).max(1),
    };
    let Ok(ds) = Dataset::parse_csv(reader, "fuzz.csv") else {
        return;
    };
    assert!(ds.current_rows() >= MIN_ROWS);
    for r in ds.rows() {
        let values = [
            Some(r.omega_n),
            Some(r.tau_rot),
            r.i_in,
            r.t_s,
            r.v_in,
            r.temp_c,
        ];
        assert!(values.iter().flatten().all(|v| v.is_finite()), "{r:?}");
    }
    let mut csv = Vec::new();
    ds.write_csv(&mut csv).expect("accepted data writes as CSV");
    let again = Dataset::parse_csv(csv.as_slice(), "fuzz.csv").expect("written data reads back");
    assert_eq!(again, ds);
});
