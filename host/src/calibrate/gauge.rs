//! Gauge readings from a CSV file, for `rig calibrate --gauge-csv`.

use super::Plan;
use crate::RigError;

/// Gauge readings from a CSV file: a `gauge_nmm` column (torque, N mm), one row per torque
/// step in order; an optional `volts` column is checked against the plan.
pub fn read_gauge_csv(path: &std::path::Path, plan: &Plan) -> Result<Vec<f64>, RigError> {
    let name = path.display().to_string();
    let bad = |why: String| RigError::MeasuredFile {
        file: name.clone(),
        why,
    };
    let mut r = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_path(path)
        .map_err(|e| bad(format!("cannot read it ({e})")))?;
    let headers = r
        .headers()
        .map_err(|e| bad(format!("no header row ({e})")))?
        .clone();
    let col = |name: &str| headers.iter().position(|h| h.eq_ignore_ascii_case(name));
    let gauge = col("gauge_nmm").ok_or_else(|| {
        bad(format!(
            "no gauge_nmm column (found: {}); give one gauge torque in N mm per torque step",
            headers.iter().collect::<Vec<_>>().join(", ")
        ))
    })?;
    let volts = col("volts");
    let mut out = Vec::new();
    for (k, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| bad(format!("row {}: {e}", k + 1)))?;
        let field = rec.get(gauge).unwrap_or("");
        let v: f64 = field
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| {
                bad(format!(
                    "row {}: gauge_nmm '{field}' is not a number",
                    k + 1
                ))
            })?;
        if let (Some(c), Some(&planned)) = (volts, plan.torque_volts.get(k)) {
            let given: Option<f64> = rec.get(c).and_then(|s| s.parse().ok());
            if given.is_some_and(|g| (g - planned).abs() > 0.011) {
                return Err(bad(format!(
                    "row {}: volts {} but step {} of the procedure drives {planned:.2} V",
                    k + 1,
                    rec.get(c).unwrap_or(""),
                    k + 1
                )));
            }
        }
        out.push(v);
    }
    if out.len() != plan.torque_volts.len() {
        return Err(bad(format!(
            "{} gauge readings for {} torque steps ({} V); give one row per step",
            out.len(),
            plan.torque_volts.len(),
            plan.torque_volts
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauge_csv_is_checked_against_the_plan() {
        let plan = Plan::default();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.csv");
        let mut text = String::from("volts,gauge_nmm\n");
        for (k, v) in plan.torque_volts.iter().enumerate() {
            text.push_str(&format!("{v:.2},{}\n", 10.0 * k as f64));
        }
        std::fs::write(&path, &text).unwrap();
        assert_eq!(read_gauge_csv(&path, &plan).unwrap().len(), 9);
        std::fs::write(&path, "gauge_nmm\n1\n2\n").unwrap();
        let e = read_gauge_csv(&path, &plan).unwrap_err().to_string();
        assert!(e.contains("2 gauge readings for 9 torque steps"), "{e}");
        std::fs::write(&path, "torque\n1\n").unwrap();
        let e = read_gauge_csv(&path, &plan).unwrap_err().to_string();
        assert!(e.contains("no gauge_nmm column"), "{e}");
        std::fs::write(&path, "gauge_nmm\nabc\n").unwrap();
        let e = read_gauge_csv(&path, &plan).unwrap_err().to_string();
        assert!(e.contains("row 1"), "{e}");
    }
}
