//! The figures' file formats: every figure is drawn once as SVG (plotters, [`crate::plot`]);
//! [`export`] writes it as PNG (rendered by resvg, cargo feature `png`) or PDF (converted
//! by svg2pdf, feature `pdf`), at a chosen width. A format this build lacks is refused
//! with the feature that adds it.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use crate::ReportError;

/// A figure file format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Format {
    /// Scalable vector graphics, as drawn.
    #[default]
    Svg,
    /// A raster image (resvg).
    Png,
    /// A vector PDF page (svg2pdf).
    Pdf,
}

impl Format {
    /// Every format, in the order `--format` lists them.
    pub const ALL: [Format; 3] = [Format::Svg, Format::Png, Format::Pdf];

    /// The file extension and the format's name on the command line.
    pub fn extension(self) -> &'static str {
        match self {
            Format::Svg => "svg",
            Format::Png => "png",
            Format::Pdf => "pdf",
        }
    }

    /// Whether this build can write the format.
    pub fn available(self) -> bool {
        match self {
            Format::Svg => true,
            Format::Png => cfg!(feature = "png"),
            Format::Pdf => cfg!(feature = "pdf"),
        }
    }

    /// `Ok` when this build writes the format, else what to do.
    pub fn check_available(self) -> Result<(), String> {
        if self.available() {
            Ok(())
        } else {
            Err(format!(
                "this build of rig writes no {} figures: rebuild with the `figures` feature of the host crate (`cargo install --path host --features figures`), or use --format svg",
                self.extension().to_uppercase()
            ))
        }
    }
}

impl FromStr for Format {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "svg" => Ok(Format::Svg),
            "png" => Ok(Format::Png),
            "pdf" => Ok(Format::Pdf),
            other => Err(format!(
                "'{other}' is not a figure format: choose svg, png or pdf"
            )),
        }
    }
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.extension())
    }
}

/// Pixels per inch of the figures' drawings: CSS pixels, as SVG, resvg and svg2pdf measure
/// them (a figure drawn `w` px wide prints `w / 96` in wide, `0.75 w` pt).
pub const PX_PER_IN: f64 = 96.0;
/// A journal's single column, in (3.5 in: Elsevier 90 mm, IEEE 3.5 in, Springer 84 mm).
pub const SINGLE_COLUMN_IN: f64 = 3.5;
/// A journal's full page width, two columns, in (7.2 in: Elsevier 190 mm, IEEE 7.16 in).
pub const DOUBLE_COLUMN_IN: f64 = 7.2;
/// The smallest text a journal prints, pt (1/72 in).
pub const MIN_TEXT_PT: f64 = 7.0;
/// Resolution of a PNG of a journal width, dots per inch (the journals' line-art minimum).
pub const PNG_DPI: f64 = 300.0;

/// How wide a figure prints: the figures are drawn at this width ([`FigureSize::width_px`])
/// with their text sized for it, so the text keeps its size in points when printed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FigureSize {
    /// A journal's single column ([`SINGLE_COLUMN_IN`]).
    Single,
    /// A journal's full page width ([`DOUBLE_COLUMN_IN`]), the default.
    #[default]
    Double,
    /// This many pixels, printed at [`PX_PER_IN`] (a PNG of exactly these pixels).
    Pixels(u32),
}

impl FigureSize {
    /// The printed width, in.
    pub fn width_in(self) -> f64 {
        match self {
            Self::Single => SINGLE_COLUMN_IN,
            Self::Double => DOUBLE_COLUMN_IN,
            Self::Pixels(px) => f64::from(px) / PX_PER_IN,
        }
    }

    /// The drawing's width, px: the printed width at [`PX_PER_IN`].
    pub fn width_px(self) -> u32 {
        match self {
            Self::Pixels(px) => px,
            _ => (self.width_in() * PX_PER_IN).round() as u32,
        }
    }

    /// Font size, px of a drawing [`FigureSize::width_px`] wide, of text that prints `pt`
    /// points (1/72 in) high at [`FigureSize::width_in`]; rounded up to 0.01 px.
    pub fn font_px(self, pt: f64) -> f64 {
        let px = pt / 72.0 * f64::from(self.width_px()) / self.width_in();
        (px * 100.0).ceil() / 100.0
    }

    /// Width of a PNG of this size, px: [`PNG_DPI`] across a journal width, the pixels
    /// asked for otherwise.
    pub fn png_width_px(self) -> u32 {
        match self {
            Self::Pixels(px) => px,
            _ => (self.width_in() * PNG_DPI).round() as u32,
        }
    }
}

impl FromStr for FigureSize {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        parse_size(s)
    }
}

impl std::fmt::Display for FigureSize {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Single => f.write_str("single"),
            Self::Double => f.write_str("double"),
            Self::Pixels(px) => write!(f, "{px}"),
        }
    }
}

/// How the figures are written: format and size.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FigureOptions {
    /// The file format.
    pub format: Format,
    /// The printed width (the drawing's, a PNG's pixels, a PDF page's points).
    pub size: FigureSize,
}

/// Widest figure `--size` accepts, px (a 600 dpi page width is about 5000).
pub const MAX_WIDTH: u32 = 10_000;

/// Narrowest figure `--size` accepts, px: room for one panel with its 7 pt text.
pub const MIN_WIDTH: u32 = 100;

/// Parses a figure width, px: a whole number from [`MIN_WIDTH`] to [`MAX_WIDTH`].
pub fn parse_width(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(w) if (MIN_WIDTH..=MAX_WIDTH).contains(&w) => Ok(w),
        _ => Err(format!(
            "'{s}' is not a figure width: give `single` (3.5 in), `double` (7.2 in) or whole pixels from {MIN_WIDTH} to {MAX_WIDTH} (at 96 px/in)"
        )),
    }
}

/// Parses `--size`: `single` (a journal column, 3.5 in), `double` (a page width, 7.2 in)
/// or whole pixels ([`parse_width`], printed at 96 px/in).
pub fn parse_size(s: &str) -> Result<FigureSize, String> {
    match s.trim().to_ascii_lowercase().as_str() {
        "single" => Ok(FigureSize::Single),
        "double" => Ok(FigureSize::Double),
        _ => parse_width(s).map(FigureSize::Pixels),
    }
}

/// Writes the SVG figure `svg_path` in `options.format` beside it (same name, the format's
/// extension; atomically) and returns the path written; for SVG, the SVG itself (drawn at
/// its size already).
pub fn export(svg_path: &Path, options: &FigureOptions) -> Result<PathBuf, ReportError> {
    if options.format == Format::Svg {
        return Ok(svg_path.to_path_buf());
    }
    let plot_error = |why: String| ReportError::Plot {
        path: svg_path.display().to_string(),
        why,
    };
    options.format.check_available().map_err(plot_error)?;
    let svg = std::fs::read_to_string(svg_path).map_err(|source| ReportError::File {
        action: "read",
        path: svg_path.display().to_string(),
        source,
    })?;
    let out = svg_path.with_extension(options.format.extension());
    let bytes = convert(&svg, options).map_err(plot_error)?;
    crate::write_atomic(&out, &bytes)?;
    Ok(out)
}

/// `svg` (a document) converted to `options.format`'s bytes.
pub fn convert(svg: &str, options: &FigureOptions) -> Result<Vec<u8>, String> {
    match options.format {
        Format::Svg => Ok(svg.as_bytes().to_vec()),
        Format::Png => png(svg, options.size.png_width_px()),
        Format::Pdf => pdf(svg, options.size.width_in()),
    }
}

/// The system's fonts, with `sans-serif` (the figures' font) mapped to a sans face that is
/// there: fontdb's default (Arial) is missing on most Linux systems, and text in a face
/// that is not there is not drawn at all.
#[cfg(any(feature = "png", feature = "pdf"))]
fn load_fonts(db: &mut usvg_fonts::Database) {
    db.load_system_fonts();
    const SANS: [&str; 6] = [
        "DejaVu Sans",
        "Liberation Sans",
        "Noto Sans",
        "Arial",
        "Helvetica",
        "FreeSans",
    ];
    let has = |name: &str| {
        db.faces()
            .any(|f| f.families.iter().any(|(family, _)| family == name))
    };
    let family = SANS
        .iter()
        .find(|n| has(n))
        .map(|n| n.to_string())
        .or_else(|| {
            db.faces()
                .find_map(|f| f.families.first().map(|(family, _)| family.clone()))
        });
    if let Some(family) = family {
        db.set_sans_serif_family(family);
    }
}

#[cfg(feature = "png")]
use resvg::usvg::fontdb as usvg_fonts;
#[cfg(all(feature = "pdf", not(feature = "png")))]
use svg2pdf::usvg::fontdb as usvg_fonts;

#[cfg(feature = "png")]
fn png(svg: &str, width: u32) -> Result<Vec<u8>, String> {
    use resvg::{tiny_skia, usvg};
    let mut opt = usvg::Options::default();
    load_fonts(opt.fontdb_mut());
    let tree = usvg::Tree::from_str(svg, &opt).map_err(|e| e.to_string())?;
    let size = tree.size();
    let scale = width as f32 / size.width();
    let (w, h) = (
        (size.width() * scale).ceil() as u32,
        (size.height() * scale).ceil() as u32,
    );
    let mut pixmap = tiny_skia::Pixmap::new(w.max(1), h.max(1))
        .ok_or_else(|| format!("cannot make a {w} x {h} image"))?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        tiny_skia::Transform::from_scale(scale, scale),
        &mut pixmap.as_mut(),
    );
    pixmap.encode_png().map_err(|e| e.to_string())
}

#[cfg(not(feature = "png"))]
fn png(_svg: &str, _width: u32) -> Result<Vec<u8>, String> {
    Format::Png.check_available().map(|()| Vec::new())
}

/// A PDF page `width_in` wide: the drawing's width set to `width_in` * 96 px, converted at
/// 96 px/in (0.75 pt per SVG pixel).
#[cfg(feature = "pdf")]
fn pdf(svg: &str, width_in: f64) -> Result<Vec<u8>, String> {
    use svg2pdf::usvg;
    let mut opt = usvg::Options::default();
    load_fonts(opt.fontdb_mut());
    let svg = with_width(svg, width_in * PX_PER_IN);
    let tree = usvg::Tree::from_str(&svg, &opt).map_err(|e| e.to_string())?;
    svg2pdf::to_pdf(
        &tree,
        svg2pdf::ConversionOptions::default(),
        // SVG pixels are CSS pixels: 96 to the inch (svg2pdf's default is 72).
        svg2pdf::PageOptions {
            dpi: PX_PER_IN as f32,
        },
    )
    .map_err(|e| e.to_string())
}

#[cfg(not(feature = "pdf"))]
fn pdf(_svg: &str, _width_in: f64) -> Result<Vec<u8>, String> {
    Format::Pdf.check_available().map(|()| Vec::new())
}

/// The SVG document scaled to `width` (its viewBox kept, so the drawing scales): the
/// root's `width` and `height` attributes replaced.
#[cfg_attr(not(feature = "pdf"), allow(dead_code))]
fn with_width(svg: &str, width: f64) -> String {
    let Some(start) = svg.find("<svg") else {
        return svg.to_string();
    };
    let Some(len) = svg[start..].find('>') else {
        return svg.to_string();
    };
    let tag = &svg[start..start + len];
    let attr = |name: &str| -> Option<f64> {
        let key = format!(" {name}=\"");
        let at = tag.find(&key)? + key.len();
        let end = tag[at..].find('"')?;
        tag[at..at + end].trim_end_matches("px").parse().ok()
    };
    let (Some(w), Some(h)) = (attr("width"), attr("height")) else {
        return svg.to_string();
    };
    let height = h * width / w;
    let mut new_tag = tag.to_string();
    for (name, new) in [("width", width), ("height", height)] {
        let key = format!(" {name}=\"");
        if let Some(at) = new_tag.find(&key) {
            let from = at + key.len();
            if let Some(end) = new_tag[from..].find('"') {
                new_tag.replace_range(from..from + end, &new.to_string());
            }
        }
    }
    if !new_tag.contains("viewBox") {
        new_tag.push_str(&format!(" viewBox=\"0 0 {w} {h}\""));
    }
    format!("{}{}{}", &svg[..start], new_tag, &svg[start + len..])
}

#[cfg(test)]
mod tests {
    use super::*;

    const SVG: &str = "<svg width=\"200\" height=\"100\" xmlns=\"http://www.w3.org/2000/svg\"><rect x=\"10\" y=\"10\" width=\"50\" height=\"50\" fill=\"#0072b2\"/><text x=\"80\" y=\"50\" font-family=\"sans-serif\" font-size=\"12\">τ_rot, N m ± μ_d Λ ω_n</text></svg>";

    #[test]
    fn formats_and_widths_are_parsed_with_the_fix_in_the_message() {
        assert_eq!("PNG".parse::<Format>(), Ok(Format::Png));
        assert!(
            "gif"
                .parse::<Format>()
                .unwrap_err()
                .contains("svg, png or pdf")
        );
        assert_eq!(parse_width("1200"), Ok(1200));
        assert!(parse_width("0").unwrap_err().contains("100 to"));
        assert!(parse_width("wide").is_err());
        assert_eq!(parse_size("single"), Ok(FigureSize::Single));
        assert_eq!(parse_size("Double"), Ok(FigureSize::Double));
        assert_eq!(parse_size("800"), Ok(FigureSize::Pixels(800)));
        assert!(
            parse_size("wide")
                .unwrap_err()
                .contains("`single` (3.5 in)")
        );
        assert_eq!(FigureSize::default(), FigureSize::Double);
    }

    #[test]
    fn sizes_print_their_text_at_its_points() {
        // A single column is 336 px at 96 px/in, a page width 691 px (7.2 in: 691.2).
        assert_eq!(FigureSize::Single.width_px(), 336);
        assert_eq!(FigureSize::Double.width_px(), 691);
        assert_eq!(FigureSize::Pixels(500).width_in(), 500.0 / 96.0);
        for size in [
            FigureSize::Single,
            FigureSize::Double,
            FigureSize::Pixels(500),
        ] {
            // 7 pt = 7/72 in: at the printed width, font px * (in per px) * 72 >= 7.
            let px = size.font_px(MIN_TEXT_PT);
            let printed_pt = px * size.width_in() / f64::from(size.width_px()) * 72.0;
            assert!((7.0..7.01).contains(&printed_pt), "{size}: {printed_pt} pt");
        }
        // 96 px/in: 7 pt is 9.33 px on a drawing of pixels.
        assert_eq!(FigureSize::Pixels(500).font_px(7.0), 9.34);
        assert_eq!(FigureSize::Single.png_width_px(), 1050);
    }

    #[test]
    fn the_width_is_set_and_the_drawing_scales() {
        let scaled = with_width(SVG, 400.0);
        assert!(scaled.contains("width=\"400\" height=\"200\""), "{scaled}");
        assert!(scaled.contains("viewBox=\"0 0 200 100\""), "{scaled}");
    }

    #[cfg(feature = "png")]
    #[test]
    fn png_is_a_png_of_the_asked_width() {
        let bytes = convert(
            SVG,
            &FigureOptions {
                format: Format::Png,
                size: FigureSize::Pixels(400),
            },
        )
        .unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        // IHDR: width and height, big-endian, at bytes 16..24.
        let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
        let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
        assert_eq!((w, h), (400, 200));
    }

    #[cfg(feature = "pdf")]
    #[test]
    fn pdf_is_a_pdf() {
        let bytes = convert(
            SVG,
            &FigureOptions {
                format: Format::Pdf,
                size: FigureSize::Single,
            },
        )
        .unwrap();
        assert!(bytes.starts_with(b"%PDF-"));
        // A page of the printed width: 3.5 in = 252 pt (the 200 x 100 px drawing scaled).
        let page = crate::check::pdf_page_pt(&bytes).expect("a page");
        assert!(
            (page.0 - 252.0).abs() < 0.01 && (page.1 - 126.0).abs() < 0.01,
            "{page:?}"
        );
    }

    #[test]
    fn export_writes_beside_the_svg() {
        let dir = tempfile::tempdir().unwrap();
        let svg = dir.path().join("fig.svg");
        std::fs::write(&svg, SVG).unwrap();
        let same = export(&svg, &FigureOptions::default()).unwrap();
        assert_eq!(same, svg);
        for format in [Format::Png, Format::Pdf] {
            let o = FigureOptions {
                format,
                size: FigureSize::Single,
            };
            match export(&svg, &o) {
                Ok(p) => {
                    assert!(format.available());
                    assert_eq!(p, svg.with_extension(format.extension()));
                    assert!(std::fs::metadata(&p).unwrap().len() > 100);
                }
                Err(e) => {
                    assert!(!format.available());
                    assert!(e.to_string().contains("figures"), "{e}");
                }
            }
        }
    }
}
