//! `rig experiment`: the paper's experiments as procedures that run the same code on a
//! real rig (`--port`), on a served virtual rig, and on the in-process virtual rig
//! (`--sim`, and `rig sim fig5|table1|torque-sweep`), through one interface, [`Bench`].
//!
//! - [`sweep`]: the required-torque test (Figs. 8-9), writing `rig explain`'s CSV with
//!   provenance, resumable.
//! - [`hold_release`]: Fig. 5's time history before, during and after a release.
//! - [`backdrive`]: Table 1's verdicts, held or backdriven, without and with vibration.
//! - [`paper`]: the three on the in-process virtual rig, in the shapes `rig sim` prints.
//!
//! On a virtual rig the procedure hangs the load itself (`SimCommand::SetLoad`); on a real
//! one (or with `--operator`) it asks the operator ([`Operator`]).

pub mod backdrive;
pub mod bench;
pub mod hold_release;
pub mod paper;
pub mod plan;
pub mod sweep;

pub use bench::{Bench, DeviceBench, InProcessBench, Operator};
pub use plan::Plan;

/// The mass that loads the output with `tau_rot_nm` on the paper's output pulley (radius
/// `model::paper::R_OUT`), kg: what the operator hangs.
pub fn load_mass_kg(tau_rot_nm: f64) -> f64 {
    tau_rot_nm / (model::G * model::paper::R_OUT)
}

/// A load as the operator hangs it: `2.752 kg on the 75 mm pulley (2.024 N m)`.
pub fn load_text(tau_rot_nm: f64) -> String {
    format!(
        "{:.3} kg on the {} mm pulley ({} N m)",
        load_mass_kg(tau_rot_nm),
        reporting::human(model::paper::R_OUT * 1e3),
        reporting::human(reporting::significant(tau_rot_nm, 4))
    )
}

#[cfg(test)]
mod load_tests {
    #[test]
    fn loads_are_named_as_the_mass_on_the_pulley() {
        // Fig. 5: 1.0 kg on 75 mm is 0.7355 N m; 2.024 N m is 2.752 kg.
        let fig5 = model::paper::FIG5_LOAD.torque();
        assert!((super::load_mass_kg(fig5) - 1.0).abs() < 1e-12);
        assert_eq!(
            super::load_text(2.024),
            "2.752 kg on the 75 mm pulley (2.024 N m)"
        );
    }
}
