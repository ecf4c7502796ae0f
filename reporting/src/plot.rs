//! Residual plots of the report (SVG via plotters): measured minus model current against cam
//! speed, load and temperature or time, one panel each.

use std::path::Path;

use plotters::prelude::*;

use crate::ReportError;

/// Most points drawn per panel; larger data is thinned evenly (the statistics use every row).
const MAX_POINTS: usize = 4000;

/// One panel: residuals (mA) against one test condition.
#[derive(Debug, Clone)]
pub struct Panel {
    /// Axis label of the condition.
    pub x_label: String,
    /// The condition per row.
    pub x: Vec<f64>,
    /// Residual per row, mA.
    pub residual_ma: Vec<f64>,
}

fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-6 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

/// Draws `panels` side by side under `title` into the SVG file `path`, all with the same
/// residual axis of +-`y_max_ma`.
pub fn residual_figure(
    path: &Path,
    title: &str,
    panels: &[Panel],
    y_max_ma: f64,
) -> Result<(), ReportError> {
    let err = |e: String| ReportError::Plot {
        path: path.display().to_string(),
        why: e,
    };
    let width = 380 * panels.len().max(1) as u32;
    let root = SVGBackend::new(path, (width, 360)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
    let root = root
        .titled(title, ("sans-serif", 18))
        .map_err(|e| err(e.to_string()))?;
    let areas = root.split_evenly((1, panels.len().max(1)));
    let y = y_max_ma.max(1.0);
    for (area, p) in areas.iter().zip(panels) {
        let (x0, x1) = range(p.x.iter().copied());
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(55)
            .build_cartesian_2d(x0..x1, -y..y)
            .map_err(|e| err(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc(p.x_label.as_str())
            .y_desc("measured - model, mA")
            .light_line_style(WHITE)
            .draw()
            .map_err(|e| err(e.to_string()))?;
        chart
            .draw_series(LineSeries::new(
                [(x0, 0.0), (x1, 0.0)],
                BLACK.stroke_width(1),
            ))
            .map_err(|e| err(e.to_string()))?;
        let stride = p.x.len().div_ceil(MAX_POINTS).max(1);
        chart
            .draw_series(
                p.x.iter()
                    .zip(&p.residual_ma)
                    .step_by(stride)
                    .map(|(&x, &r)| Circle::new((x, r.clamp(-y, y)), 2, BLUE.mix(0.6).filled())),
            )
            .map_err(|e| err(e.to_string()))?;
    }
    root.present().map_err(|e| err(e.to_string()))?;
    Ok(())
}
