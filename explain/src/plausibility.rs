//! Physical plausibility of a fitted candidate: its parameters against the limits of the one
//! effects table ([`model::effects::EffectInfo::limits`]), mu against
//! [`model::effects::MU_PHYSICAL`], and a family form's or user effect's shape parameters
//! against the edges of their search. A fit that needs a value beyond a limit (the value
//! outside and its 95 % interval, where it has one, too) or whose shape sits on the edge of
//! its search does not name its effect; the report says which limit and why.
//!
//! A value a little past a limit whose interval still reaches into the physical region is a
//! fit that wandered out of it, not a law that does not apply: the law is plausible and the
//! check says `at_limit` (the reported value is then the limit itself, with the fitted value
//! kept as `fitted`). The same holds for a law that a bound of the fit stopped on its limit.
//! Every limit with a parameter that has a standard error is judged with its interval; the
//! load-dependent return's kappa at the largest load (kappa + kappa_per_nm |tau|) gets its
//! interval from the fit's covariance of the two.

use model::effects::{Effect, LimitContext, LimitKind, MU_PHYSICAL, PhysicalLimit};
use serde::Serialize;

use super::fit::Fit;
use super::mechanism::Mechanism;
use super::points::TestPoints;

/// A shape coordinate this close to an edge of its search (share of the search's width, in
/// the fit's coordinate) sits on it.
const EDGE_SHARE: f64 = 1e-3;

/// One limit checked.
#[derive(Debug, Clone, Serialize)]
pub struct LimitCheck {
    /// The parameter.
    pub param: String,
    /// Its fitted value.
    pub value: f64,
    /// The limit in words.
    pub limit: String,
    /// Whether the fit stays within it (its value, or its 95 % interval).
    pub within: bool,
    /// Whether the law sits at the physical limit: its fitted value is on the limit or past
    /// it by less than its interval reaches (then `value` is the limit and `fitted` the
    /// fitted value).
    pub at_limit: bool,
    /// The fitted value when it lies past the limit it is at; null otherwise.
    pub fitted: Option<f64>,
    /// The 95 % interval the check read, when the parameter has one.
    pub interval: Option<[f64; 2]>,
    /// Why the limit is there.
    pub why: String,
    /// Whether it is the edge of a shape's search rather than a physical limit.
    #[serde(skip)]
    pub search_edge: bool,
}

/// The plausibility of one fitted candidate.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Plausibility {
    /// Whether every limit holds.
    pub plausible: bool,
    /// Every limit checked.
    pub checks: Vec<LimitCheck>,
}

impl Plausibility {
    /// Whether every limit broken is a physical one (no shape on the edge of its search,
    /// which says the law only mimics the data whatever else is added).
    pub fn only_physical_limits_broken(&self) -> bool {
        self.checks.iter().all(|c| c.within || !c.search_edge)
    }

    /// The limits at which the fit sits, in words ("kappa at its physical limit -1 (fitted
    /// -1.007, 95 % interval reaching into kappa within [-1, 1])").
    pub fn at_limits(&self) -> String {
        self.checks
            .iter()
            .filter(|c| c.within && c.at_limit)
            .map(LimitCheck::at_limit_text)
            .collect::<Vec<_>>()
            .join("; ")
    }

    /// The limits that fail, in words ("kappa = 2.4 is beyond kappa within [-1, 1]: why").
    pub fn failures(&self) -> String {
        self.checks
            .iter()
            .filter(|c| !c.within)
            .map(|c| {
                format!(
                    "{} = {} is beyond {} ({})",
                    c.param,
                    reporting::human(c.value),
                    c.limit,
                    c.why
                )
            })
            .collect::<Vec<_>>()
            .join("; ")
    }
}

impl LimitCheck {
    /// "kappa at its physical limit -1 (fitted -1.007, its 95 % interval reaches kappa within
    /// [-1, 1])".
    pub fn at_limit_text(&self) -> String {
        match self.fitted {
            Some(f) => format!(
                "{} at its physical limit {} (fitted {}, its 95 % interval reaches {})",
                self.param,
                reporting::human(self.value),
                reporting::human(f),
                self.limit
            ),
            None => format!(
                "{} at its physical limit {} ({})",
                self.param,
                reporting::human(self.value),
                self.limit
            ),
        }
    }
}

/// `limit` in words, e.g. "kappa within [-1, 1]".
pub fn describe(limit: &PhysicalLimit, ctx: &LimitContext) -> String {
    let (lo, hi) = limit.range(ctx);
    match limit.kind {
        LimitKind::Range(..) if hi.is_infinite() => format!("{} >= {lo}", limit.key),
        LimitKind::Range(..) => format!("{} within [{lo}, {hi}]", limit.key),
        LimitKind::StrokeShare(share) => format!(
            "{} <= {} (a deflection of at most {:.0} % of the {} mm stroke at the largest axial force, {:.0} N)",
            limit.key,
            reporting::human(hi),
            share * 100.0,
            reporting::human(limit_mm(ctx.eccentricity_m)),
            ctx.max_axial_force_n
        ),
    }
}

fn limit_mm(m: f64) -> f64 {
    m * 1e3
}

/// What the data-dependent limits need: the largest axial force at the tested loads with the
/// fit's mu, and the cam's eccentricity.
fn context(points: &TestPoints, fit: &Fit) -> LimitContext {
    let tau_max = points
        .ops
        .iter()
        .fold(0.0f64, |m, op| m.max(op.tau_rot.abs()));
    LimitContext {
        max_axial_force_n: fit.model.drive.friction_force(fit.model.mu, tau_max),
        eccentricity_m: fit.model.drive.eccentricity,
    }
}

fn check_limit(
    limit: &PhysicalLimit,
    value: f64,
    interval: Option<[f64; 2]>,
    ctx: &LimitContext,
) -> LimitCheck {
    let (lo, hi) = limit.range(ctx);
    let slack = 1e-9 * (1.0 + value.abs());
    let inside = value >= lo - slack && value <= hi + slack;
    // The data does not need a value outside when its interval reaches into the range.
    let reaches = interval.is_some_and(|[a, b]| a <= hi && b >= lo);
    let within = value.is_finite() && (inside || reaches);
    // On a finite edge (a bound of the fit stopped it there), or past it within the interval:
    // the law at its limit, reported at the limit.
    let edge = |e: f64| e.is_finite() && (value - e).abs() <= 1e-6 * (1.0 + e.abs());
    let past = within && !inside;
    let at_limit = within && (past || edge(lo) || edge(hi));
    let at = if value < lo { lo } else { hi };
    LimitCheck {
        param: limit.key.to_string(),
        value: if past { at } else { value },
        limit: describe(limit, ctx),
        within,
        at_limit,
        fitted: past.then_some(value),
        interval,
        why: limit.why.to_string(),
        search_edge: false,
    }
}

/// The plausibility of `cand` as fitted in `fit` (a fit that carries it) on `points`.
pub fn check(points: &TestPoints, cand: Mechanism, fit: &Fit) -> Plausibility {
    let ctx = context(points, fit);
    let params = crate::cand_params(points, cand, fit, points.thermal);
    let intervals = crate::cand_intervals(points, cand, fit, points.thermal);
    let mut checks = Vec::new();
    let effect: Option<Effect> = cand.effect(points);
    if let Some(e) = effect {
        for limit in e.info().limits {
            if let Some(&v) = params.get(limit.key) {
                checks.push(check_limit(
                    limit,
                    v,
                    intervals.get(limit.key).copied(),
                    &ctx,
                ));
            }
        }
    }
    checks.push(check_limit(&MU_PHYSICAL, fit.model.mu, None, &ctx));
    // A load-dependent power return must keep kappa(tau) = kappa + kappa_per_nm |tau| within
    // the library's kappa limits at every tested load, not only at zero load.
    if let (Mechanism::Term(t), Some(&k0), Some(&k1)) =
        (cand, params.get("kappa"), params.get("kappa_per_nm"))
        && points.terms[t].form() == Some(crate::terms::Form::LoadDependentReturn)
        && let Some(limit) = Effect::InertiaRectification
            .info()
            .limits
            .iter()
            .find(|l| l.key == "kappa")
    {
        let tau_max = points
            .ops
            .iter()
            .fold(0.0f64, |m, op| m.max(op.tau_rot.abs()));
        let interval = kappa_at_load_interval(fit, t, tau_max);
        let mut at_max = check_limit(limit, k0 + k1 * tau_max, interval, &ctx);
        at_max.param = format!("kappa at {} N m", reporting::human(tau_max));
        checks.push(at_max);
    }
    if let Mechanism::Term(t) = cand
        && let Some(pos) = fit.spec.terms.iter().position(|&x| x == t)
    {
        let term = &points.terms[t];
        for (p, &x) in term.params.iter().zip(&fit.term_x[pos]) {
            if !p.log {
                continue;
            }
            let (a, b) = p.fit_bounds();
            let width = (b - a).abs();
            let on_edge = width.is_finite()
                && ((x - a).abs() <= EDGE_SHARE * width || (b - x).abs() <= EDGE_SHARE * width);
            checks.push(LimitCheck {
                param: p.key.clone(),
                value: p.from_fit(x),
                limit: format!(
                    "{} inside its search [{}, {}] {}",
                    p.key,
                    reporting::human(p.bounds.0),
                    reporting::human(p.bounds.1),
                    p.unit
                ),
                within: !on_edge,
                at_limit: false,
                fitted: None,
                interval: None,
                search_edge: true,
                why: "a shape on the edge of its search means the data asks for a bend outside the range it can place; the law only mimics the data".into(),
            });
        }
    }
    Plausibility {
        plausible: checks.iter().all(|c| c.within),
        checks,
    }
}

/// The 95 % interval of the load-dependent return's kappa at `tau` (kappa + kappa_per_nm
/// tau), from the fit's covariance of its two coordinates (`None` when either sits on a
/// bound of the fit or `fit` does not carry term `t`).
fn kappa_at_load_interval(fit: &Fit, t: usize, tau: f64) -> Option<[f64; 2]> {
    let pos = fit.spec.terms.iter().position(|&x| x == t)?;
    let x = fit.term_x.get(pos)?;
    let (v00, v11, v01) = (
        fit.term_cov(pos, 0, 0)?,
        fit.term_cov(pos, 1, 1)?,
        fit.term_cov(pos, 0, 1)?,
    );
    let var = v00 + tau * tau * v11 + 2.0 * tau * v01;
    let v = x[0] + x[1] * tau;
    (var.is_finite() && var >= 0.0).then(|| {
        let h = 1.96 * var.sqrt();
        [v - h, v + h]
    })
}

/// The plausibility of every effect and term `fit` carries (and its mu): a model is
/// plausible only when each of its effects is, so an effect added later cannot push an
/// earlier one beyond its limits unnoticed. Each check's parameter names its effect.
pub fn check_model(points: &TestPoints, fit: &Fit) -> Plausibility {
    let cands = fit
        .spec
        .effects
        .iter()
        .map(|&e| Mechanism::Effect(e))
        .chain(fit.spec.terms.iter().map(|&t| Mechanism::Term(t)));
    let mut checks: Vec<LimitCheck> = Vec::new();
    for c in cands {
        for mut k in check(points, c, fit).checks {
            if k.param == MU_PHYSICAL.key {
                continue;
            }
            k.param = format!("{} {}", c.name(points), k.param);
            checks.push(k);
        }
    }
    checks.push(check_limit(
        &MU_PHYSICAL,
        fit.model.mu,
        None,
        &context(points, fit),
    ));
    Plausibility {
        plausible: checks.iter().all(|c| c.within),
        checks,
    }
}
