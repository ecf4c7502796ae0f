//! Physics of the vibration-switched 2K-H planetary gear rig.
//!
//! Everything here follows Noda et al., "Switching backdrivability of a planetary gear by
//! vibration" (equation numbers in the docs are the paper's). Units are SI inside
//! (m, kg, N m, rad/s); the paper's N mm and mm only appear in the `*_paper` helpers of
//! [`calibration`] and at the edges of the host tools.
//!
//! `no_std` + `libm`, so the firmware runs exactly the code the host and the tests use.
//!
//! One home for each fact:
//!
//! - [`paper`]: the paper's numbers (Tables 1 and 2, mu_s, mu_d, e, M_hat, I_hat, L, the
//!   test conditions, Fig. 5's load);
//! - [`hardware`]: the rig's hardware constants (RS-735, ACS714 and its divider, ADC,
//!   AMT102, the board);
//! - [`effects`]: every effect law beyond the paper, the table describing them
//!   ([`effects::EFFECTS`]) and the augmented current model;
//! - [`calibration`]: C1-C6 in SI, their plausibility ([`Calibration::check`]) and the
//!   board's caps ([`BoardLimits`]).
#![cfg_attr(not(test), no_std)]
// No silent numeric narrowing on the target: every cast that can truncate, lose a sign or
// wrap is written so it cannot, or carries an `allow` with its reason.
#![deny(
    clippy::cast_possible_truncation,
    clippy::cast_sign_loss,
    clippy::cast_possible_wrap
)]

pub mod calibration;
pub mod dynamics;
pub mod effects;
pub mod excitation;
pub mod friction;
pub mod gear;
pub mod hardware;
pub mod involute;
pub mod load;
mod math;
pub mod paper;
pub mod plant;
pub mod tooth_strength;

pub use calibration::{
    BoardLimits, Calibration, CalibrationConsistency, CalibrationField, CalibrationIssue,
    CheckFloat, IssueKind, LimitField, LimitIssue, LimitIssueKind, check_constants, check_limits,
};
pub use dynamics::{Inertias, OutputShaft};
pub use excitation::CamDrive;
pub use gear::{GearError, GearSet};
pub use hardware::MotorConstants;
pub use paper::TABLE1;

/// Standard gravity, m/s^2.
pub const G: f64 = 9.80665;

// The paper's constants under their older names; their one home is [`paper`].
pub use paper::{
    CARRIER_MASS as CARRIER_MASS_PAPER, CARRIER_RADIUS as CARRIER_RADIUS_PAPER,
    ECCENTRICITY as ECCENTRICITY_PAPER, I_HAT as I_HAT_PAPER, MU_D as MU_D_PAPER,
    MU_S as MU_S_PAPER, TAU_ROT_MAX as TAU_ROT_MAX_PAPER,
};
