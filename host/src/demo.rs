//! `rig demo`: the README's main job. For now it runs the design check on the paper's
//! Table 1 and compares every verdict with the paper.

use crate::RigError;
use crate::design::{self, DesignReport, RigParams};

/// The paper's Table 1: which gear sets had a non-backdriven point (n = 1 only).
pub const TABLE1_PAPER_HOLDS: [bool; 6] = [true, true, false, false, false, false];

/// Result of the demo's design check.
#[derive(Debug, Clone, serde::Serialize)]
pub struct DemoSummary {
    /// One evaluated gear set per Table 1 row.
    pub table1: Vec<DesignReport>,
    /// Whether every hold verdict agrees with the paper.
    pub agrees_with_paper: bool,
}

/// Runs the design check over Table 1 at the paper's rig values.
pub fn run() -> Result<DemoSummary, RigError> {
    let table1 = model::TABLE1
        .iter()
        .map(|&z| design::evaluate(z, &RigParams::default(), None))
        .collect::<Result<Vec<_>, _>>()?;
    let agrees_with_paper = table1
        .iter()
        .zip(TABLE1_PAPER_HOLDS)
        .all(|(r, holds)| r.holds_load == holds);
    Ok(DemoSummary {
        table1,
        agrees_with_paper,
    })
}

/// Short human-readable summary.
pub fn render_text(s: &DemoSummary) -> String {
    use std::fmt::Write;
    let mut out = String::from("design check, paper's Table 1 (mu_s = 0.271, mu_d = 0.174):\n");
    let _ = writeln!(
        out,
        "  {:<16} {:>8} {:>12} {:>12}  verdict",
        "Z1,Z2,Z3,Z4", "rho", "mu_s*Lambda", "mu_d*Lambda"
    );
    for (r, paper) in s.table1.iter().zip(TABLE1_PAPER_HOLDS) {
        let z = r.z.map(|v| v.to_string()).join(",");
        let verdict = if r.holds_load { "holds" } else { "backdrives" };
        let mark = if r.holds_load == paper {
            "as in the paper"
        } else {
            "DIFFERS from the paper"
        };
        let _ = writeln!(
            out,
            "  {z:<16} {:>8.2} {:>12.3} {:>12.3}  {verdict} ({mark})",
            r.rho, r.mu_s_lambda, r.mu_d_lambda
        );
    }
    let _ = writeln!(
        out,
        "result: {}",
        if s.agrees_with_paper {
            "every verdict agrees with the paper"
        } else {
            "some verdicts disagree with the paper"
        }
    );
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn demo_agrees_with_the_paper() {
        let s = super::run().unwrap();
        assert!(s.agrees_with_paper);
        assert_eq!(s.table1.len(), 6);
    }
}
