//! `rig design`: command-line front of [`crate::design`].

use std::io::Write;
use std::process::ExitCode;

use clap::Args;
use model::Inertias;

use crate::design::{self, RigParams};
use crate::{RigError, args};

/// Arguments of `rig design`.
#[derive(Debug, Args)]
pub struct DesignArgs {
    /// Tooth counts Z1,Z2,Z3,Z4 (G1 fixed, G2-G3 planet, G4 output).
    #[arg(long, value_parser = args::parse_teeth, allow_hyphen_values = true, default_value = "49,51,50,50", conflicts_with = "table1")]
    z: [u32; 4],
    /// Evaluate the paper's six Table 1 gear sets instead of --z.
    #[arg(long)]
    table1: bool,
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
    /// Load torque on the output, N m.
    #[arg(long, value_parser = args::non_negative, default_value_t = model::TAU_ROT_MAX_PAPER, allow_hyphen_values = true)]
    tau_rot: f64,
    /// Vibration frequency, Hz.
    #[arg(long, value_parser = args::positive, default_value_t = 10.0, allow_hyphen_values = true)]
    freq: f64,
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

/// Runs `rig design`.
pub fn run(a: DesignArgs) -> Result<ExitCode, RigError> {
    if a.pressure_angle >= 45.0 {
        return Err(RigError::BadValue {
            what: format!("--pressure-angle {}", a.pressure_angle),
            why: "must be below 45 degrees (standard gears use 20)".into(),
        });
    }
    let params = RigParams {
        module: a.module * 1e-3,
        pressure_angle: a.pressure_angle.to_radians(),
        mu_s: a.mu_s,
        mu_d: a.mu_d,
        eccentricity: a.eccentricity_mm * 1e-3,
        carrier_mass: a.carrier_mass,
        tau_rot: a.tau_rot,
        vibration_hz: a.freq,
        inertias: match (a.i1, a.m23, a.i23, a.i4) {
            (Some(i1), Some(m23), Some(i23), Some(i4)) => Some(Inertias { i1, m23, i23, i4 }),
            _ => None,
        },
    };
    let sets: Vec<[u32; 4]> = if a.table1 {
        model::TABLE1.to_vec()
    } else {
        vec![a.z]
    };
    let reports = sets
        .into_iter()
        .map(|z| design::evaluate(z, &params, a.eta_gross))
        .collect::<Result<Vec<_>, _>>()?;
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
