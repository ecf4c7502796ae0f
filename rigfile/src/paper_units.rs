//! C1-C6 in the paper's units (Table 2: C1 N mm/A, C2 N mm, C3 N mm s/rad, C4 N mm,
//! C5 A s/rad, C6 A) at the edges, [`model::Calibration`] (SI) inside: the conversions and a
//! serde `with` module that writes a `model::Calibration` as the keys `c1`..`c6` in the
//! paper's units, so files and reports read straight against Table 2 without a struct of
//! their own.

use serde::ser::SerializeMap;
use serde::{Serialize, Serializer};

/// The key names, C1 first.
pub const KEYS: [&str; 6] = ["c1", "c2", "c3", "c4", "c5", "c6"];

/// Units of C1..C6 as in Table 2.
pub const UNITS: [&str; 6] = ["N mm/A", "N mm", "N mm s/rad", "N mm", "A s/rad", "A"];

/// `v` with 15 significant digits: the unit conversion's last-bit noise removed, so
/// 62.1 N mm/A stored as 0.0621 N m/A reads back as 62.1, not 62.10000000000001.
pub fn tidy(v: f64) -> f64 {
    if !v.is_finite() || v == 0.0 {
        return v;
    }
    format!("{v:.14e}").parse().unwrap_or(v)
}

/// C1..C6 of `c` in the paper's units.
pub fn to_paper(c: &model::Calibration) -> [f64; 6] {
    c.to_paper_units().map(tidy)
}

/// A calibration from C1..C6 in the paper's units.
pub fn from_paper(c: [f64; 6]) -> model::Calibration {
    model::Calibration::from_paper_units(c)
}

/// Table 2 in the paper's units.
pub fn table2() -> [f64; 6] {
    to_paper(&model::Calibration::PAPER)
}

/// Serialises a [`model::Calibration`] as the map `c1`..`c6` in the paper's units; for
/// `#[serde(flatten, serialize_with = "rigfile::paper_units::serialize")]`.
pub fn serialize<S: Serializer>(c: &model::Calibration, s: S) -> Result<S::Ok, S::Error> {
    let mut map = s.serialize_map(Some(6))?;
    for (k, v) in KEYS.iter().zip(to_paper(c)) {
        map.serialize_entry(k, &v)?;
    }
    map.end()
}

/// A [`model::Calibration`] that serialises as `c1`..`c6` in the paper's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaperUnits<'a>(pub &'a model::Calibration);

impl Serialize for PaperUnits<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        serialize(self.0, s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table2_reads_as_printed() {
        assert_eq!(table2(), [62.1, -138.0, 0.235, 1.69, 0.00378, 2.25]);
        for c in [62.1, -138.0, 0.235, 1.69, 1e-9, 123.456789012345] {
            let back = to_paper(&from_paper([c, c, c, c, c, c]));
            assert!(back.iter().all(|&b| b == c), "{c}: {back:?}");
        }
        let json = serde_json_like(&model::Calibration::PAPER);
        assert_eq!(
            json,
            "c1 = 62.1\nc2 = -138.0\nc3 = 0.235\nc4 = 1.69\nc5 = 0.00378\nc6 = 2.25\n"
        );
    }

    fn serde_json_like(c: &model::Calibration) -> String {
        toml::to_string(&PaperUnits(c)).unwrap()
    }
}
