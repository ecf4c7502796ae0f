//! Presets of the virtual rig, and effects hidden in its plant by name.
//!
//! * [`Preset::ideal`]: the paper's equations alone (Eqs. 6-10 with Table 2's calibration):
//!   every effect of [`model::plant::PlantEffects`] off.
//! * [`Preset::paper`]: what the paper *measured*, not only its model. Two effects the paper
//!   itself names as the explanation of its discrepancies are switched on:
//!
//! | Effect (`rig explain` name) | Plant setting | Value | Where it comes from |
//! |---|---|---|---|
//! | `speed-dependent-axial-friction` | `axial_friction_speed = (depth, omega0)` | `(0.6, 35 rad/s)` | The paper measured less torque than Eq. (10) at 3.6 V (about 5 Hz, 31 rad/s) and explains it by mu_ax falling at low cam speed. The dip mu_ax = mu (1 - 0.6 exp(-w / 35)) lowers mu_ax by 25 % at 31 rad/s, 10 % at 62 rad/s (6.2 V) and 4 % at 95 rad/s (8.8 V), so the mean of (measured - Eq. 10) is most negative at 3.6 V. |
//! | `linear-bush-friction` | `bush_friction`, `bush_hold_arm`, `bush_omega` | `1 N`, `1.75 m`, `20 rad/s` | The paper saw no backdrive at 0.368 N m with 3.6 and 6.2 V and explains it by the carrier's linear bush. Its hold T_0 / (1 + w / w_b) with T_0 = 1.75 N m and w_b = 20 rad/s is 0.69 N m at 31 rad/s (below Fig. 5's 0.736 N m, which still falls), 0.41 N m at 65 rad/s (above 0.368 N m: held at 6.2 V) and 0.30 N m at 97 rad/s (below 0.368 N m: backdriven at 8.8 V, as measured). The force (1 N, an effective value) only adds (2/pi) F e = 0.64 mN m to the cam torque; the lever arm is T_0 / F. |
//!
//! Table 1 (3.68 N m) is far above the bush's hold at any cam speed, so its verdicts do not
//! change; the trends of Figs. 8-9 (current and torque grow with load and speed) stay.

use std::collections::BTreeMap;

use model::effects::{Effect, EffectParams};
use model::plant::{PlantEffects, PlantParams};

use crate::SimError;

/// A named configuration of the plant's effects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preset {
    /// Its name on the command line (`paper`, `ideal`).
    pub name: &'static str,
    /// The plant's effects.
    pub effects: PlantEffects,
}

/// The presets' names, default first.
pub const PRESETS: [&str; 2] = ["paper", "ideal"];

/// `paper`'s speed-dependent axial friction: depth of the dip of mu_ax at standstill.
pub const PAPER_AXIAL_DIP_DEPTH: f64 = 0.6;
/// `paper`'s speed-dependent axial friction: cam speed over which the dip fades, rad/s.
pub const PAPER_AXIAL_DIP_OMEGA0: f64 = 35.0;
/// `paper`'s linear bush: Coulomb force, N (an effective value, see the module docs).
pub const PAPER_BUSH_FORCE_N: f64 = 1.0;
/// `paper`'s linear bush: holding torque at rest T_0, N m.
pub const PAPER_BUSH_HOLD_NM: f64 = 1.75;
/// `paper`'s linear bush: cam speed at which the hold has halved, rad/s.
pub const PAPER_BUSH_OMEGA_RAD_S: f64 = 20.0;

impl Preset {
    /// The drive the paper's rig used: a bench supply through a drive that took no power
    /// back (coasting, kappa -1/2), as its Eq. (10) and Fig. 9 show (the measured cam
    /// torque grows with speed by the acceleration phase's inertia term, which a braking
    /// drive would return through the gearhead, 82 % of it). A preset sets effects only;
    /// the virtual rig's drive is the rig's (`[drive] decay`, braking by default): a rig
    /// file with `[drive] decay = "coast"` reproduces the paper's (`docs/presets.md`).
    pub const PAPER_DRIVE: rigfile::DecayMode = rigfile::DecayMode::Coast;

    /// The paper's equations alone: no effect.
    pub fn ideal() -> Self {
        Self {
            name: "ideal",
            effects: PlantEffects::default(),
        }
    }

    /// What the paper measured (see the module documentation for each value).
    pub fn paper() -> Self {
        Self {
            name: "paper",
            effects: PlantEffects {
                axial_friction_speed: Some((PAPER_AXIAL_DIP_DEPTH, PAPER_AXIAL_DIP_OMEGA0)),
                bush_friction: PAPER_BUSH_FORCE_N,
                bush_hold_arm: PAPER_BUSH_HOLD_NM / PAPER_BUSH_FORCE_N,
                bush_omega: PAPER_BUSH_OMEGA_RAD_S,
                ..PlantEffects::default()
            },
        }
    }

    /// The preset called `name` ([`PRESETS`]).
    pub fn by_name(name: &str) -> Result<Self, SimError> {
        match name {
            "paper" => Ok(Self::paper()),
            "ideal" => Ok(Self::ideal()),
            other => Err(SimError::BadValue {
                what: format!("preset '{other}'"),
                why: format!("unknown preset: give one of {}", PRESETS.join(", ")),
            }),
        }
    }

    /// Puts the preset's effects into `plant` (replacing its effects).
    pub fn apply(&self, plant: &mut PlantParams) {
        plant.effects = self.effects;
    }
}

/// An effect hidden in the plant, as `--effect NAME[:k=v,...]` gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct EffectSpec {
    /// The effect.
    pub effect: Effect,
    /// Its parameters by the names of `rig explain` (the effects table), SI with the unit
    /// in the name.
    pub params: BTreeMap<String, f64>,
}

impl EffectSpec {
    /// Parses `NAME[:k=v,...]`, e.g. `current-sensor-offset:offset_a=0.05`.
    pub fn parse(s: &str) -> Result<Self, SimError> {
        let bad = |why: String| SimError::BadValue {
            what: format!("--effect {s}"),
            why,
        };
        let (name, rest) = match s.split_once(':') {
            Some((n, r)) => (n.trim(), Some(r)),
            None => (s.trim(), None),
        };
        let effect = Effect::from_name(name).ok_or_else(|| {
            bad(format!(
                "unknown effect '{name}': give one of {}",
                Effect::ALL.map(|e| e.name()).join(", ")
            ))
        })?;
        let mut params = BTreeMap::new();
        for kv in rest.into_iter().flat_map(|r| r.split(',')) {
            let kv = kv.trim();
            if kv.is_empty() {
                continue;
            }
            let (k, v) = kv.split_once('=').ok_or_else(|| {
                bad(format!(
                    "'{kv}' is not key=value (for example {name}:{}=1.0)",
                    plant_keys(effect).first().copied().unwrap_or("key")
                ))
            })?;
            let v: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite())
                .ok_or_else(|| bad(format!("{k} = '{v}' is not a finite number")))?;
            params.insert(k.trim().to_string(), v);
        }
        Ok(Self { effect, params })
    }

    /// Why the effect cannot show in the rows a client logs through the firmware (a served
    /// rig, `Rig.virtual`, `rig discover`), or `None` when it can: the firmware zeroes its
    /// current reading with the motor off (as on the board), so a current-sensor offset
    /// cancels in every current it reports. Only a separate logger on the sensor (the
    /// paper's) sees it.
    pub fn unseen_through_firmware(&self) -> Option<String> {
        let name = self.effect.name();
        (self.effect == Effect::CurrentSensorOffset).then(|| {
            format!(
                "--effect {name}: the virtual rig adds the offset to the sensor's reading, but the firmware zeroes its current reading with the motor off (as on the board), so the offset cancels in the rows logged through the firmware (a served rig, Rig.virtual, `rig discover`) and `rig explain` on them ends no-missing-effect; it cannot be found this way. A separate logger on the sensor (as the paper's) would see it: try `rig explain --synthetic {name}`"
            )
        })
    }

    /// Puts the effect into `plant` with its parameters (defaults: the paper preset's
    /// values for its two effects, otherwise a clearly visible strength).
    pub fn apply(&self, plant: &mut PlantParams) -> Result<(), SimError> {
        let name = self.effect.name();
        let bad = |why: String| SimError::BadValue {
            what: format!("--effect {name}"),
            why,
        };
        let get = |key: &str, default: f64| self.params.get(key).copied().unwrap_or(default);
        // The plant's own law for the speed-dependent friction is a variant (see
        // `PlantEffects::axial_friction_speed`); its parameters are the variant's.
        if self.effect == Effect::SpeedDependentAxialFriction {
            for k in self.params.keys() {
                if !["depth", "omega0_rad_s"].contains(&k.as_str()) {
                    return Err(bad(format!(
                        "the plant runs this effect as mu (1 - depth exp(-w / omega0)): it takes depth and omega0_rad_s, not {k}"
                    )));
                }
            }
            let depth = get("depth", PAPER_AXIAL_DIP_DEPTH);
            let omega0 = get("omega0_rad_s", PAPER_AXIAL_DIP_OMEGA0);
            if !(0.0..=1.0).contains(&depth) || omega0 <= 0.0 {
                return Err(bad(
                    "depth must be in [0, 1] and omega0_rad_s above 0".to_string()
                ));
            }
            plant.effects.axial_friction_speed = Some((depth, omega0));
            return Ok(());
        }
        let mut p = EffectParams {
            load_exponent: 0.3,
            current_offset: 0.05,
            thermal_coeff: 0.004,
            viscous_loss: 0.15e-3,
            bush_force: PAPER_BUSH_FORCE_N,
            bush_hold_torque: PAPER_BUSH_HOLD_NM,
            bush_corner_speed: PAPER_BUSH_OMEGA_RAD_S,
            rectification: -0.5,
            // Seed 004's few micrometres per newton: 2 um/N shortens the 1 mm stroke by
            // about a seventh at the paper's largest load (68 N axially), inside the
            // library's limit of a quarter.
            tooth_compliance: 2e-6,
            // Seed 003's mesh friction ripples by about a tenth over a mesh cycle.
            mesh_ripple_rms: 0.1,
            ..EffectParams::default()
        };
        rigfile::apply_params(self.effect, &self.params, &mut p).map_err(bad)?;
        let e = &mut plant.effects;
        match self.effect {
            Effect::LoadDependentFriction => {
                e.load_friction =
                    Some((p.load_exponent, model::effects::LOAD_FRICTION_REFERENCE_NM));
            }
            Effect::CurrentSensorOffset => e.current_offset = p.current_offset,
            Effect::ThermalDrift => e.thermal_drift = Some(p.thermal_coeff),
            Effect::VibratorViscousLoss => e.extra_viscous = p.viscous_loss,
            Effect::LinearBushFriction => {
                if p.bush_force <= 0.0 {
                    return Err(bad("force_n must be above 0".into()));
                }
                e.bush_friction = p.bush_force;
                e.bush_hold_arm = p.bush_hold_torque / p.bush_force;
                e.bush_omega = p.bush_corner_speed;
            }
            Effect::InertiaRectification => {
                plant.regeneration = model::effects::kappa_returns_power(p.rectification);
                e.inertia_kappa = Some((p.rectification, 0.0));
            }
            Effect::ToothCompliance => {
                if p.tooth_compliance <= 0.0 {
                    return Err(bad("compliance_um_per_n must be above 0".into()));
                }
                e.tooth_compliance = p.tooth_compliance;
            }
            Effect::MeshLoadSharingRipple => {
                if !(p.mesh_ripple_rms > 0.0 && p.mesh_ripple_rms <= 1.0) {
                    return Err(bad("ripple_rms must be above 0 and at most 1".into()));
                }
                e.mesh_ripple_rms = p.mesh_ripple_rms;
            }
            // Handled above, as the plant's variant of the law.
            Effect::SpeedDependentAxialFriction => {}
        }
        Ok(())
    }
}

/// Cam speeds over which a fitted Eq. (40) speed factor is matched by the plant's own law,
/// rad/s: 3 to 20 Hz, the board's range.
const AXIAL_MATCH_RANGE: (f64, f64) = (
    2.0 * std::f64::consts::PI * 3.0,
    2.0 * std::f64::consts::PI * 20.0,
);

/// The plant's law for `speed-dependent-axial-friction`, mu (1 - depth exp(-w / omega0)),
/// closest (least squares over 3-20 Hz) to the fitted Eq. (40) factor
/// w / sqrt(w^2 + w_c^2) with corner `omega_c` (rad/s): `(depth, omega0)`.
pub fn axial_dip_for_corner(omega_c: f64) -> (f64, f64) {
    use model::effects::{AxialSpeedLaw, axial_friction_speed_factor};
    if !(omega_c.is_finite() && omega_c > 0.0) {
        return (0.0, PAPER_AXIAL_DIP_OMEGA0);
    }
    let (lo, hi) = AXIAL_MATCH_RANGE;
    let speeds: Vec<f64> = (0..=60).map(|k| lo + (hi - lo) * k as f64 / 60.0).collect();
    let mut best = (f64::INFINITY, 0.0, PAPER_AXIAL_DIP_OMEGA0);
    // omega0 on a log grid; depth in closed form for each (the law is linear in it).
    for j in 0..=400 {
        let omega0 = 2.0 * 10f64.powf(3.0 * j as f64 / 400.0);
        let (mut num, mut den) = (0.0, 0.0);
        for &w in &speeds {
            let e = (-w / omega0).exp();
            num += (1.0 - axial_friction_speed_factor(w, omega_c)) * e;
            den += e * e;
        }
        let depth = if den > 0.0 {
            (num / den).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let law = AxialSpeedLaw::ExponentialDip { depth, omega0 };
        let sse: f64 = speeds
            .iter()
            .map(|&w| (law.factor(w) - axial_friction_speed_factor(w, omega_c)).powi(2))
            .sum();
        if sse < best.0 {
            best = (sse, depth, omega0);
        }
    }
    (best.1, best.2)
}

/// Runs the fitted `[model]` of `rig` in `config`'s plant: mu (the axial friction's) and
/// every effect, each at its physical place (`rigfile`'s mapping, and the speed-dependent
/// axial friction as Eq. (40) with its fitted corner, the law `rig explain` fits), and its
/// user effects ([`crate::user_effects`]). An effect the plant cannot run is an error
/// naming it. Without a `[model]`, nothing changes.
pub fn apply_model(rig: &rigfile::RigFile, config: &mut crate::SimConfig) -> Result<(), SimError> {
    let plant = &mut config.plant;
    let Some(m) = &rig.model else {
        return Ok(());
    };
    let bad = |why: String| SimError::BadValue {
        what: "the rig file's [model]".into(),
        why,
    };
    let setup = rig.plant_effects().map_err(|e| bad(e.to_string()))?;
    let (_, params) = rig.effects().map_err(bad)?;
    let mut missing = Vec::new();
    let mut effects = setup.effects;
    for e in setup.not_in_plant {
        match e {
            // The law `rig explain` fits (Eq. 40 with its corner), run as fitted.
            Effect::SpeedDependentAxialFriction => {
                effects.axial_friction_corner =
                    (params.axial_corner_speed > 0.0).then_some(params.axial_corner_speed);
            }
            // Seed 004's and seed 003's physics of the teeth, at the fitted strength.
            Effect::ToothCompliance => effects.tooth_compliance = params.tooth_compliance,
            Effect::MeshLoadSharingRipple => effects.mesh_ripple_rms = params.mesh_ripple_rms,
            Effect::ThermalDrift => missing.push(format!(
                "{} against time (k_per_s: the plant drifts with its winding temperature; log temp_c and refit)",
                e.name()
            )),
            other => missing.push(other.name().to_string()),
        }
    }
    missing.extend(setup.terms_not_in_plant);
    if !missing.is_empty() {
        return Err(bad(format!(
            "the virtual rig's plant cannot run {} (it runs: {}); remove {} from [model] to simulate the rest",
            missing.join(", "),
            PLANT_EFFECTS.join(", "),
            if missing.len() == 1 { "it" } else { "them" }
        )));
    }
    plant.mu_ax = m.mu;
    plant.effects = effects;
    // The drive's regeneration is the board's unless the model fitted it.
    if let Some(regeneration) = setup.regeneration {
        plant.regeneration = regeneration;
    }
    config.user_effects = crate::user_effects::UserEffects::of(rig, setup.user_terms)?;
    Ok(())
}

/// The effects the plant can run (`--effect`).
pub const PLANT_EFFECTS: [&str; 9] = [
    "speed-dependent-axial-friction",
    "load-dependent-friction",
    "current-sensor-offset",
    "thermal-drift",
    "vibrator-viscous-loss",
    "inertia-rectification",
    "linear-bush-friction",
    "tooth-compliance",
    "mesh-load-sharing-ripple",
];

fn plant_keys(effect: Effect) -> Vec<&'static str> {
    if effect == Effect::SpeedDependentAxialFriction {
        vec!["depth", "omega0_rad_s"]
    } else {
        effect.info().keys().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fitted_model_runs_in_the_plant_or_names_what_cannot() {
        use model::effects::{AxialSpeedLaw, axial_friction_speed_factor};
        // The matched dip follows Eq. (40) within a few per cent over the board's range.
        for wc in [12.0, 20.0, 30.0] {
            let (depth, omega0) = axial_dip_for_corner(wc);
            let law = AxialSpeedLaw::ExponentialDip { depth, omega0 };
            for hz in [5.0, 10.0, 15.0] {
                let w = 2.0 * std::f64::consts::PI * hz;
                let err = law.factor(w) - axial_friction_speed_factor(w, wc);
                assert!(err.abs() < 0.03, "w_c {wc}, {hz} Hz: {err}");
            }
        }
        let rig = rigfile::RigFile::paper().with_model(
            0.25,
            vec![
                rigfile::EffectEntry {
                    name: "speed-dependent-axial-friction".into(),
                    params: [("omega_c_rad_s".to_string(), 20.0)].into(),
                },
                rigfile::EffectEntry {
                    name: "current-sensor-offset".into(),
                    params: [("offset_a".to_string(), 0.04)].into(),
                },
            ],
        );
        let mut config = crate::SimConfig::paper();
        apply_model(&rig, &mut config).unwrap();
        let plant = &config.plant;
        assert_eq!(plant.mu_ax, 0.25);
        assert!((plant.effects.current_offset - 0.04).abs() < 1e-12);
        // Eq. (40) with the fitted corner, the law `rig explain` fitted, not an approximation.
        assert_eq!(plant.effects.axial_friction_corner, Some(20.0));
        assert!(plant.effects.axial_friction_speed.is_none());
        // A drift against time: the plant drifts with its winding temperature only.
        let timed = rigfile::RigFile::paper().with_model(
            0.25,
            vec![rigfile::EffectEntry {
                name: "thermal-drift".into(),
                params: [("k_per_s".to_string(), 1e-6)].into(),
            }],
        );
        let e = apply_model(&timed, &mut config).unwrap_err().to_string();
        assert!(e.contains("cannot run thermal-drift against time"), "{e}");
        // The seeds' tooth compliance runs as the plant's physics, at its fitted value.
        let tooth = rigfile::RigFile::paper().with_model(
            0.25,
            vec![rigfile::EffectEntry {
                name: "tooth-compliance".into(),
                params: [("compliance_um_per_n".to_string(), 15.0)].into(),
            }],
        );
        apply_model(&tooth, &mut config).unwrap();
        assert!((config.plant.effects.tooth_compliance - 15e-6).abs() < 1e-15);
    }

    #[test]
    fn a_fitted_rectification_runs_as_its_kappa_and_no_term_is_dropped() {
        // `rig explain`'s load-dependent rectification, as `--write-model` writes it.
        let mut rig = rigfile::RigFile::paper().with_model_terms(
            0.27,
            vec![],
            vec![rigfile::TermEntry {
                name: "inertia-rectification".into(),
                form: Some("load-dependent".into()),
                params: [
                    ("kappa".to_string(), -0.45),
                    ("kappa_per_nm".to_string(), 0.03),
                ]
                .into(),
            }],
        );
        let mut config = crate::SimConfig::paper();
        apply_model(&rig, &mut config).unwrap();
        assert_eq!(config.plant.effects.inertia_kappa, Some((-0.45, 0.03)));
        assert!(!config.plant.regeneration);
        // A term the plant has no law for is named, not silently left out.
        if let Some(m) = rig.model.as_mut() {
            m.terms[0].form = Some("warm-up-in-time".into());
            m.terms[0].name = "thermal-drift".into();
        }
        let err = apply_model(&rig, &mut crate::SimConfig::paper())
            .unwrap_err()
            .to_string();
        assert!(err.contains("thermal-drift (warm-up-in-time)"), "{err}");
    }

    #[test]
    fn presets_and_effects_parse() {
        assert_eq!(
            Preset::by_name("ideal").unwrap().effects,
            PlantEffects::default()
        );
        let p = Preset::paper().effects;
        assert!((p.bush_hold_torque(0.0) - PAPER_BUSH_HOLD_NM).abs() < 1e-12);
        // The hold's design points (module docs).
        assert!(p.bush_hold_torque(31.4) < 0.736);
        assert!(p.bush_hold_torque(65.0) > 0.368);
        assert!(p.bush_hold_torque(97.0) < 0.368);
        assert!(
            Preset::by_name("real")
                .unwrap_err()
                .to_string()
                .contains("paper, ideal")
        );
        let mut plant = crate::SimConfig::paper().plant;
        let s = EffectSpec::parse("current-sensor-offset:offset_a=0.1").unwrap();
        assert!(
            s.unseen_through_firmware()
                .is_some_and(|w| w.contains("zeroes its current reading"))
        );
        assert!(
            EffectSpec::parse("thermal-drift")
                .unwrap()
                .unseen_through_firmware()
                .is_none()
        );
        s.apply(&mut plant).unwrap();
        assert!((plant.effects.current_offset - 0.1).abs() < 1e-12);
        EffectSpec::parse("speed-dependent-axial-friction")
            .unwrap()
            .apply(&mut plant)
            .unwrap();
        assert_eq!(plant.effects.axial_friction_speed, Some((0.6, 35.0)));
        let e = EffectSpec::parse("no-such").unwrap_err().to_string();
        assert!(e.contains("linear-bush-friction"), "{e}");
        let e = EffectSpec::parse("thermal-drift:k=x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a finite number"), "{e}");
        // Every library effect runs in the plant, the seeds' two as physics of the teeth.
        for effect in Effect::ALL {
            let mut p = plant;
            p.effects = PlantEffects::default();
            EffectSpec::parse(effect.name())
                .unwrap()
                .apply(&mut p)
                .unwrap_or_else(|e| panic!("{}: {e}", effect.name()));
            assert_ne!(p.effects, PlantEffects::default(), "{}", effect.name());
        }
        let e = EffectSpec::parse("tooth-compliance:compliance_um_per_n=0")
            .unwrap()
            .apply(&mut plant)
            .unwrap_err()
            .to_string();
        assert!(e.contains("above 0"), "{e}");
    }
}
