//! `rig design`: command-line front of [`crate::design`]; `rig design search` of
//! [`crate::design::search`].

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Args, Subcommand};
use model::Inertias;

use crate::design::search::{self, SearchSpace};
use crate::design::{self, CheckLimits, DesignReport, RigParams};
use crate::{RigError, args};

/// Arguments of `rig design`.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct DesignArgs {
    /// Search tooth numbers and profile shifts instead of evaluating one set.
    #[command(subcommand)]
    command: Option<DesignCommand>,
    /// Tooth counts Z1,Z2,Z3,Z4 (G1 fixed, G2-G3 planet, G4 output).
    #[arg(long, value_parser = args::parse_teeth, allow_hyphen_values = true, default_value = "49,51,50,50", conflicts_with = "table1")]
    z: [u32; 4],
    /// Profile shift coefficients x1,x2,x3,x4 (0 for standard gears); both meshes must
    /// share one working centre distance.
    #[arg(long, value_parser = parse_shifts, allow_hyphen_values = true, default_value = "0,0,0,0", conflicts_with = "table1")]
    x: [f64; 4],
    /// Evaluate the paper's six Table 1 gear sets instead of --z.
    #[arg(long)]
    table1: bool,
    #[command(flatten)]
    rig: RigArgs,
    /// Measured gross efficiency: also print the friction coefficient it implies (Eq. 12).
    #[arg(long, value_parser = args::efficiency, allow_hyphen_values = true)]
    eta_gross: Option<f64>,
    /// I1: inertia of input shaft and carrier, kg m^2 (with --m23, --i23, --i4 gives I_hat, Eq. 7).
    #[arg(long, value_parser = args::non_negative, requires_all = ["m23", "i23", "i4"], allow_hyphen_values = true)]
    i1: Option<f64>,
    /// M23: mass of the compound planet, kg.
    #[arg(long, value_parser = args::non_negative, requires = "i1", allow_hyphen_values = true)]
    m23: Option<f64>,
    /// I23: inertia of the compound planet, kg m^2.
    #[arg(long, value_parser = args::non_negative, requires = "i1", allow_hyphen_values = true)]
    i23: Option<f64>,
    /// I4: inertia of the output shaft, kg m^2.
    #[arg(long, value_parser = args::non_negative, requires = "i1", allow_hyphen_values = true)]
    i4: Option<f64>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// The rig values a design is evaluated at, shared by `rig design` and `rig design search`.
#[derive(Debug, Args)]
struct RigArgs {
    /// Module, mm.
    #[arg(long, value_parser = args::positive, default_value_t = 1.0, allow_hyphen_values = true)]
    module: f64,
    /// Pressure angle, degrees.
    #[arg(long, value_parser = args::positive, default_value_t = 20.0, allow_hyphen_values = true)]
    pressure_angle: f64,
    /// Static friction coefficient.
    #[arg(long, value_parser = args::non_negative, default_value_t = model::MU_S_PAPER, allow_hyphen_values = true)]
    mu_s: f64,
    /// Dynamic friction coefficient.
    #[arg(long, value_parser = args::non_negative, default_value_t = model::MU_D_PAPER, allow_hyphen_values = true)]
    mu_d: f64,
    /// Cam eccentricity (vibration amplitude), mm.
    #[arg(long = "e", value_parser = args::positive, default_value_t = 1.0, allow_hyphen_values = true)]
    eccentricity_mm: f64,
    /// Carrier mass M_hat = M1 + M23, kg.
    #[arg(long, value_parser = args::positive, default_value_t = model::CARRIER_MASS_PAPER, allow_hyphen_values = true)]
    carrier_mass: f64,
    /// Load torque on the output (the rated load of the strength and cam-torque checks), N m.
    #[arg(long, value_parser = args::non_negative, default_value_t = model::TAU_ROT_MAX_PAPER, allow_hyphen_values = true)]
    tau_rot: f64,
    /// Vibration frequency, Hz.
    #[arg(long, value_parser = args::positive, default_value_t = 10.0, allow_hyphen_values = true)]
    freq: f64,
    /// The board's current limit for the vibrator, A (the cam-torque check).
    #[arg(long, value_parser = args::positive, default_value_t = 4.5, allow_hyphen_values = true)]
    max_current: f64,
    /// Smallest tooth thickness at the tip, in modules.
    #[arg(long, value_parser = args::positive, default_value_t = 0.25, allow_hyphen_values = true)]
    min_tip_thickness: f64,
    /// Smallest contact ratio of each mesh.
    #[arg(long, value_parser = args::positive, default_value_t = 1.1, allow_hyphen_values = true)]
    min_contact_ratio: f64,
    /// Smallest root-stress margin against the paper's gear at 3.68 N m.
    #[arg(long, value_parser = args::positive, default_value_t = 1.0, allow_hyphen_values = true)]
    min_strength_margin: f64,
    /// Face width, mm: with --root-stress-limit also checks the root stress absolutely.
    #[arg(long, value_parser = args::positive, requires = "root_stress_limit", allow_hyphen_values = true)]
    face_width: Option<f64>,
    /// Permissible tooth-root stress of the material sigma_FP (ISO 6336-5), MPa.
    #[arg(long, value_parser = args::positive, requires = "face_width", allow_hyphen_values = true)]
    root_stress_limit: Option<f64>,
}

/// `rig design` subcommands.
#[derive(Debug, Subcommand)]
enum DesignCommand {
    /// Search tooth numbers and profile shifts for gears that hold, release and stop.
    Search(Box<SearchArgs>),
}

/// Arguments of `rig design search`.
#[derive(Debug, Args)]
struct SearchArgs {
    #[command(flatten)]
    rig: RigArgs,
    /// Tooth counts of every gear, MIN,MAX.
    #[arg(long, value_parser = parse_teeth_range, default_value = "45,55")]
    teeth: (u32, u32),
    /// Largest tooth difference n = |Z1 - Z4|.
    #[arg(long, default_value_t = 2)]
    max_n: u32,
    /// Largest |(Z1 + Z2) - (Z3 + Z4)| (closed by profile shift).
    #[arg(long, default_value_t = 2)]
    max_sum_difference: u32,
    /// Profile shift range, MIN,MAX.
    #[arg(long, value_parser = parse_range, allow_hyphen_values = true, default_value = "-0.5,1.0")]
    shift: (f64, f64),
    /// Step of the shift grid.
    #[arg(long, value_parser = args::positive, default_value_t = 0.1)]
    shift_step: f64,
    /// Range of |rho|, MIN,MAX.
    #[arg(long, value_parser = parse_range, default_value = "5,60")]
    ratio: (f64, f64),
    /// Range of the working centre distance, mm, MIN,MAX.
    #[arg(long, value_parser = parse_range, default_value = "48,52")]
    centre_distance: (f64, f64),
    /// Hold margin m_s: require mu_s Lambda >= 1 + m_s.
    #[arg(long, value_parser = args::non_negative, default_value_t = 0.05)]
    hold_margin: f64,
    /// Stop margin m_d: require mu_d Lambda >= 1 + m_d (with 1.15 the paper's output
    /// stops within seconds of the cam; just above 1 it coasts for minutes).
    #[arg(long, value_parser = args::non_negative, default_value_t = 0.15)]
    stop_margin: f64,
    /// Worker threads (default: the machine's cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Show at most this many designs of the front.
    #[arg(long, default_value_t = 20)]
    limit: usize,
    /// Draw the front into this SVG file.
    #[arg(long)]
    svg: Option<PathBuf>,
    /// The --svg plot's printed size, and a png or pdf of it beside it (with --svg).
    #[command(flatten)]
    figures: super::figures::FigureArgs,
    /// Write a rig file per shown design into this folder (design-01.toml, ...).
    #[arg(long)]
    write: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

/// Parses `x1,x2,x3,x4` profile shift coefficients.
fn parse_shifts(s: &str) -> Result<[f64; 4], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 4 {
        return Err(format!(
            "expected four comma-separated shift coefficients x1,x2,x3,x4 (for example 0,0,0,0), got {} value(s) in '{s}'",
            parts.len()
        ));
    }
    let mut x = [0.0; 4];
    for (i, p) in parts.iter().enumerate() {
        x[i] = args::finite(p).map_err(|e| format!("x{}: {e}", i + 1))?;
    }
    Ok(x)
}

/// Parses `MIN,MAX` numbers with MIN <= MAX.
fn parse_range(s: &str) -> Result<(f64, f64), String> {
    let Some((a, b)) = s.split_once(',') else {
        return Err(format!("expected MIN,MAX (for example 5,60), got '{s}'"));
    };
    let (a, b) = (args::finite(a)?, args::finite(b)?);
    if a > b {
        return Err(format!("MIN {a} is above MAX {b}"));
    }
    Ok((a, b))
}

/// Parses `MIN,MAX` tooth counts, each at least 4.
fn parse_teeth_range(s: &str) -> Result<(u32, u32), String> {
    let (a, b) = parse_range(s)?;
    if a < 4.0 || a.fract() != 0.0 || b.fract() != 0.0 || b > 400.0 {
        return Err(format!(
            "tooth counts must be whole numbers from 4 to 400, got '{s}'"
        ));
    }
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "checked 4..=400"
    )]
    Ok((a as u32, b as u32))
}

impl RigArgs {
    fn params(&self, inertias: Option<Inertias>) -> Result<RigParams, RigError> {
        if self.pressure_angle >= 45.0 {
            return Err(RigError::BadValue {
                what: format!("--pressure-angle {}", self.pressure_angle),
                why: "must be below 45 degrees (standard gears use 20)".into(),
            });
        }
        Ok(RigParams {
            module: self.module * 1e-3,
            pressure_angle: self.pressure_angle.to_radians(),
            mu_s: self.mu_s,
            mu_d: self.mu_d,
            eccentricity: self.eccentricity_mm * 1e-3,
            carrier_mass: self.carrier_mass,
            tau_rot: self.tau_rot,
            vibration_hz: self.freq,
            inertias,
            max_current_a: self.max_current,
            limits: CheckLimits {
                min_tip_thickness_modules: self.min_tip_thickness,
                min_contact_ratio: self.min_contact_ratio,
                min_strength_margin: self.min_strength_margin,
                material: match (self.face_width, self.root_stress_limit) {
                    (Some(b), Some(sigma)) => Some(design::Material {
                        face_width: b * 1e-3,
                        root_stress_limit: sigma * 1e6,
                    }),
                    _ => None,
                },
            },
            ..RigParams::default()
        })
    }
}

/// Runs `rig design`.
pub fn run(a: DesignArgs) -> Result<ExitCode, RigError> {
    if let Some(DesignCommand::Search(s)) = a.command {
        return run_search(*s);
    }
    let params = a.rig.params(match (a.i1, a.m23, a.i23, a.i4) {
        (Some(i1), Some(m23), Some(i23), Some(i4)) => Some(Inertias { i1, m23, i23, i4 }),
        _ => None,
    })?;
    let reports = if a.table1 {
        model::TABLE1
            .iter()
            .map(|&z| design::evaluate(z, &params, a.eta_gross))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        vec![design::evaluate_shifted(a.z, a.x, &params, a.eta_gross)?]
    };
    let mut out = std::io::stdout().lock();
    if a.json {
        if a.table1 {
            super::print_json(&mut out, &reports)?;
        } else {
            super::print_json(&mut out, &reports[0])?;
        }
    } else {
        for r in &reports {
            write!(out, "{}", design::render_text(r))?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn run_search(a: SearchArgs) -> Result<ExitCode, RigError> {
    if a.svg.is_none()
        && let Some(option) = a.figures.given()
    {
        return Err(RigError::BadValue {
            what: option.into(),
            why: "it sets the --svg plot's figure: add --svg FILE.svg".into(),
        });
    }
    let params = a.rig.params(None)?;
    if a.shift.0 < -1.0 || a.shift.1 > 2.0 {
        return Err(RigError::BadValue {
            what: format!("--shift {},{}", a.shift.0, a.shift.1),
            why: "profile shifts must lie within -1,2 (the range a gear set accepts)".into(),
        });
    }
    let points = ((a.shift.1 - a.shift.0) / a.shift_step).floor() + 1.0;
    if points > 200.0 {
        return Err(RigError::BadValue {
            what: format!("--shift-step {}", a.shift_step),
            why: format!(
                "{points} grid points per shift ({} candidates per tooth set): use a step of at least {:.3}",
                points.powi(3),
                (a.shift.1 - a.shift.0) / 199.0
            ),
        });
    }
    let space = SearchSpace {
        teeth: a.teeth,
        max_tooth_difference: a.max_n,
        max_sum_difference: a.max_sum_difference,
        shift: a.shift,
        shift_step: a.shift_step,
        ratio: a.ratio,
        centre_distance: (a.centre_distance.0 * 1e-3, a.centre_distance.1 * 1e-3),
        hold_margin: a.hold_margin,
        stop_margin: a.stop_margin,
    };
    let threads = a
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from));
    let mut result = search::search(&space, &params, threads);
    result.designs.truncate(a.limit);
    if let Some(path) = &a.svg {
        let options = a.figures.options();
        search::plot(path, &result, options.size)?;
        reporting::figure::export(path, &options)?;
    }
    let written = match &a.write {
        Some(dir) => write_rig_files(dir, &result.designs, &params)?,
        None => Vec::new(),
    };
    let mut out = std::io::stdout().lock();
    if a.json {
        super::print_json(&mut out, &result)?;
    } else {
        write!(out, "{}", search::render_table(&result))?;
        for p in &written {
            writeln!(out, "wrote {}", p.display())?;
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// One rig file per design in `dir`: the paper's rig with the design's gear.
fn write_rig_files(
    dir: &Path,
    designs: &[DesignReport],
    params: &RigParams,
) -> Result<Vec<PathBuf>, RigError> {
    std::fs::create_dir_all(dir).map_err(|source| RigError::BadValue {
        what: format!("--write {}", dir.display()),
        why: format!("cannot create the folder: {source}"),
    })?;
    let mut written = Vec::new();
    for (k, d) in designs.iter().enumerate() {
        let mut rig = rigfile::RigFile::default();
        rig.gear.z = d.z;
        rig.gear.profile_shift = d.x;
        rig.gear.module_mm = params.module * 1e3;
        rig.gear.pressure_angle_deg = params.pressure_angle.to_degrees();
        rig.friction.mu_s = params.mu_s;
        rig.friction.mu_d = params.mu_d;
        let path = dir.join(format!("design-{:02}.toml", k + 1));
        let comment = format!(
            "Designed by `rig design search`: mu_d Lambda {:.3}, |rho| {:.2}, cam torque {:.1} N mm, strength margin {:.3}",
            d.mu_d_lambda_conservative,
            d.rho.abs(),
            d.tau_cam_hat_nm * 1e3,
            d.strength_margin
        );
        rig.save_with_comment(&path, &comment)
            .map_err(|e| RigError::BadValue {
                what: path.display().to_string(),
                why: e.to_string(),
            })?;
        written.push(path);
    }
    Ok(written)
}
