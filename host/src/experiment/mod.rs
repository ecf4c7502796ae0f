//! `rig experiment`: the paper's experiments as procedures that run the same code on a
//! real rig (`--port`), on a served virtual rig, and on the in-process virtual rig
//! (`--sim`, and `rig sim fig5|table1|torque-sweep`), through one interface, [`Bench`].
//!
//! - [`sweep`]: the required-torque test (Figs. 8-9), writing `rig explain`'s CSV with
//!   provenance, resumable.
//! - [`hold_release`]: Fig. 5's time history before, during and after a release.
//! - [`backdrive`]: Table 1's verdicts, held or backdriven, without and with vibration.
//!
//! On a virtual rig the procedure hangs the load itself (`SimCommand::SetLoad`); on a real
//! one (or with `--operator`) it asks the operator ([`Operator`]).

pub mod backdrive;
pub mod bench;
pub mod hold_release;
pub mod plan;
pub mod sweep;

pub use bench::{Bench, DeviceBench, Operator, SimBench};
pub use plan::Plan;
