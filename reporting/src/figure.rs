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

/// How the figures are written: format and width.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FigureOptions {
    /// The file format.
    pub format: Format,
    /// Width of a PNG in pixels, or of a PDF page in points (1/72 in); `None`: the
    /// figure's own size (its SVG pixels; a PDF then measures 0.75 pt per pixel).
    pub width: Option<u32>,
}

/// Widest figure `--size` accepts, px (a 600 dpi page width is about 5000).
pub const MAX_WIDTH: u32 = 10_000;

/// Parses a figure width, px: a whole number from 100 to [`MAX_WIDTH`].
pub fn parse_width(s: &str) -> Result<u32, String> {
    match s.trim().parse::<u32>() {
        Ok(w) if (100..=MAX_WIDTH).contains(&w) => Ok(w),
        _ => Err(format!(
            "'{s}' is not a figure width: give whole pixels from 100 to {MAX_WIDTH}"
        )),
    }
}

/// Writes the SVG figure `svg_path` in `options.format` beside it (same name, the format's
/// extension; atomically) and returns the path written; for SVG at its own size, the SVG
/// itself.
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
        Format::Png => png(svg, options.width),
        Format::Pdf => pdf(svg, options.width),
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
fn png(svg: &str, width: Option<u32>) -> Result<Vec<u8>, String> {
    use resvg::{tiny_skia, usvg};
    let mut opt = usvg::Options::default();
    load_fonts(opt.fontdb_mut());
    let tree = usvg::Tree::from_str(svg, &opt).map_err(|e| e.to_string())?;
    let size = tree.size();
    let scale = width.map_or(1.0, |w| w as f32 / size.width());
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
fn png(_svg: &str, _width: Option<u32>) -> Result<Vec<u8>, String> {
    Format::Png.check_available().map(|()| Vec::new())
}

#[cfg(feature = "pdf")]
fn pdf(svg: &str, width: Option<u32>) -> Result<Vec<u8>, String> {
    use svg2pdf::usvg;
    let mut opt = usvg::Options::default();
    load_fonts(opt.fontdb_mut());
    let mut svg = svg.to_string();
    if let Some(w) = width {
        svg = with_width(&svg, w);
    }
    let tree = usvg::Tree::from_str(&svg, &opt).map_err(|e| e.to_string())?;
    svg2pdf::to_pdf(
        &tree,
        svg2pdf::ConversionOptions::default(),
        svg2pdf::PageOptions::default(),
    )
    .map_err(|e| e.to_string())
}

#[cfg(not(feature = "pdf"))]
fn pdf(_svg: &str, _width: Option<u32>) -> Result<Vec<u8>, String> {
    Format::Pdf.check_available().map(|()| Vec::new())
}

/// The SVG document scaled to `width` (its viewBox kept, so the drawing scales): the
/// root's `width` and `height` attributes replaced.
#[cfg_attr(not(feature = "pdf"), allow(dead_code))]
fn with_width(svg: &str, width: u32) -> String {
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
    let height = (h * f64::from(width) / w).round();
    let mut new_tag = tag.to_string();
    for (name, old, new) in [("width", w, f64::from(width)), ("height", h, height)] {
        let _ = old;
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

    const SVG: &str = "<svg width=\"200\" height=\"100\" xmlns=\"http://www.w3.org/2000/svg\"><rect x=\"10\" y=\"10\" width=\"50\" height=\"50\" fill=\"#0072b2\"/><text x=\"80\" y=\"50\" font-family=\"sans-serif\" font-size=\"12\">[N m]</text></svg>";

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
    }

    #[test]
    fn the_width_is_set_and_the_drawing_scales() {
        let scaled = with_width(SVG, 400);
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
                width: Some(400),
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
                width: None,
            },
        )
        .unwrap();
        assert!(bytes.starts_with(b"%PDF-"));
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
                width: None,
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
