//! Physics of the vibration-switched 2K-H planetary gear rig.
//!
//! Everything here follows Noda et al., "Switching backdrivability of a planetary gear by
//! vibration" (equation numbers in the docs are the paper's). Units are SI inside
//! (m, kg, N m, rad/s); the paper's N mm and mm only appear in the `*_paper` helpers of
//! [`calibration`] and at the edges of the host tools.
//!
//! `no_std` + `libm`, so the firmware runs exactly the code the host and the tests use.
#![cfg_attr(not(test), no_std)]

pub mod calibration;
pub mod dynamics;
pub mod effects;
pub mod excitation;
pub mod friction;
pub mod gear;
mod math;
pub mod plant;

pub use calibration::{Calibration, CalibrationConsistency};
pub use dynamics::{Inertias, OutputShaft};
pub use excitation::CamDrive;
pub use gear::{GearError, GearSet, TABLE1};

/// Standard gravity, m/s^2.
pub const G: f64 = 9.80665;

/// Static friction coefficient of the paper's gears (from eta_gross = 0.423).
pub const MU_S_PAPER: f64 = 0.271;
/// Dynamic friction coefficient of the paper's gears (from eta_gross = 0.533).
pub const MU_D_PAPER: f64 = 0.174;
/// Cam eccentricity (vibration amplitude) of the paper's rig, m.
pub const ECCENTRICITY_PAPER: f64 = 1.0e-3;
/// Carrier mass M_hat = M1 + M23 of the paper's rig, kg.
pub const CARRIER_MASS_PAPER: f64 = 3.82;
/// Equivalent output inertia I_hat of the paper's (49, 50) rig from CAD, kg m^2.
pub const I_HAT_PAPER: f64 = 2.79;
/// Carrier radius L of the paper's rig, m.
pub const CARRIER_RADIUS_PAPER: f64 = 0.100;
/// Largest load torque on the output the paper's gear teeth take, N m.
pub const TAU_ROT_MAX_PAPER: f64 = 3.68;
