//! The torque sweep's files: the CSV `rig explain` reads, and the figure (SVG, drawn with
//! [`reporting::plot`]) in the paper's style: Fig. 8 (current against load per supply
//! voltage) and Fig. 9 (cam torque against load, with Eq. (10) at the mean cam speed).
//! Both are written atomically: a failed run keeps an existing file.

use std::path::Path;

use reporting::plot::{self, Legend, PALETTE, Series, XyPanel};

use crate::RigError;
use sim::scenarios::sweep::SweepPoint;

pub use crate::experiment::plan::{SWEEP_LOADS_NM, sweep_loads};

/// The supply voltages of the sweep, ascending.
fn voltages(points: &[SweepPoint]) -> Vec<f64> {
    let mut v: Vec<f64> = points.iter().map(|p| p.v_in_v).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// The two panels of the sweep figure: Fig. 8 and Fig. 9.
pub fn sweep_panels(points: &[SweepPoint]) -> [XyPanel; 2] {
    let volts = voltages(points);
    let at = |v: f64| points.iter().filter(move |p| p.v_in_v == v);
    let color = |k: usize| PALETTE[k % PALETTE.len()];
    let x = plot::span(points.iter().map(|p| p.tau_rot_nm), 0.08, false);
    let current = XyPanel {
        caption: Some("current (Fig. 8)".into()),
        x_label: "tau_rot, N m".into(),
        y_label: "i_in, A".into(),
        series: volts
            .iter()
            .enumerate()
            .map(|(k, &v)| {
                let pts = at(v).map(|p| (p.tau_rot_nm, p.i_in_a)).collect();
                Series::points(color(k), 3, pts).labelled(format!("{v:.1} V"))
            })
            .collect(),
        x_range: Some(x),
        legend: Some(Legend::MiddleRight),
        fine_grid: true,
        ..XyPanel::default()
    };
    let mut torque = Vec::new();
    for (k, &v) in volts.iter().enumerate() {
        let measured = at(v)
            .map(|p| (p.tau_rot_nm, p.tau_cam_meas_nm * 1e3))
            .collect();
        torque.push(Series::points(color(k), 3, measured));
        let eq10 = at(v)
            .map(|p| (p.tau_rot_nm, p.tau_cam_eq10_nm * 1e3))
            .collect();
        torque.push(Series::line(color(k), 2, eq10));
    }
    let torque = XyPanel {
        caption: Some("cam torque (Fig. 9): points measured, lines Eq. (10)".into()),
        x_label: "tau_rot, N m".into(),
        y_label: "tau_cam, N mm".into(),
        series: torque,
        x_range: Some(x),
        fine_grid: true,
        ..XyPanel::default()
    };
    [current, torque]
}

/// Draws Figs. 8 and 9 of the sweep side by side into the SVG `path`, atomically.
pub fn sweep_figure(path: &Path, points: &[SweepPoint]) -> Result<(), RigError> {
    Ok(plot::columns_figure(
        path,
        (480, 400),
        None,
        &sweep_panels(points),
    )?)
}

/// Mean and standard deviation (0 for one value) of `values`.
fn mean_sd(values: &[f64]) -> (f64, f64) {
    let n = values.len().max(1) as f64;
    let mean = values.iter().sum::<f64>() / n;
    let var = if values.len() > 1 {
        values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (mean, var.sqrt())
}

/// Panels of a `rig experiment torque-sweep` CSV: the current (Fig. 8) and the cam speed
/// (Fig. 8's speed panel) against the load, per supply voltage (or frequency): the mean
/// over repeats as points, the spread (mean +- one standard deviation) as bars.
pub fn experiment_panels(rows: &[crate::experiment::sweep::Row]) -> [XyPanel; 2] {
    let drive = |r: &crate::experiment::sweep::Row| r.v_in_v.or(r.target_hz).unwrap_or(0.0);
    let unit = if rows.iter().any(|r| r.v_in_v.is_some()) {
        "V"
    } else {
        "Hz"
    };
    let mut drives: Vec<f64> = rows.iter().map(drive).collect();
    drives.sort_by(f64::total_cmp);
    drives.dedup();
    let x = plot::span(rows.iter().map(|r| r.tau_rot_nm), 0.08, false);
    let panel = |caption: &str, y: &str, f: &dyn Fn(&crate::experiment::sweep::Row) -> f64| {
        let mut series = Vec::new();
        for (k, &d) in drives.iter().enumerate() {
            let color = PALETTE[k % PALETTE.len()];
            let mut loads: Vec<f64> = rows
                .iter()
                .filter(|r| drive(r) == d)
                .map(|r| r.tau_rot_nm)
                .collect();
            loads.sort_by(f64::total_cmp);
            loads.dedup();
            let mut means = Vec::new();
            for &l in &loads {
                let vals: Vec<f64> = rows
                    .iter()
                    .filter(|r| drive(r) == d && r.tau_rot_nm == l)
                    .map(f)
                    .collect();
                let (m, sd) = mean_sd(&vals);
                means.push((l, m));
                if sd > 0.0 {
                    series.push(Series::line(color, 1, vec![(l, m - sd), (l, m + sd)]));
                }
            }
            series.push(Series::points(color, 3, means).labelled(format!("{d:.1} {unit}")));
        }
        XyPanel {
            caption: Some(caption.into()),
            x_label: "tau_rot, N m".into(),
            y_label: y.into(),
            series,
            x_range: Some(x),
            legend: Some(Legend::MiddleRight),
            fine_grid: true,
            ..XyPanel::default()
        }
    };
    [
        panel(
            "current (Fig. 8): mean, bars +-1 sd over repeats",
            "i_in, A",
            &|r| r.i_in_a,
        ),
        panel("cam speed (Fig. 8)", "w_n, rad/s", &|r| r.omega_n_rad_s),
    ]
}

/// Draws [`experiment_panels`] side by side into the SVG `path`, atomically.
pub fn experiment_figure(
    path: &Path,
    rows: &[crate::experiment::sweep::Row],
) -> Result<(), RigError> {
    Ok(plot::columns_figure(
        path,
        (480, 400),
        None,
        &experiment_panels(rows),
    )?)
}

/// Writes the sweep points as CSV to `path`, atomically (a failed run keeps an existing file).
pub fn write_csv(points: &[SweepPoint], path: &Path) -> Result<(), RigError> {
    reporting::write_atomic_with(path, |tmp| {
        let file = std::fs::File::create(tmp).map_err(|source| RigError::File {
            action: "write",
            path: path.display().to_string(),
            source,
        })?;
        sim::scenarios::sweep::write_csv(points, std::io::BufWriter::new(file)).map_err(|e| {
            RigError::BadValue {
                what: path.display().to_string(),
                why: format!("cannot write the CSV: {e}"),
            }
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(v: f64, load: f64) -> SweepPoint {
        SweepPoint {
            t_s: 0.0,
            v_in_v: v,
            omega_n_rad_s: 30.0 * v,
            tau_rot_nm: load,
            i_in_a: 2.0 + 0.2 * load,
            temp_c: 25.0,
            repeat: 0,
            tau_cam_est_nm: 0.01 * load,
            tau_cam_meas_nm: 0.01 * load,
            tau_cam_eq10_nm: 0.011 * load,
            backdriven: 1,
        }
    }

    #[test]
    fn loads_are_as_written() {
        let loads = sweep_loads(10);
        assert_eq!(loads.len(), 10);
        assert_eq!(loads[0].to_string(), "0.368");
        assert_eq!(loads[2].to_string(), "1.104");
        assert_eq!(loads[9].to_string(), "3.68");
        assert_eq!(sweep_loads(3), [0.368, 2.024, 3.68]);
    }

    #[test]
    fn figure_has_both_panels_and_every_voltage() {
        let points: Vec<SweepPoint> = [3.6, 6.2, 8.8]
            .iter()
            .flat_map(|&v| [0.368, 1.84, 3.68].map(|l| point(v, l)))
            .collect();
        let [current, torque] = sweep_panels(&points);
        assert_eq!(current.series.len(), 3);
        assert_eq!(torque.series.len(), 6);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sweep.svg");
        sweep_figure(&path, &points).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        for want in ["Fig. 8", "Fig. 9", "3.6 V", "8.8 V", "tau_cam, N mm"] {
            assert!(svg.contains(want), "missing {want}");
        }
    }
}
