//! `backdrive_rig._native`: the Python extension behind the `backdrive_rig` package. A thin
//! door onto the host library (the `rig` tool's): the same client, procedures, checks and
//! error messages; no protocol, procedure or physics of its own. A Rust thread owns each
//! rig's port (module `worker`); every blocking call releases the GIL.
//!
//! Built as a wheel by maturin (`python/pyproject.toml`, feature `extension-module`); the
//! Python package (`python/backdrive_rig/`) turns the JSON and column bytes returned here
//! into objects, numpy arrays and pandas DataFrames.

// pyo3's macros expand to `unsafe` FFI glue; this crate writes none itself.
#![allow(unsafe_code)]

mod columns;
mod errors;
mod rig;
mod worker;

use std::path::PathBuf;

use host::RigError;
use host::design::RigParams;
use pyo3::prelude::*;

use errors::to_py;

/// `rig design --json` for tooth counts `z` (profile shifts `x`), or `--table1` (a list):
/// the paper's rig with the given values replaced.
#[pyfunction(name = "design")]
#[pyo3(signature = (z = None, x = None, table1 = false, eta_gross = None, module_mm = None,
    pressure_angle_deg = None, mu_s = None, mu_d = None, eccentricity_mm = None,
    carrier_mass_kg = None, tau_rot_nm = None, freq_hz = None, max_current_a = None))]
#[allow(clippy::too_many_arguments)]
fn design_report(
    z: Option<[u32; 4]>,
    x: Option<[f64; 4]>,
    table1: bool,
    eta_gross: Option<f64>,
    module_mm: Option<f64>,
    pressure_angle_deg: Option<f64>,
    mu_s: Option<f64>,
    mu_d: Option<f64>,
    eccentricity_mm: Option<f64>,
    carrier_mass_kg: Option<f64>,
    tau_rot_nm: Option<f64>,
    freq_hz: Option<f64>,
    max_current_a: Option<f64>,
) -> PyResult<String> {
    (|| -> Result<String, RigError> {
        let bad = |what: String, why: &str| RigError::BadValue {
            what,
            why: why.into(),
        };
        let mut p = RigParams::default();
        for (name, v) in [
            ("module_mm", module_mm),
            ("eccentricity_mm", eccentricity_mm),
            ("carrier_mass_kg", carrier_mass_kg),
            ("freq_hz", freq_hz),
            ("max_current_a", max_current_a),
        ] {
            if let Some(v) = v
                && !(v.is_finite() && v > 0.0)
            {
                return Err(bad(format!("{name} {v}"), "give a positive number"));
            }
        }
        for (name, v) in [("mu_s", mu_s), ("mu_d", mu_d), ("tau_rot_nm", tau_rot_nm)] {
            if let Some(v) = v
                && !(v.is_finite() && v >= 0.0)
            {
                return Err(bad(format!("{name} {v}"), "give zero or a positive number"));
            }
        }
        if let Some(a) = pressure_angle_deg
            && !(a.is_finite() && a > 0.0 && a < 45.0)
        {
            return Err(bad(
                format!("pressure_angle_deg {a}"),
                "must be above 0 and below 45 degrees (standard gears use 20)",
            ));
        }
        p.module = module_mm.map_or(p.module, |v| v * 1e-3);
        p.pressure_angle = pressure_angle_deg.map_or(p.pressure_angle, f64::to_radians);
        p.mu_s = mu_s.unwrap_or(p.mu_s);
        p.mu_d = mu_d.unwrap_or(p.mu_d);
        p.eccentricity = eccentricity_mm.map_or(p.eccentricity, |v| v * 1e-3);
        p.carrier_mass = carrier_mass_kg.unwrap_or(p.carrier_mass);
        p.tau_rot = tau_rot_nm.unwrap_or(p.tau_rot);
        p.vibration_hz = freq_hz.unwrap_or(p.vibration_hz);
        p.max_current_a = max_current_a.unwrap_or(p.max_current_a);
        if table1 {
            if z.is_some() || x.is_some() {
                return Err(bad(
                    "table1".into(),
                    "evaluates the six sets of Table 1: leave z and x out",
                ));
            }
            let reports = model::TABLE1
                .iter()
                .map(|&z| host::design::evaluate(z, &p, eta_gross))
                .collect::<Result<Vec<_>, _>>()?;
            return Ok(serde_json::to_string(&reports)?);
        }
        let z = z.unwrap_or(model::paper::RIG_Z);
        let report = host::design::evaluate_shifted(z, x.unwrap_or([0.0; 4]), &p, eta_gross)?;
        Ok(serde_json::to_string(&report)?)
    })()
    .map_err(to_py)
}

/// `rig explain --measured CSV [--model RIG] --json` (no report folder, no proposal): the
/// explanation's JSON. The CSV's provenance line of the drive's decay mode is read as the
/// CLI reads it.
#[pyfunction(name = "explain")]
#[pyo3(signature = (csv, model = None, alpha = None, folds = None, replicates = None, stated_noise_ma = None, propose = false))]
#[allow(clippy::too_many_arguments)]
fn explain_csv(
    py: Python<'_>,
    csv: PathBuf,
    model: Option<PathBuf>,
    alpha: Option<f64>,
    folds: Option<u32>,
    replicates: Option<u32>,
    stated_noise_ma: Option<f64>,
    propose: bool,
) -> PyResult<String> {
    py.detach(|| -> Result<String, RigError> {
        // The CLI's checks of each setting (`explain::options`), named as Python spells it.
        let options = ::explain::Options::checked(alpha, folds, replicates, stated_noise_ma)?;
        let rig = match &model {
            Some(p) => rigfile::RigFile::load(p)?,
            None => rigfile::RigFile::paper(),
        };
        let data = ::explain::Dataset::read_csv(&csv)?;
        let (rig, drive_warning) = host::provenance::with_stated_drive(rig, &csv);
        let mut outcome = ::explain::explain(&data, &rig, &options)?;
        outcome.explanation.warnings.extend(drive_warning);
        // As the CLI: a proposal on request, and offered when the data cannot separate the
        // leaders or a discrepancy remains that no named effect explains.
        let offered = matches!(
            outcome.explanation.verdict,
            ::explain::Verdict::Ambiguous | ::explain::Verdict::Unexplained
        );
        let proposal = (propose || offered).then(|| {
            host::explanation::proposal_for(
                &outcome,
                &data,
                &rig,
                &::explain::design::DesignOptions::default(),
            )
        });
        let mut value = serde_json::to_value(host::explanation::ExplainJson {
            explanation: &outcome.explanation,
            proposal: proposal
                .as_ref()
                .map(|proposal| host::explanation::ProposalJson {
                    proposal,
                    plan_written: None,
                }),
        })?;
        // Besides the CLI's keys: the plan's text, for `Rig.torque_sweep(plan_toml=...)`.
        if let (Some(p), Some(json)) = (
            &proposal,
            value.get_mut("proposal").and_then(|v| v.as_object_mut()),
        ) {
            let source = format!("proposed by backdrive_rig.explain for {}", csv.display());
            json.insert("plan_toml".into(), p.to_plan_toml(&source, 1).into());
        }
        Ok(serde_json::to_string(&value)?)
    })
    .map_err(to_py)
}

/// `rig compare --measured CSV [--model FITTED] [--rig BASE] --json`: the measured sweep
/// replayed on the virtual rig with the base model and, when given, the fitted one.
#[pyfunction(name = "compare")]
#[pyo3(signature = (measured, model = None, rig = None, seed = 1))]
fn compare_csv(
    py: Python<'_>,
    measured: PathBuf,
    model: Option<PathBuf>,
    rig: Option<PathBuf>,
    seed: u64,
) -> PyResult<String> {
    py.detach(|| -> Result<String, RigError> {
        // The CLI's resolution of --model and --rig, with its messages.
        let model_rig = match &model {
            Some(p) => {
                let r = rigfile::RigFile::load(p)?;
                if r.model.is_none() {
                    return Err(RigError::BadValue {
                        what: format!("model {}", p.display()),
                        why: "the rig file has no fitted [model]: write one with `rig explain --measured X --write-model FILE`".into(),
                    });
                }
                Some(r)
            }
            None => None,
        };
        let base_rig = match (&rig, &model_rig) {
            (Some(p), _) => rigfile::RigFile::load(p)?,
            (None, Some(m)) => m.clone(),
            (None, None) => rigfile::RigFile::paper(),
        };
        let mut c = host::compare::compare(&measured, &base_rig, model_rig.as_ref(), seed)?;
        c.model = model.as_ref().map(|p| p.display().to_string());
        Ok(serde_json::to_string(&c)?)
    })
    .map_err(to_py)
}

/// The host library's versions: the package's, the protocol's and its schema hash.
#[pyfunction]
fn versions() -> (String, u16, String) {
    (
        env!("CARGO_PKG_VERSION").to_owned(),
        protocol::PROTOCOL_VERSION,
        format!("{:#010x}", protocol::SCHEMA_HASH),
    )
}

/// The module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<rig::NativeRig>()?;
    m.add_class::<rig::NativeReleaseStatus>()?;
    m.add_class::<rig::NativeRecording>()?;
    m.add_function(wrap_pyfunction!(design_report, m)?)?;
    m.add_function(wrap_pyfunction!(explain_csv, m)?)?;
    m.add_function(wrap_pyfunction!(compare_csv, m)?)?;
    m.add_function(wrap_pyfunction!(versions, m)?)?;
    m.add("DEFAULT_BAUD_RATE", protocol::DEFAULT_BAUD_RATE)?;
    // Fig. 5's procedure as `rig experiment hold-release` runs it by default.
    let fig5 = host::experiment::hold_release::HoldRelease::default();
    let defaults = pyo3::types::PyDict::new(m.py());
    defaults.set_item("load_nm", fig5.load_nm)?;
    defaults.set_item("hold_s", fig5.hold_s)?;
    defaults.set_item("freq_hz", fig5.hz)?;
    defaults.set_item("release_s", fig5.release_s)?;
    defaults.set_item("after_s", fig5.after_s)?;
    m.add("HOLD_RELEASE_DEFAULTS", defaults)?;
    m.add("TELEMETRY_COLUMNS", host::monitor::CSV_HEADER.to_vec())?;
    m.add(
        "STREAM_COLUMNS",
        host::recording::STREAM_CSV_COLUMNS[..host::recording::STREAM_CSV_COLUMNS.len() - 1]
            .to_vec(),
    )?;
    m.add("MAX_STREAM_RATE_HZ", protocol::MAX_STREAM_RATE_HZ)?;
    Ok(())
}
