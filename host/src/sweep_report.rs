//! The torque sweep's files: the CSV `rig explain` reads, and the figure (SVG via plotters)
//! in the paper's style: Fig. 8 (current against load per supply voltage) and Fig. 9 (cam
//! torque against load, with Eq. (10) at the mean cam speed).

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::RigError;
use sim::scenarios::sweep::SweepPoint;

const COLORS: [RGBColor; 6] = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];

fn span(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-6);
    (lo - pad, hi + pad)
}

/// One panel: axes over `x` and `y` with the load on the x axis.
fn panel<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    caption: &str,
    x: (f64, f64),
    y: (f64, f64),
    y_desc: &str,
) -> Result<ChartContext<'a, SVGBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>, String> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc("tau_rot, N m")
        .y_desc(y_desc)
        .draw()
        .map_err(|e| e.to_string())?;
    Ok(chart)
}

/// Draws Figs. 8 and 9 of the sweep side by side into the SVG `path`.
pub fn sweep_figure(path: &Path, points: &[SweepPoint]) -> Result<(), RigError> {
    let err = |e: String| RigError::Plot {
        path: path.display().to_string(),
        why: e,
    };
    let root = SVGBackend::new(path, (960, 400)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let (left, right) = root.split_horizontally(480);
    let mut voltages: Vec<f64> = points.iter().map(|p| p.v_in_v).collect();
    voltages.sort_by(f64::total_cmp);
    voltages.dedup();
    let (x0, x1) = span(points.iter().map(|p| p.tau_rot_nm));

    let mut chart = panel(
        &left,
        "current (Fig. 8)",
        (x0, x1),
        span(points.iter().map(|p| p.i_in_a)),
        "i_in, A",
    )
    .map_err(err)?;
    for (k, &v) in voltages.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.v_in_v == v)
                    .map(|p| Circle::new((p.tau_rot_nm, p.i_in_a), 3, color.filled())),
            )
            .map_err(|e| err(e.to_string()))?
            .label(format!("{v:.1} V"))
            .legend(move |(x, y)| Circle::new((x, y), 3, color.filled()));
    }
    chart
        .configure_series_labels()
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(e.to_string()))?;

    let nmm = |p: &SweepPoint| p.tau_cam_meas_nm * 1e3;
    let mut chart = panel(
        &right,
        "cam torque (Fig. 9): points measured, lines Eq. (10)",
        (x0, x1),
        span(
            points
                .iter()
                .flat_map(|p| [nmm(p), p.tau_cam_eq10_nm * 1e3]),
        ),
        "tau_cam, N mm",
    )
    .map_err(err)?;
    for (k, &v) in voltages.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| p.v_in_v == v)
                    .map(|p| Circle::new((p.tau_rot_nm, nmm(p)), 3, color.filled())),
            )
            .map_err(|e| err(e.to_string()))?;
        let mut line: Vec<(f64, f64)> = points
            .iter()
            .filter(|p| p.v_in_v == v)
            .map(|p| (p.tau_rot_nm, p.tau_cam_eq10_nm * 1e3))
            .collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(line, color.stroke_width(2)))
            .map_err(|e| err(e.to_string()))?;
    }
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
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
