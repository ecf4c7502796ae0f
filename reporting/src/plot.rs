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
//! The style for a paper: figures drawn at the width they print ([`FigureSize`]: a
//! journal's single or double column) with every text [`TEXT_PT`] there, axis labels in one
//! unit style with symbols as printed ([`axis_label`]: `τ_rot, N m`, subscripts set by
//! [`subscripts`]), a panel letter on every panel of a multi-panel figure ((a), (b), ...),
//! legends below the plot area ([`Legend::Below`]) and band names above it, never over the
//! data, shaded phases ([`Band`]), reference values from the paper drawn as their own
//! labelled series. [`crate::check`] measures a written SVG against these rules.
//!
//! `rig design`'s sweep figure (host `sweep_report`) is built from these; the calibration's
//! fit plot (a panel over a residual panel sharing its x axis) fits them too: [`svg_figure`]
//! with a vertical split, [`XyPanel::x_range`] for the shared axis and
//! [`XyPanel::include_zero_y`] for the residuals.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;
pub use plotters::style::RGBColor;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::ReportError;
use crate::figure::{FigureSize, MIN_TEXT_PT};

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

/// An axis label in the figures' one unit style, `quantity, unit` as printed: symbols in
/// Unicode (τ_rot, ω_n, μ_d Λ, ±), subscripts after `_` (set lowered and smaller in the
/// written figure, [`subscripts`]), and a unitless quantity (a ratio, a count) alone. [`crate::check::ascii_stand_in`] finds the ASCII names this replaces.
pub fn axis_label(quantity: &str, unit: &str) -> String {
    if unit.is_empty() {
        quantity.to_string()
    } else {
        format!("{quantity}, {unit}")
    }
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
    /// Below the plot area, clear of the data, one entry per line (the panel's plot is
    /// shorter by the legend's height).
    Below,
}

/// A shaded range of x (a phase of an experiment), with its name written above the plot
/// area at the range's start (clear of the data).
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    /// Start and end of the range, in x units.
    pub from: f64,
    /// End of the range.
    pub to: f64,
    /// The name written above the band.
    pub label: String,
    /// Fill colour (drawn at 15 % opacity).
    pub color: RGBColor,
}

/// Size of the figures' text, pt at the printed size: axis labels, ticks, captions,
/// legends (at least [`MIN_TEXT_PT`]).
pub const TEXT_PT: f64 = 8.0;
/// Size of a figure's title, pt at the printed size.
pub const TITLE_PT: f64 = 9.0;
const _: () = assert!(TEXT_PT >= MIN_TEXT_PT && TITLE_PT >= MIN_TEXT_PT);
/// Narrowest panel of a grid, px (2.3 in at 96 px/in): a figure as wide as two puts its
/// panels side by side, a single column stacks them.
pub const MIN_PANEL_PX: u32 = 220;
/// Tallest figure, px (8.5 in: a page's text height less room for its caption); stacked
/// panels are made flatter to fit.
pub const MAX_HEIGHT_PX: u32 = 816;
/// plotters writes an SVG text's `font-size` as its font's size / 1.24.
const PLOTTERS_FONT_SCALE: f64 = 1.24;

/// The type and spacing of one figure, from its printed size: every text is
/// [`TEXT_PT`] or [`TITLE_PT`] when the figure prints at [`FigureSize::width_in`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Style {
    /// The printed size the figure is drawn for.
    pub size: FigureSize,
    /// Font size of the text, px of the drawing.
    pub text_px: f64,
    /// Font size of the title, px of the drawing.
    pub title_px: f64,
    /// Height kept for every panel's caption, px (at least its own; the panels of a row
    /// then have their plots level).
    pub caption_px: u32,
    /// Height kept below every panel for its legend, px (at least its own).
    pub legend_px: u32,
}

impl Style {
    /// The style of a figure printed at `size`.
    pub fn new(size: FigureSize) -> Self {
        Self {
            size,
            text_px: size.font_px(TEXT_PT),
            title_px: size.font_px(TITLE_PT),
            caption_px: 0,
            legend_px: 0,
        }
    }

    /// A plotters font whose SVG text is `px` high.
    pub fn font(&self, px: f64) -> FontDesc<'static> {
        ("sans-serif", px * PLOTTERS_FONT_SCALE).into_font()
    }

    /// The text's font.
    pub fn text(&self) -> FontDesc<'static> {
        self.font(self.text_px)
    }

    /// `k` times the text's height, whole px.
    pub fn em(&self, k: f64) -> u32 {
        (self.text_px * k).ceil() as u32
    }

    /// Height of a line of text, px.
    pub fn line_px(&self) -> u32 {
        self.em(1.35)
    }

    /// `text` broken at spaces into lines no wider than `width` px in a font `px` high.
    pub fn wrap(text: &str, px: f64, width: u32) -> Vec<String> {
        let mut lines: Vec<String> = Vec::new();
        for word in text.split(' ') {
            match lines.last_mut() {
                Some(line)
                    if crate::check::text_width_px(&format!("{line} {word}"), px)
                        <= f64::from(width) =>
                {
                    line.push(' ');
                    line.push_str(word);
                }
                _ => lines.push(word.to_string()),
            }
        }
        lines
    }

    /// Height of `text` wrapped to `width` px in a font `px` high, px.
    fn wrapped_height(text: &str, px: f64, width: u32) -> u32 {
        let lines = Self::wrap(text, px, width).len() as f64;
        (lines * px * 1.3 + px * 0.8).ceil() as u32
    }

    /// Height of the legend below `panel`, px (none without labelled series).
    pub fn legend_height(&self, panel: &XyPanel) -> u32 {
        let n = legend_entries(panel).count() as u32;
        if panel.legend.is_none() || n == 0 {
            0
        } else {
            n * self.line_px() + self.em(0.5)
        }
    }
}

impl Default for Style {
    fn default() -> Self {
        Self::new(FigureSize::default())
    }
}

/// The series of `panel` its legend lists.
fn legend_entries(panel: &XyPanel) -> impl Iterator<Item = &Series> {
    panel.series.iter().filter(|s| s.label.is_some())
}

/// Draws `text` wrapped to the width of `area`, centred, from its top in a font `px` high;
/// returns the height used, px.
fn draw_wrapped(area: &Area<'_>, text: &str, style: &Style, px: f64) -> Result<u32, String> {
    let (width, _) = area.dim_in_pixel();
    let line = (px * 1.3).ceil() as i32;
    let font = style
        .font(px)
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Top));
    for (k, l) in Style::wrap(text, px, width).iter().enumerate() {
        area.draw(&Text::new(
            l.clone(),
            ((width / 2) as i32, (px * 0.6) as i32 + k as i32 * line),
            font.clone(),
        ))
        .map_err(|e| e.to_string())?;
    }
    Ok(Style::wrapped_height(text, px, width))
}

/// One pair of axes with its series.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct XyPanel {
    /// Panel letter, written as "(a)" before the caption ([`columns_figure`] letters the
    /// panels of a multi-panel figure when none is set).
    pub letter: Option<char>,
    /// Shaded x ranges, drawn under the series.
    pub bands: Vec<Band>,
    /// Caption above the panel (wrapped to its width).
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

/// Draws `panel` into `area` in `style`: its caption (with its letter) wrapped above, the
/// plot area framed, band names above it, the legend below it; errors are the drawing
/// backend's, as text.
pub fn draw_panel(area: &Area<'_>, panel: &XyPanel, style: &Style) -> Result<(), String> {
    let caption = match (panel.letter, &panel.caption) {
        (Some(l), Some(c)) => Some(format!("({l}) {c}")),
        (Some(l), None) => Some(format!("({l})")),
        (None, c) => c.clone(),
    };
    let area = match caption {
        Some(c) => {
            let (w, _) = area.dim_in_pixel();
            let used = Style::wrapped_height(&c, style.text_px, w).max(style.caption_px);
            let (top, rest) = area.split_vertically(used);
            draw_wrapped(&top, &c, style, style.text_px)?;
            rest
        }
        None => area.clone(),
    };
    let (_, height) = area.dim_in_pixel();
    let own = style.legend_height(panel);
    let legend_h = own.max(style.legend_px);
    let (plot_area, legend_area) = if legend_h > 0 && height > legend_h + style.em(8.0) {
        let (a, b) = area.split_vertically(height - legend_h);
        (a, Some(b))
    } else {
        (area.clone(), None)
    };
    let left = draw_axes(&plot_area, panel, style)?;
    if let Some(legend) = legend_area {
        draw_legend_below(&legend, panel, style, left)?;
    }
    Ok(())
}

/// The legend of `panel`'s labelled series below its plot, one entry per line, from `left`
/// px (the plot area's left edge).
fn draw_legend_below(
    area: &Area<'_>,
    panel: &XyPanel,
    style: &Style,
    left: i32,
) -> Result<(), String> {
    let line = style.line_px() as i32;
    let sample = style.em(2.0) as i32;
    let font = style
        .text()
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    for (k, s) in legend_entries(panel).enumerate() {
        let y = style.em(0.3) as i32 + k as i32 * line + line / 2;
        let color = s.color.mix(s.opacity);
        match s.mark {
            Mark::Points(r) => area
                .draw(&Circle::new(
                    (left + sample / 2, y),
                    r.max(2),
                    color.filled(),
                ))
                .map_err(|e| e.to_string())?,
            Mark::Line(w) => area
                .draw(&PathElement::new(
                    [(left, y), (left + sample, y)],
                    color.stroke_width(w),
                ))
                .map_err(|e| e.to_string())?,
        }
        area.draw(&Text::new(
            s.label.clone().unwrap_or_default(),
            (left + sample + style.em(0.5) as i32, y),
            font.clone(),
        ))
        .map_err(|e| e.to_string())?;
    }
    Ok(())
}

/// Draws the axes, bands and series of `panel` into `area`; returns the plot area's left
/// edge, px from `area`'s.
fn draw_axes(area: &Area<'_>, panel: &XyPanel, style: &Style) -> Result<i32, String> {
    let (x0, x1) = panel.x_span();
    let (y0, y1) = panel.y_span();
    let band_rows = panel.bands.len().min(2) as u32;
    let mut builder = ChartBuilder::on(area);
    builder
        .margin(style.em(0.5))
        .margin_top(style.em(0.6) + band_rows * style.line_px())
        .margin_right(style.em(1.5))
        .x_label_area_size(style.em(3.3))
        .y_label_area_size(style.em(5.4));
    let mut chart = builder
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| e.to_string())?;
    let (px, py) = chart.plotting_area().get_pixel_range();
    let (ax, ay) = area.get_pixel_range();
    // Ticks a readable distance apart at this size.
    let x_ticks = ((px.end - px.start) as f64 / (style.text_px * 4.0)).clamp(3.0, 10.0) as usize;
    let y_ticks = ((py.end - py.start) as f64 / (style.text_px * 2.6)).clamp(3.0, 10.0) as usize;
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(panel.x_label.as_str())
        .y_desc(panel.y_label.as_str())
        .label_style(style.text())
        .axis_desc_style(style.text())
        .x_labels(x_ticks)
        .y_labels(y_ticks);
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
    let name_font = style
        .text()
        .color(&BLACK.mix(0.8))
        .pos(Pos::new(HPos::Left, VPos::Bottom));
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
        // Above the plot area, every other name a line higher (narrow neighbours do not
        // run together), kept inside the panel.
        let width = crate::check::text_width_px(&b.label, style.text_px).ceil() as i32;
        let at = chart.backend_coord(&(from, y1)).0;
        let x = at.min(px.end + style.em(1.0) as i32 - width).max(px.start) - ax.start;
        let y =
            py.start - ay.start - style.em(0.2) as i32 - (k % 2) as i32 * style.line_px() as i32;
        area.draw(&Text::new(b.label.clone(), (x, y), name_font.clone()))
            .map_err(|e| e.to_string())?;
    }
    for s in &panel.series {
        let color = s.color.mix(s.opacity);
        match s.mark {
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
    }
    // The plot area framed: the figure checker ([`crate::check`]) finds it by this frame.
    chart
        .draw_series(std::iter::once(Rectangle::new(
            [(x0, y0), (x1, y1)],
            BLACK.stroke_width(1),
        )))
        .map_err(|e| e.to_string())?;
    Ok(px.start - ax.start)
}

/// Draws a figure printed at `size` ([`FigureSize::width_px`] wide, `height` px high) with
/// `draw` (given the white root area, under `title` when there is one, and the figure's
/// [`Style`]) and writes it to the SVG file `path` atomically.
pub fn svg_figure(
    path: &Path,
    size: FigureSize,
    height: u32,
    title: Option<&str>,
    draw: impl FnOnce(&Area<'_>, &Style) -> Result<(), String>,
) -> Result<(), ReportError> {
    let err = |why: String| ReportError::Plot {
        path: path.display().to_string(),
        why,
    };
    let style = Style::new(size);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (size.width_px(), height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        let area = match title {
            Some(t) => {
                let used = title_height(t, &style);
                let (top, rest) = root.split_vertically(used);
                draw_wrapped(&top, t, &style, style.title_px).map_err(err)?;
                rest
            }
            None => root.clone(),
        };
        draw(&area, &style).map_err(err)?;
        root.present().map_err(|e| err(e.to_string()))?;
    }
    crate::write_atomic(path, subscripts(&svg).as_bytes())
}

/// Subscript size, relative to its text: [`TEXT_PT`] text keeps its subscripts at
/// [`MIN_TEXT_PT`] or more ([`crate::check::check_svg`] measures them).
const SUBSCRIPT_SIZE: &str = "88%";
const _: () = assert!(TEXT_PT * 0.88 >= MIN_TEXT_PT);

/// The figure `svg` with every subscript of its texts set as printed: `τ_cam` (a letter,
/// `_`, letters or digits) becomes `τ` and a lowered, smaller `cam` (an SVG `tspan`, which
/// resvg and svg2pdf draw as well), so labels are written `τ_cam` everywhere in the code
/// and print τ with cam below.
pub fn subscripts(svg: &str) -> String {
    let mut out = String::with_capacity(svg.len());
    let mut rest = svg;
    while let Some(open) = rest.find("<text") {
        let Some(body) = rest[open..].find('>').map(|k| open + k + 1) else {
            break;
        };
        let Some(close) = rest[body..].find("</text>").map(|k| body + k) else {
            break;
        };
        out.push_str(&rest[..body]);
        let text = &rest[body..close];
        let mut prev: Option<char> = None;
        let mut chars = text.chars().peekable();
        while let Some(c) = chars.next() {
            let starts = c == '_'
                && prev.is_some_and(char::is_alphabetic)
                && chars.peek().is_some_and(|n| n.is_alphanumeric());
            if starts {
                out.push_str(&format!(
                    "<tspan baseline-shift=\"sub\" font-size=\"{SUBSCRIPT_SIZE}\">"
                ));
                while let Some(&n) = chars.peek().filter(|n| n.is_alphanumeric()) {
                    out.push(n);
                    chars.next();
                }
                out.push_str("</tspan>");
                prev = None;
            } else {
                out.push(c);
                prev = Some(c);
            }
        }
        rest = &rest[close..];
    }
    out.push_str(rest);
    out
}

/// Height of `title` over a figure in `style`, px.
pub fn title_height(title: &str, style: &Style) -> u32 {
    Style::wrapped_height(title, style.title_px, style.size.width_px())
}

/// `panels` in a grid printed at `size`, under `title`, into the SVG file `path`: as many
/// side by side as fit ([`MIN_PANEL_PX`] each; a single column stacks them), each plot
/// `aspect` (width, height) in proportion (flatter when the figure would be taller than
/// [`MAX_HEIGHT_PX`]), the legends below.
pub fn columns_figure(
    path: &Path,
    size: FigureSize,
    aspect: (u32, u32),
    title: Option<&str>,
    panels: &[XyPanel],
) -> Result<(), ReportError> {
    let style = Style::new(size);
    let n = panels.len().max(1);
    let width = size.width_px();
    let cols = ((width / MIN_PANEL_PX).max(1) as usize).min(n);
    let rows = n.div_ceil(cols) as u32;
    let panel_w = width / cols as u32;
    let title_h = title.map_or(0, |t| title_height(t, &style));
    // Every panel keeps room for the tallest caption and legend: the plots stay level.
    let mut style = style;
    style.caption_px = panels
        .iter()
        .filter_map(|p| {
            let c = p.caption.as_deref()?;
            Some(Style::wrapped_height(
                &format!("(a) {c}"),
                style.text_px,
                panel_w,
            ))
        })
        .max()
        .unwrap_or(0);
    style.legend_px = panels
        .iter()
        .map(|p| style.legend_height(p))
        .max()
        .unwrap_or(0);
    let above = style.caption_px + style.legend_px;
    let plot_h = (u64::from(panel_w) * u64::from(aspect.1) / u64::from(aspect.0.max(1))) as u32;
    let room = (MAX_HEIGHT_PX.saturating_sub(title_h) / rows).saturating_sub(above);
    let panel_h = plot_h.min(room.max(style.em(14.0))) + above;
    svg_figure(path, size, title_h + rows * panel_h, title, |root, _| {
        let areas = root.split_evenly((rows as usize, cols));
        for (k, (area, p)) in areas.iter().zip(panels).enumerate() {
            if n > 1 && p.letter.is_none() {
                let mut lettered = p.clone();
                lettered.letter = Some(panel_letter(k));
                draw_panel(area, &lettered, &style)?;
            } else {
                draw_panel(area, p, &style)?;
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

/// Draws `panels` side by side under `title` into the SVG file `path` printed at `size`,
/// all with the same residual axis of ±`y_max_ma` (points beyond it drawn at its edge).
pub fn residual_figure(
    path: &Path,
    size: FigureSize,
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
                y_label: axis_label("measured − model", "mA"),
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
    columns_figure(path, size, (380, 360), Some(title), &panels)
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
    fn subscripts_are_set_lowered_and_smaller() {
        let sub = |s: &str| format!("<tspan baseline-shift=\"sub\" font-size=\"88%\">{s}</tspan>");
        let svg = "<svg><text x=\"1\">\n|τ_cam| = C1 i_in + C2, ω_n2 x_ _y a_b_c\n</text><rect id=\"a_b\"/></svg>";
        assert_eq!(
            subscripts(svg),
            format!(
                "<svg><text x=\"1\">\n|τ{}| = C1 i{} + C2, ω{} x_ _y a{}{}\n</text><rect id=\"a_b\"/></svg>",
                sub("cam"),
                sub("in"),
                sub("n2"),
                sub("b"),
                "_c"
            )
        );
    }

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

    /// Fig. 5's shape: three time histories with phase bands, one with a legend.
    fn fig5_like() -> Vec<XyPanel> {
        let t: Vec<f64> = (0..400).map(|k| f64::from(k) * 0.05).collect();
        let bands = ["hold", "release", "after"]
            .iter()
            .zip([(0.0, 14.5), (14.5, 16.5), (16.5, 20.0)])
            .enumerate()
            .map(|(k, (l, (from, to)))| Band {
                from,
                to,
                label: (*l).into(),
                color: PALETTE[k],
            })
            .collect::<Vec<_>>();
        let panel = |caption: &str, f: &dyn Fn(f64) -> f64| XyPanel {
            caption: Some(caption.into()),
            x_label: axis_label("t", "s"),
            y_label: axis_label("i_in", "A"),
            series: vec![
                Series::line(PALETTE[0], 2, t.iter().map(|&x| (x, f(x))).collect())
                    .labelled("measured current"),
                Series::line(PALETTE[5], 1, vec![(14.5, 0.0), (14.5, 3.0)])
                    .labelled("paper: held 14.5 s"),
            ],
            bands: bands.clone(),
            legend: Some(Legend::Below),
            ..XyPanel::default()
        };
        vec![
            panel("output angle (Fig. 5)", &|x| {
                if x > 14.5 { x - 14.5 } else { 0.0 }
            }),
            panel("cam speed", &|x| {
                if (14.5..16.5).contains(&x) { 3.0 } else { 0.1 }
            }),
            panel("motor current", &|x| (x * 3.0).sin() + 1.5),
        ]
    }

    #[test]
    fn figures_print_their_text_at_7_pt_or_more_clear_of_the_data() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fig.svg");
        for size in [
            FigureSize::Single,
            FigureSize::Double,
            FigureSize::Pixels(500),
            FigureSize::Pixels(1600),
        ] {
            columns_figure(
                &path,
                size,
                (470, 360),
                Some("Fig. 5: hold, release, after"),
                &fig5_like(),
            )
            .unwrap();
            let svg = std::fs::read_to_string(&path).unwrap();
            let problems = crate::check::check_svg(&svg, size.width_in());
            assert!(problems.is_empty(), "{size}: {problems:?}");
            assert!(
                svg.contains(&format!("width=\"{}\"", size.width_px())),
                "{size}"
            );
            // The legend below the plot, one entry per line; the band names above it.
            assert!(svg.contains("paper: held 14.5 s") && svg.contains("release"));
        }
        // A label put on the plotted data of the drawn figure is found: on the middle
        // point of the first panel's line.
        let svg = std::fs::read_to_string(&path).unwrap();
        let line = svg
            .lines()
            .find(|l| l.starts_with("<polyline") && l.contains("stroke=\"#0072B2\""))
            .unwrap();
        let points: Vec<&str> = line
            .split("points=\"")
            .nth(1)
            .unwrap()
            .split_whitespace()
            .collect();
        let (x, y) = points[points.len() / 2].split_once(',').unwrap();
        let label = format!(
            "<text x=\"{x}\" y=\"{y}\" dy=\"0.5ex\" text-anchor=\"middle\" font-family=\"sans-serif\" font-size=\"12\">release here</text>\n</svg>"
        );
        let covered = svg.replace("</svg>", &label);
        let problems = crate::check::check_svg(&covered, 1600.0 / 96.0);
        assert!(
            matches!(problems.as_slice(), [crate::check::Problem::OnData { text, .. }] if text == "release here"),
            "{problems:?}"
        );
        // The same figure printed narrower than drawn: its text is too small.
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(
            crate::check::check_svg(&svg, 3.5)
                .iter()
                .any(|p| matches!(p, crate::check::Problem::SmallText { .. }))
        );
    }

    #[test]
    fn figures_are_written_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fig.svg");
        let panel = XyPanel {
            caption: Some("current".into()),
            x_label: axis_label("τ_rot", "N m"),
            y_label: "i_in, A".into(),
            series: vec![
                Series::points(PALETTE[0], 3, vec![(0.368, 2.3), (3.68, 2.9)]).labelled("3.6 V"),
                Series::line(PALETTE[1], 2, vec![(3.68, 3.0), (0.368, 2.4)]),
            ],
            legend: Some(Legend::Below),
            bands: vec![Band {
                from: 1.0,
                to: 2.0,
                label: "release".into(),
                color: PALETTE[2],
            }],
            ..XyPanel::default()
        };
        columns_figure(
            &path,
            FigureSize::Single,
            (400, 300),
            Some("sweep"),
            &[panel.clone(), panel],
        )
        .unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("3.6 V") && svg.contains("sweep"));
        // Each panel lettered, the band named.
        assert!(svg.contains("(a)") && svg.contains("(b)") && svg.contains("release"));
        // A failed drawing leaves the file as it was and nothing else.
        let r = svg_figure(&path, FigureSize::Single, 100, None, |_, _| {
            Err("no data".into())
        });
        assert!(r.unwrap_err().to_string().contains("no data"));
        assert_eq!(std::fs::read_to_string(&path).unwrap(), svg);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let residuals = Panel {
            x_label: "speed".into(),
            x: vec![1.0, 2.0, 3.0],
            residual_ma: vec![5.0, -50.0, 1.0],
        };
        residual_figure(&path, FigureSize::Single, "residuals", &[residuals], 10.0).unwrap();
        assert!(
            std::fs::read_to_string(&path)
                .unwrap()
                .contains("measured − model, mA")
        );
    }
}
