//! The one table of effects: for every [`Effect`], its name, its law, its parameters with
//! units and bounds, what data it needs to show, and how the plant takes it. Adding an
//! effect to the description is one row of [`EFFECTS`]; `rig explain`'s library, the rig
//! file and the docs read this table.

use super::{Effect, EffectParams, Param};

/// The range the fit keeps mu of Eq. (10) in.
pub const MU_BOUNDS: (f64, f64) = (0.0, 3.0);

/// One effect, described.
#[derive(Debug, Clone, Copy)]
pub struct EffectInfo {
    /// The effect.
    pub effect: Effect,
    /// Its name, as on the command line and in rig files.
    pub name: &'static str,
    /// The law, in the paper's notation.
    pub law: &'static str,
    /// Where the law comes from.
    pub source: &'static str,
    /// The parameter of the mean current it brings, if any (the ripple only scatters).
    pub mean: Option<MeanParam>,
    /// Its parameters as reports and rig files name them.
    pub params: &'static [EffectParam],
    /// What the data must offer for it to show.
    pub needs: DataNeeds,
    /// Whether its null value sits on a bound of its parameter, so the data can only push
    /// it one way (a one-sided test).
    pub one_sided: bool,
    /// Parameters it adds to the likelihood (mean, hold and scatter parameters).
    pub likelihood_params: usize,
    /// How the plant takes it.
    pub plant: PlantTakes,
    /// The physical limits of its reported parameters, each with its reason: a fit that
    /// needs a value beyond one does not name the effect.
    pub limits: &'static [PhysicalLimit],
}

/// A physical limit of one reported parameter of an effect, with its reason.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PhysicalLimit {
    /// The reported parameter ([`EffectParam::key`]).
    pub key: &'static str,
    /// The limit.
    pub kind: LimitKind,
    /// Why, in a sentence.
    pub why: &'static str,
}

/// The shape of a physical limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LimitKind {
    /// The reported value lies in [lo, hi].
    Range(f64, f64),
    /// The deflection, reported value (um/N) times the largest axial force of the data, stays
    /// below this share of the cam's eccentricity.
    StrokeShare(f64),
}

/// What a limit that depends on the data needs to know of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LimitContext {
    /// The largest axial tooth force at the tested loads, N.
    pub max_axial_force_n: f64,
    /// The cam's eccentricity, m.
    pub eccentricity_m: f64,
}

impl PhysicalLimit {
    /// The allowed range of the reported value on data described by `ctx`.
    pub fn range(&self, ctx: &LimitContext) -> (f64, f64) {
        match self.kind {
            LimitKind::Range(lo, hi) => (lo, hi),
            LimitKind::StrokeShare(share) => {
                // um/N whose deflection at the largest force is `share` of the stroke.
                let f = ctx.max_axial_force_n.max(1e-9);
                (0.0, share * ctx.eccentricity_m * 1e6 / f)
            }
        }
    }
}

/// Physical range of the friction coefficient mu of Eq. (10): lubricated steel gears run at
/// 0.02-0.2, dry ones up to about 0.6; the paper measured 0.17-0.27.
pub const MU_PHYSICAL: PhysicalLimit = PhysicalLimit {
    key: "mu",
    kind: LimitKind::Range(0.02, 0.6),
    why: "tooth friction of steel gears lies between about 0.02 (well lubricated) and 0.6 (dry); the paper measured 0.17-0.27",
};

/// The mean-current parameter of an effect and the reported parameter it is shown as.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeanParam {
    /// The parameter in the fit's vector.
    pub param: Param,
    /// The reported parameter ([`EffectParam::key`]) that shows it.
    pub key: &'static str,
    /// From the fitted value to the reported one.
    pub report: ReportMap,
}

/// How a fitted parameter becomes its reported value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ReportMap {
    /// Reported = fitted times the factor.
    Scale(f64),
    /// Reported = the square root of the fitted value (the fit uses w_c^2, smooth at 0).
    SquareRoot,
}

/// One parameter of an effect as reports and rig files name it.
#[derive(Debug, Clone, Copy)]
pub struct EffectParam {
    /// Name in reports and rig files (SI with the unit in the name).
    pub key: &'static str,
    /// Unit of the reported value.
    pub unit: &'static str,
    /// What it is.
    pub meaning: &'static str,
    /// The range the fit keeps the reported value in; for parameters fitted apart from the
    /// mean current, the physical range.
    pub bounds: (f64, f64),
    /// Where the value lives.
    pub value: ParamValue,
}

/// Where a reported parameter's value lives.
#[derive(Debug, Clone, Copy)]
pub enum ParamValue {
    /// A field of [`EffectParams`], in SI; reported = SI value times `scale`.
    Field {
        /// Reported units per SI unit.
        scale: f64,
        /// Reads the field (SI).
        get: fn(&EffectParams) -> f64,
        /// Writes the field (SI), clamping values the physics excludes (negative forces).
        set: fn(&mut EffectParams, f64),
    },
    /// Fixed by the library at this value.
    Fixed(f64),
    /// A property of the data set, not of the effect (the thermal drift's reference
    /// temperature).
    DataProperty,
}

impl EffectParam {
    /// The reported value in `p` (`None` for a data property).
    pub fn report(&self, p: &EffectParams) -> Option<f64> {
        match self.value {
            ParamValue::Field { scale, get, .. } => Some(get(p) * scale),
            ParamValue::Fixed(v) => Some(v),
            ParamValue::DataProperty => None,
        }
    }

    /// Sets the field from a reported value `v`; `false` when the parameter is not a field
    /// (fixed or a data property).
    pub fn apply(&self, p: &mut EffectParams, v: f64) -> bool {
        match self.value {
            ParamValue::Field { scale, set, .. } => {
                set(p, v * (1.0 / scale));
                true
            }
            _ => false,
        }
    }
}

/// What a data set offers, for deciding which effects can show in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DataSummary {
    /// Distinct cam speeds.
    pub speed_levels: usize,
    /// Distinct loads.
    pub load_levels: usize,
    /// Rows with a current.
    pub rows: usize,
    /// Whether a thermal driver (temperature or time) is known.
    pub thermal_driver: bool,
    /// Rows whose output was not backdriven.
    pub held_rows: usize,
}

/// What an effect needs of the data to show.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataNeeds {
    /// Least distinct cam speeds.
    pub speed_levels: usize,
    /// Least distinct loads.
    pub load_levels: usize,
    /// Least rows.
    pub rows: usize,
    /// A thermal driver is needed.
    pub thermal_driver: bool,
    /// Non-backdriven rows are needed.
    pub held_rows: bool,
    /// What to tell the user when the data falls short.
    pub why: &'static str,
}

impl DataNeeds {
    /// Needs nothing beyond the paper's own data.
    pub const NOTHING: DataNeeds = DataNeeds {
        speed_levels: 0,
        load_levels: 0,
        rows: 0,
        thermal_driver: false,
        held_rows: false,
        why: "",
    };

    const fn speeds(why: &'static str) -> Self {
        Self {
            speed_levels: 2,
            why,
            ..Self::NOTHING
        }
    }

    const fn loads(why: &'static str) -> Self {
        Self {
            load_levels: 3,
            why,
            ..Self::NOTHING
        }
    }

    /// Why `data` cannot show the effect, or `None` when it can.
    pub fn unmet(&self, data: &DataSummary) -> Option<&'static str> {
        let short = data.speed_levels < self.speed_levels
            || data.load_levels < self.load_levels
            || data.rows < self.rows
            || (self.thermal_driver && !data.thermal_driver)
            || (self.held_rows && data.held_rows == 0);
        short.then_some(self.why)
    }
}

/// How the plant ([`crate::plant`]) takes an effect.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlantTakes {
    /// Same law, a variant, or not at all.
    pub form: PlantForm,
    /// The plant setting that switches it on.
    pub setting: &'static str,
    /// How, and what it cannot represent.
    pub note: &'static str,
}

/// Whether the plant runs an effect's law.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlantForm {
    /// The law of this library, as written.
    Same,
    /// A named variant of the law (a robustness test of `rig explain`).
    Variant,
    /// Not modelled.
    Absent,
}

const fn field(
    key: &'static str,
    unit: &'static str,
    meaning: &'static str,
    bounds: (f64, f64),
    scale: f64,
    get: fn(&EffectParams) -> f64,
    set: fn(&mut EffectParams, f64),
) -> EffectParam {
    EffectParam {
        key,
        unit,
        meaning,
        bounds,
        value: ParamValue::Field { scale, get, set },
    }
}

const fn mean(param: Param, key: &'static str, report: ReportMap) -> Option<MeanParam> {
    Some(MeanParam { param, key, report })
}

/// Every effect, in the order of [`Effect::ALL`].
pub const EFFECTS: &[EffectInfo] = &[
    EffectInfo {
        effect: Effect::SpeedDependentAxialFriction,
        name: "speed-dependent-axial-friction",
        law: "mu_ax = mu w_n / sqrt(w_n^2 + w_c^2) in Eq. (10)'s friction term",
        source: "the paper's Eq. (40), with w_c = |w_t| / lambda; its own explanation of the low torque at 3.6 V",
        mean: mean(Param::AxialCornerSq, "omega_c_rad_s", ReportMap::SquareRoot),
        params: &[field(
            "omega_c_rad_s",
            "rad/s",
            "corner speed w_c",
            (0.0, 1.0e3),
            1.0,
            |p| p.axial_corner_speed,
            |p, v| p.axial_corner_speed = v.abs(),
        )],
        needs: DataNeeds::speeds("needs tests at two or more cam speeds"),
        one_sided: true,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Variant,
            setting: "PlantEffects::axial_friction_speed = Some((depth, omega0))",
            note: "AxialSpeedLaw::ExponentialDip, mu (1 - depth exp(-w_n / w_0)): a shape the library does not fit, so the tests show `rig explain` finding the effect from a law it does not contain; PlantParams::friction_split applies Eq. (40) with the simulated output speed instead of a fixed corner",
        },
        limits: &[PhysicalLimit {
            key: "omega_c_rad_s",
            kind: LimitKind::Range(0.0, 500.0),
            why: "w_c = |w_t| / lambda is a sliding speed of the output; far above the motor's top cam speed (about 100 rad/s) mu_ax is proportional to speed everywhere, a viscous law rather than a corner",
        }],
    },
    EffectInfo {
        effect: Effect::LoadDependentFriction,
        name: "load-dependent-friction",
        law: "mu (|tau_rot| / tau_ref)^b in Eq. (10)'s friction term",
        source: "seed 003's average friction coefficient, Eq. 12 there (b = 0.2)",
        mean: mean(Param::LoadExponent, "exponent", ReportMap::Scale(1.0)),
        params: &[
            field(
                "exponent",
                "1",
                "exponent b",
                (-0.9, 0.9),
                1.0,
                |p| p.load_exponent,
                |p, v| p.load_exponent = v,
            ),
            EffectParam {
                key: "tau_ref_nm",
                unit: "N m",
                meaning: "reference load tau_ref",
                bounds: (
                    super::LOAD_FRICTION_REFERENCE_NM,
                    super::LOAD_FRICTION_REFERENCE_NM,
                ),
                value: ParamValue::Fixed(super::LOAD_FRICTION_REFERENCE_NM),
            },
        ],
        needs: DataNeeds::loads("needs tests at three or more loads"),
        one_sided: false,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Same,
            setting: "PlantEffects::load_friction = Some((exponent, tau_ref))",
            note: "the same law with tau_ref free",
        },
        limits: &[PhysicalLimit {
            key: "exponent",
            kind: LimitKind::Range(-0.5, 0.5),
            why: "seed 003's Eq. 12 gives b = 0.2 for lubricated teeth; |b| above 0.5 would change mu more than threefold over a tenfold load range, beyond any lubrication regime it describes",
        }],
    },
    EffectInfo {
        effect: Effect::CurrentSensorOffset,
        name: "current-sensor-offset",
        law: "i_measured = i + i_0",
        source: "the ACS714's zero is not exactly at Vcc / 2",
        mean: mean(Param::CurrentOffset, "offset_a", ReportMap::Scale(1.0)),
        params: &[field(
            "offset_a",
            "A",
            "offset i_0",
            (-100.0, 100.0),
            1.0,
            |p| p.current_offset,
            |p, v| p.current_offset = v,
        )],
        needs: DataNeeds::NOTHING,
        one_sided: false,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Same,
            setting: "PlantEffects::current_offset",
            note: "added to the logger's reading (Plant::logged_current), not to the firmware's ADC",
        },
        limits: &[PhysicalLimit {
            key: "offset_a",
            kind: LimitKind::Range(-0.25, 0.25),
            why: "the ACS714's zero lies within its electrical offset (+-15 mV, 81 mA at 185 mV/A) plus the zero's share of the 5 V supply's tolerance; a larger shift is a scaling or wiring fault, not an offset",
        }],
    },
    EffectInfo {
        effect: Effect::ThermalDrift,
        name: "thermal-drift",
        law: "C1 -> C1 max(1 - k x, 0.1), x = T - T0 (or the time t when only that is known)",
        source: "the motor's magnets weaken as the winding warms",
        mean: mean(Param::ThermalCoeff, "k_per_c", ReportMap::Scale(1.0)),
        params: &[
            field(
                "k_per_c",
                "1/K",
                "coefficient k against the motor temperature",
                (-1.0, 1.0),
                1.0,
                |p| p.thermal_coeff,
                |p, v| p.thermal_coeff = v,
            ),
            field(
                "k_per_s",
                "1/s",
                "coefficient k against the time (no temperature column)",
                (-1.0, 1.0),
                1.0,
                |p| p.thermal_coeff,
                |p, v| p.thermal_coeff = v,
            ),
            EffectParam {
                key: "reference_c",
                unit: "deg C",
                meaning: "reference temperature T0 (the calibration's)",
                bounds: (-273.15, f64::INFINITY),
                value: ParamValue::DataProperty,
            },
        ],
        needs: DataNeeds {
            thermal_driver: true,
            why: "needs a temp_c or t_s column",
            ..DataNeeds::NOTHING
        },
        one_sided: false,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Same,
            setting: "PlantEffects::thermal_drift = Some(k)",
            note: "against the simulated winding temperature above ambient; a drift against time is not representable",
        },
        limits: &[
            PhysicalLimit {
                key: "k_per_c",
                kind: LimitKind::Range(0.0, 0.005),
                why: "the torque constant falls as the magnets warm (ferrite about 0.2 %/K, rare-earth 0.1 %/K): it cannot rise, and 0.5 %/K is beyond any permanent magnet",
            },
            PhysicalLimit {
                key: "k_per_s",
                kind: LimitKind::Range(0.0, f64::INFINITY),
                why: "the winding warms during a session, so the torque constant falls with time: it cannot rise",
            },
        ],
    },
    EffectInfo {
        effect: Effect::VibratorViscousLoss,
        name: "vibrator-viscous-loss",
        law: "extra vibrator loss c_v w_n next to C3 w_n",
        source: "a speed-proportional loss the calibration missed",
        mean: mean(
            Param::ViscousLoss,
            "c_v_n_mm_s_per_rad",
            ReportMap::Scale(1e3),
        ),
        params: &[field(
            "c_v_n_mm_s_per_rad",
            "N mm s/rad",
            "extra viscous loss c_v",
            (-1.0e3, 1.0e3),
            1e3,
            |p| p.viscous_loss,
            |p, v| p.viscous_loss = v,
        )],
        needs: DataNeeds::speeds("needs tests at two or more cam speeds"),
        one_sided: false,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Same,
            setting: "PlantEffects::extra_viscous",
            note: "an extra viscous torque at the cam shaft",
        },
        limits: &[PhysicalLimit {
            key: "c_v_n_mm_s_per_rad",
            kind: LimitKind::Range(-0.235, 2.35),
            why: "the vibrator's whole viscous loss C3 + c_v cannot be negative (C3 = 0.235 N mm s/rad, Table 2), and ten times C3 would be a seized gearhead, not a loss the calibration missed",
        }],
    },
    EffectInfo {
        effect: Effect::InertiaRectification,
        name: "inertia-rectification",
        law: "inertia term (1 + kappa) M_hat w_n^2 e^2 / pi (kappa = 0: Eq. 10; -1: power returned; -1/2: not returned; 1: fully rectified)",
        source: "Eq. (9)'s inertia term when the drive cannot take the carrier's power back (the paper's ref. [18])",
        mean: mean(Param::Rectification, "kappa", ReportMap::Scale(1.0)),
        params: &[field(
            "kappa",
            "1",
            "rectification kappa",
            (-1.0, 20.0),
            1.0,
            |p| p.rectification,
            |p, v| p.rectification = v,
        )],
        needs: DataNeeds::speeds("needs tests at two or more cam speeds"),
        one_sided: false,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Same,
            setting: "PlantEffects::inertia_kappa",
            note: "Eq. (9)'s instantaneous inertia term taken with the fitted kappa (carrier_inertia_torque_at_kappa, whose turn mean is this law; `load-dependent`: kappa + kappa_per_nm |tau_rot|); without it the drive's own, PlantParams::regeneration (kappa -1 or -1/2)",
        },
        limits: &[PhysicalLimit {
            key: "kappa",
            kind: LimitKind::Range(-1.0, 1.0),
            why: "kappa = -1 returns all of the carrier's power to the drive and 1 rectifies all of it; beyond either the inertia term would need more energy than the carrier's motion holds",
        }],
    },
    EffectInfo {
        effect: Effect::LinearBushFriction,
        name: "linear-bush-friction",
        law: "cam torque (2/pi) F_b e; the load holds while tau_rot <= T_0 / (1 + w_n / w_b)",
        source: "the paper's explanation of the non-backdriven points at 0.368 N m, 3.6 and 6.2 V",
        mean: mean(Param::BushForce, "force_n", ReportMap::Scale(1.0)),
        params: &[
            field(
                "force_n",
                "N",
                "Coulomb force F_b",
                (0.0, 1.0e4),
                1.0,
                |p| p.bush_force,
                |p, v| p.bush_force = v.max(0.0),
            ),
            field(
                "hold_nm",
                "N m",
                "holding torque T_0 at rest",
                (0.0, f64::INFINITY),
                1.0,
                |p| p.bush_hold_torque,
                |p, v| p.bush_hold_torque = v.max(0.0),
            ),
            field(
                "omega_b_rad_s",
                "rad/s",
                "cam speed w_b at which the hold has halved",
                (0.0, f64::INFINITY),
                1.0,
                |p| p.bush_corner_speed,
                |p, v| p.bush_corner_speed = v.max(0.0),
            ),
        ],
        needs: DataNeeds {
            held_rows: true,
            why: "needs non-backdriven points (backdriven = 0); without them its constant torque cannot be told from a current offset",
            ..DataNeeds::NOTHING
        },
        one_sided: true,
        likelihood_params: 3,
        plant: PlantTakes {
            form: PlantForm::Same,
            setting: "PlantEffects::bush_friction, bush_hold_arm, bush_omega",
            note: "T_0 = bush_friction x bush_hold_arm; the force adds to Eq. (9)'s axial Coulomb force (F e |sin|, whose turn mean is (2/pi) F e)",
        },
        limits: &[PhysicalLimit {
            key: "force_n",
            kind: LimitKind::Range(0.0, 100.0),
            why: "a linear bush guiding the 3.82 kg carrier: even a dry bush (mu 0.3) under a side load of ten times its weight rubs with about 110 N",
        }],
    },
    EffectInfo {
        effect: Effect::ToothCompliance,
        name: "tooth-compliance",
        law: "sliding stroke e - c F_ax in Eq. (10)'s friction term",
        source: "seed 004's elastic tooth displacement",
        mean: mean(
            Param::ToothCompliance,
            "compliance_um_per_n",
            ReportMap::Scale(1e6),
        ),
        params: &[field(
            "compliance_um_per_n",
            "um/N",
            "axial tooth compliance c",
            (0.0, 1.0e3),
            1e6,
            |p| p.tooth_compliance,
            |p, v| p.tooth_compliance = v.max(0.0),
        )],
        needs: DataNeeds::loads("needs tests at three or more loads"),
        one_sided: true,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Same,
            setting: "PlantEffects::tooth_compliance",
            note: "the teeth's axial friction force F works over the stroke e - c F at every instant (plant::compliant_stroke), whose turn mean is this law",
        },
        limits: &[PhysicalLimit {
            key: "compliance_um_per_n",
            kind: LimitKind::StrokeShare(0.25),
            why: "teeth that deflect by a quarter of the cam's stroke or more at the largest load would no longer slide as Eq. (10) assumes; the elastic deflection of module-1 steel teeth is a few micrometres",
        }],
    },
    EffectInfo {
        effect: Effect::MeshLoadSharingRipple,
        name: "mesh-load-sharing-ripple",
        law: "the friction term scatters by ripple_rms (relative rms) from test to test",
        source: "seed 003's load sharing, Eq. 11 there, with its load-dependent friction",
        mean: None,
        params: &[field(
            "ripple_rms",
            "1",
            "relative rms scatter of the friction term",
            (0.0, f64::INFINITY),
            1.0,
            |p| p.mesh_ripple_rms,
            |p, v| p.mesh_ripple_rms = v.max(0.0),
        )],
        needs: DataNeeds {
            load_levels: 3,
            rows: 20,
            why: "needs repeated tests at three or more loads",
            ..DataNeeds::NOTHING
        },
        one_sided: true,
        likelihood_params: 1,
        plant: PlantTakes {
            form: PlantForm::Variant,
            setting: "PlantEffects::mesh_ripple_rms",
            note: "the teeth's friction force follows seed 003's load sharing over the output mesh's angle (plant::MeshRipple), relative rms ripple_rms: a test's window at its own mesh phase scatters the friction term as this law says",
        },
        limits: &[PhysicalLimit {
            key: "ripple_rms",
            kind: LimitKind::Range(0.0, 0.5),
            why: "seed 003's load sharing changes the mesh friction by a few tens of percent over a mesh cycle; averaged over a test it scatters far less than half the friction term",
        }],
    },
];

impl Effect {
    /// The effect's row of [`EFFECTS`].
    pub const fn info(self) -> &'static EffectInfo {
        &EFFECTS[self as usize]
    }
}

impl EffectInfo {
    /// The reported parameter called `key`.
    pub fn param(&self, key: &str) -> Option<&'static EffectParam> {
        self.params.iter().find(|p| p.key == key)
    }

    /// The keys of its parameters, in order.
    pub fn keys(&self) -> impl Iterator<Item = &'static str> {
        self.params.iter().map(|p| p.key)
    }

    /// Sets every field of the effect to zero: the paper's model for this effect.
    pub fn clear(&self, p: &mut EffectParams) {
        for q in self.params {
            q.apply(p, 0.0);
        }
    }
}

impl Param {
    /// The effect whose mean parameter this is (`None` for mu).
    pub fn effect(self) -> Option<&'static EffectInfo> {
        EFFECTS
            .iter()
            .find(|e| e.mean.is_some_and(|m| m.param == self))
    }

    /// The range the fit keeps the parameter in, in the fit's units (SI; w_c^2 for the
    /// corner speed): the table's bounds of the reported parameter, mapped back.
    pub fn bounds(self) -> (f64, f64) {
        let Some((mean, reported)) = self.reported() else {
            return MU_BOUNDS;
        };
        let (lo, hi) = reported.bounds;
        match mean.report {
            ReportMap::Scale(s) => (lo / s, hi / s),
            ReportMap::SquareRoot => (lo * lo, hi * hi),
        }
    }

    /// From the fitted value to the reported one (mu: as is).
    pub fn report_map(self) -> ReportMap {
        self.reported()
            .map_or(ReportMap::Scale(1.0), |(mean, _)| mean.report)
    }

    /// The mean parameter's row entry and the reported parameter that shows it.
    fn reported(self) -> Option<(MeanParam, &'static EffectParam)> {
        let info = self.effect()?;
        let mean = info.mean?;
        Some((mean, info.param(mean.key)?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_follows_the_effect_order_and_names_its_keys() {
        assert_eq!(EFFECTS.len(), Effect::ALL.len());
        for (row, e) in EFFECTS.iter().zip(Effect::ALL) {
            assert_eq!(row.effect, e);
            assert_eq!(e.info().name, e.name());
            if let Some(m) = row.mean {
                assert!(row.param(m.key).is_some(), "{}: {}", row.name, m.key);
                assert_eq!(m.param.effect().map(|i| i.effect), Some(e));
            }
            assert!(!row.params.is_empty() && !row.law.is_empty());
            assert!(row.likelihood_params >= 1);
        }
        // Each fitted parameter (but mu) belongs to exactly one effect.
        for p in Param::ALL {
            let owners = EFFECTS
                .iter()
                .filter(|e| e.mean.is_some_and(|m| m.param == p))
                .count();
            assert_eq!(owners, usize::from(p != Param::Mu), "{p:?}");
        }
    }

    #[test]
    fn fit_bounds_are_the_libraries_bounds() {
        // The bounds `rig explain` has always fitted in.
        let expected = [
            (Param::Mu, (0.0, 3.0)),
            (Param::AxialCornerSq, (0.0, 1.0e6)),
            (Param::LoadExponent, (-0.9, 0.9)),
            (Param::ToothCompliance, (0.0, 1.0e-3)),
            (Param::Rectification, (-1.0, 20.0)),
            (Param::ViscousLoss, (-1.0, 1.0)),
            (Param::BushForce, (0.0, 1.0e4)),
            (Param::ThermalCoeff, (-1.0, 1.0)),
            (Param::CurrentOffset, (-100.0, 100.0)),
        ];
        for (p, b) in expected {
            assert_eq!(p.bounds(), b, "{p:?}");
        }
        assert_eq!(Param::AxialCornerSq.report_map(), ReportMap::SquareRoot);
        assert_eq!(Param::ViscousLoss.report_map(), ReportMap::Scale(1e3));
        assert_eq!(Param::Mu.report_map(), ReportMap::Scale(1.0));
    }

    #[test]
    fn report_and_apply_round_trip_through_the_table() {
        let p = EffectParams {
            axial_corner_speed: 20.0,
            load_exponent: 0.2,
            tooth_compliance: 1e-6,
            rectification: -1.0,
            viscous_loss: 1e-4,
            bush_force: 3.0,
            bush_hold_torque: 0.5,
            bush_corner_speed: 40.0,
            thermal_coeff: 2e-3,
            current_offset: 0.03,
            mesh_ripple_rms: 0.05,
        };
        let mut back = EffectParams::default();
        for row in EFFECTS {
            for q in row.params {
                if let Some(v) = q.report(&p) {
                    q.apply(&mut back, v);
                }
            }
        }
        assert_eq!(back, p);
        for row in EFFECTS {
            row.clear(&mut back);
        }
        assert_eq!(back, EffectParams::default());
        let q = Effect::VibratorViscousLoss
            .info()
            .param("c_v_n_mm_s_per_rad")
            .unwrap();
        assert!((q.report(&p).unwrap() - 0.1).abs() < 1e-15);
        assert!(
            !Effect::ThermalDrift
                .info()
                .param("reference_c")
                .unwrap()
                .apply(&mut back, 25.0)
        );
    }

    #[test]
    fn data_needs_name_what_is_missing() {
        let mut d = DataSummary {
            speed_levels: 3,
            load_levels: 10,
            rows: 150,
            thermal_driver: false,
            held_rows: 0,
        };
        let unmet = |e: Effect, d: &DataSummary| e.info().needs.unmet(d);
        assert_eq!(
            unmet(Effect::ThermalDrift, &d),
            Some("needs a temp_c or t_s column")
        );
        assert!(unmet(Effect::LinearBushFriction, &d).is_some());
        assert!(unmet(Effect::CurrentSensorOffset, &d).is_none());
        d.thermal_driver = true;
        d.held_rows = 4;
        assert!(unmet(Effect::ThermalDrift, &d).is_none());
        assert!(unmet(Effect::LinearBushFriction, &d).is_none());
        d.speed_levels = 1;
        assert!(unmet(Effect::InertiaRectification, &d).is_some());
        d.rows = 19;
        assert_eq!(
            unmet(Effect::MeshLoadSharingRipple, &d),
            Some("needs repeated tests at three or more loads")
        );
    }
}
