//! Experiment design (`rig explain --propose`): the test points that best separate the
//! leading candidates of an explanation, or, when the finding is clear, that best pin the
//! named effect's size; written as a plan file in the format of `docs/plans.md` that
//! `rig experiment torque-sweep --plan FILE` runs.
//!
//! 1. Candidate models. Each leading candidate is taken in the law the selection showed it
//!    in (its library law, a family form such as load-dependent friction's `light-load`, or
//!    a user effect: the named effect's selected law, a rival's best law in the first step's
//!    table) and fitted jointly with the model it competes against by the selection's own
//!    candidate fit, so every candidate agrees with the data already measured; they differ
//!    where nothing was measured. Each predicts its mean current at a new point with its
//!    terms.
//! 2. The space of feasible points: supply voltage (open loop, as the data's `v_in_v`) or
//!    vibration frequency (closed loop, when the data has no voltage) times load, within the
//!    rig's and the board's caps ([`model::BoardLimits`], the rig file's `[limits]`, the
//!    paper's loads up to 3.68 N m, the bridge supply) and a predicted current under the
//!    current limit. Cam speed at a voltage comes from the data itself (a least-squares line
//!    w = a + b v + c tau over its rows), else the paper's 5 / 10 / 15 Hz at 3.6 / 6.2 / 8.8 V.
//! 3. Score. At each point x every pair of leading models (A, B) differs by
//!    d_AB(x) = i_A(x) - i_B(x); over the noise sigma (the outcome's robust residual scale)
//!    that is how many standard deviations one test there tells them apart. Points are chosen
//!    greedily, each maximising the gain sum_AB [ln(1 + S_AB + z^2) - ln(1 + S_AB)] (S_AB:
//!    the separation already bought for the pair, so every pair gets its share) times a
//!    spread factor 1 - exp(-d^2 / (2 * 0.12^2)) (d: distance to the nearest chosen point in
//!    the unit square of the space), so the points spread over the space rather than pile up
//!    at one corner. Repeats per point: enough for `target_sigmas` separation, within
//!    `max_repeats`.
//! 4. Pinning (verdict `explained`): the pair is the final model against itself with the
//!    named effect's main parameter moved by one standard error: the points where one more
//!    test narrows the parameter most.
//! 5. Seeking (verdict `no-missing-effect`): the leading candidates of the first step
//!    against the starting model: where an effect the data hints at would show most.
//!
//! Temperatures: the design predicts at the data's median thermal driver (and, for terms,
//! the data's median motor temperature and a warm-up's heated state at the data's median
//! time); a point's `temp_c` is not set (the plan waits for no temperature).

use std::collections::BTreeMap;
use std::f64::consts::PI;

use model::effects::{CurrentModel, Effect, OperatingPoint};
use rigfile::RigFile;
use rigfile::plan::{Order, Plan, PlanPoint};
use serde::Serialize;

use crate::fit::Fit;
use crate::mechanism::Mechanism;
use crate::points::TestPoints;
use crate::select;
use crate::terms::{Form, Inputs};
use crate::{Dataset, Outcome, Verdict};

/// Lightest load a proposal hangs, N m: the paper's lightest (Figs. 8-9).
pub const MIN_LOAD_NM: f64 = model::paper::TAU_ROT_MIN_TESTED;
/// Lowest vibration frequency a proposal drives, Hz: the paper's lowest (5 Hz at 3.6 V);
/// slower, a heavy load released during the long spin-up can outrun the output's overspeed
/// limit (seen on the virtual rig at 4 Hz and 2.8 N m).
pub const MIN_FREQ_HZ: f64 = 5.0;
/// Lowest supply voltage a proposal gives, V (the paper's lowest).
pub const MIN_SUPPLY_V: f64 = 3.6;
/// Share of the board's load cap (3.68 N m) a proposed point may hang: at the cap itself the
/// firmware's load estimate, noisy around it, can trip the overload guard mid-run.
pub const LOAD_MARGIN: f64 = 0.9;
/// Share of the current limit a proposed point may be predicted to draw.
pub const CURRENT_MARGIN: f64 = 0.8;

/// How a proposal drives the vibrator: the plan file's drive ([`rigfile::plan`]).
pub use rigfile::plan::DriveMode;

/// What a proposal is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Goal {
    /// Tell the leading candidates of an ambiguous verdict apart.
    Separate,
    /// Narrow the named effect's parameters.
    Pin,
    /// Look where the first step's leading candidates would show most (no finding yet).
    Seek,
    /// Resolve the shape of a discrepancy no named effect explains (`unexplained`): where
    /// the residual's shape ([`crate::residual_shape`]) departs most from the model, e.g. a
    /// denser speed grid about a peak, more loads where it bends.
    Resolve,
}

/// Cam speed at a supply voltage and load, w = a + b v + c tau (rad/s).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SpeedMap {
    /// a, rad/s.
    pub a: f64,
    /// b, rad/s per V.
    pub b: f64,
    /// c, rad/s per N m (the droop under load).
    pub c: f64,
}

impl SpeedMap {
    /// The paper's: 3.6 / 6.2 / 8.8 V give about 5 / 10 / 15 Hz ([`crate::synth::nominal_cam_speed`]).
    pub fn paper() -> Self {
        let b = 2.0 * PI * 5.0 / 2.6;
        Self {
            a: 2.0 * PI * 5.0 - b * 3.6,
            b,
            c: 0.0,
        }
    }

    /// Fitted to `data`'s rows with a voltage (least squares); the paper's when the data
    /// has fewer than two voltages, shifted to the data's mean speed when it has one.
    pub fn from_data(data: &Dataset) -> Self {
        let paper = Self::paper();
        let Some(v) = data.v_in() else {
            return paper;
        };
        let (w, t) = (data.omega_n(), data.tau_rot());
        let rows: Vec<(f64, f64, f64)> = (0..data.len())
            .map(|k| (v[k], t[k].abs(), w[k]))
            .filter(|r| r.0.is_finite() && r.1.is_finite() && r.2.is_finite() && r.2 > 0.0)
            .collect();
        if rows.is_empty() {
            return paper;
        }
        let (vmin, vmax) = rows
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| {
                (lo.min(r.0), hi.max(r.0))
            });
        if vmax - vmin < 0.5 {
            let n = rows.len() as f64;
            let shift = rows
                .iter()
                .map(|r| r.2 - paper.speed(r.0, 0.0))
                .sum::<f64>()
                / n;
            return Self {
                a: paper.a + shift,
                ..paper
            };
        }
        // Normal equations of w = a + b v + c tau.
        let mut m = [[0.0; 3]; 3];
        let mut y = [0.0; 3];
        for &(vi, ti, wi) in &rows {
            let x = [1.0, vi, ti];
            for i in 0..3 {
                y[i] += x[i] * wi;
                for j in 0..3 {
                    m[i][j] += x[i] * x[j];
                }
            }
        }
        match solve3(m, y) {
            Some([a, b, c]) if b > 0.0 && c <= 0.0 => Self { a, b, c },
            _ => match solve2([[m[0][0], m[0][1]], [m[1][0], m[1][1]]], [y[0], y[1]]) {
                Some([a, b]) if b > 0.0 => Self { a, b, c: 0.0 },
                _ => paper,
            },
        }
    }

    /// Cam speed at supply `volts` under load `load_nm`, rad/s.
    pub fn speed(&self, volts: f64, load_nm: f64) -> f64 {
        self.a + self.b * volts + self.c * load_nm.abs()
    }

    /// Supply voltage that gives cam speed `omega` unloaded, V.
    pub fn volts_for(&self, omega: f64) -> f64 {
        (omega - self.a) / self.b
    }
}

fn solve2(m: [[f64; 2]; 2], y: [f64; 2]) -> Option<[f64; 2]> {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    if det.abs() < 1e-12 * (m[0][0] * m[1][1]).abs().max(1e-300) {
        return None;
    }
    Some([
        (y[0] * m[1][1] - m[0][1] * y[1]) / det,
        (m[0][0] * y[1] - m[1][0] * y[0]) / det,
    ])
}

fn solve3(m: [[f64; 3]; 3], y: [f64; 3]) -> Option<[f64; 3]> {
    let det = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(m);
    let scale = m[0][0] * m[1][1] * m[2][2];
    if d.is_nan() || d.abs() <= 1e-10 * scale.abs() {
        return None;
    }
    let mut out = [0.0; 3];
    for (k, o) in out.iter_mut().enumerate() {
        let mut a = m;
        for r in 0..3 {
            a[r][k] = y[r];
        }
        *o = det(a) / d;
    }
    Some(out)
}

/// The feasible test points.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Space {
    /// Open or closed loop.
    pub mode: DriveMode,
    /// Lightest and heaviest load, N m.
    pub loads_nm: (f64, f64),
    /// Lowest and highest supply voltage (open loop), V.
    pub volts: (f64, f64),
    /// Lowest and highest vibration frequency, Hz.
    pub hz: (f64, f64),
    /// Largest predicted current, A.
    pub max_current_a: f64,
    /// Cam speed at a voltage.
    pub speed: SpeedMap,
    /// Grid steps along the drive and the load axis.
    pub steps: (usize, usize),
}

impl Space {
    /// The points a rig (`rig`'s limits capped by the board's) can run for data like `data`:
    /// open loop when the data logs the supply voltage, else closed loop.
    pub fn for_rig(rig: &RigFile, data: &Dataset) -> Self {
        let board = model::BoardLimits::PAPER;
        let max_hz = rig.limits.max_freq_hz.min(board.max_freq_hz);
        let max_load = LOAD_MARGIN * board.max_release_load_nm.min(model::paper::TAU_ROT_MAX);
        let max_current = rig.limits.max_current_a.min(board.max_current_a);
        let speed = SpeedMap::from_data(data);
        let v_hi = speed
            .volts_for(2.0 * PI * max_hz)
            .min(model::hardware::board::BRIDGE_SUPPLY_V);
        let v_lo = speed.volts_for(2.0 * PI * MIN_FREQ_HZ).max(MIN_SUPPLY_V);
        Self {
            mode: if data.has_voltage {
                DriveMode::OpenLoop
            } else {
                DriveMode::ClosedLoop
            },
            loads_nm: (MIN_LOAD_NM, max_load),
            volts: (v_lo, v_hi.max(v_lo)),
            hz: (MIN_FREQ_HZ, max_hz.max(MIN_FREQ_HZ)),
            max_current_a: CURRENT_MARGIN * max_current,
            speed,
            steps: (13, 13),
        }
    }

    /// Every grid point: (drive value, load, cam speed, unit coordinates).
    fn grid(&self) -> Vec<GridPoint> {
        let (nd, nl) = (self.steps.0.max(2), self.steps.1.max(2));
        let mut out = Vec::with_capacity(nd * nl);
        for i in 0..nd {
            let u = i as f64 / (nd - 1) as f64;
            for j in 0..nl {
                let s = j as f64 / (nl - 1) as f64;
                let load = round_to(lerp(self.loads_nm, s), 1e-3);
                let (drive, omega) = match self.mode {
                    DriveMode::OpenLoop => {
                        let v = round_to(lerp(self.volts, u), 0.01);
                        (v, self.speed.speed(v, load))
                    }
                    DriveMode::ClosedLoop => {
                        let hz = round_to(lerp(self.hz, u), 0.01);
                        (hz, 2.0 * PI * hz)
                    }
                };
                if omega > 0.0 {
                    out.push(GridPoint {
                        drive,
                        load,
                        omega,
                        unit: (u, s),
                    });
                }
            }
        }
        out
    }
}

fn lerp((lo, hi): (f64, f64), s: f64) -> f64 {
    lo + (hi - lo) * s
}

/// `v` to a multiple of `step` (1e-3, 0.01), as a person writes it: 0.475, not
/// 0.47500000000000003.
fn round_to(v: f64, step: f64) -> f64 {
    let per = (1.0 / step).round();
    (v * per).round() / per
}

#[derive(Debug, Clone, Copy)]
struct GridPoint {
    drive: f64,
    load: f64,
    omega: f64,
    unit: (f64, f64),
}

/// How many points, and how much separation each should buy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DesignOptions {
    /// Most test points (plan points x repeats) the proposal may use.
    pub max_test_points: usize,
    /// Most distinct plan points.
    pub max_points: usize,
    /// Most repeats of one point.
    pub max_repeats: u32,
    /// Separation, in noise standard deviations, each point's repeats should reach.
    pub target_sigmas: f64,
    /// Leading candidates compared at most.
    pub max_candidates: usize,
}

impl Default for DesignOptions {
    /// 12 test points over up to 8 plan points, up to 3 repeats each, 3 sigma, 3 candidates.
    fn default() -> Self {
        Self {
            max_test_points: 12,
            max_points: 8,
            max_repeats: 3,
            target_sigmas: 3.0,
            max_candidates: 3,
        }
    }
}

/// One proposed test point.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProposedPoint {
    /// Load, N m.
    pub load_nm: f64,
    /// Supply voltage (open loop), V.
    pub volts: Option<f64>,
    /// Vibration frequency (closed loop), Hz.
    pub hz: Option<f64>,
    /// Predicted cam speed, rad/s.
    pub omega_n_rad_s: f64,
    /// Repeats.
    pub repeats: u32,
    /// Mean current each compared model predicts there, A.
    pub predicted_a: BTreeMap<String, f64>,
    /// Largest predicted difference between two compared models, in noise standard
    /// deviations, for one test.
    pub separation_sigma: f64,
}

/// A proposed set of test points and why.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Proposal {
    /// What the points are for.
    pub goal: Goal,
    /// The models compared (`base` for the model without a new effect).
    pub candidates: Vec<String>,
    /// Open or closed loop.
    pub mode: DriveMode,
    /// The points, in the order chosen (most informative first).
    pub points: Vec<ProposedPoint>,
    /// The noise the separations are measured against, A.
    pub sigma_a: f64,
    /// Why these points, in words (the plan's `reason`).
    pub reason: String,
}

impl Proposal {
    /// Test points (plan points x repeats).
    pub fn test_points(&self) -> usize {
        self.points.iter().map(|p| p.repeats as usize).sum()
    }

    /// The plan of these points ([`rigfile::plan::Plan`]) named `name`, in random order
    /// `seed`, with the paper's rest and averaging window.
    pub fn to_plan(&self, name: &str, seed: u64) -> Plan {
        Plan {
            name: name.to_string(),
            mode: self.mode,
            repeats: 1,
            order: Order::Random,
            seed,
            rest_s: 2.0,
            window_s: model::paper::CURRENT_AVERAGING_S,
            reason: self.reason.clone(),
            points: self
                .points
                .iter()
                .map(|q| PlanPoint {
                    load_nm: q.load_nm,
                    volts: q.volts,
                    hz: q.hz,
                    repeats: Some(q.repeats),
                    duration_s: None,
                    temp_c: None,
                })
                .collect(),
        }
    }

    /// The plan file (docs/plans.md's format, written by the `toml` crate) of
    /// [`Proposal::to_plan`]; each point's predictions as a comment above it.
    pub fn to_plan_toml(&self, name: &str, seed: u64) -> String {
        let text = self.to_plan(name, seed).to_toml();
        let mut out = format!(
            "# Test plan proposed by `rig explain --propose` ({} points, {} test points); run it with\n# `rig experiment torque-sweep --plan FILE --csv MORE.csv`, then explain the old and the new rows together.\n",
            self.points.len(),
            self.test_points()
        );
        let mut tables = text.split("\n[[points]]\n");
        out.push_str(tables.next().unwrap_or_default());
        for (p, table) in self.points.iter().zip(tables) {
            let predicted: Vec<String> = p
                .predicted_a
                .iter()
                .map(|(k, v)| format!("{k} {v:.4} A"))
                .collect();
            out.push_str(&format!(
                "\n# predicted: {} ({:.1} sigma per test)\n[[points]]\n{table}",
                predicted.join(", "),
                p.separation_sigma,
            ));
        }
        out
    }
}

/// A model compared in the design: a fit's mean law with its terms.
struct Compared {
    name: String,
    model: CurrentModel,
    terms: Vec<usize>,
    term_x: Vec<Vec<f64>>,
    /// A residual shape added to the mean current (basis, coefficient in A).
    shape: Vec<(crate::residual_shape::BasisKind, f64)>,
}

impl Compared {
    fn of(name: String, fit: &Fit) -> Self {
        Self {
            name,
            model: fit.model,
            terms: fit.spec.terms.clone(),
            term_x: fit.term_x.clone(),
            shape: Vec::new(),
        }
    }

    /// Its mean current at `ops`, A; the terms see every point at time `time` s (the heated
    /// state a test that long after the start has) and motor temperature `temp` deg C.
    fn currents(
        &self,
        points: &TestPoints,
        ops: &[OperatingPoint],
        time: f64,
        temp: f64,
    ) -> Vec<f64> {
        let ev = self.model.evaluator();
        let mut out: Vec<f64> = ops
            .iter()
            .map(|op| {
                ev.current(op)
                    + self
                        .shape
                        .iter()
                        .map(|(k, c)| c * k.eval(op.omega_n, op.tau_rot, time, temp))
                        .sum::<f64>()
            })
            .collect();
        if self.terms.is_empty() {
            return out;
        }
        let time = vec![time; ops.len()];
        let temp = vec![temp; ops.len()];
        let order: Vec<usize> = (0..ops.len()).collect();
        let inputs = Inputs {
            ops,
            time: &time,
            temp: &temp,
            order: &order,
        };
        for (&t, x) in self.terms.iter().zip(&self.term_x) {
            points.terms[t].add(&self.model, &inputs, x, &mut out);
        }
        out
    }
}

/// A leading candidate: the law the selection fitted it in, and its label.
#[derive(Debug, Clone)]
struct Leader {
    cand: Mechanism,
    /// Its name (the effect's; a family form's is its library effect's).
    name: String,
    /// Its name with its family form, e.g. `load-dependent-friction (light-load)`.
    label: String,
}

/// The candidate named `name` in law `form` (its library law without one).
fn cand_of(points: &TestPoints, name: &str, form: Option<&str>) -> Option<Mechanism> {
    let term = |want: Option<&str>| {
        points
            .terms
            .iter()
            .position(|t| t.name == name && t.form().map(Form::name) == want)
            .map(Mechanism::Term)
    };
    match form {
        Some(f) => term(Some(f)),
        None => match Effect::from_name(name) {
            // Only laws that move the mean current can be told apart by it.
            Some(e) if e.mean_param().is_some() || e == Effect::CurrentSensorOffset => {
                Some(Mechanism::Effect(e))
            }
            Some(_) => None,
            // A user effect.
            None => term(None),
        },
    }
}

/// The law the selection's first step showed `name` in (its best law there), else its
/// library law.
fn form_in_table<'a>(outcome: &'a Outcome, name: &str) -> Option<&'a str> {
    outcome
        .explanation
        .candidates
        .iter()
        .find(|c| c.name == name)
        .and_then(|c| c.form.as_deref())
}

fn leader(outcome: &Outcome, name: &str, form: Option<&str>) -> Option<Leader> {
    let cand = cand_of(&outcome.points, name, form)?;
    Some(Leader {
        cand,
        name: name.to_string(),
        label: match form {
            Some(f) => format!("{name} ({f})"),
            None => name.to_string(),
        },
    })
}

/// The leading candidates the design compares (in the laws the selection fitted them), and
/// its goal.
fn leading(outcome: &Outcome, options: &DesignOptions) -> (Goal, Vec<Leader>) {
    let e = &outcome.explanation;
    let named = |names: &mut dyn Iterator<Item = &String>| -> Vec<Leader> {
        names
            .filter_map(|n| {
                // The named effect in its selected law, a rival in its best law of the
                // step that named it (the first: the verdict turns on the leading finding).
                let form = match e.effects.first() {
                    Some(f) if &f.name == n => f.form.as_deref(),
                    _ => form_in_table(outcome, n),
                };
                leader(outcome, n, form)
            })
            .take(options.max_candidates)
            .collect()
    };
    match e.verdict {
        Verdict::Ambiguous => {
            let list = named(&mut e.ambiguous.iter());
            if list.len() >= 2 {
                return (Goal::Separate, list);
            }
            (Goal::Pin, list)
        }
        Verdict::Explained | Verdict::PartlyExplained => {
            let first = e.effects.first().map(|f| f.name.clone());
            (Goal::Pin, named(&mut first.iter()))
        }
        Verdict::Unexplained
            if e.residual_shape
                .as_ref()
                .is_some_and(|r| !r.parts.is_empty()) =>
        {
            (Goal::Resolve, Vec::new())
        }
        Verdict::NoMissingEffect | Verdict::Unexplained => {
            let mut c: Vec<(&String, f64)> = e
                .candidates
                .iter()
                .filter_map(|c| Some((&c.name, c.delta_bic?)))
                .collect();
            c.sort_by(|a, b| a.1.total_cmp(&b.1));
            (Goal::Seek, named(&mut c.into_iter().map(|x| x.0)))
        }
    }
}

/// The median of `values` (0 when empty).
fn median(values: &[f64]) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

/// The final model with the pinned candidate's main parameter moved by one standard error,
/// when it has one.
fn moved_by_one_se(outcome: &Outcome, cand: Mechanism) -> Option<Compared> {
    let after = &outcome.after;
    let mut moved = Compared::of(String::new(), after);
    match cand {
        Mechanism::Effect(e) => {
            let q = e.mean_param()?;
            let mut p = moved.model.params();
            let v = p[q.index()];
            let step = after
                .std_error(q)
                .filter(|s| s.is_finite() && *s > 0.0)
                .unwrap_or(0.1 * v.abs().max(1e-6));
            p[q.index()] = v + step;
            moved.model.set_params(&p);
        }
        Mechanism::Term(t) => {
            let pos = after.spec.terms.iter().position(|&x| x == t)?;
            let term = &outcome.points.terms[t];
            // Its first linear parameter (its size); shapes are fitted in ln.
            let c = term.params.iter().position(|p| !p.log)?;
            let v = moved.term_x[pos][c];
            let step = after
                .term_std_error(pos, c)
                .filter(|s| s.is_finite() && *s > 0.0)
                .unwrap_or(0.1 * v.abs().max(1e-6));
            moved.term_x[pos][c] = v + step;
        }
    }
    Some(moved)
}

/// Proposes the test points that best separate the leading candidates of `outcome` (the
/// explanation), or pin the named effect, within `space`.
pub fn propose(outcome: &Outcome, space: &Space, options: &DesignOptions) -> Proposal {
    let (goal, leaders) = leading(outcome, options);
    let sigma = outcome.explanation.robust_sigma_a.max(1e-3);
    let points = &outcome.points;
    // The conditions the predictions use: the data's median thermal driver, time and
    // motor temperature.
    let thermal = median(&points.ops.iter().map(|o| o.thermal).collect::<Vec<_>>());
    let time = median(&points.time_s);
    let temp = median(&points.temp_c);
    let fitted = |l: &Leader| {
        let f = select::fit_candidate(points, &outcome.before, l.cand);
        Compared::of(l.name.clone(), &f)
    };

    // The models compared, and the pairs to separate.
    let mut models: Vec<Compared> = Vec::new();
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    match goal {
        Goal::Separate => {
            models = crate::parallel::par_map(&leaders, fitted);
            for a in 0..models.len() {
                for b in a + 1..models.len() {
                    pairs.push((a, b));
                }
            }
        }
        Goal::Seek => {
            models.push(Compared::of("base".into(), &outcome.before));
            models.extend(crate::parallel::par_map(&leaders, fitted));
            pairs.extend((1..models.len()).map(|k| (0, k)));
        }
        Goal::Resolve => {
            if let Some(shape) = &outcome.explanation.residual_shape {
                models.push(Compared::of("model".into(), &outcome.after));
                let mut with = Compared::of("model + residual shape".into(), &outcome.after);
                with.shape = shape.parts.clone();
                models.push(with);
                pairs.push((0, 1));
            }
        }
        Goal::Pin => {
            if let Some(l) = leaders.first() {
                if let Some(mut moved) = moved_by_one_se(outcome, l.cand) {
                    moved.name = format!("{} + 1 se", l.name);
                    models.push(Compared::of(l.name.clone(), &outcome.after));
                    models.push(moved);
                } else {
                    // An offset-like effect without a mean parameter of its own: pin it
                    // against the model without it.
                    models.push(Compared::of(l.name.clone(), &outcome.after));
                    models.push(Compared::of("base".into(), &outcome.before));
                }
                pairs.push((0, 1));
            }
        }
    }

    // Predictions on the grid (feasible points only).
    let grid = space.grid();
    let ops: Vec<OperatingPoint> = grid
        .iter()
        .map(|g| OperatingPoint::new(g.omega, g.load, thermal))
        .collect();
    let by_model: Vec<Vec<f64>> = models
        .iter()
        .map(|m| m.currents(points, &ops, time, temp))
        .collect();
    let mut preds: Vec<(GridPoint, Vec<f64>)> = Vec::new();
    for (k, g) in grid.into_iter().enumerate() {
        let i: Vec<f64> = by_model.iter().map(|m| m[k]).collect();
        if i.iter()
            .all(|x| x.is_finite() && *x <= space.max_current_a && *x > 0.0)
        {
            preds.push((g, i));
        }
    }
    let z = |i: &[f64], (a, b): (usize, usize)| (i[a] - i[b]) / sigma;

    let mut chosen: Vec<(GridPoint, Vec<f64>, u32, f64)> = Vec::new();
    let mut bought = vec![0.0; pairs.len()];
    let mut used = 0usize;
    while chosen.len() < options.max_points && used < options.max_test_points && !pairs.is_empty() {
        let mut best: Option<(usize, f64)> = None;
        for (k, (g, i)) in preds.iter().enumerate() {
            if chosen.iter().any(|c| c.0.unit == g.unit) {
                continue;
            }
            let gain: f64 = pairs
                .iter()
                .zip(&bought)
                .map(|(&p, &s)| {
                    let zz = z(i, p).powi(2);
                    (1.0 + s + zz).ln() - (1.0 + s).ln()
                })
                .sum();
            let d2 = chosen
                .iter()
                .map(|c| (c.0.unit.0 - g.unit.0).powi(2) + (c.0.unit.1 - g.unit.1).powi(2))
                .fold(f64::INFINITY, f64::min);
            let spread = if d2.is_finite() {
                1.0 - (-d2 / (2.0 * 0.12 * 0.12)).exp()
            } else {
                1.0
            };
            let score = gain * spread;
            if best.is_none_or(|(_, s)| score > s) {
                best = Some((k, score));
            }
        }
        let Some((k, score)) = best else {
            break;
        };
        if score <= 0.0 {
            break;
        }
        let (g, i) = preds[k].clone();
        let sep = pairs.iter().map(|&p| z(&i, p).abs()).fold(0.0, f64::max);
        let want = if sep > 0.0 {
            (options.target_sigmas / sep).powi(2).ceil()
        } else {
            f64::from(options.max_repeats)
        };
        let left = (options.max_test_points - used) as f64;
        let repeats = want.clamp(1.0, f64::from(options.max_repeats).min(left)) as u32;
        for (p, s) in pairs.iter().zip(bought.iter_mut()) {
            *s += f64::from(repeats) * z(&i, *p).powi(2);
        }
        used += repeats as usize;
        chosen.push((g, i, repeats, sep));
    }

    let points: Vec<ProposedPoint> = chosen
        .iter()
        .map(|(g, i, repeats, sep)| ProposedPoint {
            load_nm: g.load,
            volts: (space.mode == DriveMode::OpenLoop).then_some(g.drive),
            hz: (space.mode == DriveMode::ClosedLoop).then_some(g.drive),
            omega_n_rad_s: g.omega,
            repeats: *repeats,
            predicted_a: models
                .iter()
                .zip(i)
                .map(|(m, &x)| (m.name.clone(), x))
                .collect(),
            separation_sigma: *sep,
        })
        .collect();
    let names: Vec<String> = leaders.iter().map(|l| l.label.clone()).collect();
    let best = points
        .iter()
        .map(|p| p.separation_sigma)
        .fold(0.0, f64::max);
    let reason = match goal {
        Goal::Separate => format!(
            "separates {} (the data cannot tell them apart): up to {best:.1} noise sd per test between their predictions",
            names.join(" from ")
        ),
        Goal::Pin => format!(
            "pins {}: where one standard error of its size moves the current most (up to {best:.2} noise sd per test)",
            names.first().map_or("the finding", String::as_str)
        ),
        Goal::Seek => format!(
            "no effect found yet: where the leading candidates ({}) would differ most from the model (up to {best:.1} noise sd per test at their fitted size)",
            names.join(", ")
        ),
        Goal::Resolve => format!(
            "a discrepancy no named effect explains: where its shape ({}) departs most from the model (up to {best:.1} noise sd per test), to resolve it",
            outcome
                .explanation
                .residual_shape
                .as_ref()
                .map_or("unknown".into(), |r| r
                    .terms
                    .iter()
                    .map(|t| t.words.clone())
                    .collect::<Vec<_>>()
                    .join(", "))
        ),
    };
    let mut candidates: Vec<String> = models.iter().map(|m| m.name.clone()).collect();
    if goal == Goal::Pin {
        candidates.truncate(1);
    }
    Proposal {
        goal,
        candidates,
        mode: space.mode,
        points,
        sigma_a: sigma,
        reason,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_map_of_the_paper_gives_its_frequencies() {
        let m = SpeedMap::paper();
        assert!((m.speed(3.6, 0.0) / (2.0 * PI) - 5.0).abs() < 1e-9);
        assert!((m.speed(8.8, 0.0) / (2.0 * PI) - 15.0).abs() < 1e-9);
        assert!((m.volts_for(m.speed(6.2, 0.0)) - 6.2).abs() < 1e-9);
    }
}

#[cfg(test)]
mod separation_tests {
    use super::*;
    use crate::synth::{self, SweepPlan};
    use crate::{MeasuredRow, Options, explain};
    use model::effects::EffectParams;

    fn plan(loads: Vec<f64>, volts: Vec<f64>, repeats: usize, noise: f64) -> SweepPlan {
        SweepPlan {
            loads_nm: loads,
            voltages_v: volts,
            repeats,
            noise_a: noise,
            with_time: false,
            with_temperature: false,
            ..SweepPlan::default()
        }
    }

    /// The paper's model with one effect set by `set`.
    fn truth(set: impl Fn(&mut EffectParams)) -> CurrentModel {
        let rig = RigFile::paper();
        let mut m = rig.current_model().unwrap();
        m.effects = EffectParams::default();
        set(&mut m.effects);
        m
    }

    /// Data the selection cannot settle (few loads, two close voltages), from `truth`;
    /// explained again with the proposed points measured on the same truth.
    fn before_and_after(
        truth: &CurrentModel,
        loads: &[f64],
        seed: u64,
    ) -> (Outcome, Proposal, Outcome) {
        let rig = RigFile::paper();
        let opts = Options {
            replicates: 100,
            ..Options::default()
        };
        let rows = synth::generate(truth, &plan(loads.to_vec(), vec![5.8, 6.6], 4, 0.01), seed);
        let data = Dataset::from_rows("narrow", rows.clone()).unwrap();
        let before = explain(&data, &rig, &opts).unwrap();
        let space = Space::for_rig(&rig, &data);
        let proposal = propose(&before, &space, &DesignOptions::default());
        let mut all: Vec<MeasuredRow> = rows;
        for (k, pt) in proposal.points.iter().enumerate() {
            let volts = pt.volts.expect("the data logs the voltage: open loop");
            let p = plan(vec![pt.load_nm], vec![volts], pt.repeats as usize, 0.01);
            all.extend(synth::generate(truth, &p, 100 + k as u64));
        }
        let more = Dataset::from_rows("narrow + proposed", all).unwrap();
        let after = explain(&more, &rig, &opts).unwrap();
        (before, proposal, after)
    }

    #[test]
    fn proposed_points_separate_candidates_the_data_cannot() {
        // (truth, its loads, seeds where the first data cannot separate the leaders)
        let ldf = truth(|p| p.load_exponent = 0.25);
        let offset = truth(|p| p.current_offset = 0.05);
        let cases = [
            (&ldf, "load-dependent-friction", [1.5, 1.8, 2.1, 2.4], 2),
            (&ldf, "load-dependent-friction", [1.5, 1.8, 2.1, 2.4], 3),
            (&offset, "current-sensor-offset", [0.368, 1.5, 2.4, 3.68], 1),
        ];
        for (t, name, loads, seed) in cases {
            let (before, proposal, after) = before_and_after(t, &loads, seed);
            let b = &before.explanation;
            assert_eq!(b.verdict, Verdict::Ambiguous, "{name} seed {seed}: {b:?}");
            assert!(b.ambiguous.iter().any(|n| n == name), "{:?}", b.ambiguous);
            assert_eq!(proposal.goal, Goal::Separate);
            assert!(proposal.candidates.iter().any(|n| n == name));
            assert!(proposal.test_points() <= DesignOptions::default().max_test_points);
            assert!(proposal.reason.contains(name), "{}", proposal.reason);
            // Every leader is compared in the law the selection showed it in (a family
            // form named with it).
            for n in &b.ambiguous {
                let form = b
                    .candidates
                    .iter()
                    .find(|c| &c.name == n)
                    .and_then(|c| c.form.clone());
                let form = match b.effects.first() {
                    Some(f) if &f.name == n => f.form.clone(),
                    _ => form,
                };
                let label = match form {
                    Some(f) => format!("{n} ({f})"),
                    None => n.clone(),
                };
                assert!(
                    proposal.reason.contains(&label),
                    "{label}: {}",
                    proposal.reason
                );
            }
            // Spread over the space: not all at one voltage or one load.
            let volts: Vec<f64> = proposal.points.iter().filter_map(|p| p.volts).collect();
            assert!(
                volts.iter().any(|v| (v - volts[0]).abs() > 1.0),
                "{volts:?}"
            );
            // Within the caps.
            for p in &proposal.points {
                assert!((MIN_LOAD_NM..=3.68).contains(&p.load_nm));
                assert!(p.omega_n_rad_s <= 2.0 * PI * 15.0 + 1e-9);
            }
            let a = &after.explanation;
            assert_eq!(a.verdict, Verdict::Explained, "{name} seed {seed}: {a:?}");
            assert_eq!(a.effects[0].name, name);
        }
    }

    #[test]
    fn a_family_form_leader_is_fitted_and_predicted_as_the_selection_does() {
        // The offset case of the test above: the data cannot tell the offset from the
        // light-load form of load-dependent friction.
        let offset = truth(|p| p.current_offset = 0.05);
        let (before, proposal, _) = before_and_after(&offset, &[0.368, 1.5, 2.4, 3.68], 1);
        let (goal, leaders) = leading(&before, &DesignOptions::default());
        assert_eq!(goal, Goal::Separate);
        let light = leaders
            .iter()
            .find(|l| l.label == "load-dependent-friction (light-load)")
            .unwrap_or_else(|| panic!("{:?}", before.explanation.ambiguous));
        assert!(matches!(light.cand, Mechanism::Term(_)), "{light:?}");
        assert!(
            proposal
                .reason
                .contains("load-dependent-friction (light-load)")
        );
        // Its predictions at the data's own points are the selection's fit's.
        let points = &before.points;
        let f = select::fit_candidate(points, &before.before, light.cand);
        assert!(!f.spec.terms.is_empty());
        let m = Compared::of(light.name.clone(), &f);
        let ours = m.currents(points, &points.ops, 0.0, 25.0);
        for (a, b) in ours.iter().zip(f.predict(points)) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        // At the proposed points the leaders differ by what the proposal says (its widest
        // pair).
        for p in &proposal.points {
            let i: Vec<f64> = p.predicted_a.values().copied().collect();
            assert_eq!(i.len(), leaders.len(), "{:?}", p.predicted_a);
            let z = i
                .iter()
                .flat_map(|a| i.iter().map(move |b| (a - b).abs()))
                .fold(0.0, f64::max)
                / proposal.sigma_a;
            assert!(
                (z - p.separation_sigma).abs() < 1e-9,
                "{z} vs {}",
                p.separation_sigma
            );
        }
    }

    #[test]
    fn a_clear_finding_gets_points_that_pin_it_and_the_plan_text_is_complete() {
        let t = truth(|p| p.viscous_loss = 0.15e-3);
        let rows = synth::generate(
            &t,
            &plan(vec![0.368, 1.5, 2.4, 3.68], vec![3.6, 6.2, 8.8], 3, 0.01),
            1,
        );
        let data = Dataset::from_rows("x", rows).unwrap();
        let rig = RigFile::paper();
        let o = explain(
            &data,
            &rig,
            &Options {
                replicates: 50,
                ..Options::default()
            },
        )
        .unwrap();
        assert_eq!(o.explanation.verdict, Verdict::Explained);
        let p = propose(&o, &Space::for_rig(&rig, &data), &DesignOptions::default());
        assert_eq!(p.goal, Goal::Pin);
        assert_eq!(p.candidates, vec!["vibrator-viscous-loss".to_string()]);
        assert!(!p.points.is_empty());
        // A viscous loss shows most at the highest speed.
        let top = p.points[0].omega_n_rad_s;
        assert!(top > 2.0 * PI * 12.0, "{top}");
        let text = p.to_plan_toml("pin", 7);
        for key in [
            "name = \"pin\"",
            "mode = \"open-loop\"",
            "seed = 7",
            "[[points]]",
            "volts = ",
            "reason = \"pins",
        ] {
            assert!(text.contains(key), "{key} in {text}");
        }
        assert_eq!(text.matches("[[points]]").count(), p.points.len());
        // Written through the one plan type: it reads back as the same plan.
        let back = Plan::parse(&text, "pin").unwrap();
        assert_eq!(back, p.to_plan("pin", 7));
    }
}
