//! Output-path safety for the verbs that write: an output that names one of the verb's
//! inputs (the same file, by any path) is refused before anything runs, so a measurement
//! is never overwritten by what was computed from it.

use std::path::Path;

use crate::RigError;

/// Whether `a` and `b` are the same file: equal paths, or (both existing) one file by
/// any path (links, `./`, `..`).
pub fn same_file(a: &Path, b: &Path) -> bool {
    if a == b {
        return true;
    }
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// Refuses any of `outputs` (option name, path) that is one of `inputs` (option name,
/// path), naming both options.
pub fn refuse_outputs_over_inputs(
    inputs: &[(&str, Option<&Path>)],
    outputs: &[(&str, Option<&Path>)],
) -> Result<(), RigError> {
    for (out_name, out) in outputs {
        let Some(out) = out else { continue };
        for (in_name, input) in inputs {
            let Some(input) = input else { continue };
            if same_file(out, input) {
                return Err(RigError::BadValue {
                    what: format!("{out_name} {}", out.display()),
                    why: format!(
                        "is the file {in_name} reads: writing it would destroy the input; give another file name (nothing was written)"
                    ),
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_over_an_input_is_refused_by_any_path() {
        let dir = tempfile::tempdir().unwrap();
        let data = dir.path().join("s.csv");
        std::fs::write(&data, "x").unwrap();
        let other = dir.path().join("m.toml");
        let via_dot = dir.path().join(".").join("s.csv");
        assert!(same_file(&data, &via_dot));
        assert!(!same_file(&data, &other));
        let e = refuse_outputs_over_inputs(
            &[("--measured", Some(&data))],
            &[("--propose", None), ("--write-model", Some(&via_dot))],
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("--write-model") && e.contains("--measured"),
            "{e}"
        );
        assert!(
            refuse_outputs_over_inputs(&[("--measured", Some(&data))], &[("--svg", Some(&other))])
                .is_ok()
        );
        assert_eq!(std::fs::read_to_string(&data).unwrap(), "x");
    }
}
