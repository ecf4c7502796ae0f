//! The figure options of every verb that draws (`rig demo`, `rig calibrate`, `rig compare`,
//! `rig experiment`, `rig design search`, `rig explain` and `rig discover`): `--format`
//! and `--size`, defined once. Figures are drawn at the
//! width they print ([`reporting::figure::FigureSize`]) with every text 8 pt there
//! ([`reporting::plot::TEXT_PT`]); `reporting::check::check_svg` measures them.

use clap::Args;
use reporting::figure::{FigureOptions, FigureSize, Format};

/// `--format` and `--size` of a verb that draws.
#[derive(Debug, Clone, Copy, Args)]
pub struct FigureArgs {
    /// Figure format: svg, png (resvg; 300 dpi at a journal width) or pdf (svg2pdf; a page
    /// of the printed size); the SVG is always kept too.
    #[arg(long, default_value = "svg", value_parser = parse_format)]
    pub format: Format,
    /// Printed width: `single` (a journal column, 3.5 in), `double` (a page width, 7.2 in)
    /// or pixels (printed at 96 px/in: a PNG of that many pixels, a PDF of 0.75 pt each).
    /// Text is 8 pt at that width, never under 7; heights follow the panels' proportions
    /// [default: double].
    #[arg(long, value_name = "single|double|PX", value_parser = reporting::figure::parse_size)]
    pub size: Option<FigureSize>,
}

impl FigureArgs {
    /// The format and size asked for (the default size: a page width).
    pub fn options(&self) -> FigureOptions {
        FigureOptions {
            format: self.format,
            size: self.size.unwrap_or_default(),
        }
    }

    /// The printed size asked for.
    pub fn size(&self) -> FigureSize {
        self.size.unwrap_or_default()
    }

    /// Writes the SVG figures `svgs` also in the asked format (beside them); returns the
    /// files written (none for SVG).
    pub fn export_all(
        &self,
        svgs: &[std::path::PathBuf],
    ) -> Result<Vec<std::path::PathBuf>, crate::RigError> {
        let options = self.options();
        if options.format == Format::Svg {
            return Ok(Vec::new());
        }
        svgs.iter()
            .map(|svg| Ok(reporting::figure::export(svg, &options)?))
            .collect()
    }

    /// The option given on the command line, if either was (`--size` first).
    pub fn given(&self) -> Option<&'static str> {
        if self.size.is_some() {
            Some("--size")
        } else if self.format != Format::Svg {
            Some("--format")
        } else {
            None
        }
    }
}

/// A `--format` value this build can write.
pub fn parse_format(s: &str) -> Result<Format, String> {
    let f: Format = s.parse()?;
    f.check_available()?;
    Ok(f)
}
