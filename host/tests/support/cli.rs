//! What the CLI tests read back from the `rig` binary: a successful run's JSON, and a sweep
//! CSV's data rows.
#![allow(dead_code)]

use std::borrow::BorrowMut;
use std::path::Path;

use assert_cmd::Command;
use serde_json::Value;

/// The standard output of `c`, which must succeed.
pub fn stdout_of(mut c: impl BorrowMut<Command>) -> String {
    let out = c
        .borrow_mut()
        .assert()
        .success()
        .get_output()
        .stdout
        .clone();
    String::from_utf8(out).expect("stdout is UTF-8")
}

/// The JSON `c` prints on success.
pub fn json_of(c: impl BorrowMut<Command>) -> Value {
    let text = stdout_of(c);
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("not JSON ({e}):\n{text}"))
}

/// The data rows of a sweep CSV (no provenance `#` lines, no header), as text.
pub fn data_rows(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("point,") && !l.is_empty())
        .map(str::to_string)
        .collect()
}
