//! What a candidate stands for: a library effect in its own law, or a term (a family form
//! of a library effect, or a user effect). Its own module so that the selection, the
//! bootstrap and the plausibility checks share it without importing one another.

use model::effects::Effect;

use crate::fit::ModelSpec;
use crate::library::{self, DataTraits};
use crate::points::TestPoints;

/// A candidate effect: a library effect in its own law, or a term ([`TestPoints::terms`]: a
/// family form of a library effect or a user effect).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Mechanism {
    /// A library effect in its own law.
    Effect(Effect),
    /// A term.
    Term(usize),
}

impl Mechanism {
    /// The name reports give it (a family form has its library effect's).
    pub fn name<'a>(&self, points: &'a TestPoints) -> &'a str {
        match *self {
            Mechanism::Effect(e) => e.name(),
            Mechanism::Term(t) => &points.terms[t].name,
        }
    }

    /// The library effect it is a law of, if any.
    pub fn effect(&self, points: &TestPoints) -> Option<Effect> {
        match *self {
            Mechanism::Effect(e) => Some(e),
            Mechanism::Term(t) => points.terms[t].effect(),
        }
    }

    /// The family form's name, for a family member.
    pub fn form(&self, points: &TestPoints) -> Option<&'static str> {
        match *self {
            Mechanism::Effect(_) => None,
            Mechanism::Term(t) => points.terms[t].form().map(|f| f.name()),
        }
    }

    /// Why the data cannot show it, or `None`.
    pub fn not_applicable(&self, points: &TestPoints, traits: &DataTraits) -> Option<&'static str> {
        match *self {
            Mechanism::Effect(e) => library::not_applicable(e, traits),
            Mechanism::Term(t) => points.terms[t].not_applicable(traits),
        }
    }

    /// Parameters it adds to the likelihood.
    pub fn parameter_count(&self, points: &TestPoints) -> usize {
        match *self {
            Mechanism::Effect(e) => library::parameter_count(e),
            Mechanism::Term(t) => points.terms[t].parameter_count(),
        }
    }

    /// Its BIC penalty for `n` rows.
    pub fn penalty(&self, points: &TestPoints, n: f64) -> f64 {
        match *self {
            Mechanism::Effect(e) => library::parameter_count(e) as f64 * n.ln(),
            Mechanism::Term(t) => points.terms[t].penalty(n),
        }
    }

    /// Whether `spec` carries it.
    pub fn in_spec(&self, spec: &ModelSpec) -> bool {
        match *self {
            Mechanism::Effect(e) => spec.has(e),
            Mechanism::Term(t) => spec.terms.contains(&t),
        }
    }

    /// `spec` with it added.
    pub fn added_to(&self, spec: &ModelSpec) -> ModelSpec {
        match *self {
            Mechanism::Effect(e) => spec.with(e),
            Mechanism::Term(t) => spec.with_term(t),
        }
    }
}
