//! Which effects a model carries: the library effects in their own laws and the terms, with
//! their free parameters and the information criterion's penalty.

use model::effects::{Effect, Param};

use crate::library;
use crate::terms::Term;

/// Which effects a model carries on top of the paper's.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ModelSpec {
    /// The library effects in their own laws, in the order they were added.
    pub effects: Vec<Effect>,
    /// The terms ([`crate::points::TestPoints::terms`] indices), in the order they were added.
    pub terms: Vec<usize>,
}

impl ModelSpec {
    /// The paper's model (mu fitted).
    pub fn base() -> Self {
        Self::default()
    }

    /// This model with `effect` added.
    pub fn with(&self, effect: Effect) -> Self {
        let mut s = self.clone();
        if !s.has(effect) {
            s.effects.push(effect);
        }
        s
    }

    /// This model with term `term` added.
    pub fn with_term(&self, term: usize) -> Self {
        let mut s = self.clone();
        if !s.terms.contains(&term) {
            s.terms.push(term);
        }
        s
    }

    /// Whether the model carries `effect` in its library law.
    pub fn has(&self, effect: Effect) -> bool {
        self.effects.contains(&effect)
    }

    /// Parameters of the mean current that are fitted: mu and one per effect (the terms'
    /// coordinates follow them in a fit).
    pub fn free_params(&self) -> Vec<Param> {
        let mut p = vec![Param::Mu];
        p.extend(self.effects.iter().filter_map(|e| e.mean_param()));
        p
    }

    /// BIC penalty for `n` rows: ln n per parameter (noise level included), the terms'
    /// shapes at [`crate::terms::SHAPE_PENALTY`].
    pub fn penalty(&self, terms: &[Term], n: f64) -> f64 {
        let shapes: usize = self.terms.iter().map(|&t| terms[t].shape_count()).sum();
        (self.parameter_count(terms) - shapes) as f64 * n.ln()
            + shapes as f64 * crate::terms::SHAPE_PENALTY
    }

    /// Parameters counted by the information criterion (noise level included), the terms of
    /// `terms`.
    pub fn parameter_count(&self, terms: &[Term]) -> usize {
        2 + self
            .effects
            .iter()
            .map(|&e| library::parameter_count(e))
            .sum::<usize>()
            + self
                .terms
                .iter()
                .map(|&t| terms[t].parameter_count())
                .sum::<usize>()
    }
}
