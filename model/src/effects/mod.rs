//! Effects beyond the paper's steady-state model of the vibrator current, each a physical
//! formula with its own parameters entering at its physical place, and the augmented
//! current model [`CurrentModel`] that carries them.
//!
//! The paper's model of the mean vibrator current at cam speed w_n under output load tau_rot
//! (Eqs. 10 and 15-17) is
//!
//! ```text
//! i = (tau_cam_hat(tau_rot, w_n; mu) + C3 w_n + C4 - C2) / C1,
//! tau_cam_hat = (2/pi) e F_ax + M_hat w_n^2 e^2 / pi,   F_ax = mu tau_rot 2 (1 + Z3/Z2) / (m Z4 cos a).
//! ```
//!
//! Each [`Effect`] adds one physical mechanism; with every parameter at zero the model is
//! exactly the paper's. With all effects:
//!
//! ```text
//! F_ax   = mu g(w_n) h(tau_rot) 2 |tau_rot| (1 + Z3/Z2) / (m Z4 cos a)
//!          g = w_n / sqrt(w_n^2 + w_c^2)             speed-dependent-axial-friction (Eq. 40)
//!          h = (|tau_rot| / tau_ref)^b                load-dependent-friction (seed 003, Eq. 12)
//! tau_f  = (2/pi) F_ax (e - c F_ax)                   tooth-compliance (seed 004)
//! tau_i  = (1 + kappa) M_hat w_n^2 e^2 / pi           inertia-rectification
//! tau_l  = C3 w_n + C4 + c_v w_n                      vibrator-viscous-loss
//! tau_b  = (2/pi) F_b e                               linear-bush-friction
//! i      = (tau_f + tau_i + tau_l + tau_b - C2) / (C1 (1 - k x)) + i_0
//!                                                     thermal-drift (x = T - T0 or t), current-sensor-offset
//! ```
//!
//! The mesh load-sharing ripple (seed 003, Eq. 11) does not move the mean: it scatters the
//! friction term from test to test ([`CurrentModel::friction_current`] times
//! [`EffectParams::mesh_ripple_rms`]). The linear bush also holds light loads at low cam
//! speed ([`CurrentModel::backdrives`]).
//!
//! The module's parts:
//!
//! - the laws (the functions and [`AxialSpeedLaw`] of this module): every effect law,
//!   written once; the current model, the plant
//!   ([`crate::plant`]) and the firmware's estimator call them. Where the plant runs a
//!   deliberately different shape (a robustness test of `rig explain`) that shape is a named
//!   variant of the law ([`AxialSpeedLaw::ExponentialDip`]).
//! - the mesh load-sharing ripple ([`mesh_friction`] and its helpers);
//! - [`EFFECTS`]: the one table describing every effect (name, law, parameters with units
//!   and bounds, the data it needs, how the plant takes it);
//! - [`CurrentModel`], the augmented current model, and [`CurrentEvaluator`], the same
//!   physics with its constants folded for fitting.

mod current_model;
mod evaluator;
mod laws;
mod mesh;
mod table;
#[cfg(test)]
mod tests;

pub use current_model::{CurrentModel, TorqueParts};
pub use evaluator::CurrentEvaluator;
pub use laws::*;
pub use mesh::*;
pub use table::*;

/// A named physical effect the paper's current model leaves out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "kebab-case"))]
pub enum Effect {
    /// The axial friction coefficient falls at low cam speed (the paper's own explanation of
    /// the low torque at 3.6 V): mu_ax = mu w_n / sqrt(w_n^2 + w_c^2), Eq. (40) with
    /// w_c = |w_t| / lambda.
    SpeedDependentAxialFriction,
    /// The friction coefficient changes with tooth load, as seed 003's average friction
    /// coefficient (Eq. 12 there, exponent 0.2): mu(tau) = mu (|tau| / tau_ref)^b.
    LoadDependentFriction,
    /// A constant offset of the current sensor (ACS714 zero not at Vcc/2), A.
    CurrentSensorOffset,
    /// The motor's torque constant falls as it warms: C1 -> C1 (1 - k (T - T0)), or
    /// C1 (1 - k t) when only the time is known.
    ThermalDrift,
    /// A speed-proportional vibrator loss missing from C3: extra torque c_v w_n.
    VibratorViscousLoss,
    /// How much of the carrier's inertial power the motor pays without taking it back:
    /// inertia term (1 + kappa) M_hat w_n^2 e^2 / pi. kappa = 0 is Eq. (10)'s acceleration-phase
    /// mean; kappa = -1 a regenerating drive (the term averages out over a turn); kappa = -1/2
    /// a drive that cannot take power back but lets the carrier coast (only the positive half,
    /// M_hat w_n^2 e^2 / (2 pi)); kappa = 1 the fully rectified 2 M_hat w_n^2 e^2 / pi.
    InertiaRectification,
    /// Coulomb friction F_b of the carrier's linear bush: extra cam torque (2/pi) F_b e, and a
    /// holding torque that keeps light loads from backdriving at low cam speed.
    LinearBushFriction,
    /// Axial compliance c of the tooth contacts (seed 004): the teeth deflect F_ax c before
    /// they slide, so the sliding stroke is e - c F_ax.
    ToothCompliance,
    /// Load sharing between single- and double-tooth contact (seed 003, Eq. 11) with a
    /// load-dependent local friction modulates the friction over a mesh cycle; the current's
    /// averaging window sits at a random mesh phase, so the friction term scatters.
    MeshLoadSharingRipple,
}

impl Effect {
    /// Every effect, in the order of the library.
    pub const ALL: [Effect; 9] = [
        Effect::SpeedDependentAxialFriction,
        Effect::LoadDependentFriction,
        Effect::CurrentSensorOffset,
        Effect::ThermalDrift,
        Effect::VibratorViscousLoss,
        Effect::InertiaRectification,
        Effect::LinearBushFriction,
        Effect::ToothCompliance,
        Effect::MeshLoadSharingRipple,
    ];

    /// The effect's name, as on the command line and in rig files ([`EFFECTS`]).
    pub const fn name(self) -> &'static str {
        self.info().name
    }

    /// The effect called `name` (see [`Effect::name`]).
    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The parameter of the mean current this effect brings, if any (the ripple only
    /// scatters the current; [`EFFECTS`]).
    pub const fn mean_param(self) -> Option<Param> {
        match self.info().mean {
            Some(m) => Some(m.param),
            None => None,
        }
    }
}

/// Number of parameters of the mean current, see [`Param`].
pub const PARAM_COUNT: usize = 9;

/// The parameters of the mean current, as a vector for fitting ([`CurrentModel::params`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Param {
    /// mu of Eq. (10).
    Mu,
    /// w_c^2 of the speed-dependent axial friction, rad^2/s^2 (squared so the model is
    /// smooth at w_c = 0).
    AxialCornerSq,
    /// Exponent b of the load-dependent friction.
    LoadExponent,
    /// Axial tooth compliance c, m/N.
    ToothCompliance,
    /// Rectification kappa of the inertia term.
    Rectification,
    /// Extra viscous vibrator loss c_v, N m s/rad.
    ViscousLoss,
    /// Coulomb force of the linear bush F_b, N.
    BushForce,
    /// Thermal coefficient k of the torque constant, 1/K (or 1/s against time).
    ThermalCoeff,
    /// Current-sensor offset i_0, A.
    CurrentOffset,
}

impl Param {
    /// Every parameter, in vector order.
    pub const ALL: [Param; PARAM_COUNT] = [
        Param::Mu,
        Param::AxialCornerSq,
        Param::LoadExponent,
        Param::ToothCompliance,
        Param::Rectification,
        Param::ViscousLoss,
        Param::BushForce,
        Param::ThermalCoeff,
        Param::CurrentOffset,
    ];

    /// Position in the parameter vector.
    pub const fn index(self) -> usize {
        self as usize
    }
}

/// Parameters of the effects; zero means the effect is absent.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct EffectParams {
    /// w_c of the speed-dependent axial friction, rad/s.
    pub axial_corner_speed: f64,
    /// Exponent b of the load-dependent friction (seed 003's average friction uses 0.2).
    pub load_exponent: f64,
    /// Axial compliance c of the tooth contacts, m/N.
    pub tooth_compliance: f64,
    /// kappa of the inertia rectification (0: the paper's Eq. 10, -1: averaged out, 1: fully
    /// rectified; see [`Effect::InertiaRectification`]).
    pub rectification: f64,
    /// Extra viscous vibrator loss c_v, N m s/rad.
    pub viscous_loss: f64,
    /// Coulomb force of the linear bush F_b, N.
    pub bush_force: f64,
    /// Holding torque of the linear bush at the output without vibration, N m.
    pub bush_hold_torque: f64,
    /// Cam speed over which vibration frees the bush, rad/s (see [`bush_holding_torque`]).
    pub bush_corner_speed: f64,
    /// Thermal coefficient k of the torque constant, 1/K (or 1/s, see [`OperatingPoint`]).
    pub thermal_coeff: f64,
    /// Current-sensor offset i_0, A.
    pub current_offset: f64,
    /// Relative rms scatter of the friction term from the mesh load-sharing ripple.
    pub mesh_ripple_rms: f64,
}

/// One steady-state operating point of the vibrator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OperatingPoint {
    /// Cam speed w_n, rad/s.
    pub omega_n: f64,
    /// Load torque on the output tau_rot, N m.
    pub tau_rot: f64,
    /// Thermal driver x of the thermal drift: T - T0 in K when the motor temperature is
    /// known, else the time since the first test in s (0 when neither is known).
    pub thermal: f64,
    /// ln(|tau_rot| / tau_ref), cached for the load-dependent friction (0 at zero load).
    ln_load: f64,
    /// w_n^2, cached.
    omega_sq: f64,
}

impl OperatingPoint {
    /// The point at cam speed `omega_n` (rad/s), load `tau_rot` (N m) and thermal driver
    /// `thermal` (see [`OperatingPoint::thermal`]).
    pub fn new(omega_n: f64, tau_rot: f64, thermal: f64) -> Self {
        let load = tau_rot.abs();
        Self {
            omega_n,
            tau_rot,
            thermal,
            ln_load: if load > 0.0 {
                libm::log(load / LOAD_FRICTION_REFERENCE_NM)
            } else {
                0.0
            },
            omega_sq: omega_n * omega_n,
        }
    }
}
