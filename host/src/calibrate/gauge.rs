//! Gauge readings: typed at the prompt (a torque, or a force and its arm), from a CSV file
//! (`rig calibrate --gauge-csv`), and the measured points read back (`--from-points`).

use super::{CalibrationSchedule, Measurements, StepMeasurement, TorquePoint};
use crate::RigError;

/// What the gauge shows (`rig calibrate --gauge torque|force`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GaugeUnit {
    /// A torque gauge: readings in N mm.
    Torque,
    /// A force gauge on an arm: readings in N, times the arm length (`--arm-m`, or given
    /// with each reading as `F N @ L m`).
    Force {
        /// The arm from the shaft's axis to the gauge, m.
        arm_m: Option<f64>,
    },
}

/// A number with an optional unit word after it (`12.5`, `12.5 N`, `75 mm`).
fn quantity(text: &str) -> Option<(f64, String)> {
    let t = text.trim();
    let split = t
        .find(|c: char| c.is_ascii_alphabetic() || c == ' ')
        .unwrap_or(t.len());
    let v: f64 = t[..split].trim().parse().ok()?;
    let unit: String = t[split..].chars().filter(|c| !c.is_whitespace()).collect();
    v.is_finite().then_some((v, unit.to_ascii_lowercase()))
}

/// One typed gauge reading as a torque, N mm: `37.5` (N mm with a torque gauge; N with a
/// force gauge and `--arm-m`), `37.5 N mm`, or a force and its arm, `12.5 N @ 0.075 m`
/// (also `@ 75 mm`), whatever the gauge. The error says what to type.
pub fn parse_reading(text: &str, unit: GaugeUnit) -> Result<f64, String> {
    let bad = |why: &str| format!("'{}' {why}", text.trim());
    if let Some((force, arm)) = text.split_once('@') {
        let (f, fu) = quantity(force)
            .ok_or_else(|| bad("is not a force and an arm: type e.g. 12.5 N @ 0.075 m"))?;
        if !(fu.is_empty() || fu == "n") {
            return Err(bad(
                "gives the force in another unit than N: e.g. 12.5 N @ 0.075 m",
            ));
        }
        let (l, lu) =
            quantity(arm).ok_or_else(|| bad("has no arm length after @: e.g. 12.5 N @ 0.075 m"))?;
        let arm_m = match lu.as_str() {
            "" | "m" => l,
            "mm" => l / 1000.0,
            _ => return Err(bad("gives the arm in another unit than m or mm")),
        };
        if arm_m <= 0.0 {
            return Err(bad("gives an arm that is not positive"));
        }
        return Ok(f * arm_m * 1000.0);
    }
    let (v, u) = quantity(text).ok_or_else(|| match unit {
        GaugeUnit::Torque => bad("is not a number: type the torque in N mm, e.g. 37.5 (or a force and its arm, 12.5 N @ 0.075 m; r redoes the step)"),
        GaugeUnit::Force { .. } => bad("is not a number: type the force in N, e.g. 12.5 (or 12.5 N @ 0.075 m; r redoes the step)"),
    })?;
    match (u.as_str(), unit) {
        ("nmm", _) | ("", GaugeUnit::Torque) => Ok(v),
        ("n" | "", GaugeUnit::Force { arm_m: Some(l) }) => Ok(v * l * 1000.0),
        ("n" | "", _) => Err(bad(
            "is a force without its arm: type 12.5 N @ 0.075 m, or give --arm-m",
        )),
        _ => Err(bad(
            "has an unknown unit: N mm for a torque, N @ m for a force",
        )),
    }
}

/// A CSV file of the operator's (fields trimmed, `#` comments skipped) and its header row;
/// `bad` turns a reason into the file's error.
fn open_csv(
    path: &std::path::Path,
    bad: &dyn Fn(String) -> RigError,
) -> Result<(csv::Reader<std::io::Cursor<String>>, csv::StringRecord), RigError> {
    // Bounded: a FIFO, a device or a file without line ends is refused, not read forever.
    let text =
        rigfile::text_input::read_text(path, rigfile::text_input::MAX_TABLE_BYTES, "a CSV table")
            .map_err(bad)?;
    let mut r = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(std::io::Cursor::new(text));
    let headers = r
        .headers()
        .map_err(|e| bad(format!("no header row ({e})")))?
        .clone();
    Ok((r, headers))
}

/// The points `rig calibrate` wrote (`points.csv`: `test, volts, current_a, current_sd_a,
/// cam_speed_rad_s, gauge_nmm`), for `--from-points`.
pub fn read_points_csv(path: &std::path::Path) -> Result<Measurements, RigError> {
    let name = path.display().to_string();
    let bad = |why: String| RigError::MeasuredFile {
        file: name.clone(),
        why,
    };
    let (mut r, headers) = open_csv(path, &bad)?;
    let want = [
        "test",
        "volts",
        "current_a",
        "current_sd_a",
        "cam_speed_rad_s",
        "gauge_nmm",
    ];
    let mut cols = [0usize; 6];
    for (k, w) in want.iter().enumerate() {
        cols[k] = headers.iter().position(|h| h == *w).ok_or_else(|| {
            bad(format!(
                "no {w} column: give the points.csv `rig calibrate` wrote ({})",
                want.join(", ")
            ))
        })?;
    }
    let mut m = Measurements::default();
    for (k, rec) in r.records().enumerate() {
        let rec = rec.map_err(|e| bad(format!("row {}: {e}", k + 1)))?;
        let num = |c: usize| -> Result<f64, RigError> {
            let field = rec.get(cols[c]).unwrap_or("");
            field
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(format!(
                        "row {}: {} '{field}' is not a number",
                        k + 1,
                        want[c]
                    ))
                })
        };
        let step = StepMeasurement {
            volts: num(1)?,
            current_a: num(2)?,
            current_sd_a: num(3)?,
            cam_speed_rad_s: num(4)?,
            samples: 0,
        };
        match rec.get(cols[0]).unwrap_or("") {
            "no_load" => m.no_load.push(step),
            "torque" => m.torque.push(TorquePoint {
                step,
                gauge_nmm: num(5)?,
            }),
            other => {
                return Err(bad(format!(
                    "row {}: test '{other}' is neither no_load nor torque",
                    k + 1
                )));
            }
        }
    }
    Ok(m)
}

/// Gauge readings from a CSV file: a `gauge_nmm` column (torque, N mm), one row per torque
/// step in order; an optional `volts` column is checked against the plan.
pub fn read_gauge_csv(
    path: &std::path::Path,
    plan: &CalibrationSchedule,
) -> Result<Vec<f64>, RigError> {
    let name = path.display().to_string();
    let bad = |why: String| RigError::MeasuredFile {
        file: name.clone(),
        why,
    };
    let (mut r, headers) = open_csv(path, &bad)?;
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
    fn readings_as_torque_force_and_arm() {
        let torque = GaugeUnit::Torque;
        assert_eq!(parse_reading("37.5", torque), Ok(37.5));
        assert_eq!(parse_reading(" 37.5 N mm ", torque), Ok(37.5));
        let t = parse_reading("12.5 N @ 0.075 m", torque).unwrap();
        assert!((t - 937.5).abs() < 1e-9, "{t}");
        let t = parse_reading("12.5@75 mm", torque).unwrap();
        assert!((t - 937.5).abs() < 1e-9, "{t}");
        let force = GaugeUnit::Force { arm_m: Some(0.1) };
        assert!((parse_reading("2", force).unwrap() - 200.0).abs() < 1e-9);
        assert!((parse_reading("2 N", force).unwrap() - 200.0).abs() < 1e-9);
        let e = parse_reading("2 N", torque).unwrap_err();
        assert!(e.contains("without its arm"), "{e}");
        let e = parse_reading("2", GaugeUnit::Force { arm_m: None }).unwrap_err();
        assert!(e.contains("--arm-m"), "{e}");
        let e = parse_reading("abc", torque).unwrap_err();
        assert!(e.contains("not a number") && e.contains("N mm"), "{e}");
        let e = parse_reading("2 kg @ 1 m", torque).unwrap_err();
        assert!(e.contains("another unit"), "{e}");
    }

    #[test]
    fn gauge_csv_is_checked_against_the_plan() {
        let plan = CalibrationSchedule::default();
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
