//! Physical plausibility of a fitted candidate: its parameters against the limits of the one
//! effects table ([`model::effects::EffectInfo::limits`]), mu against
//! [`model::effects::MU_PHYSICAL`], and a family form's or user effect's shape parameters
//! against the edges of their search. A fit that needs a value beyond a limit (the value
//! outside and its 95 % interval, where it has one, too) or whose shape sits on the edge of
//! its search does not name its effect; the report says which limit and why.

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
    /// Whether the fit stays within it.
    pub within: bool,
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
    LimitCheck {
        param: limit.key.to_string(),
        value,
        limit: describe(limit, ctx),
        within: value.is_finite() && (inside || reaches),
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
        let mut at_max = check_limit(limit, k0 + k1 * tau_max, None, &ctx);
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
