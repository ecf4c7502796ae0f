//! The rig parameter record stored on the device and exchanged with the host: the
//! vibrator's calibration constants C1-C6, the gear's geometry and friction, and the
//! safety limits.
//!
//! Units are the paper's (N mm, mm, A, rad/s) so values read straight against its
//! Table 2; the model converts to SI. The field names are the rig file's TOML keys.

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::sizes::{F32, U16};

/// Vibrator constants (Eqs. 15-17), gear geometry, friction and safety limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RigParameters {
    /// C1, torque per current of the vibrator motor, N mm/A (`|tau_cam| = C1 i_in + C2`).
    pub c1_nmm_per_a: f32,
    /// C2, torque offset of the torque-current line, N mm.
    pub c2_nmm: f32,
    /// C3, speed slope of the vibrator's own loss torque, N mm s/rad.
    pub c3_nmm_s_per_rad: f32,
    /// C4, offset of the vibrator's own loss torque, N mm.
    pub c4_nmm: f32,
    /// C5, speed slope of the no-load current, A s/rad.
    pub c5_a_s_per_rad: f32,
    /// C6, offset of the no-load current, A.
    pub c6_a: f32,
    /// Tooth counts (Z1, Z2, Z3, Z4): G1 fixed, G2-G3 the compound planet, G4 the output.
    pub z: [u16; 4],
    /// Gear module, mm.
    pub module_mm: f32,
    /// Pressure angle, degrees.
    pub pressure_angle_deg: f32,
    /// Cam eccentricity e (vibration amplitude), mm.
    pub eccentricity_mm: f32,
    /// Vibrating mass M_hat = M1 + M23, kg.
    pub carrier_mass_kg: f32,
    /// Static tooth friction coefficient.
    pub mu_s: f32,
    /// Dynamic tooth friction coefficient.
    pub mu_d: f32,
    /// Largest output load the firmware will release, N m.
    pub max_release_load_nm: f32,
    /// Motor current limit, A.
    pub max_current_a: f32,
    /// Highest vibration frequency the firmware will drive, Hz.
    pub max_freq_hz: f32,
    /// Profile shift coefficients x1..x4 (ISO 21771), all zero for standard gears. Last in
    /// the record (protocol v7): Z1 + Z2 may differ from Z3 + Z4 when the shifts give both
    /// meshes one working centre distance (the model decides: `model::GearSet::shifted`).
    pub profile_shift: [f32; 4],
}

impl RigParameters {
    /// Largest serialised size, bytes: 19 `f32` (four of them the shifts) and four `u16`
    /// varints.
    pub const MAX_WIRE_SIZE: usize = 19 * F32 + 4 * U16;

    /// The paper's rig: Table 2 constants, gear set (49, 51, 50, 50), m 1 mm, 20 deg,
    /// e 1 mm, M_hat 3.82 kg, mu_s 0.271, mu_d 0.174.
    ///
    /// Limits: 3.68 N m (tooth strength), 4.5 A (inside the ACS714's +-5 A range so an
    /// overcurrent is still measurable), 15 Hz (the paper's fastest test, 8.8 V).
    pub const fn paper() -> Self {
        Self {
            c1_nmm_per_a: 62.1,
            c2_nmm: -138.0,
            c3_nmm_s_per_rad: 0.235,
            c4_nmm: 1.69,
            c5_a_s_per_rad: 0.00378,
            c6_a: 2.25,
            z: [49, 51, 50, 50],
            module_mm: 1.0,
            pressure_angle_deg: 20.0,
            eccentricity_mm: 1.0,
            carrier_mass_kg: 3.82,
            mu_s: 0.271,
            mu_d: 0.174,
            max_release_load_nm: 3.68,
            max_current_a: 4.5,
            max_freq_hz: 15.0,
            profile_shift: [0.0; 4],
        }
    }

    /// C1..C6 in the paper's units (see the field docs), widened to `f64` for the model.
    pub fn constants(&self) -> [f64; 6] {
        [
            self.c1_nmm_per_a,
            self.c2_nmm,
            self.c3_nmm_s_per_rad,
            self.c4_nmm,
            self.c5_a_s_per_rad,
            self.c6_a,
        ]
        .map(f64::from)
    }

    /// The value of a scalar field, or `None` for [`ParameterField::Z`] (four integers) and
    /// [`ParameterField::ProfileShift`] (four numbers).
    pub const fn get(&self, field: ParameterField) -> Option<f32> {
        use ParameterField as F;
        Some(match field {
            F::C1 => self.c1_nmm_per_a,
            F::C2 => self.c2_nmm,
            F::C3 => self.c3_nmm_s_per_rad,
            F::C4 => self.c4_nmm,
            F::C5 => self.c5_a_s_per_rad,
            F::C6 => self.c6_a,
            F::Z => return None,
            F::Module => self.module_mm,
            F::PressureAngle => self.pressure_angle_deg,
            F::Eccentricity => self.eccentricity_mm,
            F::CarrierMass => self.carrier_mass_kg,
            F::MuS => self.mu_s,
            F::MuD => self.mu_d,
            F::MaxReleaseLoad => self.max_release_load_nm,
            F::MaxCurrent => self.max_current_a,
            F::MaxFreq => self.max_freq_hz,
            F::ProfileShift => return None,
        })
    }

    /// Range checks shared by host (before sending) and firmware (before storing); the
    /// first failing field is named, in field order.
    ///
    /// They reject values that are non-finite or physically meaningless, not values that
    /// are merely unusual: the model decides whether a gear set locks, and the firmware
    /// adds its board caps ([`RejectReason::AboveBoardCap`]) and the model's plausibility
    /// rules ([`RejectReason::Implausible`], [`RejectReason::Inconsistent`]) on top.
    pub fn validate(&self) -> Result<(), ParameterRejection> {
        use ParameterField as F;
        for (field, in_range) in CONSTANT_RULES {
            check(self, field, in_range)?;
        }
        let [z1, z2, z3, z4] = self.z.map(u32::from);
        if self.z.iter().any(|&z| z < 4) {
            return Err(ParameterRejection::new(F::Z, RejectReason::OutOfRange));
        }
        // Z1 Z3 = Z2 Z4 gives 1/rho = 0 (Eq. 1): the output would not turn at all.
        if z1 * z3 == z2 * z4 {
            return Err(ParameterRejection::new(F::Z, RejectReason::Inconsistent));
        }
        for (field, in_range) in GEAR_RULES {
            check(self, field, in_range)?;
        }
        if self.mu_d > self.mu_s {
            return Err(ParameterRejection::new(F::MuD, RejectReason::Inconsistent));
        }
        for (field, in_range) in LIMIT_RULES {
            check(self, field, in_range)?;
        }
        // The shifts' range and the centre distances they give are the model's to judge
        // (the firmware's gear check); here only what no gear can have.
        if self.profile_shift.iter().any(|x| !x.is_finite()) {
            return Err(ParameterRejection::new(
                F::ProfileShift,
                RejectReason::NotFinite,
            ));
        }
        Ok(())
    }
}

/// A scalar field and the range its finite values must lie in.
type Rule = (ParameterField, fn(f32) -> bool);

fn any(_: f32) -> bool {
    true
}

fn positive(v: f32) -> bool {
    v > 0.0
}

fn non_negative(v: f32) -> bool {
    v >= 0.0
}

/// C1..C6: C1 is a torque constant (positive); C3, C5 and C6 are losses (never negative).
const CONSTANT_RULES: [Rule; 6] = [
    (ParameterField::C1, positive),
    (ParameterField::C2, any),
    (ParameterField::C3, non_negative),
    (ParameterField::C4, any),
    (ParameterField::C5, non_negative),
    (ParameterField::C6, non_negative),
];

/// Geometry, mass and friction, in record order after `z`.
const GEAR_RULES: [Rule; 6] = [
    (ParameterField::Module, positive),
    (ParameterField::PressureAngle, |a| a > 0.0 && a < 45.0),
    (ParameterField::Eccentricity, positive),
    (ParameterField::CarrierMass, positive),
    (ParameterField::MuS, |mu| mu > 0.0 && mu < 1.0),
    (ParameterField::MuD, positive),
];

/// The safety limits.
const LIMIT_RULES: [Rule; 3] = [
    (ParameterField::MaxReleaseLoad, positive),
    (ParameterField::MaxCurrent, positive),
    (ParameterField::MaxFreq, positive),
];

/// `NotFinite` or `OutOfRange` for a scalar field that fails `in_range`.
fn check(
    p: &RigParameters,
    field: ParameterField,
    in_range: fn(f32) -> bool,
) -> Result<(), ParameterRejection> {
    let value = p.get(field).unwrap_or(0.0);
    let reason = if !value.is_finite() {
        RejectReason::NotFinite
    } else if !in_range(value) {
        RejectReason::OutOfRange
    } else {
        return Ok(());
    };
    Err(ParameterRejection::new(field, reason))
}

impl Default for RigParameters {
    fn default() -> Self {
        Self::paper()
    }
}

/// One field of [`RigParameters`], as named in refusals. Wire order: the record's field
/// order; append new fields at the end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ParameterField {
    /// `c1_nmm_per_a`.
    C1,
    /// `c2_nmm`.
    C2,
    /// `c3_nmm_s_per_rad`.
    C3,
    /// `c4_nmm`.
    C4,
    /// `c5_a_s_per_rad`.
    C5,
    /// `c6_a`.
    C6,
    /// `z`, the four tooth counts.
    Z,
    /// `module_mm`.
    Module,
    /// `pressure_angle_deg`.
    PressureAngle,
    /// `eccentricity_mm`.
    Eccentricity,
    /// `carrier_mass_kg`.
    CarrierMass,
    /// `mu_s`.
    MuS,
    /// `mu_d`.
    MuD,
    /// `max_release_load_nm`.
    MaxReleaseLoad,
    /// `max_current_a`.
    MaxCurrent,
    /// `max_freq_hz`.
    MaxFreq,
    /// `profile_shift`, the four profile shift coefficients (protocol v7).
    ProfileShift,
}

impl ParameterField {
    /// Every field, in the record's order.
    pub const ALL: [Self; 17] = [
        Self::C1,
        Self::C2,
        Self::C3,
        Self::C4,
        Self::C5,
        Self::C6,
        Self::Z,
        Self::Module,
        Self::PressureAngle,
        Self::Eccentricity,
        Self::CarrierMass,
        Self::MuS,
        Self::MuD,
        Self::MaxReleaseLoad,
        Self::MaxCurrent,
        Self::MaxFreq,
        Self::ProfileShift,
    ];

    /// The user-facing name: the [`RigParameters`] field and the rig file's TOML key.
    pub const fn name(self) -> &'static str {
        match self {
            Self::C1 => "c1_nmm_per_a",
            Self::C2 => "c2_nmm",
            Self::C3 => "c3_nmm_s_per_rad",
            Self::C4 => "c4_nmm",
            Self::C5 => "c5_a_s_per_rad",
            Self::C6 => "c6_a",
            Self::Z => "z",
            Self::Module => "module_mm",
            Self::PressureAngle => "pressure_angle_deg",
            Self::Eccentricity => "eccentricity_mm",
            Self::CarrierMass => "carrier_mass_kg",
            Self::MuS => "mu_s",
            Self::MuD => "mu_d",
            Self::MaxReleaseLoad => "max_release_load_nm",
            Self::MaxCurrent => "max_current_a",
            Self::MaxFreq => "max_freq_hz",
            Self::ProfileShift => "profile_shift",
        }
    }

    /// The field's unit as people write it (`""` for pure numbers).
    pub const fn unit(self) -> &'static str {
        match self {
            Self::C1 => "N mm/A",
            Self::C2 | Self::C4 => "N mm",
            Self::C3 => "N mm s/rad",
            Self::C5 => "A s/rad",
            Self::C6 | Self::MaxCurrent => "A",
            Self::Z | Self::MuS | Self::MuD | Self::ProfileShift => "",
            Self::Module | Self::Eccentricity => "mm",
            Self::PressureAngle => "deg",
            Self::CarrierMass => "kg",
            Self::MaxReleaseLoad => "N m",
            Self::MaxFreq => "Hz",
        }
    }

    /// The field named `name` (a TOML key), if there is one.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }
}

impl fmt::Display for ParameterField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a [`ParameterField`] was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[non_exhaustive]
pub enum RejectReason {
    /// NaN or infinite.
    NotFinite,
    /// Outside the field's meaningful range (e.g. a negative mass, a pressure angle of
    /// 90 degrees, a tooth count below 4).
    OutOfRange,
    /// Above the cap the board's firmware configuration sets (a limit the host cannot lift).
    AboveBoardCap,
    /// Contradicts another field (mu_d above mu_s, Z1 Z3 = Z2 Z4, C3 != C1 C5, ...).
    Inconsistent,
    /// Finite and in range but physically implausible for the rig (e.g. a C1 far from the
    /// motor's own torque constant).
    Implausible,
}

impl RejectReason {
    /// Short snake-case name for JSON and logs.
    pub const fn name(self) -> &'static str {
        match self {
            Self::NotFinite => "not_finite",
            Self::OutOfRange => "out_of_range",
            Self::AboveBoardCap => "above_board_cap",
            Self::Inconsistent => "inconsistent",
            Self::Implausible => "implausible",
        }
    }

    /// The reason as the end of a sentence starting with the field's name.
    pub const fn describe(self) -> &'static str {
        match self {
            Self::NotFinite => "is not a finite number",
            Self::OutOfRange => "is outside its allowed range",
            Self::AboveBoardCap => "is above the cap the board's firmware allows",
            Self::Inconsistent => "contradicts another field",
            Self::Implausible => "is physically implausible for this rig",
        }
    }
}

/// A refused [`RigParameters`] record: which field, and why. Returned by
/// [`RigParameters::validate`] and carried by [`crate::NackCode::ParametersRejected`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ParameterRejection {
    /// The offending field.
    pub field: ParameterField,
    /// What is wrong with it.
    pub reason: RejectReason,
}

impl ParameterRejection {
    /// A rejection of `field` for `reason`.
    pub const fn new(field: ParameterField, reason: RejectReason) -> Self {
        Self { field, reason }
    }
}

/// For example "`max_release_load_nm` is above the cap the board's firmware allows".
impl fmt::Display for ParameterRejection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "`{}` {}", self.field.name(), self.reason.describe())
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ParameterRejection {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_values_are_valid() {
        assert_eq!(RigParameters::paper().validate(), Ok(()));
        assert_eq!(RigParameters::default(), RigParameters::paper());
    }

    fn rejection(p: RigParameters) -> (&'static str, RejectReason) {
        match p.validate() {
            Err(r) => (r.field.name(), r.reason),
            Ok(()) => panic!("expected a rejection"),
        }
    }

    #[test]
    fn rejects_bad_fields_by_name() {
        use RejectReason::*;
        let p = RigParameters::paper();
        assert_eq!(
            rejection(RigParameters {
                c1_nmm_per_a: f32::NAN,
                ..p
            }),
            ("c1_nmm_per_a", NotFinite)
        );
        assert_eq!(
            rejection(RigParameters {
                z: [50, 50, 50, 50],
                ..p
            }),
            ("z", Inconsistent)
        );
        assert_eq!(
            rejection(RigParameters {
                z: [0, 51, 50, 50],
                ..p
            }),
            ("z", OutOfRange)
        );
        assert_eq!(
            rejection(RigParameters { mu_d: 0.3, ..p }),
            ("mu_d", Inconsistent)
        );
        assert_eq!(
            rejection(RigParameters {
                pressure_angle_deg: 90.0,
                ..p
            }),
            ("pressure_angle_deg", OutOfRange)
        );
        assert_eq!(
            rejection(RigParameters {
                max_freq_hz: 0.0,
                ..p
            }),
            ("max_freq_hz", OutOfRange)
        );
        assert_eq!(
            rejection(RigParameters {
                max_release_load_nm: f32::INFINITY,
                ..p
            }),
            ("max_release_load_nm", NotFinite)
        );
        assert_eq!(
            rejection(RigParameters {
                carrier_mass_kg: -3.82,
                ..p
            }),
            ("carrier_mass_kg", OutOfRange)
        );
    }

    #[test]
    fn the_first_bad_field_in_record_order_is_named() {
        let p = RigParameters {
            c6_a: -1.0,
            mu_s: 2.0,
            max_current_a: f32::NAN,
            ..RigParameters::paper()
        };
        assert_eq!(rejection(p), ("c6_a", RejectReason::OutOfRange));
    }

    #[test]
    fn every_field_has_a_unique_name_matching_the_record() {
        // The field names are the record's serde field names (the TOML keys).
        let mut names: Vec<_> = ParameterField::ALL.iter().map(|f| f.name()).collect();
        for (i, field) in ParameterField::ALL.iter().enumerate() {
            assert_eq!(*field as usize, i, "ALL is in declaration order");
            assert_eq!(ParameterField::from_name(field.name()), Some(*field));
        }
        assert_eq!(ParameterField::from_name("c7"), None);
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), ParameterField::ALL.len());
        // Each scalar field reads back its own value.
        let p = RigParameters::paper();
        assert_eq!(p.get(ParameterField::MaxReleaseLoad), Some(3.68));
        assert_eq!(p.get(ParameterField::C1), Some(62.1));
        assert_eq!(p.get(ParameterField::Z), None);
    }

    #[test]
    fn rejection_says_field_and_reason() {
        let r =
            ParameterRejection::new(ParameterField::MaxReleaseLoad, RejectReason::AboveBoardCap);
        assert_eq!(
            r.to_string(),
            "`max_release_load_nm` is above the cap the board's firmware allows"
        );
    }
}
