//! The law of a `[[user_effects]]` entry: its expression compiled once, evaluated wherever
//! the entry is used (`rig explain` fits it; the virtual rig's plant runs it).
//!
//! An expression (parsed by [`exmex`]) over `w` (cam speed, rad/s), `tau` (load, N m), `t`
//! (time since the first test, s), `temp` (motor temperature, deg C), `i` (the model's
//! current, A), `i_f` (its friction current, A), `i_m` (the inertia term's current, A) and
//! `f_ax` (the axial tooth force, N), and the effect's parameters; its value is the extra
//! current in A.

use std::collections::BTreeMap;

use model::effects::{CurrentModel, OperatingPoint};

/// Variables a user effect may use, in the order of [`UserLaw::eval`]'s data vector.
pub const USER_VARIABLES: [&str; 8] = ["w", "tau", "t", "temp", "i", "i_f", "i_m", "f_ax"];

/// A user effect's expression, compiled.
#[derive(Debug, Clone)]
pub struct UserLaw {
    /// The expression as written.
    pub expression: String,
    expr: exmex::FlatEx<f64>,
    /// For each variable of the expression (alphabetical, exmex's order): an index into
    /// the data variables (< 8) or 8 + the parameter's index.
    slots: Vec<usize>,
}

impl PartialEq for UserLaw {
    fn eq(&self, other: &Self) -> bool {
        self.expression == other.expression && self.slots == other.slots
    }
}

impl UserLaw {
    /// Compiles the expression of user effect `name` over [`USER_VARIABLES`] and the
    /// parameters `params` (in the order [`UserLaw::eval`] takes their values). An error (what
    /// to fix) when it does not parse, uses an unknown name, or leaves a parameter out.
    pub fn compile(name: &str, expression: &str, params: &[&str]) -> Result<Self, String> {
        let rewritten = leading_minus(expression)
            .map_err(|why| format!("user effect {name}: expression '{expression}': {why}"))?;
        let expr = exmex::parse::<f64>(&rewritten).map_err(|e| {
            format!("user effect {name}: expression '{expression}' does not parse: {e}")
        })?;
        let mut slots = Vec::new();
        for v in exmex::Express::var_names(&expr) {
            if let Some(k) = USER_VARIABLES.iter().position(|u| u == v) {
                slots.push(k);
            } else if let Some(k) = params.iter().position(|p| p == v) {
                slots.push(USER_VARIABLES.len() + k);
            } else {
                return Err(format!(
                    "user effect {name}: '{v}' in '{expression}' is neither a variable ({}) nor one of its parameters ({}): declare it under params or fix the name",
                    USER_VARIABLES.join(", "),
                    params.join(", ")
                ));
            }
        }
        for (k, p) in params.iter().enumerate() {
            if !slots.contains(&(USER_VARIABLES.len() + k)) {
                return Err(format!(
                    "user effect {name}: parameter {p} is not used in '{expression}': use it or drop it"
                ));
            }
        }
        Ok(Self {
            expression: expression.to_string(),
            expr,
            slots,
        })
    }

    /// The extra current at `data` (the [`USER_VARIABLES`] in order) with parameter values
    /// `params`, A; 0 where the expression is not finite (a pole or a root of a negative).
    /// `scratch` holds the expression's own variables between calls.
    pub fn eval(&self, data: &[f64; 8], params: &[f64], scratch: &mut Vec<f64>) -> f64 {
        scratch.clear();
        scratch.extend(self.slots.iter().map(|&slot| {
            if slot < data.len() {
                data[slot]
            } else {
                params.get(slot - data.len()).copied().unwrap_or(f64::NAN)
            }
        }));
        let r = exmex::Express::eval(&self.expr, scratch).unwrap_or(f64::NAN);
        if r.is_finite() { r } else { 0.0 }
    }
}

/// A user effect the model carries (`[[model.terms]]` naming a `[[user_effects]]` entry),
/// ready to run: its law and its parameter values (the term's, else the entry's start).
#[derive(Debug, Clone, PartialEq)]
pub struct UserTerm {
    /// The effect's name.
    pub name: String,
    /// Its law.
    pub law: UserLaw,
    /// Its parameters' values, in the law's order.
    pub values: Vec<f64>,
}

impl UserTerm {
    /// The extra current at cam speed `w` (rad/s), load `tau` (N m), session time `t` (s)
    /// and motor temperature `temp` (deg C), with the model's own quantities there from
    /// `model` at thermal driver `thermal` ([`OperatingPoint::thermal`]), as `rig explain`
    /// evaluates the term at a test point, A.
    pub fn current(
        &self,
        model: &CurrentModel,
        [w, tau, t, temp]: [f64; 4],
        thermal: f64,
        scratch: &mut Vec<f64>,
    ) -> f64 {
        let op = OperatingPoint::new(w, tau, thermal);
        let parts = model.torque_parts_with(&op, model.drive.gear.axial_force_per_torque());
        let data = [
            w,
            tau,
            t,
            temp,
            model.current_of(&parts, &op),
            model.friction_current_of(&parts, &op),
            inertia_current(model, &op),
            parts.axial_force,
        ];
        self.law.eval(&data, &self.values, scratch)
    }
}

/// The inertia term's current at `op` (the paper's M_hat w^2 e^2 / pi over the torque
/// constant), A.
pub fn inertia_current(model: &CurrentModel, op: &OperatingPoint) -> f64 {
    model.drive.required_inertia_torque(op.omega_n) / model.torque_constant(op)
}

/// The user terms of a model: each `[[model.terms]]` entry without a form names a
/// `[[user_effects]]` definition in `defs`; its parameters are the entry's values, else the
/// definition's start (or null).
pub(crate) fn user_terms(
    entries: &[crate::TermEntry],
    defs: &[crate::UserEffectDef],
) -> Result<Vec<UserTerm>, String> {
    let mut out = Vec::new();
    for t in entries.iter().filter(|t| t.form.is_none()) {
        let Some(def) = defs.iter().find(|d| d.name == t.name) else {
            continue;
        };
        let keys: Vec<&str> = def.params.keys().map(String::as_str).collect();
        let law = UserLaw::compile(&def.name, &def.expression, &keys)?;
        let values = def
            .params
            .iter()
            .map(|(k, p)| value_of(&t.params, k, p.start.unwrap_or(p.null)))
            .collect();
        out.push(UserTerm {
            name: def.name.clone(),
            law,
            values,
        });
    }
    Ok(out)
}

fn value_of(params: &BTreeMap<String, f64>, key: &str, default: f64) -> f64 {
    params.get(key).copied().unwrap_or(default)
}

/// Rewrites every unary minus (at the start, after `(`, `,` or an operator) as `(-1)*`, so
/// that it binds as in mathematics (`-x^2` is `-(x^2)`; exmex itself binds a unary operator
/// tighter than `^`). A minus right after `/` or `^` is refused (what to write instead),
/// since no such rewriting keeps its meaning.
pub fn leading_minus(expression: &str) -> Result<String, String> {
    let mut out = String::with_capacity(expression.len() + 8);
    let mut previous: Option<char> = None;
    for c in expression.chars() {
        if c == '-' {
            match previous {
                None | Some('(' | ',' | '+' | '-' | '*') => {
                    out.push_str("(-1)*");
                    previous = Some('*');
                    continue;
                }
                Some(p @ ('/' | '^')) => {
                    return Err(format!(
                        "a minus right after '{p}' is ambiguous: put the negative in parentheses (x{p}(-2), not x{p}-2)"
                    ));
                }
                _ => {}
            }
        }
        out.push(c);
        if !c.is_whitespace() {
            previous = Some(c);
        }
    }
    Ok(out)
}
