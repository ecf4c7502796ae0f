//! Effects whose law is an extra term of the current: the physically plausible families of
//! the library's laws ([`Form`]) and the user's own effects from the rig file ([`UserEffect`]).
//!
//! A term adds a current (A) at each test point, computed from the point's conditions and
//! the model's own quantities there (its current, friction current, inertia current and
//! axial force), with parameters of its own. It enters the same selection as the library's
//! effects: fitted jointly with the model, scored by BIC, guarded by the same null
//! simulation and confirmed on held-out points. A term vanishes at its parameters' null
//! values, so the model without it is nested in the model with it.
//!
//! The families (each nests its library law or generalises it where the data need it):
//!
//! | effect | form | law | when it is a candidate |
//! |---|---|---|---|
//! | `thermal-drift` | `warm-up-in-time` | C1 -> C1 (1 - k x), x = tau_th h(t): h the motor's heated share, rising as 1 - exp(-on / tau_th) while testing and falling as exp(-off / tau_th) in rests (gaps over twice the usual spacing); tau_th -> infinity gives x = t | only the time is logged |
//! | `load-dependent-friction` | `light-load` | mu -> mu (1 + a exp(-tau_rot / tau_0)): friction that changes at light load only | three or more loads |
//! | `tooth-compliance` | `saturating` | stroke e - c F_s tanh(F_ax / F_s): the teeth yield c F_ax at first, at most c F_s | three or more loads |
//! | `inertia-rectification` | `load-dependent` | inertia term (1 + kappa + kappa_tau tau_rot) M_hat w_n^2 e^2 / pi: the share of the carrier's inertial power the drive returns changes with load | two or more speeds and three or more loads |
//!
//! User effects: an expression (the rig file's law, [`rigfile::UserLaw`]) over
//! `w` (cam speed, rad/s), `tau` (load, N m), `t` (time since the first test, s; 0 without a
//! `t_s` column), `temp` (motor temperature, deg C; the calibration's without a `temp_c`
//! column), `i` (the model's current, A), `i_f` (its friction current, A), `i_m` (the inertia
//! term's current, A) and `f_ax` (the axial tooth force, N), and the effect's parameters; its
//! value is the extra current in A.

use model::effects::{CurrentModel, Effect, OperatingPoint};

use crate::library::{DataTraits, ThermalDriver};

/// BIC penalty of a shape parameter: 2 ln 3, the price of choosing among the three shapes
/// its fit starts from and its score test looks along (a shape is a nuisance the null
/// simulation of the guard accounts for; counting it as a full parameter, ln n, would let a
/// simpler impostor beat the true law whenever the data cannot pin the shape).
pub const SHAPE_PENALTY: f64 = 2.197_224_577_336_219_4;

/// Variables a user effect may use, in the order of the data vector of [`Term::add`] (the
/// rig file's: [`rigfile::USER_VARIABLES`]).
pub use rigfile::USER_VARIABLES;

/// A family member of a library law.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Form {
    /// thermal-drift against the time, levelling off (and cooling in rests).
    WarmUpInTime,
    /// load-dependent-friction at light load only.
    LightLoad,
    /// tooth-compliance that saturates.
    SaturatingCompliance,
    /// inertia-rectification that changes with load.
    LoadDependentReturn,
}

/// A parameter of a family form, as its row of [`FORMS`] gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FormParam {
    /// Name in reports and rig files.
    pub key: &'static str,
    /// Unit of the value.
    pub unit: &'static str,
    /// The range the fit keeps it in.
    pub bounds: (f64, f64),
    /// The value at which the form reduces to its null (for a shape: the start).
    pub null: f64,
    /// The fit's first start.
    pub start: f64,
    /// Fitted in ln (a positive scale: a shape).
    pub log: bool,
}

/// What the data must offer for a family form to show.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FormNeeds {
    /// Only the time is logged (no temperature column).
    pub time_only: bool,
    /// Fewest cam-speed levels.
    pub speed_levels: usize,
    /// Fewest load levels.
    pub load_levels: usize,
    /// What to say when the data lack them.
    pub why: &'static str,
}

/// A family form's row: everything about it but the law's code ([`Term::add_at`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FormInfo {
    /// The form.
    pub form: Form,
    /// Its name, as in reports and rig files (`form = "..."`).
    pub name: &'static str,
    /// The library effect whose family it is.
    pub effect: Effect,
    /// The law, in words.
    pub law: &'static str,
    /// Its parameters, in fit order.
    pub params: &'static [FormParam],
    /// The model quantities its law reads.
    pub reads: Needs,
    /// What the data must offer.
    pub needs: FormNeeds,
}

/// Every family form, one row each (the order of [`Form::ALL`]).
pub const FORMS: [FormInfo; 4] = [
    FormInfo {
        form: Form::WarmUpInTime,
        name: "warm-up-in-time",
        effect: Effect::ThermalDrift,
        law: "C1 -> C1 (1 - k x), x = tau_th h(t): the motor's heated share h rising while testing and falling in rests",
        params: &[
            FormParam {
                key: "k_per_s",
                unit: "1/s",
                bounds: (-1e-3, 1e-3),
                null: 0.0,
                start: 0.0,
                log: false,
            },
            FormParam {
                key: "tau_s",
                unit: "s",
                bounds: (60.0, 1.0e5),
                null: 1200.0,
                start: 1200.0,
                log: true,
            },
        ],
        reads: Needs {
            current: true,
            friction: false,
            inertia: false,
            axial: false,
        },
        needs: FormNeeds {
            time_only: true,
            speed_levels: 0,
            load_levels: 0,
            why: "needs a t_s column without temp_c (with the temperature the law is linear in it)",
        },
    },
    FormInfo {
        form: Form::LightLoad,
        name: "light-load",
        effect: Effect::LoadDependentFriction,
        law: "mu -> mu (1 + a exp(-tau_rot / tau_0)): friction that changes at light load only",
        params: &[
            FormParam {
                key: "a",
                unit: "1",
                bounds: (-0.95, 5.0),
                null: 0.0,
                start: 0.0,
                log: false,
            },
            FormParam {
                key: "tau_0_nm",
                unit: "N m",
                bounds: (0.05, 10.0),
                null: 0.5,
                start: 0.5,
                log: true,
            },
        ],
        reads: Needs {
            current: false,
            friction: true,
            inertia: false,
            axial: false,
        },
        needs: FormNeeds {
            time_only: false,
            speed_levels: 0,
            load_levels: 3,
            why: "needs tests at three or more loads",
        },
    },
    FormInfo {
        form: Form::SaturatingCompliance,
        name: "saturating",
        effect: Effect::ToothCompliance,
        law: "stroke e - c F_s tanh(F_ax / F_s): the teeth yield c F_ax at first, at most c F_s",
        params: &[
            FormParam {
                key: "compliance_um_per_n",
                unit: "um/N",
                bounds: (0.0, 1.0e3),
                null: 0.0,
                start: 0.0,
                log: false,
            },
            FormParam {
                key: "f_s_n",
                unit: "N",
                bounds: (1.0, 1.0e5),
                null: 100.0,
                start: 100.0,
                log: true,
            },
        ],
        reads: Needs {
            current: false,
            friction: true,
            inertia: false,
            axial: true,
        },
        needs: FormNeeds {
            time_only: false,
            speed_levels: 0,
            load_levels: 3,
            why: "needs tests at three or more loads",
        },
    },
    FormInfo {
        form: Form::LoadDependentReturn,
        name: "load-dependent",
        effect: Effect::InertiaRectification,
        law: "inertia term (1 + kappa + kappa_tau tau_rot) M_hat w_n^2 e^2 / pi: the share of the carrier's inertial power the drive returns changes with load",
        params: &[
            FormParam {
                key: "kappa",
                unit: "1",
                bounds: (-1.0, 20.0),
                null: 0.0,
                start: 0.0,
                log: false,
            },
            FormParam {
                key: "kappa_per_nm",
                unit: "1/(N m)",
                bounds: (-5.0, 5.0),
                null: 0.0,
                start: 0.0,
                log: false,
            },
        ],
        reads: Needs {
            current: false,
            friction: false,
            inertia: true,
            axial: false,
        },
        needs: FormNeeds {
            time_only: false,
            speed_levels: 2,
            load_levels: 3,
            why: "needs tests at two or more speeds and three or more loads",
        },
    },
];

impl Form {
    /// Every family member.
    pub const ALL: [Form; 4] = [
        Form::WarmUpInTime,
        Form::LightLoad,
        Form::SaturatingCompliance,
        Form::LoadDependentReturn,
    ];

    /// Its row of [`FORMS`].
    pub fn info(self) -> &'static FormInfo {
        FORMS
            .iter()
            .find(|row| row.form == self)
            .expect("every form has its row in FORMS")
    }

    /// The library effect whose family it is.
    pub fn effect(self) -> Effect {
        self.info().effect
    }

    /// Its name, as in reports and rig files (`form = "..."`).
    pub fn name(self) -> &'static str {
        self.info().name
    }

    /// The form called `name`.
    pub fn from_name(name: &str) -> Option<Form> {
        FORMS
            .iter()
            .find(|row| row.name == name)
            .map(|row| row.form)
    }

    fn params(self) -> Vec<TermParam> {
        self.info()
            .params
            .iter()
            .map(|p| TermParam {
                key: p.key.into(),
                unit: p.unit.into(),
                bounds: p.bounds,
                null: p.null,
                start: p.start,
                log: p.log,
            })
            .collect()
    }

    /// Why the data cannot show this form, or `None`.
    fn not_applicable(self, data: &DataTraits) -> Option<&'static str> {
        let needs = self.info().needs;
        let lacking = (needs.time_only && data.thermal != ThermalDriver::Time)
            || data.speed_levels < needs.speed_levels
            || data.load_levels < needs.load_levels;
        lacking.then_some(needs.why)
    }
}

/// One parameter of a term.
#[derive(Debug, Clone, PartialEq)]
pub struct TermParam {
    /// Name in reports and rig files.
    pub key: String,
    /// Unit of the value.
    pub unit: String,
    /// The range the fit keeps it in.
    pub bounds: (f64, f64),
    /// The value at which the term vanishes (for shape parameters: any value; the start).
    pub null: f64,
    /// The fit's first start.
    pub start: f64,
    /// Fitted in ln (a positive scale).
    pub log: bool,
}

impl TermParam {
    /// The fit's coordinate of value `v`.
    pub fn to_fit(&self, v: f64) -> f64 {
        if self.log { v.max(1e-300).ln() } else { v }
    }

    /// The value of fit coordinate `x`.
    pub fn from_fit(&self, x: f64) -> f64 {
        if self.log { x.exp() } else { x }
    }

    /// Bounds in the fit's coordinate.
    pub fn fit_bounds(&self) -> (f64, f64) {
        (self.to_fit(self.bounds.0), self.to_fit(self.bounds.1))
    }
}

/// A user effect's expression (the rig file's law, [`rigfile::UserLaw`]).
pub type UserEffect = rigfile::UserLaw;

/// What a term is.
#[derive(Debug, Clone)]
pub enum TermKind {
    /// A family member of a library law.
    Family(Form),
    /// The user's own.
    User(Box<UserEffect>),
}

/// A term effect: a name, a form, parameters, its law.
#[derive(Debug, Clone)]
pub struct Term {
    /// The effect's name (the library effect's for a family member).
    pub name: String,
    /// Units and meaning of the value, for reports.
    pub note: String,
    /// Its parameters.
    pub params: Vec<TermParam>,
    /// Its law.
    pub kind: TermKind,
    /// The warm-up's heated shares by time constant, last used first.
    heat: HeatCache,
}

/// The model quantities a term's law uses.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Needs {
    /// The model's current.
    pub current: bool,
    /// Its friction current.
    pub friction: bool,
    /// The inertia term's current.
    pub inertia: bool,
    /// The axial tooth force.
    pub axial: bool,
}

impl Needs {
    /// Both sets.
    pub fn or(self, other: Needs) -> Needs {
        Needs {
            current: self.current || other.current,
            friction: self.friction || other.friction,
            inertia: self.inertia || other.inertia,
            axial: self.axial || other.axial,
        }
    }
}

/// A model's quantities at each point (empty where not needed).
#[derive(Debug, Clone, Default)]
pub struct ModelAt {
    /// The model's current, A.
    pub current: Vec<f64>,
    /// Its friction current, A.
    pub friction: Vec<f64>,
    /// The inertia term's current, A.
    pub inertia: Vec<f64>,
    /// The axial tooth force, N.
    pub axial: Vec<f64>,
    /// The cam's eccentricity, m.
    pub eccentricity: f64,
}

impl ModelAt {
    /// `model`'s quantities `needs` at `ops`: one pass over the points, the torque parts
    /// once per point (they give the current, the friction current and the axial force) and
    /// the gear's axial force per torque once.
    pub fn new(model: &CurrentModel, ops: &[OperatingPoint], needs: Needs) -> Self {
        let col = |on: bool| {
            if on {
                Vec::with_capacity(ops.len())
            } else {
                Vec::new()
            }
        };
        let mut at = Self {
            current: col(needs.current),
            friction: col(needs.friction),
            inertia: col(needs.inertia),
            axial: col(needs.axial),
            eccentricity: model.drive.eccentricity,
        };
        let per_torque = model.drive.gear.axial_force_per_torque();
        let parts_needed = needs.current || needs.friction || needs.axial;
        for op in ops {
            if parts_needed {
                let parts = model.torque_parts_with(op, per_torque);
                if needs.current {
                    at.current.push(model.current_of(&parts, op));
                }
                if needs.friction {
                    at.friction.push(model.friction_current_of(&parts, op));
                }
                if needs.axial {
                    at.axial.push(parts.axial_force);
                }
            }
            if needs.inertia {
                at.inertia.push(inertia_current(model, op));
            }
        }
        at
    }
}

/// Entries of a [`HeatCache`].
const HEAT_CACHE_ENTRIES: usize = 8;

/// The heated shares ([`heated_share`]) of the last few time constants and point sets: a
/// fit asks for the same ones over and over (one per Jacobian column).
#[derive(Debug, Default)]
struct HeatCache(std::sync::Mutex<Vec<(HeatKey, std::sync::Arc<Vec<f64>>)>>);

/// What a heated share depends on: the time constant and the points' times and order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct HeatKey {
    tau: u64,
    len: usize,
    times: u64,
    order: u64,
}

impl HeatKey {
    fn new(inputs: &Inputs, tau: f64) -> Self {
        let mix = |h: u64, v: u64| (h ^ v).wrapping_mul(0x100_0000_01b3).rotate_left(5);
        Self {
            tau: tau.to_bits(),
            len: inputs.time.len(),
            times: inputs
                .time
                .iter()
                .fold(0xcbf2_9ce4_8422_2325, |h, t| mix(h, t.to_bits())),
            order: inputs
                .order
                .iter()
                .fold(0xcbf2_9ce4_8422_2325, |h, &k| mix(h, k as u64)),
        }
    }
}

impl Clone for HeatCache {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl HeatCache {
    /// The heated share at `inputs` for time constant `tau`, computed once.
    fn get(&self, inputs: &Inputs, tau: f64) -> std::sync::Arc<Vec<f64>> {
        let key = HeatKey::new(inputs, tau);
        if let Ok(mut entries) = self.0.lock()
            && let Some(i) = entries.iter().position(|(k, _)| *k == key)
        {
            let hit = entries.remove(i);
            let value = hit.1.clone();
            entries.insert(0, hit);
            return value;
        }
        let value = std::sync::Arc::new(heated_share(inputs.time, inputs.order, tau));
        if let Ok(mut entries) = self.0.lock() {
            entries.insert(0, (key, value.clone()));
            entries.truncate(HEAT_CACHE_ENTRIES);
        }
        value
    }
}

/// The conditions of a set of points, for evaluating terms.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// Operating points.
    pub ops: &'a [OperatingPoint],
    /// Time since the first test, s (0 when unknown).
    pub time: &'a [f64],
    /// Motor temperature, deg C (the calibration's when unknown).
    pub temp: &'a [f64],
    /// The points in time order.
    pub order: &'a [usize],
}

impl Term {
    /// The family member `form`.
    pub fn family(form: Form) -> Self {
        Self {
            name: form.effect().name().to_string(),
            note: format!("{} in its {} form", form.effect().name(), form.name()),
            params: form.params(),
            kind: TermKind::Family(form),
            heat: HeatCache::default(),
        }
    }

    /// A user effect `name` with `expression` over [`USER_VARIABLES`] and `params`. An error
    /// (what to fix) when the expression does not parse, uses an unknown name, or leaves a
    /// parameter out.
    pub fn user(name: &str, expression: &str, params: Vec<TermParam>) -> Result<Self, String> {
        let keys: Vec<&str> = params.iter().map(|p| p.key.as_str()).collect();
        let law = rigfile::UserLaw::compile(name, expression, &keys)?;
        Ok(Self {
            name: name.to_string(),
            note: format!("user effect {expression}"),
            params,
            kind: TermKind::User(Box::new(law)),
            heat: HeatCache::default(),
        })
    }

    /// Centres a family form's shape on the data (`model`'s quantities at `ops`): the light-load
    /// fade tau_0 and the saturation force F_s start at the geometric middle of the tested
    /// loads and of the axial forces there, so the shape grid (the start, a third and three
    /// times it) spans the data's range whatever the rig and plan. A shape far below the
    /// range makes the form a change of mu (every tested point saturated or past the fade),
    /// far above it the library law; either way no start there can find a bend inside the
    /// range. Other terms, and data without two distinct nonzero values, are left alone.
    pub fn centre_on(&mut self, model: &CurrentModel, ops: &[OperatingPoint]) {
        let values: Vec<f64> = match self.form() {
            Some(Form::LightLoad) => ops.iter().map(|op| op.tau_rot.abs()).collect(),
            Some(Form::SaturatingCompliance) => {
                ops.iter().map(|op| model.axial_force(op).abs()).collect()
            }
            _ => return,
        };
        let positive = values.iter().copied().filter(|v| v.is_finite() && *v > 0.0);
        let lo = positive.clone().fold(f64::INFINITY, f64::min);
        let hi = positive.fold(0.0f64, f64::max);
        if !(lo.is_finite() && hi > lo) {
            return;
        }
        if let Some(shape) = self.params.iter_mut().find(|p| p.log) {
            let middle = (lo * hi).sqrt().clamp(shape.bounds.0, shape.bounds.1);
            shape.start = middle;
            shape.null = middle;
        }
    }

    /// The family member, if this is one.
    pub fn form(&self) -> Option<Form> {
        match self.kind {
            TermKind::Family(f) => Some(f),
            TermKind::User(_) => None,
        }
    }

    /// The library effect whose family this is, if any.
    pub fn effect(&self) -> Option<Effect> {
        self.form().map(Form::effect)
    }

    /// Why the data cannot show the term, or `None`.
    pub fn not_applicable(&self, data: &DataTraits) -> Option<&'static str> {
        match self.kind {
            TermKind::Family(f) => f.not_applicable(data),
            TermKind::User(_) => None,
        }
    }

    /// Parameters the term adds to the likelihood.
    pub fn parameter_count(&self) -> usize {
        self.params.len()
    }

    /// Its shape parameters (fitted in ln): a shape costs [`SHAPE_PENALTY`] in the BIC
    /// rather than ln n.
    pub fn shape_count(&self) -> usize {
        self.params.iter().filter(|p| p.log).count()
    }

    /// Its BIC penalty for `n` rows: ln n per linear parameter, [`SHAPE_PENALTY`] per shape.
    pub fn penalty(&self, n: f64) -> f64 {
        let shapes = self.shape_count();
        (self.params.len() - shapes) as f64 * n.ln() + shapes as f64 * SHAPE_PENALTY
    }

    /// The fit coordinates at the term's null (start values for shape parameters).
    pub fn null_point(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.to_fit(p.null)).collect()
    }

    /// The fit coordinates of the first start.
    pub fn start_point(&self) -> Vec<f64> {
        self.params.iter().map(|p| p.to_fit(p.start)).collect()
    }

    /// Parameter values (reported units) from fit coordinates `x`.
    pub fn values(&self, x: &[f64]) -> Vec<f64> {
        self.params
            .iter()
            .zip(x)
            .map(|(p, &x)| p.from_fit(x))
            .collect()
    }

    /// The model quantities the term's law uses.
    pub fn needs(&self) -> Needs {
        match &self.kind {
            TermKind::Family(f) => f.info().reads,
            TermKind::User(_) => Needs {
                current: true,
                friction: true,
                inertia: true,
                axial: true,
            },
        }
    }

    /// Adds the term's current at every point of `inputs` (model `model`, fit coordinates
    /// `x`) to `out`.
    pub fn add(&self, model: &CurrentModel, inputs: &Inputs, x: &[f64], out: &mut [f64]) {
        let at = ModelAt::new(model, inputs.ops, self.needs());
        self.add_at(&at, inputs, x, out);
    }

    /// [`Term::add`] with the model's quantities at the points computed beforehand (`at`
    /// must carry [`Term::needs`]).
    pub fn add_at(&self, at: &ModelAt, inputs: &Inputs, x: &[f64], out: &mut [f64]) {
        let v = self.values(x);
        match &self.kind {
            TermKind::Family(Form::WarmUpInTime) => {
                let (k, tau) = (v[0], v[1]);
                if k == 0.0 {
                    return;
                }
                let heat = self.heat.get(inputs, tau);
                for ((o, h), i) in out.iter_mut().zip(heat.iter()).zip(&at.current) {
                    let factor = (1.0 - k * tau * h).max(0.1);
                    *o += i * (1.0 / factor - 1.0);
                }
            }
            TermKind::Family(Form::LightLoad) => {
                let (a, tau0) = (v[0], v[1]);
                for (j, op) in inputs.ops.iter().enumerate() {
                    out[j] += a * (-op.tau_rot.abs() / tau0).exp() * at.friction[j];
                }
            }
            TermKind::Family(Form::SaturatingCompliance) => {
                let (c, f_s) = (v[0] * 1e-6, v[1]);
                if c == 0.0 {
                    return;
                }
                let e = at.eccentricity;
                for ((o, f), fr) in out.iter_mut().zip(&at.axial).zip(&at.friction) {
                    *o -= fr * c * f_s * (f / f_s).tanh() / e;
                }
            }
            TermKind::Family(Form::LoadDependentReturn) => {
                let (kappa, per_nm) = (v[0], v[1]);
                for (j, op) in inputs.ops.iter().enumerate() {
                    out[j] += (kappa + per_nm * op.tau_rot.abs()) * at.inertia[j];
                }
            }
            TermKind::User(u) => {
                let mut scratch = Vec::new();
                for (j, op) in inputs.ops.iter().enumerate() {
                    let data = [
                        op.omega_n,
                        op.tau_rot,
                        inputs.time[j],
                        inputs.temp[j],
                        at.current[j],
                        at.friction[j],
                        at.inertia[j],
                        at.axial[j],
                    ];
                    out[j] += u.eval(&data, &v, &mut scratch);
                }
            }
        }
    }

    /// The term's parameters as reported and stored in rig files.
    pub fn report(&self, x: &[f64]) -> std::collections::BTreeMap<String, f64> {
        self.params
            .iter()
            .zip(self.values(x))
            .map(|(p, v)| (p.key.clone(), v))
            .collect()
    }

    /// One sentence on what the term means at `x`.
    pub fn describe(&self, x: &[f64]) -> String {
        let v = self.values(x);
        match &self.kind {
            TermKind::Family(Form::WarmUpInTime) => format!(
                "the torque constant drifts as the motor warms, levelling off with a time constant of {:.0} s (and cooling in rests): {:.3} % per minute at first, {:.2} % once warm (no temperature column: the time and the rests stand in for the motor temperature)",
                v[1],
                v[0] * 6000.0,
                v[0] * v[1] * 100.0
            ),
            TermKind::Family(Form::LightLoad) => format!(
                "the tooth friction coefficient is {:+.0} % off at light load, fading over {:.2} N m of load (mu (1 + a exp(-tau / tau_0)))",
                v[0] * 100.0,
                v[1]
            ),
            TermKind::Family(Form::SaturatingCompliance) => format!(
                "the tooth contacts yield {:.2} um per N at first, at most {:.1} um (F_s = {:.0} N), shortening the sliding stroke under load",
                v[0],
                v[0] * v[1],
                v[1]
            ),
            TermKind::Family(Form::LoadDependentReturn) => format!(
                "the inertia term is (1 {:+.2} {:+.3}/N m x tau_rot) M w^2 e^2 / pi: the share of the carrier's inertial power the drive takes back changes with load",
                v[0], v[1]
            ),
            TermKind::User(u) => format!(
                "the user effect {} = {} A with {}",
                self.name,
                u.expression,
                self.params
                    .iter()
                    .zip(&v)
                    .map(|(p, v)| format!("{} = {v:.4} {}", p.key, p.unit))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// The inertia term's current at an operating point (the rig file's user laws use it too).
pub use rigfile::user_law::inertia_current;

/// The motor's heated share at each point (in time order `order`): rising as
/// 1 - exp(-on / tau) over the test time and falling as exp(-off / tau) in rests, a rest
/// being the part of a gap between tests beyond twice the usual (median) spacing.
pub fn heated_share(time: &[f64], order: &[usize], tau: f64) -> Vec<f64> {
    let mut out = vec![0.0; time.len()];
    if order.is_empty() {
        return out;
    }
    let mut gaps: Vec<f64> = order
        .windows(2)
        .map(|w| (time[w[1]] - time[w[0]]).max(0.0))
        .filter(|g| *g > 0.0)
        .collect();
    let usual = if gaps.is_empty() {
        0.0
    } else {
        let mid = gaps.len() / 2;
        *gaps.select_nth_unstable_by(mid, f64::total_cmp).1
    };
    let mut h = 0.0f64;
    let mut prev = 0.0f64;
    for &k in order {
        let gap = (time[k] - prev).max(0.0);
        let on = if usual > 0.0 {
            gap.min(2.0 * usual)
        } else {
            gap
        };
        let off = gap - on;
        h *= (-off / tau).exp();
        h = 1.0 - (1.0 - h) * (-on / tau).exp();
        out[k] = h;
        prev = time[k];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::{CamDrive, paper};

    fn model() -> CurrentModel {
        CurrentModel::paper(
            CamDrive::paper(paper::RIG_GEARS),
            paper::CALIBRATION,
            paper::MU_S,
        )
    }

    #[test]
    fn warm_up_levels_off_and_cools_in_rests() {
        let time: Vec<f64> = (0..40)
            .map(|k| 20.0 * k as f64 + if k >= 20 { 3000.0 } else { 0.0 })
            .collect();
        let order: Vec<usize> = (0..40).collect();
        let h = heated_share(&time, &order, 600.0);
        assert!(h[19] > 0.4 && h[19] < 0.5, "{}", h[19]);
        assert!(h[20] < 0.1, "{}", h[20]);
        // A long time constant gives the time itself: tau h -> t.
        let h = heated_share(&time[..20], &order[..20], 1e7);
        assert!((1e7 * h[19] - 380.0).abs() < 0.1, "{}", 1e7 * h[19]);
    }

    #[test]
    fn the_form_table_has_one_row_per_form_in_order() {
        assert_eq!(FORMS.map(|row| row.form), Form::ALL);
        for (k, row) in FORMS.iter().enumerate() {
            assert_eq!(Form::from_name(row.name), Some(row.form));
            assert!(FORMS[..k].iter().all(|r| r.name != row.name));
            // A linear amplitude that vanishes at its null, then at most one shape.
            assert!(
                !row.params[0].log && row.params[0].null == 0.0,
                "{}",
                row.name
            );
            assert!(row.params.iter().filter(|p| p.log).count() <= 1);
            for p in row.params {
                assert!(p.bounds.0 < p.bounds.1, "{} {}", row.name, p.key);
                assert!((p.bounds.0..=p.bounds.1).contains(&p.start));
            }
            let term = Term::family(row.form);
            assert_eq!(term.needs(), row.reads);
            assert_eq!(term.effect(), Some(row.effect));
        }
    }

    #[test]
    fn family_terms_vanish_at_their_null_and_nest_the_library_law() {
        let m = model();
        let ops: Vec<OperatingPoint> = (1..=10)
            .map(|k| OperatingPoint::new(31.4 * (1 + k % 3) as f64, 0.368 * k as f64, 0.0))
            .collect();
        let time: Vec<f64> = (0..10).map(|k| 20.0 * k as f64).collect();
        let temp = vec![25.0; 10];
        let order: Vec<usize> = (0..10).collect();
        let inputs = Inputs {
            ops: &ops,
            time: &time,
            temp: &temp,
            order: &order,
        };
        for form in Form::ALL {
            let t = Term::family(form);
            let mut out = vec![0.0; 10];
            t.add(&m, &inputs, &t.null_point(), &mut out);
            assert!(out.iter().all(|v| *v == 0.0), "{form:?}");
        }
        // The load-dependent return with kappa_per_nm = 0 is the library's kappa.
        let t = Term::family(Form::LoadDependentReturn);
        let mut out = vec![0.0; 10];
        t.add(&m, &inputs, &[-0.5, 0.0], &mut out);
        let mut lib = m;
        lib.effects.rectification = -0.5;
        for (j, op) in ops.iter().enumerate() {
            assert!((m.current(op) + out[j] - lib.current(op)).abs() < 1e-12);
        }
    }

    #[test]
    fn shapes_start_in_the_middle_of_the_data() {
        let m = model();
        let ops: Vec<OperatingPoint> = (1..=10)
            .map(|k| OperatingPoint::new(60.0, 0.368 * k as f64, 0.0))
            .collect();
        let mut light = Term::family(Form::LightLoad);
        light.centre_on(&m, &ops);
        let tau0 = light.params[1].start;
        assert!((tau0 - (0.368f64 * 3.68).sqrt()).abs() < 1e-9, "{tau0}");
        assert_eq!(light.params[1].null, tau0);
        // The saturation force: the middle of the axial forces, whatever the rig's scale.
        let mut sat = Term::family(Form::SaturatingCompliance);
        sat.centre_on(&m, &ops);
        let (f_lo, f_hi) = (m.axial_force(&ops[0]), m.axial_force(&ops[9]));
        assert!((sat.params[1].start - (f_lo * f_hi).sqrt()).abs() < 1e-9);
        // The grid the fit starts from spans the data: a third to three times the middle.
        assert!(sat.params[1].start / 3.0 < 0.5 * f_hi && 3.0 * sat.params[1].start > 2.0 * f_lo);
        // Other terms, and data at one load, keep their starts.
        let mut warm = Term::family(Form::WarmUpInTime);
        warm.centre_on(&m, &ops);
        assert_eq!(warm.params[1].start, 1200.0);
        let mut one = Term::family(Form::LightLoad);
        one.centre_on(&m, &ops[..1]);
        assert_eq!(one.params[1].start, 0.5);
    }

    #[test]
    fn a_stroke_that_shortens_with_load_is_a_friction_that_falls_with_load() {
        // Why the data cannot tell a saturating compliance from friction that changes with
        // load: both change only the friction torque, as a function of the load (the axial
        // force here does not depend on the speed), so for any deflection d(F) the friction
        // coefficient mu (1 - d(F) / e) gives the same current at every speed and load.
        let m = model();
        let ops: Vec<OperatingPoint> = (1..=10)
            .flat_map(|k| [31.4, 54.7, 94.2].map(|w| OperatingPoint::new(w, 0.368 * k as f64, 0.0)))
            .collect();
        let zeros = vec![0.0; ops.len()];
        let order: Vec<usize> = (0..ops.len()).collect();
        let inputs = Inputs {
            ops: &ops,
            time: &zeros,
            temp: &zeros,
            order: &order,
        };
        let sat = Term::family(Form::SaturatingCompliance);
        let (c_um, f_s) = (20.0, 25.0f64);
        let mut with_sat = vec![0.0; ops.len()];
        sat.add(&m, &inputs, &[c_um, f_s.ln()], &mut with_sat);
        let e = m.drive.eccentricity;
        for (j, op) in ops.iter().enumerate() {
            let d = c_um * 1e-6 * f_s * (m.axial_force(op) / f_s).tanh();
            let mut lower_mu = m;
            lower_mu.mu = m.mu * (1.0 - d / e);
            let gap = m.current(op) + with_sat[j] - lower_mu.current(op);
            assert!(gap.abs() < 1e-12, "{gap}");
        }
    }

    #[test]
    fn user_effects_parse_and_name_what_is_wrong() {
        let p = |key: &str| TermParam {
            key: key.into(),
            unit: "A".into(),
            bounds: (-1.0, 1.0),
            null: 0.0,
            start: 0.0,
            log: false,
        };
        let t = Term::user("brush", "c * (w / 100)^2", vec![p("c")]).unwrap();
        let ops = [OperatingPoint::new(50.0, 1.0, 0.0)];
        let inputs = Inputs {
            ops: &ops,
            time: &[0.0],
            temp: &[25.0],
            order: &[0],
        };
        let mut out = [0.0];
        t.add(&model(), &inputs, &[0.2], &mut out);
        assert!((out[0] - 0.05).abs() < 1e-12);
        let e = Term::user("brush", "c * speed", vec![p("c")]).unwrap_err();
        assert!(e.contains("'speed'") && e.contains("w, tau"), "{e}");
        let e = Term::user("brush", "c * w", vec![p("c"), p("d")]).unwrap_err();
        assert!(e.contains("parameter d is not used"), "{e}");
        assert!(Term::user("brush", "c * (w", vec![p("c")]).is_err());
        // A leading minus binds as in mathematics: -x^2 is -(x^2).
        let t = Term::user("bump", "c * exp(-(w / 50)^2)", vec![p("c")]).unwrap();
        let mut out = [0.0];
        t.add(&model(), &inputs, &[1.0], &mut out);
        assert!((out[0] - (-1.0f64).exp()).abs() < 1e-12, "{}", out[0]);
        assert_eq!(
            rigfile::user_law::leading_minus("-x^2").unwrap(),
            "(-1)*x^2"
        );
        assert_eq!(
            rigfile::user_law::leading_minus("a - -b * 1e-3").unwrap(),
            "a - (-1)*b * 1e-3"
        );
        let e = Term::user("bump", "c * w^-2", vec![p("c")]).unwrap_err();
        assert!(
            e.contains("bump") && e.contains("expression") && e.contains("x^(-2)"),
            "{e}"
        );
    }
}
