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

use core::f64::consts::PI;

use crate::{Calibration, CamDrive};

/// Load torque at which the load-dependent friction coefficient equals mu, N m.
pub const LOAD_FRICTION_REFERENCE_NM: f64 = 1.0;

/// Local friction exponent of seed 003's average friction coefficient (Eq. 12 there):
/// mu ~ (load)^0.2. Used for the mesh load-sharing ripple.
pub const ISO_LOAD_EXPONENT: f64 = 0.2;

/// The smallest torque-constant factor 1 - k x the model accepts (keeps the current finite).
const MIN_TORQUE_CONSTANT_FACTOR: f64 = 0.1;

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

    /// The effect's name, as on the command line and in rig files.
    pub const fn name(self) -> &'static str {
        match self {
            Effect::SpeedDependentAxialFriction => "speed-dependent-axial-friction",
            Effect::LoadDependentFriction => "load-dependent-friction",
            Effect::CurrentSensorOffset => "current-sensor-offset",
            Effect::ThermalDrift => "thermal-drift",
            Effect::VibratorViscousLoss => "vibrator-viscous-loss",
            Effect::InertiaRectification => "inertia-rectification",
            Effect::LinearBushFriction => "linear-bush-friction",
            Effect::ToothCompliance => "tooth-compliance",
            Effect::MeshLoadSharingRipple => "mesh-load-sharing-ripple",
        }
    }

    /// The effect called `name` (see [`Effect::name`]).
    pub fn from_name(name: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The parameter of the mean current this effect brings, if any (the ripple only
    /// scatters the current).
    pub const fn mean_param(self) -> Option<Param> {
        match self {
            Effect::SpeedDependentAxialFriction => Some(Param::AxialCornerSq),
            Effect::LoadDependentFriction => Some(Param::LoadExponent),
            Effect::CurrentSensorOffset => Some(Param::CurrentOffset),
            Effect::ThermalDrift => Some(Param::ThermalCoeff),
            Effect::VibratorViscousLoss => Some(Param::ViscousLoss),
            Effect::InertiaRectification => Some(Param::Rectification),
            Effect::LinearBushFriction => Some(Param::BushForce),
            Effect::ToothCompliance => Some(Param::ToothCompliance),
            Effect::MeshLoadSharingRipple => None,
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

/// Speed factor of the axial friction coefficient, Eq. (40) of the paper:
/// mu_ax / mu = w_n / sqrt(w_n^2 + w_c^2) with w_c = |w_t| / lambda (the output speed over
/// lambda of Eq. 41). 1 when `omega_c` is zero.
pub fn axial_friction_speed_factor(omega_n: f64, omega_c: f64) -> f64 {
    let w = omega_n.abs();
    let d = libm::sqrt(w * w + omega_c * omega_c);
    if d == 0.0 { 1.0 } else { w / d }
}

/// Corner speed w_c = |w_t| / lambda of Eq. (40) for an output speed `omega_t` (rad/s) and
/// the gear's lambda (Eq. 41).
pub fn axial_corner_speed(omega_t: f64, small_lambda: f64) -> f64 {
    omega_t.abs() / small_lambda
}

/// Load factor of the friction coefficient, mu(tau) / mu = (|tau| / tau_ref)^b with
/// tau_ref = [`LOAD_FRICTION_REFERENCE_NM`]; seed 003's average friction coefficient (Eq. 12
/// there) grows with the tooth load to the power 0.2.
pub fn load_friction_factor(tau_rot: f64, exponent: f64) -> f64 {
    let load = tau_rot.abs();
    if load == 0.0 || exponent == 0.0 {
        1.0
    } else {
        libm::pow(load / LOAD_FRICTION_REFERENCE_NM, exponent)
    }
}

/// Fraction of the cam stroke over which the teeth slide when the axial tooth compliance is
/// `compliance` (m/N) and the axial friction force is `friction_force` (N): the contacts first
/// deflect F c (seed 004's elastic tooth displacement), then slide over e - F c.
pub fn compliance_stroke_factor(friction_force: f64, eccentricity: f64, compliance: f64) -> f64 {
    (1.0 - compliance * friction_force.abs() / eccentricity).max(0.0)
}

/// Mean inertia torque of the cam, (1 + kappa) M_hat w_n^2 e^2 / pi, N m, floored at zero.
/// `kappa` = 0 is Eq. (10)'s term (the mean over the acceleration phase); -1 a drive that
/// takes all the carrier's inertial power back (the term averages out over a turn); -1/2 one
/// that takes nothing back but lets the carrier coast (the positive half of Eq. 9's inertia
/// term, M_hat w_n^2 e^2 / (2 pi)); 1 the fully rectified mean 2 M_hat w_n^2 e^2 / pi (the
/// motor also brakes the carrier in the deceleration phase).
pub fn rectified_inertia_torque(drive: &CamDrive, omega_n: f64, kappa: f64) -> f64 {
    ((1.0 + kappa) * drive.required_inertia_torque(omega_n)).max(0.0)
}

/// Mean cam torque of a Coulomb force `force` (N) against the carrier's axial motion of
/// amplitude `eccentricity` (m): the mean of F e |sin| over a turn, (2/pi) F e, N m.
pub fn bush_cam_torque(force: f64, eccentricity: f64) -> f64 {
    2.0 / PI * force.abs() * eccentricity
}

/// Output torque the linear bush holds while the cam turns at `omega_n`: as in Eq. (39), the
/// axial slip takes the bush's friction away from the rotation, so its grip fades with cam
/// speed, T_hold(w_n) = T_0 / (1 + w_n / w_b), N m (the plant's form, see
/// `plant::PlantEffects::bush_hold_torque`). `omega_b` = 0 means vibration frees it at once.
pub fn bush_holding_torque(hold_torque: f64, omega_n: f64, omega_b: f64) -> f64 {
    if omega_b <= 0.0 {
        return 0.0;
    }
    hold_torque.abs() / (1.0 + omega_n.abs() / omega_b)
}

/// Torque constant after thermal drift, C1 (1 - k x), floored at a tenth of C1.
pub fn drifted_torque_constant(c1: f64, coeff: f64, thermal: f64) -> f64 {
    c1 * (1.0 - coeff * thermal).max(MIN_TORQUE_CONSTANT_FACTOR)
}

/// Load share of a tooth pair at position `x` along the path of contact, in base pitches
/// from the start of contact (0 ..= contact ratio), seed 003's Eq. (11): rising from 0.36 to
/// 0.64 in the double-contact zone of entry, 1 in single contact, falling from 0.64 to 0.36
/// in the double-contact zone of exit. `contact_ratio` is clamped to [1.05, 2].
pub fn load_sharing_factor(x: f64, contact_ratio: f64) -> f64 {
    let eps = contact_ratio.clamp(1.05, 2.0);
    let x = x.clamp(0.0, eps);
    if x < eps - 1.0 {
        0.36 + 0.28 * x / (eps - 1.0)
    } else if x < 1.0 {
        1.0
    } else {
        0.36 - 0.28 * (x - eps) / (eps - 1.0)
    }
}

/// Total mesh friction at mesh phase `phase` (0..1 of a base pitch) relative to a single pair
/// carrying the whole load, when the local friction coefficient grows with the local load to
/// the power `load_exponent` (seed 003, Eq. 12: 0.2): sum of lambda^(1 + b) over the pairs in
/// contact.
pub fn mesh_friction(phase: f64, contact_ratio: f64, load_exponent: f64) -> f64 {
    let eps = contact_ratio.clamp(1.05, 2.0);
    let phi = phase - libm::floor(phase);
    let mut total = libm::pow(load_sharing_factor(phi, eps), 1.0 + load_exponent);
    if phi + 1.0 < eps {
        total += libm::pow(load_sharing_factor(phi + 1.0, eps), 1.0 + load_exponent);
    }
    total
}

/// Points per mesh cycle of the averages in [`mesh_friction_modulation`].
const MESH_SAMPLES: usize = 256;

/// Relative deviation of the mesh friction at `phase` from its mean over a mesh cycle,
/// normalised to unit rms: the shape of the ripple the current window sees at a random
/// phase. Zero for a contact ratio at which the friction does not vary.
pub fn mesh_friction_modulation(phase: f64, contact_ratio: f64, load_exponent: f64) -> f64 {
    let (mean, rms) = mesh_friction_stats(contact_ratio, load_exponent);
    if rms == 0.0 {
        return 0.0;
    }
    (mesh_friction(phase, contact_ratio, load_exponent) / mean - 1.0) / rms
}

/// Mean of [`mesh_friction`] over a cycle and the rms of its relative deviation.
pub fn mesh_friction_stats(contact_ratio: f64, load_exponent: f64) -> (f64, f64) {
    let n = MESH_SAMPLES as f64;
    let sample = |k: usize| mesh_friction((k as f64 + 0.5) / n, contact_ratio, load_exponent);
    let mean = (0..MESH_SAMPLES).map(sample).sum::<f64>() / n;
    let var = (0..MESH_SAMPLES)
        .map(|k| {
            let d = sample(k) / mean - 1.0;
            d * d
        })
        .sum::<f64>()
        / n;
    (mean, libm::sqrt(var))
}

/// The paper's steady-state vibrator current (Eqs. 10, 15-17) with the effects of
/// [`EffectParams`]; every effect at zero gives the paper's model.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct CurrentModel {
    /// Gear set, eccentricity and carrier mass.
    pub drive: CamDrive,
    /// Vibrator calibration C1-C6.
    pub calibration: Calibration,
    /// Friction coefficient mu of Eq. (10).
    pub mu: f64,
    /// The effects (zero: absent).
    pub effects: EffectParams,
}

/// Parts of the cam torque at one operating point, N m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TorqueParts {
    /// Axial friction force F_ax at the teeth, N.
    pub axial_force: f64,
    /// Friction term (2/pi) F_ax (e - c F_ax).
    pub friction: f64,
    /// Inertia term (1 + kappa) M_hat w_n^2 e^2 / pi.
    pub inertia: f64,
    /// Vibrator loss C3 w_n + C4 + c_v w_n.
    pub loss: f64,
    /// Linear bush term (2/pi) F_b e.
    pub bush: f64,
}

impl TorqueParts {
    /// Gross shaft torque the motor delivers: every part.
    pub fn total(&self) -> f64 {
        self.friction + self.inertia + self.loss + self.bush
    }
}

impl CurrentModel {
    /// The paper's model around `drive` with calibration `calibration` and friction `mu`.
    pub fn paper(drive: CamDrive, calibration: Calibration, mu: f64) -> Self {
        Self {
            drive,
            calibration,
            mu,
            effects: EffectParams::default(),
        }
    }

    /// Axial friction force at the teeth F_ax, N (Eq. 8's friction part with mu_ax(w_n, tau)).
    pub fn axial_force(&self, op: &OperatingPoint) -> f64 {
        let e = &self.effects;
        let g = axial_friction_speed_factor(op.omega_n, e.axial_corner_speed);
        let h = if e.load_exponent == 0.0 {
            1.0
        } else {
            libm::exp(e.load_exponent * op.ln_load)
        };
        self.drive.friction_force(self.mu * g * h, op.tau_rot)
    }

    /// The parts of the mean cam torque at `op`.
    pub fn torque_parts(&self, op: &OperatingPoint) -> TorqueParts {
        let e = &self.effects;
        let ecc = self.drive.eccentricity;
        let f = self.axial_force(op);
        let w = op.omega_n.abs();
        TorqueParts {
            axial_force: f,
            friction: 2.0 / PI * f * ecc * compliance_stroke_factor(f, ecc, e.tooth_compliance),
            inertia: rectified_inertia_torque(&self.drive, w, e.rectification),
            loss: self.calibration.loss_torque(w) + e.viscous_loss * w,
            bush: bush_cam_torque(e.bush_force, ecc),
        }
    }

    /// The torque constant at `op` after thermal drift, N m/A.
    pub fn torque_constant(&self, op: &OperatingPoint) -> f64 {
        drifted_torque_constant(self.calibration.c1, self.effects.thermal_coeff, op.thermal)
    }

    /// Mean vibrator current at `op`, A: (torque - C2) / C1' + i_0.
    pub fn current(&self, op: &OperatingPoint) -> f64 {
        let t = self.torque_parts(op).total();
        (t - self.calibration.c2) / self.torque_constant(op) + self.effects.current_offset
    }

    /// The current the friction term draws, A: the part the mesh ripple scatters.
    pub fn friction_current(&self, op: &OperatingPoint) -> f64 {
        self.torque_parts(op).friction / self.torque_constant(op)
    }

    /// Whether the load backdrives at `op`: the linear bush holds loads below
    /// [`bush_holding_torque`]; without a bush every vibrated load backdrives (Eq. 39).
    pub fn backdrives(&self, op: &OperatingPoint) -> bool {
        let e = &self.effects;
        op.tau_rot.abs() > bush_holding_torque(e.bush_hold_torque, op.omega_n, e.bush_corner_speed)
    }

    /// The parameter vector (see [`Param`]; the axial corner speed enters squared).
    pub fn params(&self) -> [f64; PARAM_COUNT] {
        let e = &self.effects;
        [
            self.mu,
            e.axial_corner_speed * e.axial_corner_speed,
            e.load_exponent,
            e.tooth_compliance,
            e.rectification,
            e.viscous_loss,
            e.bush_force,
            e.thermal_coeff,
            e.current_offset,
        ]
    }

    /// Sets the parameter vector (inverse of [`CurrentModel::params`]).
    pub fn set_params(&mut self, p: &[f64; PARAM_COUNT]) {
        self.mu = p[0];
        let e = &mut self.effects;
        e.axial_corner_speed = libm::sqrt(p[1].max(0.0));
        e.load_exponent = p[2];
        e.tooth_compliance = p[3];
        e.rectification = p[4];
        e.viscous_loss = p[5];
        e.bush_force = p[6];
        e.thermal_coeff = p[7];
        e.current_offset = p[8];
    }

    /// Mean current at `op` and its gradient with respect to [`CurrentModel::params`].
    pub fn current_and_gradient(&self, op: &OperatingPoint, grad: &mut [f64; PARAM_COUNT]) -> f64 {
        self.evaluator().current_and_gradient(op, grad)
    }

    /// The model with its constants folded, for evaluating many operating points.
    pub fn evaluator(&self) -> CurrentEvaluator {
        let e = &self.effects;
        let ecc = self.drive.eccentricity;
        CurrentEvaluator {
            mu: self.mu,
            axial_per_torque: self.drive.gear.axial_force_per_torque(),
            eccentricity: ecc,
            inertia_per_omega_sq: self.drive.required_inertia_torque(1.0),
            corner_sq: e.axial_corner_speed * e.axial_corner_speed,
            load_exponent: e.load_exponent,
            compliance: e.tooth_compliance,
            rectification: e.rectification,
            viscous: self.calibration.c3 + e.viscous_loss,
            constant_torque: self.calibration.c4 + bush_cam_torque(e.bush_force, ecc)
                - self.calibration.c2,
            bush_per_force: 2.0 / PI * ecc,
            c1: self.calibration.c1,
            thermal_coeff: e.thermal_coeff,
            current_offset: e.current_offset,
        }
    }
}

/// A [`CurrentModel`] with its constants folded (see [`CurrentModel::evaluator`]): the same
/// physics, evaluated without recomputing the gear geometry at every point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurrentEvaluator {
    mu: f64,
    axial_per_torque: f64,
    eccentricity: f64,
    inertia_per_omega_sq: f64,
    corner_sq: f64,
    load_exponent: f64,
    compliance: f64,
    rectification: f64,
    viscous: f64,
    constant_torque: f64,
    bush_per_force: f64,
    c1: f64,
    thermal_coeff: f64,
    current_offset: f64,
}

impl CurrentEvaluator {
    /// Axial friction force without mu, N (speed and load factors included).
    fn axial_force_per_mu(&self, op: &OperatingPoint) -> f64 {
        let g = if self.corner_sq == 0.0 {
            1.0
        } else {
            op.omega_n.abs() / libm::sqrt(op.omega_sq + self.corner_sq)
        };
        let h = if self.load_exponent == 0.0 {
            1.0
        } else {
            libm::exp(self.load_exponent * op.ln_load)
        };
        g * h * self.axial_per_torque * op.tau_rot.abs()
    }

    /// Torque-constant factor 1 - k x (floored) at `op`.
    fn thermal_factor(&self, op: &OperatingPoint) -> f64 {
        (1.0 - self.thermal_coeff * op.thermal).max(MIN_TORQUE_CONSTANT_FACTOR)
    }

    /// Friction term (2/pi) F (e - c F), N m, for the axial force `f`.
    fn friction_torque(&self, f: f64) -> f64 {
        if self.compliance * f < self.eccentricity {
            2.0 / PI * f * (self.eccentricity - self.compliance * f)
        } else {
            0.0
        }
    }

    /// Mean current at `op`, A (equals [`CurrentModel::current`]).
    pub fn current(&self, op: &OperatingPoint) -> f64 {
        let w = op.omega_n.abs();
        let f = self.mu * self.axial_force_per_mu(op);
        let inertia =
            ((1.0 + self.rectification) * self.inertia_per_omega_sq * op.omega_sq).max(0.0);
        let lifted = self.friction_torque(f) + inertia + self.viscous * w + self.constant_torque;
        lifted / (self.c1 * self.thermal_factor(op)) + self.current_offset
    }

    /// The current the friction term draws at `op`, A (equals [`CurrentModel::friction_current`]).
    pub fn friction_current(&self, op: &OperatingPoint) -> f64 {
        let f = self.mu * self.axial_force_per_mu(op);
        self.friction_torque(f) / (self.c1 * self.thermal_factor(op))
    }

    /// Mean current at `op` and its gradient with respect to [`CurrentModel::params`].
    pub fn current_and_gradient(&self, op: &OperatingPoint, grad: &mut [f64; PARAM_COUNT]) -> f64 {
        let ecc = self.eccentricity;
        let w = op.omega_n.abs();
        let w2 = op.omega_sq;
        let s = self.corner_sq;
        let a = self.axial_force_per_mu(op);
        let f = self.mu * a;
        let df_ds = if w2 + s > 0.0 {
            -0.5 * f / (w2 + s)
        } else {
            0.0
        };
        let df_db = f * op.ln_load;
        let c = self.compliance;
        let (friction, dfr_df, dfr_dc) = if c * f < ecc {
            (
                2.0 / PI * f * (ecc - c * f),
                2.0 / PI * (ecc - 2.0 * c * f),
                -2.0 / PI * f * f,
            )
        } else {
            (0.0, 0.0, 0.0)
        };
        let inertia_unit = self.inertia_per_omega_sq * w2;
        let inertia_live = 1.0 + self.rectification > 0.0;
        let inertia = if inertia_live {
            (1.0 + self.rectification) * inertia_unit
        } else {
            0.0
        };
        let lifted = friction + inertia + self.viscous * w + self.constant_torque;
        let factor_raw = 1.0 - self.thermal_coeff * op.thermal;
        let clamped = factor_raw < MIN_TORQUE_CONSTANT_FACTOR;
        let factor = factor_raw.max(MIN_TORQUE_CONSTANT_FACTOR);
        let c1 = self.c1 * factor;
        let di_dt = 1.0 / c1;
        grad[Param::Mu.index()] = di_dt * dfr_df * a;
        grad[Param::AxialCornerSq.index()] = di_dt * dfr_df * df_ds;
        grad[Param::LoadExponent.index()] = di_dt * dfr_df * df_db;
        grad[Param::ToothCompliance.index()] = di_dt * dfr_dc;
        grad[Param::Rectification.index()] = if inertia_live {
            di_dt * inertia_unit
        } else {
            0.0
        };
        grad[Param::ViscousLoss.index()] = di_dt * w;
        grad[Param::BushForce.index()] = di_dt * self.bush_per_force;
        grad[Param::ThermalCoeff.index()] = if clamped {
            0.0
        } else {
            lifted * op.thermal / (c1 * factor)
        };
        grad[Param::CurrentOffset.index()] = 1.0;
        lifted * di_dt + self.current_offset
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::GearSet;

    fn model() -> CurrentModel {
        let drive = CamDrive::paper(GearSet::paper([49, 51, 50, 50]).unwrap());
        CurrentModel::paper(drive, Calibration::PAPER, crate::MU_S_PAPER)
    }

    #[test]
    fn without_effects_it_is_the_paper_model() {
        let m = model();
        for (w, tau) in [(31.4, 0.368), (62.8, 1.84), (94.2, 3.68)] {
            let op = OperatingPoint::new(w, tau, 12.0);
            let eq10 = m.drive.required_cam_torque(m.mu, tau, w);
            let expected = m.calibration.current_for(eq10, w);
            assert!((m.current(&op) - expected).abs() < 1e-12);
            let mut g = [0.0; PARAM_COUNT];
            assert!((m.current_and_gradient(&op, &mut g) - expected).abs() < 1e-12);
            assert!(m.backdrives(&op));
        }
        // The paper's current range: about 2.3 to 3.7 A.
        let lo = m.current(&OperatingPoint::new(31.4, 0.368, 0.0));
        let hi = m.current(&OperatingPoint::new(94.2, 3.68, 0.0));
        assert!(lo > 2.3 && lo < 2.6 && hi > 3.4 && hi < 3.8, "{lo} {hi}");
    }

    fn every_effect() -> CurrentModel {
        let mut m = model();
        m.effects = EffectParams {
            axial_corner_speed: 20.0,
            load_exponent: 0.2,
            tooth_compliance: 1e-6,
            rectification: 0.5,
            viscous_loss: 1e-4,
            bush_force: 3.0,
            bush_hold_torque: 0.6,
            bush_corner_speed: 40.0,
            thermal_coeff: 2e-3,
            current_offset: 0.02,
            mesh_ripple_rms: 0.05,
        };
        m
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let m = every_effect();
        let op = OperatingPoint::new(40.0, 2.2, 15.0);
        let mut g = [0.0; PARAM_COUNT];
        let i = m.current_and_gradient(&op, &mut g);
        assert!((i - m.current(&op)).abs() < 1e-12);
        let p = m.params();
        for k in 0..PARAM_COUNT {
            let h = 1e-6 * p[k].abs().max(1e-6);
            let (mut up, mut down) = (m, m);
            let (mut pu, mut pd) = (p, p);
            pu[k] += h;
            pd[k] -= h;
            up.set_params(&pu);
            down.set_params(&pd);
            let fd = (up.current(&op) - down.current(&op)) / (2.0 * h);
            let scale = fd.abs().max(1e-9);
            assert!(
                (g[k] - fd).abs() / scale < 1e-4,
                "param {k}: {} vs {fd}",
                g[k]
            );
        }
    }

    #[test]
    fn evaluator_is_the_same_physics() {
        let m = every_effect();
        let ev = m.evaluator();
        for (w, tau, x) in [(31.4, 0.368, 0.0), (62.8, 1.84, 10.0), (94.2, 3.68, 20.0)] {
            let op = OperatingPoint::new(w, tau, x);
            assert!((ev.current(&op) - m.current(&op)).abs() < 1e-12);
            assert!((ev.friction_current(&op) - m.friction_current(&op)).abs() < 1e-12);
        }
        // Past the compliance limit the friction term vanishes in both.
        let mut soft = m;
        soft.effects.tooth_compliance = 1.0;
        let op = OperatingPoint::new(50.0, 3.0, 0.0);
        assert!((soft.evaluator().current(&op) - soft.current(&op)).abs() < 1e-12);
    }

    #[test]
    fn each_effect_moves_the_current_the_physical_way() {
        let base = model();
        let op_slow = OperatingPoint::new(31.4, 3.0, 20.0);
        let op_fast = OperatingPoint::new(94.2, 3.0, 20.0);
        let with = |f: fn(&mut EffectParams)| {
            let mut m = base;
            f(&mut m.effects);
            m
        };
        // Lower axial friction at low cam speed: less current, mostly at 5 Hz.
        let m = with(|e| e.axial_corner_speed = 20.0);
        let d_slow = base.current(&op_slow) - m.current(&op_slow);
        let d_fast = base.current(&op_fast) - m.current(&op_fast);
        assert!(d_slow > 0.0 && d_slow > 3.0 * d_fast);
        // Inertia rectification grows with w^2: kappa = 1 doubles Eq. 10's inertia term.
        let m = with(|e| e.rectification = 1.0);
        let extra = m.current(&op_fast) - base.current(&op_fast);
        let expected = base.drive.required_inertia_torque(94.2) / base.calibration.c1;
        assert!((extra - expected).abs() < 1e-12);
        // Thermal drift: more current for the same torque when warm.
        let m = with(|e| e.thermal_coeff = 2e-3);
        assert!(m.current(&op_slow) > base.current(&op_slow));
        // Compliance shortens the sliding stroke: less friction current.
        let m = with(|e| e.tooth_compliance = 1e-6);
        assert!(m.current(&op_slow) < base.current(&op_slow));
        // The bush: a constant (2/pi) F e of torque.
        let m = with(|e| e.bush_force = 5.0);
        let extra = (m.current(&op_slow) - base.current(&op_slow)) * base.calibration.c1;
        assert!((extra - 2.0 / PI * 5.0 * 1e-3).abs() < 1e-12);
    }

    #[test]
    fn bush_holds_light_loads_at_low_speed_only() {
        let mut m = model();
        m.effects.bush_hold_torque = 0.8;
        m.effects.bush_corner_speed = 40.0;
        assert!(!m.backdrives(&OperatingPoint::new(31.4, 0.368, 0.0)));
        assert!(m.backdrives(&OperatingPoint::new(94.2, 0.368, 0.0)));
        assert!(m.backdrives(&OperatingPoint::new(31.4, 0.736, 0.0)));
        assert!((bush_holding_torque(0.8, 40.0, 40.0) - 0.4).abs() < 1e-12);
        assert_eq!(bush_holding_torque(0.6, 10.0, 0.0), 0.0);
    }

    #[test]
    fn speed_factor_is_eq40() {
        // Eq. (40): mu_ax = mu lambda |w_n| / sqrt(w_t^2 + lambda^2 w_n^2).
        let (lambda, wt, wn) = (0.8, 12.0, 31.4);
        let eq40 = lambda * wn / libm::sqrt(wt * wt + lambda * lambda * wn * wn);
        let f = axial_friction_speed_factor(wn, axial_corner_speed(wt, lambda));
        assert!((f - eq40).abs() < 1e-12);
        assert_eq!(axial_friction_speed_factor(10.0, 0.0), 1.0);
        assert!((load_friction_factor(2.0, 0.2) - libm::pow(2.0, 0.2)).abs() < 1e-12);
        assert_eq!(load_friction_factor(0.0, 0.2), 1.0);
    }

    #[test]
    fn load_sharing_follows_seed_003_eq11() {
        let eps = 1.7;
        assert!((load_sharing_factor(0.0, eps) - 0.36).abs() < 1e-12);
        assert!((load_sharing_factor(0.85, eps) - 1.0).abs() < 1e-12);
        assert!((load_sharing_factor(eps, eps) - 0.36).abs() < 1e-12);
        // The two pairs of a double contact carry the whole load.
        for phi in [0.0, 0.2, 0.5, 0.69] {
            let sum = load_sharing_factor(phi, eps) + load_sharing_factor(phi + 1.0, eps);
            assert!((sum - 1.0).abs() < 1e-12, "{phi}");
        }
        // Pure Coulomb friction (exponent 0) does not ripple; seed 003's 0.2 does.
        assert!(
            mesh_friction_stats(eps, 0.0).1 < 1e-12,
            "{:?}",
            mesh_friction_stats(eps, 0.0)
        );
        let (_, rms) = mesh_friction_stats(eps, ISO_LOAD_EXPONENT);
        assert!(rms > 0.01 && rms < 0.2, "{rms}");
        let mean_mod: f64 = (0..100)
            .map(|k| mesh_friction_modulation(k as f64 / 100.0, eps, 0.2))
            .sum::<f64>()
            / 100.0;
        assert!(mean_mod.abs() < 0.05);
    }

    #[test]
    fn names_round_trip() {
        for e in Effect::ALL {
            assert_eq!(Effect::from_name(e.name()), Some(e));
        }
        assert_eq!(Effect::from_name("nope"), None);
        assert_eq!(Effect::MeshLoadSharingRipple.mean_param(), None);
    }
}
