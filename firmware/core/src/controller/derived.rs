//! The rig parameters' checks and the quantities the control loop derives from them.

use protocol::{ParameterField, ParameterRejection, RejectReason, RigParameters};

use crate::config::CoreConfig;
use crate::estimator::EstimatorModel;
use crate::speed_loop::FeedForward;

/// Quantities derived from the rig parameters (recomputed when they change).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Derived {
    pub(crate) model: EstimatorModel,
    pub(crate) feed_forward: FeedForward,
    pub(crate) current_limit_a: f32,
    pub(crate) max_hz: f32,
    pub(crate) max_load_nm: f32,
    pub(crate) keeps_moving: bool,
    pub(crate) holds_at_rest: bool,
}

impl Derived {
    /// The derived quantities, or the first field the record's checks
    /// ([`RigParameters::validate`]) or the model (gear geometry, vibrator constants)
    /// refuse. Limits above the board's are clamped to it here (a stored record from before
    /// keeps working); a new record asking for more is refused by [`check_board_caps`].
    pub(crate) fn new(p: &RigParameters, config: &CoreConfig) -> Result<Self, ParameterRejection> {
        p.validate()?;
        let z = p.z.map(u32::from);
        let gear = model::GearSet::new(
            z,
            f64::from(p.module_mm) * 1e-3,
            f64::from(p.pressure_angle_deg).to_radians(),
        )
        .map_err(gear_rejection)?;
        let vibrator = model::Calibration::from_paper_units(p.constants());
        if !vibrator.is_plausible() {
            // `validate` has checked the signs but allows a zero no-load current, which
            // the model's vibrator cannot have.
            return Err(ParameterRejection::new(
                ParameterField::C6,
                RejectReason::OutOfRange,
            ));
        }
        let drive = model::CamDrive {
            gear,
            eccentricity: f64::from(p.eccentricity_mm) * 1e-3,
            carrier_mass: f64::from(p.carrier_mass_kg),
        };
        let big_lambda = gear.big_lambda();
        Ok(Self {
            model: EstimatorModel {
                drive,
                vibrator,
                mu: f64::from(p.mu_s),
                carrier_power_returned: config.estimator.carrier_power_returned,
            },
            feed_forward: FeedForward {
                resistance_ohm: config.motor.resistance_ohm,
                ke: config.motor.ke_cam_v_s_per_rad,
                c5: p.c5_a_s_per_rad,
                c6: p.c6_a,
                supply_v: config.supply_v,
            },
            current_limit_a: p.max_current_a.min(config.faults.overcurrent_a),
            max_hz: p.max_freq_hz.min(config.supervisor.max_freq_hz),
            max_load_nm: p.max_release_load_nm,
            keeps_moving: f64::from(p.mu_d) * big_lambda < 1.0,
            holds_at_rest: f64::from(p.mu_s) * big_lambda > 1.0,
        })
    }
}

/// The model's refusal of a gear set, as the record field it concerns.
fn gear_rejection(e: model::GearError) -> ParameterRejection {
    use model::GearError as G;
    let (field, reason) = match e {
        G::ZeroTeeth { .. } => (ParameterField::Z, RejectReason::OutOfRange),
        G::BadModule => (ParameterField::Module, RejectReason::OutOfRange),
        G::BadPressureAngle => (ParameterField::PressureAngle, RejectReason::OutOfRange),
        // Z1 = Z4, unequal centre distances, or a later rule about the tooth counts.
        _ => (ParameterField::Z, RejectReason::Inconsistent),
    };
    ParameterRejection::new(field, reason)
}

/// A new record may not ask for more than the board allows: a current limit above the
/// board's overcurrent trip or a frequency above the supervisor's highest would be
/// silently lowered, so `SetParameters` refuses them naming the field.
pub(crate) fn check_board_caps(
    p: &RigParameters,
    config: &CoreConfig,
) -> Result<(), ParameterRejection> {
    let caps = [
        (
            ParameterField::MaxCurrent,
            p.max_current_a,
            config.faults.overcurrent_a,
        ),
        (
            ParameterField::MaxFreq,
            p.max_freq_hz,
            config.supervisor.max_freq_hz,
        ),
    ];
    for (field, value, cap) in caps {
        if value > cap {
            return Err(ParameterRejection::new(field, RejectReason::AboveBoardCap));
        }
    }
    Ok(())
}
