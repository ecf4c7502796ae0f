//! `rig compare`: the simulation-versus-measurement gap, before and after a fitted effect
//! ([`crate::compare`] replays the measured plan; this module parses and prints).

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Args;

use crate::RigError;
pub use crate::compare::{
    Comparison, GAP_DEFINITION, GapRow, compare, gap_figure, simulate, virtual_rig,
};
use rigfile::RigFile;

/// Arguments of `rig compare`.
#[derive(Debug, Args)]
pub struct CompareArgs {
    /// The measured sweep (`rig explain`'s CSV; a `rig experiment torque-sweep` file with its
    /// provenance header gives the plan's rest and window).
    #[arg(long, value_name = "FILE.csv")]
    pub measured: PathBuf,
    /// Rig file with a fitted [model] (`rig explain --write-model`) to compare against the
    /// base model [default: the base model alone].
    #[arg(long, value_name = "FILE")]
    pub model: Option<PathBuf>,
    /// Rig file of the base model (gear, friction, calibration; its [model] is ignored)
    /// [default: --model's rig without its [model], else the paper's].
    #[arg(long, value_name = "FILE")]
    pub rig: Option<PathBuf>,
    /// Seed of the virtual rig's sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Plot both gaps per test point to this SVG.
    #[arg(long, value_name = "FILE.svg")]
    pub svg: Option<PathBuf>,
    /// The --svg plot's printed size, and a png or pdf of it beside it (with --svg).
    #[command(flatten)]
    pub figures: super::figures::FigureArgs,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `rig compare`.
pub fn run(a: CompareArgs) -> Result<ExitCode, RigError> {
    if a.svg.is_none()
        && let Some(option) = a.figures.given()
    {
        return Err(RigError::BadValue {
            what: option.into(),
            why: "it sets the --svg plot's figure: add --svg FILE.svg".into(),
        });
    }
    crate::output_paths::refuse_outputs_over_inputs(
        &[
            ("--measured", Some(a.measured.as_path())),
            ("--model", a.model.as_deref()),
            ("--rig", a.rig.as_deref()),
        ],
        &[("--svg", a.svg.as_deref())],
    )?;
    let model_rig = match &a.model {
        Some(p) => {
            let rig = RigFile::load(p)?;
            if rig.model.is_none() {
                return Err(RigError::BadValue {
                    what: format!("--model {}", p.display()),
                    why: "the rig file has no fitted [model]: write one with `rig explain --measured X --write-model FILE`".into(),
                });
            }
            Some(rig)
        }
        None => None,
    };
    let base_rig = match (&a.rig, &model_rig) {
        (Some(p), _) => RigFile::load(p)?,
        (None, Some(m)) => m.clone(),
        (None, None) => RigFile::paper(),
    };
    let mut c = compare(&a.measured, &base_rig, model_rig.as_ref(), a.seed)?;
    c.model = a.model.as_ref().map(|p| p.display().to_string());
    if let Some(svg) = &a.svg {
        let options = a.figures.options();
        gap_figure(svg, &c, options.size)?;
        c.svg = Some(svg.display().to_string());
        if options.format != reporting::figure::Format::Svg {
            c.figure = Some(
                reporting::figure::export(svg, &options)?
                    .display()
                    .to_string(),
            );
        }
    }
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &c)?;
    } else {
        write_text(&mut out, &c)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// The comparison in words.
fn write_text(out: &mut impl Write, c: &Comparison) -> std::io::Result<()> {
    writeln!(
        out,
        "{} test points of {} replayed on the virtual rig:",
        c.points, c.measured
    )?;
    writeln!(
        out,
        "  gap (measured - simulated current), base model: rms {:.1} mA, mean {:+.1} mA",
        c.gap_rmse_base_a * 1e3,
        c.gap_mean_base_a * 1e3
    )?;
    if let (Some(m), Some(mm)) = (c.gap_rmse_model_a, c.gap_mean_model_a) {
        writeln!(
            out,
            "  with {}: rms {:.1} mA, mean {:+.1} mA ({:.0} % of the base model's)",
            if c.model_effects.is_empty() {
                "the fitted model (no effects)".to_string()
            } else {
                c.model_effects.join(", ")
            },
            m * 1e3,
            mm * 1e3,
            100.0 * c.gap_ratio.unwrap_or(f64::NAN)
        )?;
    }
    writeln!(out, "  (gap: {})", c.gap_definition)?;
    if !c.skipped_rows.is_empty() {
        writeln!(
            out,
            "  {} rows not replayed (the virtual rig could not run them: load above max_release_load_nm or a protection tripped), left out of the gaps: {}",
            c.skipped_rows.len(),
            c.skipped_rows
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        )?;
    }
    if let Some(s) = &c.svg {
        writeln!(out, "  plot: {s}")?;
    }
    if let Some(f) = &c.figure {
        writeln!(out, "  plot: {f}")?;
    }
    Ok(())
}
