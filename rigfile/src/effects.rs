//! The `[model]` section at work: its effects with their parameters, the current model it
//! describes, and how the plant runs it.

use std::collections::BTreeMap;

use model::effects::{CurrentModel, Effect, EffectParams, ParamValue};

use crate::{RigFile, RigFileError};

/// Most `[[user_effects]]` entries a rig file may hold (each is a candidate of every step).
pub const MAX_USER_EFFECTS: usize = 16;
/// Longest `[[user_effects]]` expression, bytes (a few terms take a few dozen; the
/// expression is evaluated at every point of every fit and finite difference).
pub const MAX_EXPRESSION_BYTES: usize = 1024;
/// Most parameters of one user effect.
pub const MAX_USER_PARAMS: usize = 8;

/// How the plant (`model::plant`) runs a rig file's model: see [`RigFile::plant_effects`].
#[derive(Debug, Clone, PartialEq)]
pub struct PlantSetup {
    /// The plant's switchable effects.
    pub effects: model::plant::PlantEffects,
    /// Whether the drive regenerates (`PlantParams::regeneration`), when the model fits
    /// `inertia-rectification`; `None` when it does not: the plant then keeps its own drive
    /// (Eq. (10)'s kappa = 0 is neither drive the plant can run).
    pub regeneration: Option<bool>,
    /// Effects of the model the plant cannot represent.
    pub not_in_plant: Vec<Effect>,
    /// `[[model.terms]]` entries the plant cannot represent, as `name (form)`.
    pub terms_not_in_plant: Vec<String>,
    /// The model's user effects (`[[model.terms]]` naming `[[user_effects]]`), which the
    /// plant runs as a drag on the vibrator drawing their extra current
    /// (`model::plant::Plant::set_user_current`).
    pub user_terms: Vec<crate::UserTerm>,
}

impl RigFile {
    /// The `[[model.terms]]` entries (`rig explain` checks their forms and parameters).
    pub fn term_entries(&self) -> &[crate::TermEntry] {
        self.model.as_ref().map_or(&[], |m| m.terms.as_slice())
    }

    /// Checks `[[user_effects]]` (names, bounds, null and start values) and that each
    /// `[[model.terms]]` entry names a library effect with a form or a user effect; the
    /// expressions themselves are checked by `rig explain`.
    pub(crate) fn check_user_effects(&self) -> Result<(), String> {
        let mut names: Vec<&str> = Vec::new();
        if self.user_effects.len() > MAX_USER_EFFECTS {
            return Err(format!(
                "[[user_effects]]: {} entries, at most {MAX_USER_EFFECTS} are searched: keep the ones you mean to test",
                self.user_effects.len()
            ));
        }
        for u in &self.user_effects {
            let what = format!("[[user_effects]] {}", u.name);
            if u.expression.len() > MAX_EXPRESSION_BYTES {
                return Err(format!(
                    "{what}: expression is {} bytes long, at most {MAX_EXPRESSION_BYTES} are allowed (each is evaluated at every test point of every fit): write the law in fewer terms",
                    u.expression.len()
                ));
            }
            if u.params.len() > MAX_USER_PARAMS {
                return Err(format!(
                    "{what}: {} parameters, at most {MAX_USER_PARAMS}: the data of a sweep cannot pin more",
                    u.params.len()
                ));
            }
            if u.name.is_empty()
                || Effect::from_name(&u.name).is_some()
                || names.contains(&u.name.as_str())
            {
                return Err(format!(
                    "{what}: give each user effect a name of its own, not empty and not a library effect's"
                ));
            }
            names.push(&u.name);
            if u.expression.trim().is_empty() {
                return Err(format!(
                    "{what}: expression is empty: give the extra current in A as an expression"
                ));
            }
            let keys: Vec<&str> = u.params.keys().map(String::as_str).collect();
            crate::UserLaw::compile(&u.name, &u.expression, &keys)
                .map_err(|why| format!("{what}: {why}"))?;
            for (k, p) in &u.params {
                let [lo, hi] = p.bounds;
                let start = p.start.unwrap_or(p.null);
                if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                    return Err(format!(
                        "{what}: parameter {k} bounds = [{lo}, {hi}]: give finite bounds, low < high"
                    ));
                }
                if !(lo..=hi).contains(&p.null) || !(lo..=hi).contains(&start) {
                    return Err(format!(
                        "{what}: parameter {k}: null {} and start {start} must lie within [{lo}, {hi}]",
                        p.null
                    ));
                }
                if p.log && lo <= 0.0 {
                    return Err(format!(
                        "{what}: parameter {k} is fitted in ln (log = true): its bounds must be positive"
                    ));
                }
            }
        }
        for t in self.term_entries() {
            let known = match &t.form {
                Some(_) => Effect::from_name(&t.name).is_some(),
                None => names.contains(&t.name.as_str()),
            };
            if !known {
                return Err(format!(
                    "[[model.terms]] {}: give a library effect's name with a form, or the name of a [[user_effects]] definition",
                    t.name
                ));
            }
        }
        Ok(())
    }

    /// The effects of `[model]` with their parameters, in file order.
    pub fn effects(&self) -> Result<(Vec<Effect>, EffectParams), String> {
        let mut list = Vec::new();
        let mut params = EffectParams::default();
        let terms = self.term_entries();
        for entry in self.model.iter().flat_map(|m| &m.effects) {
            if terms.iter().any(|t| t.name == entry.name) {
                return Err(format!(
                    "effect {} is listed twice (once under [[model.terms]])",
                    entry.name
                ));
            }
            let effect = Effect::from_name(&entry.name).ok_or_else(|| {
                format!(
                    "unknown effect '{}' (known: {})",
                    entry.name,
                    Effect::ALL.map(|e| e.name()).join(", ")
                )
            })?;
            if list.contains(&effect) {
                return Err(format!("effect {} is listed twice", entry.name));
            }
            apply_params(effect, &entry.params, &mut params)?;
            list.push(effect);
        }
        Ok((list, params))
    }

    /// The current model this file describes: the fitted mu and effects of `[model]`, or the
    /// paper's model with mu = mu_s when there is none.
    pub fn current_model(&self) -> Result<CurrentModel, RigFileError> {
        let mut m = CurrentModel::paper(
            self.drive()?,
            self.calibration(),
            self.model.as_ref().map_or(self.friction.mu_s, |m| m.mu),
        );
        m.effects = self
            .effects()
            .map_err(|why| RigFileError::RigFile {
                file: "(in memory)".into(),
                why,
            })?
            .1;
        Ok(m)
    }

    /// The plant's switchable effects (`model::plant`) for the effects of `[model]`, so the
    /// simulator can run the augmented model, with the names of the effects the plant cannot
    /// represent. Exact: load-dependent friction, current offset, thermal drift (per K),
    /// viscous loss, linear bush (lever arm = hold / force), inertia rectification (its kappa,
    /// also as the `load-dependent` term of `[[model.terms]]`; the drive regenerates when
    /// kappa < -0.75), user effects (`user_terms`). Not in the plant: the
    /// speed-dependent axial friction of Eq. (40) with a fixed corner speed (the plant's
    /// `friction_split` applies Eq. 40 with the simulated output speed instead), tooth
    /// compliance, the mesh ripple and a thermal drift against time.
    pub fn plant_effects(&self) -> Result<PlantSetup, RigFileError> {
        let (list, p) = self.effects().map_err(|why| RigFileError::RigFile {
            file: "(in memory)".into(),
            why,
        })?;
        let mut out = model::plant::PlantEffects::default();
        let mut regeneration = None;
        let mut missing = Vec::new();
        let mut missing_terms = Vec::new();
        let time_driven = self
            .model
            .iter()
            .flat_map(|m| &m.effects)
            .any(|e| e.params.contains_key("k_per_s"));
        for e in list {
            match e {
                Effect::LoadDependentFriction => {
                    out.load_friction =
                        Some((p.load_exponent, model::effects::LOAD_FRICTION_REFERENCE_NM));
                }
                Effect::CurrentSensorOffset => out.current_offset = p.current_offset,
                Effect::ThermalDrift if !time_driven => out.thermal_drift = Some(p.thermal_coeff),
                Effect::VibratorViscousLoss => out.extra_viscous = p.viscous_loss,
                Effect::LinearBushFriction if p.bush_force > 0.0 => {
                    out.bush_friction = p.bush_force;
                    out.bush_hold_arm = p.bush_hold_torque / p.bush_force;
                    out.bush_omega = p.bush_corner_speed;
                }
                Effect::InertiaRectification => {
                    regeneration = Some(model::effects::kappa_returns_power(p.rectification));
                    out.inertia_kappa = Some((p.rectification, 0.0));
                }
                other => missing.push(other),
            }
        }
        // `[[model.terms]]`: the family forms the plant runs by the same law and the user
        // effects (as a drag drawing their current); any other is named as not in the
        // plant, never dropped.
        let user_terms = crate::user_law::user_terms(self.term_entries(), &self.user_effects)
            .map_err(|why| RigFileError::RigFile {
                file: "(in memory)".into(),
                why,
            })?;
        for t in self.term_entries() {
            let effect = Effect::from_name(&t.name);
            if t.form.is_none() && user_terms.iter().any(|u| u.name == t.name) {
                continue;
            }
            match (effect, t.form.as_deref()) {
                (Some(Effect::InertiaRectification), Some("load-dependent")) => {
                    let kappa = t.params.get("kappa").copied().unwrap_or(p.rectification);
                    let per_nm = t.params.get("kappa_per_nm").copied().unwrap_or(0.0);
                    regeneration = Some(model::effects::kappa_returns_power(kappa));
                    out.inertia_kappa = Some((kappa, per_nm));
                }
                _ => missing_terms.push(match &t.form {
                    Some(f) => format!("{} ({f})", t.name),
                    None => t.name.clone(),
                }),
            }
        }
        Ok(PlantSetup {
            effects: out,
            regeneration,
            not_in_plant: missing,
            terms_not_in_plant: missing_terms,
            user_terms,
        })
    }
}

/// Sets the effect's parameters in `p` from reported (rig-file) names, as the model's effect
/// table ([`model::effects::EFFECTS`]) names them with their units; unknown names are an
/// error naming the expected ones, a fixed parameter must keep its value, any other must be
/// finite and inside its range (the table's `bounds`, named in the error). Missing names
/// keep their value in `p`.
pub fn apply_params(
    effect: Effect,
    params: &BTreeMap<String, f64>,
    p: &mut EffectParams,
) -> Result<(), String> {
    let info = effect.info();
    for (k, &v) in params {
        let Some(param) = info.param(k) else {
            return Err(format!(
                "effect {} has no parameter {k} (it takes {})",
                effect.name(),
                info.keys().collect::<Vec<_>>().join(", ")
            ));
        };
        if !v.is_finite() {
            return Err(format!("{} {k} = {v} is not finite", effect.name()));
        }
        if let ParamValue::Fixed(fixed) = param.value {
            if (v - fixed).abs() > 1e-12 {
                return Err(format!(
                    "{} {k} is fixed at {fixed} {}",
                    effect.name(),
                    param.unit
                ));
            }
        } else if !(param.bounds.0..=param.bounds.1).contains(&v) {
            // The range the fit keeps it in (the physical one where fitted apart): a value
            // outside it came from no fit, and the laws are not made for it.
            return Err(format!(
                "{} {k} = {v} is out of range: it must be {} {}",
                effect.name(),
                crate::keys::range_text(param.bounds),
                param.unit
            ));
        }
        param.apply(p, v);
    }
    Ok(())
}
