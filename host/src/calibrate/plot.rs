//! SVG plots of the two calibration fits: measured points, the fitted line and its residuals.

use std::path::Path;

use reporting::figure::FigureSize;
use reporting::plot::{
    Legend, PALETTE, Series, Style, XyPanel, axis_label, draw_panel, span, svg_figure, title_height,
};

use super::fit::LineFit;
use crate::RigError;

/// One fit to draw.
#[derive(Debug, Clone)]
pub struct FitPlot<'a> {
    /// Title above the plot.
    pub title: &'a str,
    /// x axis label ([`axis_label`]: `quantity, unit`).
    pub x_label: &'a str,
    /// y axis label ([`axis_label`]); the residuals are labelled in its unit.
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

/// Draws `plot` into the SVG file `path` printed at `size`: the data with the fit above
/// (legend below it), residuals below. Written atomically: a failed drawing leaves an
/// existing `path` untouched.
pub fn draw(path: &Path, plot: &FitPlot<'_>, size: FigureSize) -> Result<(), RigError> {
    let (x0, x1) = span(plot.points.iter().map(|p| p.0), 0.08, false);
    let f = plot.fit;
    let mut series = vec![
        Series::points(PALETTE[1], 3, plot.points.to_vec()).labelled("measured"),
        Series::line(PALETTE[0], 2, vec![(x0, f.at(x0)), (x1, f.at(x1))]).labelled(format!(
            "fit: {} x {:+}, R² {:.5}",
            significant(f.slope, 4),
            significant(f.intercept, 4)
                .parse::<f64>()
                .unwrap_or(f.intercept),
            f.r_squared
        )),
    ];
    if let Some((slope, intercept)) = plot.reference {
        series.push(
            Series {
                opacity: 0.5,
                ..Series::line(
                    PALETTE[5],
                    1,
                    vec![(x0, slope * x0 + intercept), (x1, slope * x1 + intercept)],
                )
            }
            .labelled(format!("paper: {slope} x {intercept:+}")),
        );
    }
    let y = span(
        plot.points.iter().map(|p| p.1).chain([f.at(x0), f.at(x1)]),
        0.08,
        false,
    );
    let fit_panel = XyPanel {
        x_label: plot.x_label.into(),
        y_label: plot.y_label.into(),
        series,
        x_range: Some((x0, x1)),
        y_range: Some(y),
        legend: Some(Legend::Below),
        ..XyPanel::default()
    };
    let residuals: Vec<(f64, f64)> = plot.points.iter().map(|&(x, y)| (x, y - f.at(x))).collect();
    let residual_panel = XyPanel {
        x_label: plot.x_label.into(),
        y_label: axis_label(
            "residual",
            plot.y_label.rsplit_once(", ").map_or("", |(_, unit)| unit),
        ),
        series: vec![
            Series::line(PALETTE[5], 1, vec![(x0, 0.0), (x1, 0.0)]),
            Series::points(PALETTE[1], 3, residuals),
        ],
        x_range: Some((x0, x1)),
        include_zero_y: true,
        ..XyPanel::default()
    };
    let style = Style::new(size);
    let width = size.width_px();
    // The fit over its residuals, each as tall as the width allows on a page.
    let fit_h = (width * 55 / 100).min(300) + style.legend_height(&fit_panel);
    let residual_h = (width * 28 / 100).min(150).max(style.em(12.0));
    let height = title_height(plot.title, &style) + fit_h + residual_h;
    svg_figure(path, size, height, Some(plot.title), |root, style| {
        let (top, bottom) = root.split_vertically(fit_h);
        draw_panel(&top, &fit_panel, style)?;
        draw_panel(&bottom, &residual_panel, style)
    })?;
    Ok(())
}
