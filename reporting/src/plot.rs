//! The reports' figures (SVG via plotters), drawn one way for every tool:
//!
//! - [`svg_figure`] renders a figure in memory and writes the file atomically (a failed plot
//!   never leaves half an SVG, nor destroys an existing one);
//! - [`XyPanel`] (points and lines in one pair of axes) drawn by [`draw_panel`] into any
//!   area of a figure, so a figure of any layout is a split of the root area plus one call
//!   per panel, and [`columns_figure`] for the common side-by-side layout;
//! - [`span`], the padded axis range, and [`PALETTE`], the series colours;
//! - [`residual_figure`], the residual plots of `rig explain`.
//!
//! The style for a paper: axis labels with their units in brackets (`i_in [A]`), a panel
//! letter on every panel of a multi-panel figure ((a), (b), ...), legends beside the data
//! ([`Legend::Outside`]) rather than over it, shaded phases ([`Band`]), reference values
//! from the paper drawn as their own labelled series.
//!
//! `rig design`'s sweep figure (host `sweep_report`) is built from these; the calibration's
//! fit plot (a panel over a residual panel sharing its x axis) fits them too: [`svg_figure`]
//! with a vertical split, [`XyPanel::x_range`] for the shared axis and
//! [`XyPanel::include_zero_y`] for the residuals.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
pub use plotters::style::RGBColor;

use crate::ReportError;

/// Most points drawn per residual panel; larger data is thinned evenly (the statistics use
/// every row).
const MAX_POINTS: usize = 4000;

/// Series colours, in order: the Okabe-Ito palette (Okabe and Ito, "Color Universal
/// Design", 2002), told apart by readers with any common colour-vision deficiency: blue,
/// vermillion, bluish green, reddish purple, orange, black.
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(0, 0, 0),
];

/// The drawing area of a figure (or of one panel of it).
pub type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;

/// The range of `values` padded by `pad` of its width on both sides (at least a tiny
/// amount, so a constant series still has an axis), widened to include zero when
/// `include_zero`; `(0, 1)` without a finite value.
pub fn span(values: impl IntoIterator<Item = f64>, pad: f64, include_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if include_zero {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    let pad = ((hi - lo) * pad).max(1e-9 * hi.abs().max(lo.abs()).max(1.0));
    (lo - pad, hi + pad)
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mark {
    /// Filled circles of this radius, px.
    Points(u32),
    /// A line through the points in x order, this wide, px.
    Line(u32),
}

/// One series of a panel.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend label (none: not in the legend).
    pub label: Option<String>,
    /// Colour.
    pub color: RGBColor,
    /// Opacity, 0 to 1.
    pub opacity: f64,
    /// Points or line.
    pub mark: Mark,
    /// The (x, y) points.
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// Filled circles of `radius` px in `color`.
    pub fn points(color: RGBColor, radius: u32, points: Vec<(f64, f64)>) -> Self {
        Self {
            label: None,
            color,
            opacity: 1.0,
            mark: Mark::Points(radius),
            points,
        }
    }

    /// A line `width` px wide in `color` through `points` (drawn in x order).
    pub fn line(color: RGBColor, width: u32, points: Vec<(f64, f64)>) -> Self {
        Self {
            label: None,
            color,
            opacity: 1.0,
            mark: Mark::Line(width),
            points,
        }
    }

    /// The same series with a legend label.
    pub fn labelled(mut self, label: impl Into<String>) -> Self {
        self.label = Some(label.into());
        self
    }
}

/// Repeated measurements as their means with their spread: for every distinct x of
/// `samples`, the mean of its y as a labelled point series, and, where there is more than
/// one value, a bar from mean - sd to mean + sd (the sample standard deviation) in the same
/// colour. Bars first, so the means are drawn over them.
pub fn mean_with_spread(
    color: RGBColor,
    radius: u32,
    label: impl Into<String>,
    samples: &[(f64, f64)],
) -> Vec<Series> {
    let mut xs: Vec<f64> = samples.iter().map(|p| p.0).collect();
    xs.sort_by(f64::total_cmp);
    xs.dedup();
    let mut out = Vec::new();
    let mut means = Vec::with_capacity(xs.len());
    for x in xs {
        let ys: Vec<f64> = samples.iter().filter(|p| p.0 == x).map(|p| p.1).collect();
        let n = ys.len() as f64;
        let mean = ys.iter().sum::<f64>() / n;
        if ys.len() > 1 {
            let sd = (ys.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
            out.push(Series::line(color, 1, vec![(x, mean - sd), (x, mean + sd)]));
        }
        means.push((x, mean));
    }
    out.push(Series::points(color, radius, means).labelled(label));
    out
}

/// Where a panel's legend goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Legend {
    /// Top left corner.
    UpperLeft,
    /// Top right corner.
    UpperRight,
    /// Right edge, half-way.
    MiddleRight,
    /// Bottom left corner.
    LowerLeft,
    /// Bottom right corner.
    LowerRight,
    /// Right of the plot, outside the data (the panel's plot is narrower by the legend's
    /// width).
    Outside,
}

impl Legend {
    fn position(self) -> SeriesLabelPosition {
        match self {
            Self::UpperLeft => SeriesLabelPosition::UpperLeft,
            Self::UpperRight => SeriesLabelPosition::UpperRight,
            Self::MiddleRight => SeriesLabelPosition::MiddleRight,
            Self::LowerLeft => SeriesLabelPosition::LowerLeft,
            Self::LowerRight => SeriesLabelPosition::LowerRight,
            Self::Outside => SeriesLabelPosition::UpperRight,
        }
    }
}

/// A shaded range of x (a phase of an experiment), with its name written at its top.
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    /// Start and end of the range, in x units.
    pub from: f64,
    /// End of the range.
    pub to: f64,
    /// The name written in the band.
    pub label: String,
    /// Fill colour (drawn at 15 % opacity).
    pub color: RGBColor,
}

/// Width of an outside legend, px.
const LEGEND_WIDTH: u32 = 130;

/// One pair of axes with its series.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct XyPanel {
    /// Panel letter, drawn as "(a)" in the top left corner ([`columns_figure`] letters
    /// the panels of a multi-panel figure when none is set).
    pub letter: Option<char>,
    /// Shaded x ranges, drawn under the series.
    pub bands: Vec<Band>,
    /// Caption above the panel.
    pub caption: Option<String>,
    /// x axis label.
    pub x_label: String,
    /// y axis label.
    pub y_label: String,
    /// The series, drawn in order.
    pub series: Vec<Series>,
    /// Fixed x range (default: [`span`] of the series, padded 8 %).
    pub x_range: Option<(f64, f64)>,
    /// Fixed y range (default: [`span`] of the series, padded 8 %).
    pub y_range: Option<(f64, f64)>,
    /// Widen the automatic y range to include zero (residuals).
    pub include_zero_y: bool,
    /// Legend of the labelled series (none: no legend).
    pub legend: Option<Legend>,
    /// Draw the fine grid lines between the labelled ones.
    pub fine_grid: bool,
    /// The x values count things (run indices, test points): ticks labelled as whole
    /// numbers (`20`, not `20.0`), none between them.
    pub whole_x: bool,
}

impl XyPanel {
    /// The x range drawn.
    pub fn x_span(&self) -> (f64, f64) {
        self.x_range.unwrap_or_else(|| {
            span(
                self.series
                    .iter()
                    .flat_map(|s| s.points.iter().map(|p| p.0)),
                0.08,
                false,
            )
        })
    }

    /// The y range drawn.
    pub fn y_span(&self) -> (f64, f64) {
        self.y_range.unwrap_or_else(|| {
            span(
                self.series
                    .iter()
                    .flat_map(|s| s.points.iter().map(|p| p.1)),
                0.08,
                self.include_zero_y,
            )
        })
    }
}

/// Draws `panel` into `area`; errors are the drawing backend's, as text.
pub fn draw_panel(area: &Area<'_>, panel: &XyPanel) -> Result<(), String> {
    let outside =
        panel.legend == Some(Legend::Outside) && panel.series.iter().any(|s| s.label.is_some());
    let (width, _) = area.dim_in_pixel();
    let (plot_area, legend_area) = if outside && width > 2 * LEGEND_WIDTH {
        let (a, b) = area.split_horizontally(width - LEGEND_WIDTH);
        (a, Some(b))
    } else {
        (area.clone(), None)
    };
    draw_axes(&plot_area, panel, legend_area.is_none())?;
    if let Some(legend) = legend_area {
        draw_outside_legend(&legend, panel)?;
    }
    if let Some(letter) = panel.letter {
        area.draw(&Text::new(
            format!("({letter})"),
            (4, 4),
            ("sans-serif", 18).into_font().style(FontStyle::Bold),
        ))
        .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// The legend of `panel`'s labelled series in its own strip beside the plot.
fn draw_outside_legend(area: &Area<'_>, panel: &XyPanel) -> Result<(), String> {
    let mut y = 40;
    for s in panel.series.iter().filter(|s| s.label.is_some()) {
        let color = s.color.mix(s.opacity);
        match s.mark {
            Mark::Points(r) => area
                .draw(&Circle::new((14, y), r.max(2), color.filled()))
                .map_err(|e| e.to_string())?,
            Mark::Line(w) => area
                .draw(&PathElement::new([(4, y), (24, y)], color.stroke_width(w)))
                .map_err(|e| e.to_string())?,
        }
        area.draw(&Text::new(
            s.label.clone().unwrap_or_default(),
            (30, y - 7),
            ("sans-serif", 13),
        ))
        .map_err(|e| e.to_string())?;
        y += 20;
    }
    Ok(())
}

fn draw_axes(area: &Area<'_>, panel: &XyPanel, inside_legend: bool) -> Result<(), String> {
    let (x0, x1) = panel.x_span();
    let (y0, y1) = panel.y_span();
    let mut builder = ChartBuilder::on(area);
    builder
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60);
    if let Some(c) = &panel.caption {
        builder.caption(c, ("sans-serif", 16));
    }
    let mut chart = builder
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str());
    let whole = |x: &f64| {
        if (x - x.round()).abs() < 1e-9 {
            format!("{}", x.round() as i64)
        } else {
            String::new()
        }
    };
    if panel.whole_x {
        mesh.x_label_formatter(&whole);
    }
    if !panel.fine_grid {
        mesh.light_line_style(WHITE);
    }
    mesh.draw().map_err(|e| e.to_string())?;
    for (k, b) in panel.bands.iter().enumerate() {
        let (from, to) = (b.from.max(x0), b.to.min(x1));
        if to <= from {
            continue;
        }
        chart
            .draw_series(std::iter::once(Rectangle::new(
                [(from, y0), (to, y1)],
                b.color.mix(0.15).filled(),
            )))
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(std::iter::once(Text::new(
                b.label.clone(),
                // Every other label a line lower: narrow neighbours do not run together.
                (from, y1 - (k % 2) as f64 * 0.07 * (y1 - y0)),
                ("sans-serif", 12).into_font().color(&BLACK.mix(0.7)),
            )))
            .map_err(|e| e.to_string())?;
    }
    for s in &panel.series {
        let color = s.color.mix(s.opacity);
        let drawn = match s.mark {
            Mark::Points(radius) => chart
                .draw_series(
                    s.points
                        .iter()
                        .map(|&p| Circle::new(p, radius, color.filled())),
                )
                .map_err(|e| e.to_string())?,
            Mark::Line(width) => {
                let mut line = s.points.clone();
                line.sort_by(|a, b| a.0.total_cmp(&b.0));
                chart
                    .draw_series(LineSeries::new(line, color.stroke_width(width)))
                    .map_err(|e| e.to_string())?
            }
        };
        if let Some(label) = &s.label {
            let mark = s.mark;
            drawn.label(label).legend(move |(x, y)| match mark {
                Mark::Points(r) => Circle::new((x, y), r, color.filled()).into_dyn(),
                Mark::Line(w) => {
                    PathElement::new([(x, y), (x + 20, y)], color.stroke_width(w)).into_dyn()
                }
            });
        }
    }
    if let Some(at) = panel.legend.filter(|_| inside_legend) {
        chart
            .configure_series_labels()
            .position(at.position())
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Draws a figure of `size` px with `draw` (given the white root area, under `title` when
/// there is one) and writes it to the SVG file `path` atomically.
pub fn svg_figure(
    path: &Path,
    size: (u32, u32),
    title: Option<&str>,
    draw: impl FnOnce(&Area<'_>) -> Result<(), String>,
) -> Result<(), ReportError> {
    let err = |why: String| ReportError::Plot {
        path: path.display().to_string(),
        why,
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        let area = match title {
            Some(t) => root
                .titled(t, ("sans-serif", 18))
                .map_err(|e| err(e.to_string()))?,
            None => root.clone(),
        };
        draw(&area).map_err(err)?;
        root.present().map_err(|e| err(e.to_string()))?;
    }
    crate::write_atomic(path, svg.as_bytes())
}

/// `panels` side by side, each `panel_size` px, under `title`, into the SVG file `path`.
pub fn columns_figure(
    path: &Path,
    panel_size: (u32, u32),
    title: Option<&str>,
    panels: &[XyPanel],
) -> Result<(), ReportError> {
    let n = panels.len().max(1);
    let size = (panel_size.0 * n as u32, panel_size.1);
    svg_figure(path, size, title, |root| {
        for (k, (area, p)) in root.split_evenly((1, n)).iter().zip(panels).enumerate() {
            if n > 1 && p.letter.is_none() {
                let mut lettered = p.clone();
                lettered.letter = Some(panel_letter(k));
                draw_panel(area, &lettered)?;
            } else {
                draw_panel(area, p)?;
            }
        }
        Ok(())
    })
}

/// The letter of the `k`-th panel (0-based): a, b, c, ...
pub fn panel_letter(k: usize) -> char {
    char::from(b'a' + (k % 26) as u8)
}

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

/// Draws `panels` side by side under `title` into the SVG file `path`, all with the same
/// residual axis of +-`y_max_ma` (points beyond it drawn at its edge).
pub fn residual_figure(
    path: &Path,
    title: &str,
    panels: &[Panel],
    y_max_ma: f64,
) -> Result<(), ReportError> {
    let y = y_max_ma.max(1.0);
    let panels: Vec<XyPanel> = panels
        .iter()
        .map(|p| {
            let (x0, x1) = span(p.x.iter().copied(), 0.05, false);
            let stride = p.x.len().div_ceil(MAX_POINTS).max(1);
            let points =
                p.x.iter()
                    .zip(&p.residual_ma)
                    .step_by(stride)
                    .map(|(&x, &r)| (x, r.clamp(-y, y)))
                    .collect();
            XyPanel {
                x_label: p.x_label.clone(),
                y_label: "measured - model [mA]".into(),
                series: vec![
                    Series::line(BLACK, 1, vec![(x0, 0.0), (x1, 0.0)]),
                    Series {
                        opacity: 0.6,
                        ..Series::points(BLUE, 2, points)
                    },
                ],
                x_range: Some((x0, x1)),
                y_range: Some((-y, y)),
                ..XyPanel::default()
            }
        })
        .collect();
    columns_figure(path, (380, 360), Some(title), &panels)
}

#[cfg(test)]
mod tests {
    #[test]
    fn means_with_their_spread() {
        let samples = [(1.0, 2.0), (1.0, 4.0), (2.0, 5.0)];
        let series = mean_with_spread(PALETTE[0], 3, "a", &samples);
        // One bar (x = 1 has two values), then the means.
        assert_eq!(series.len(), 2);
        let sd = 2f64.sqrt();
        assert_eq!(series[0].mark, Mark::Line(1));
        assert_eq!(series[0].points, vec![(1.0, 3.0 - sd), (1.0, 3.0 + sd)]);
        assert_eq!(series[1].points, vec![(1.0, 3.0), (2.0, 5.0)]);
        assert_eq!(series[1].label.as_deref(), Some("a"));
    }

    use super::*;

    #[test]
    fn span_pads_and_includes_zero() {
        assert_eq!(span([], 0.1, false), (0.0, 1.0));
        let (lo, hi) = span([1.0, 3.0, f64::NAN], 0.1, false);
        assert!((lo - 0.8).abs() < 1e-12 && (hi - 3.2).abs() < 1e-12);
        let (lo, _) = span([1.0, 3.0], 0.0, true);
        assert!(lo <= 0.0);
        let (lo, hi) = span([2.0, 2.0], 0.1, false);
        assert!(lo < 2.0 && hi > 2.0);
    }

    #[test]
    fn figures_are_written_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fig.svg");
        let panel = XyPanel {
            caption: Some("current".into()),
            x_label: "tau_rot, N m".into(),
            y_label: "i_in, A".into(),
            series: vec![
                Series::points(PALETTE[0], 3, vec![(0.368, 2.3), (3.68, 2.9)]).labelled("3.6 V"),
                Series::line(PALETTE[1], 2, vec![(3.68, 3.0), (0.368, 2.4)]),
            ],
            legend: Some(Legend::Outside),
            bands: vec![Band {
                from: 1.0,
                to: 2.0,
                label: "release".into(),
                color: PALETTE[2],
            }],
            ..XyPanel::default()
        };
        columns_figure(&path, (400, 300), Some("sweep"), &[panel.clone(), panel]).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("3.6 V") && svg.contains("sweep"));
        // Each panel lettered, the band named.
        assert!(svg.contains("(a)") && svg.contains("(b)") && svg.contains("release"));
        // A failed drawing leaves the file as it was and nothing else.
        let r = svg_figure(&path, (100, 100), None, |_| Err("no data".into()));
        assert!(r.unwrap_err().to_string().contains("no data"));
        assert_eq!(std::fs::read_to_string(&path).unwrap(), svg);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let residuals = Panel {
            x_label: "speed".into(),
            x: vec![1.0, 2.0, 3.0],
            residual_ma: vec![5.0, -50.0, 1.0],
        };
        residual_figure(&path, "residuals", &[residuals], 10.0).unwrap();
        assert!(
            std::fs::read_to_string(&path)
                .unwrap()
                .contains("measured - model [mA]")
        );
    }
}
