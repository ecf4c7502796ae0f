//! The torque sweep's files: the CSV `rig explain` reads, and the figure (SVG, drawn with
//! [`reporting::plot`]) in the paper's style: Fig. 8 (current against load per supply
//! voltage) and Fig. 9 (cam torque against load, with Eq. (10) at the mean cam speed).
//! Both are written atomically: a failed run keeps an existing file.

use std::path::Path;

use reporting::figure::FigureSize;
use reporting::plot::{self, Legend, PALETTE, Series, XyPanel};

use crate::RigError;
use crate::experiment::sweep::Row;

pub use crate::experiment::plan::{SWEEP_LOADS_NM, sweep_loads};

/// The supply voltages of the sweep, ascending.
fn voltages(points: &[Row]) -> Vec<f64> {
    let mut v: Vec<f64> = points.iter().filter_map(|p| p.v_in).collect();
    v.sort_by(f64::total_cmp);
    v.dedup();
    v
}

/// A point of a sweep: its drive (supply voltage or frequency) and load.
type PointKey = (Option<f64>, f64);

/// The current panel's caption from its points ((drive, load), current in A): it promises
/// bars of ±1 SD only when some point was measured more than once, so has them, and states
/// the largest (a bar shorter than its point's mark is hidden under it).
fn current_caption(points: impl Iterator<Item = (PointKey, Option<f64>)>) -> String {
    let mut groups: Vec<(PointKey, Vec<f64>)> = Vec::new();
    for (key, i) in points {
        let values = match groups.iter_mut().find(|g| g.0 == key) {
            Some(g) => &mut g.1,
            None => {
                groups.push((key, Vec::new()));
                &mut groups.last_mut().expect("just pushed").1
            }
        };
        values.extend(i.filter(|i| i.is_finite()));
    }
    let largest_sd = groups
        .iter()
        .filter(|g| g.1.len() > 1)
        .map(|(_, ys)| {
            let n = ys.len() as f64;
            let mean = ys.iter().sum::<f64>() / n;
            (ys.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
        })
        .reduce(f64::max);
    match largest_sd {
        Some(sd) => format!(
            "current (Fig. 8): mean, bars ±1 SD over repeats (largest {} mA)",
            reporting::human(reporting::significant(sd * 1e3, 2))
        ),
        None => "current (Fig. 8): one run per point".into(),
    }
}

/// The three panels of the sweep figure: Fig. 8's current and cam speed, and Fig. 9's cam
/// torque with Eq. (10) at the mean cam speed, per supply voltage; repeats as their means
/// with bars of ±1 standard deviation ([`plot::mean_with_spread`]).
pub fn sweep_panels(points: &[Row]) -> [XyPanel; 3] {
    let volts = voltages(points);
    let at = |v: f64| points.iter().filter(move |p| p.v_in == Some(v));
    let color = |k: usize| PALETTE[k % PALETTE.len()];
    let x = plot::span(points.iter().map(|p| p.tau_rot), 0.08, false);
    // A point without the value plotted (none in the simulator's sweep) is left out.
    let per_voltage = |f: &dyn Fn(&Row) -> Option<f64>, labelled: bool| -> Vec<Series> {
        volts
            .iter()
            .enumerate()
            .flat_map(|(k, &v)| {
                let pts: Vec<(f64, f64)> = at(v).filter_map(|p| Some((p.tau_rot, f(p)?))).collect();
                let mut s = plot::mean_with_spread(color(k), 3, format!("{v:.1} V"), &pts);
                if !labelled && let Some(last) = s.last_mut() {
                    last.label = None;
                }
                s
            })
            .collect()
    };
    let current = XyPanel {
        caption: Some(current_caption(
            points.iter().map(|p| ((p.v_in, p.tau_rot), p.i_in)),
        )),
        x_label: plot::axis_label("τ_rot", "N m"),
        y_label: plot::axis_label("i_in", "A"),
        series: per_voltage(&|p| p.i_in, true),
        x_range: Some(x),
        legend: Some(Legend::Below),
        fine_grid: true,
        ..XyPanel::default()
    };
    let speed = XyPanel {
        caption: Some("cam speed (Fig. 8)".into()),
        x_label: plot::axis_label("τ_rot", "N m"),
        y_label: plot::axis_label("ω_n", "rad/s"),
        series: per_voltage(&|p| Some(p.omega_n), false),
        x_range: Some(x),
        fine_grid: true,
        ..XyPanel::default()
    };
    let mut torque = per_voltage(&|p| p.tau_cam_meas.map(|t| t * 1e3), true);
    for (k, &v) in volts.iter().enumerate() {
        let eq10: Vec<(f64, f64)> = at(v)
            .filter_map(|p| Some((p.tau_rot, p.tau_cam_eq10? * 1e3)))
            .collect();
        // Eq. (10) at the mean cam speed of the repeats: the paper's model, as reference.
        let mean = plot::mean_with_spread(color(k), 0, "", &eq10)
            .pop()
            .map_or_else(Vec::new, |s| s.points);
        // In its voltage's colour, out of the legend (one entry would stand for every
        // line): the caption says the lines are Eq. (10).
        torque.push(Series::line(color(k), 2, mean));
    }
    // The runs whose output did not move (the paper's non-backdriven points, marked as
    // in its Figs. 8-9).
    let held: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.backdriven == Some(false))
        .filter_map(|p| Some((p.tau_rot, p.tau_cam_meas? * 1e3)))
        .collect();
    if !held.is_empty() {
        // Drawn first: the means stay visible on top.
        torque.insert(
            0,
            Series::points(PALETTE[5], 6, held).labelled("not backdriven"),
        );
    }
    let torque = XyPanel {
        caption: Some("cam torque (Fig. 9): points measured, lines Eq. (10)".into()),
        x_label: plot::axis_label("τ_rot", "N m"),
        y_label: plot::axis_label("τ_cam", "N mm"),
        series: torque,
        x_range: Some(x),
        legend: Some(Legend::Below),
        fine_grid: true,
        ..XyPanel::default()
    };
    [current, speed, torque]
}

/// Draws Fig. 8 (current and cam speed) and Fig. 9 of the sweep side by side into the SVG
/// `path`, atomically.
pub fn sweep_figure(path: &Path, points: &[Row], size: FigureSize) -> Result<(), RigError> {
    Ok(plot::columns_figure(
        path,
        size,
        (460, 400),
        None,
        &sweep_panels(points),
    )?)
}

/// Panels of a `rig experiment torque-sweep` CSV: the current (Fig. 8) and the cam speed
/// (Fig. 8's speed panel) against the load, per supply voltage (or frequency): the mean
/// over repeats as points, the spread (mean ± one standard deviation) as bars.
pub fn experiment_panels(rows: &[Row]) -> [XyPanel; 2] {
    let drive = |r: &Row| r.v_in.or(r.target_hz).unwrap_or(0.0);
    let unit = if rows.iter().any(|r| r.v_in.is_some()) {
        "V"
    } else {
        "Hz"
    };
    let mut drives: Vec<f64> = rows.iter().map(drive).collect();
    drives.sort_by(f64::total_cmp);
    drives.dedup();
    let x = plot::span(rows.iter().map(|r| r.tau_rot), 0.08, false);
    let panel = |caption: &str, y: &str, f: &dyn Fn(&Row) -> Option<f64>| {
        let mut series = Vec::new();
        for (k, &d) in drives.iter().enumerate() {
            let color = PALETTE[k % PALETTE.len()];
            let samples: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| drive(r) == d)
                .filter_map(|r| Some((r.tau_rot, f(r)?)))
                .collect();
            series.extend(plot::mean_with_spread(
                color,
                3,
                format!("{d:.1} {unit}"),
                &samples,
            ));
        }
        XyPanel {
            caption: Some(caption.into()),
            x_label: plot::axis_label("τ_rot", "N m"),
            y_label: y.into(),
            series,
            x_range: Some(x),
            legend: Some(Legend::Below),
            fine_grid: true,
            ..XyPanel::default()
        }
    };
    [
        panel(
            &current_caption(rows.iter().map(|r| ((Some(drive(r)), r.tau_rot), r.i_in))),
            &plot::axis_label("i_in", "A"),
            &|r| r.i_in,
        ),
        panel(
            "cam speed (Fig. 8)",
            &plot::axis_label("ω_n", "rad/s"),
            &|r| Some(r.omega_n),
        ),
    ]
}

/// Draws [`experiment_panels`] side by side into the SVG `path`, atomically.
pub fn experiment_figure(path: &Path, rows: &[Row], size: FigureSize) -> Result<(), RigError> {
    Ok(plot::columns_figure(
        path,
        size,
        (480, 400),
        None,
        &experiment_panels(rows),
    )?)
}

/// Writes the sweep points as CSV to `path` after the provenance `header` (`#` lines, each
/// ending in a newline: [`crate::provenance::simulated_header`]), atomically (a failed run
/// keeps an existing file).
pub fn write_csv(points: &[Row], path: &Path, header: &str) -> Result<(), RigError> {
    reporting::write_atomic_with(path, |tmp| {
        let file_error = |source| RigError::File {
            action: "write",
            path: path.display().to_string(),
            source,
        };
        let mut file = std::io::BufWriter::new(std::fs::File::create(tmp).map_err(file_error)?);
        std::io::Write::write_all(&mut file, header.as_bytes()).map_err(file_error)?;
        sim::scenarios::sweep::write_csv(points, file).map_err(|e| RigError::BadValue {
            what: path.display().to_string(),
            why: format!("cannot write the CSV: {e}"),
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(v: f64, load: f64) -> Row {
        Row {
            t_s: Some(0.0),
            v_in: Some(v),
            omega_n: 30.0 * v,
            tau_rot: load,
            i_in: Some(2.0 + 0.2 * load),
            temp_c: Some(25.0),
            repeat: Some(0),
            tau_cam_est: Some(0.01 * load),
            tau_cam_meas: Some(0.01 * load),
            tau_cam_eq10: Some(0.011 * load),
            backdriven: Some(true),
            ..Row::default()
        }
    }

    #[test]
    fn repeats_are_drawn_as_means_with_bars() {
        let mut points = Vec::new();
        for r in 0..3 {
            let mut p = point(3.6, 1.0);
            p.repeat = Some(r);
            p.i_in = Some(2.2 + 0.1 * f64::from(r));
            points.push(p);
        }
        let [current, ..] = sweep_panels(&points);
        // Currents 2.2, 2.3, 2.4 A: SD 0.1 A, stated in the caption.
        assert_eq!(
            current.caption.as_deref(),
            Some("current (Fig. 8): mean, bars ±1 SD over repeats (largest 100 mA)")
        );
        // A bar and the mean point.
        assert_eq!(current.series.len(), 2);
        let mean = &current.series[1].points;
        assert!((mean[0].1 - 2.3).abs() < 1e-12, "{mean:?}");
        let bar = &current.series[0].points;
        assert!(
            (bar[1].1 - bar[0].1 - 0.2).abs() < 1e-12,
            "+-1 sd of 0.1: {bar:?}"
        );
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
        let points: Vec<Row> = [3.6, 6.2, 8.8]
            .iter()
            .flat_map(|&v| [0.368, 1.84, 3.68].map(|l| point(v, l)))
            .collect();
        let [current, speed, torque] = sweep_panels(&points);
        assert_eq!(current.series.len(), 3);
        assert_eq!(speed.series.len(), 3);
        assert_eq!(torque.series.len(), 6);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sweep.svg");
        sweep_figure(&path, &points, FigureSize::Single).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        // The texts as written (subscripts after `_`; the SVG sets them lowered).
        let texts = reporting::check::figure_texts(&svg).join("\n");
        for want in [
            "Fig. 8",
            "Fig. 9",
            "3.6 V",
            "8.8 V",
            "τ_cam, N mm",
            "i_in, A",
            "cam speed",
            "(a)",
            "(c)",
        ] {
            assert!(texts.contains(want), "missing {want}");
        }
        // One run per point: no bars, and the caption promises none; symbols as printed.
        assert!(svg.contains("one run per point") && !svg.contains("bars"));
        for ascii in ["tau_", "w_n", "+-", "["] {
            assert!(!texts.contains(ascii), "{ascii} in the figure");
        }
        assert_eq!(reporting::check::check_svg(&svg, 3.5), vec![]);
        // The lines of Eq. (10), one per voltage in its colour, are named by the caption,
        // not by one legend entry standing for all three.
        assert!(torque.caption.unwrap().contains("lines Eq. (10)"));
        assert!(
            torque
                .series
                .iter()
                .all(|s| s.mark == plot::Mark::Points(3) || s.label.is_none())
        );
    }
}
