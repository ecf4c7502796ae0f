//! SVG plots of the two calibration fits: measured points, the fitted line and its residuals.

use std::path::Path;

use plotters::prelude::*;

use super::fit::LineFit;
use crate::RigError;

/// One fit to draw.
#[derive(Debug, Clone)]
pub struct FitPlot<'a> {
    /// Title above the plot.
    pub title: &'a str,
    /// x axis label.
    pub x_label: &'a str,
    /// y axis label.
    pub y_label: &'a str,
    /// Measured points.
    pub points: &'a [(f64, f64)],
    /// The fitted line.
    pub fit: &'a LineFit,
    /// The paper's line (slope, intercept) for comparison, if any.
    pub reference: Option<(f64, f64)>,
}

/// `v` with `digits` significant digits.
fn significant(v: f64, digits: i32) -> String {
    let magnitude = if v == 0.0 {
        0
    } else {
        v.abs().log10().floor() as i32
    };
    let decimals = (digits - 1 - magnitude).max(0) as usize;
    format!("{v:.decimals$}")
}

fn span(v: impl Iterator<Item = f64>, include_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if include_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-9);
    (lo - pad, hi + pad)
}

/// Draws `plot` into the SVG file `path`: the data with the fit above, residuals below.
/// Written atomically: a failed drawing leaves an existing `path` untouched.
pub fn draw(path: &Path, plot: &FitPlot<'_>) -> Result<(), RigError> {
    reporting::write_atomic_with(path, |tmp| draw_into(tmp, path, plot))
}

/// Draws into file `target`; errors name `path`.
fn draw_into(target: &Path, path: &Path, plot: &FitPlot<'_>) -> Result<(), RigError> {
    let err = |e: &dyn std::fmt::Display| RigError::Plot {
        path: path.display().to_string(),
        why: e.to_string(),
    };
    let root = SVGBackend::new(target, (640, 560)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let root = root
        .titled(plot.title, ("sans-serif", 18))
        .map_err(|e| err(&e))?;
    let (top, bottom) = root.split_vertically(400);
    let (x0, x1) = span(plot.points.iter().map(|p| p.0), false);
    let (y0, y1) = span(
        plot.points
            .iter()
            .map(|p| p.1)
            .chain([plot.fit.at(x0), plot.fit.at(x1)]),
        false,
    );
    let mut chart = ChartBuilder::on(&top)
        .margin(12)
        .x_label_area_size(36)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    chart
        .configure_mesh()
        .x_desc(plot.x_label)
        .y_desc(plot.y_label)
        .draw()
        .map_err(|e| err(&e))?;
    let f = plot.fit;
    chart
        .draw_series(LineSeries::new(
            [(x0, f.at(x0)), (x1, f.at(x1))],
            BLUE.stroke_width(2),
        ))
        .map_err(|e| err(&e))?
        .label(format!(
            "fit: {} x {:+}, R² {:.5}",
            significant(f.slope, 4),
            significant(f.intercept, 4)
                .parse::<f64>()
                .unwrap_or(f.intercept),
            f.r_squared
        ))
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLUE.stroke_width(2)));
    if let Some((slope, intercept)) = plot.reference {
        chart
            .draw_series(LineSeries::new(
                [(x0, slope * x0 + intercept), (x1, slope * x1 + intercept)],
                BLACK.mix(0.5).stroke_width(1),
            ))
            .map_err(|e| err(&e))?
            .label(format!("paper: {slope} x {intercept:+}"))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.5)));
    }
    chart
        .draw_series(
            plot.points
                .iter()
                .map(|&(x, y)| Circle::new((x, y), 4, RED.filled())),
        )
        .map_err(|e| err(&e))?;
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| err(&e))?;

    let residuals: Vec<(f64, f64)> = plot.points.iter().map(|&(x, y)| (x, y - f.at(x))).collect();
    let (r0, r1) = span(residuals.iter().map(|r| r.1), true);
    let mut res = ChartBuilder::on(&bottom)
        .margin(12)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, r0..r1)
        .map_err(|e| err(&e))?;
    res.configure_mesh()
        .y_desc("residual")
        .draw()
        .map_err(|e| err(&e))?;
    res.draw_series(LineSeries::new(
        [(x0, 0.0), (x1, 0.0)],
        BLACK.stroke_width(1),
    ))
    .map_err(|e| err(&e))?;
    res.draw_series(
        residuals
            .iter()
            .map(|&(x, r)| Circle::new((x, r), 3, RED.filled())),
    )
    .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
