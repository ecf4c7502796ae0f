//! Vibrator calibration, Eqs. (15)-(17) and Table 2: torque from current, the vibrator's own
//! loss, and the no-load current.

/// Calibration constants C1-C6 of the vibrator, in SI units (N m, A, rad/s).
///
/// - |tau_cam| = C1 i_in + C2 (Eq. 15),
/// - |tau_loss| = C3 w_n + C4 (Eq. 16),
/// - |i_loss| = C5 w_n + C6 (Eq. 17).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Calibration {
    /// C1, N m/A.
    pub c1: f64,
    /// C2, N m.
    pub c2: f64,
    /// C3, N m s/rad.
    pub c3: f64,
    /// C4, N m.
    pub c4: f64,
    /// C5, A s/rad.
    pub c5: f64,
    /// C6, A.
    pub c6: f64,
}

/// How well C3 and C4 agree with the values implied by C1, C2, C5 and C6.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationConsistency {
    /// C1 C5, N m s/rad (what C3 should be).
    pub c3_implied: f64,
    /// C1 C6 + C2, N m (what C4 should be).
    pub c4_implied: f64,
    /// |C3 - C1 C5| / |C3|.
    pub c3_rel_error: f64,
    /// |C4 - (C1 C6 + C2)| / |C4|.
    pub c4_rel_error: f64,
}

impl Calibration {
    /// Table 2 of the paper.
    pub const PAPER: Calibration =
        Calibration::from_paper_units([62.1, -138.0, 0.235, 1.69, 0.00378, 2.25]);

    /// From the paper's units: C1 N mm/A, C2 N mm, C3 N mm s/rad, C4 N mm, C5 A s/rad, C6 A.
    pub const fn from_paper_units(c: [f64; 6]) -> Self {
        Self {
            c1: c[0] * 1e-3,
            c2: c[1] * 1e-3,
            c3: c[2] * 1e-3,
            c4: c[3] * 1e-3,
            c5: c[4],
            c6: c[5],
        }
    }

    /// In the paper's units, `[C1, .., C6]` (see [`Calibration::from_paper_units`]).
    pub fn to_paper_units(&self) -> [f64; 6] {
        [
            self.c1 * 1e3,
            self.c2 * 1e3,
            self.c3 * 1e3,
            self.c4 * 1e3,
            self.c5,
            self.c6,
        ]
    }

    /// Vibrator from C1, C2 (torque-current) and C5, C6 (no-load current), with C3 and C4
    /// derived as the torque of the no-load current: C3 = C1 C5, C4 = C1 C6 + C2.
    pub fn from_torque_and_no_load(c1: f64, c2: f64, c5: f64, c6: f64) -> Self {
        Self {
            c1,
            c2,
            c3: c1 * c5,
            c4: c1 * c6 + c2,
            c5,
            c6,
        }
    }

    /// Gross shaft torque for input current `i_in` (A), Eq. (15), N m.
    pub fn gross_torque(&self, i_in: f64) -> f64 {
        self.c1 * i_in + self.c2
    }

    /// The vibrator's own loss torque at cam speed `omega_n` (rad/s), Eq. (16), N m.
    pub fn loss_torque(&self, omega_n: f64) -> f64 {
        self.c3 * omega_n.abs() + self.c4
    }

    /// No-load current at cam speed `omega_n`, Eq. (17), A.
    pub fn no_load_current(&self, omega_n: f64) -> f64 {
        self.c5 * omega_n.abs() + self.c6
    }

    /// Torque reaching the cam under load: tau_cam = C1 i + C2 - (C3 w_n + C4), N m.
    pub fn cam_torque(&self, i_in: f64, omega_n: f64) -> f64 {
        self.gross_torque(i_in) - self.loss_torque(omega_n)
    }

    /// Current that delivers cam torque `tau_cam` at `omega_n` (inverse of [`Self::cam_torque`]), A.
    pub fn current_for(&self, tau_cam: f64, omega_n: f64) -> f64 {
        (tau_cam + self.loss_torque(omega_n) - self.c2) / self.c1
    }

    /// Consistency of C3 and C4 with C1 C5 and C1 C6 + C2.
    pub fn consistency(&self) -> CalibrationConsistency {
        let c3_implied = self.c1 * self.c5;
        let c4_implied = self.c1 * self.c6 + self.c2;
        CalibrationConsistency {
            c3_implied,
            c4_implied,
            c3_rel_error: ((self.c3 - c3_implied) / self.c3).abs(),
            c4_rel_error: ((self.c4 - c4_implied) / self.c4).abs(),
        }
    }

    /// Whether every constant is finite and physically signed (C1, C3, C5, C6 > 0).
    pub fn is_plausible(&self) -> bool {
        let all = [self.c1, self.c2, self.c3, self.c4, self.c5, self.c6];
        all.iter().all(|c| c.is_finite())
            && self.c1 > 0.0
            && self.c3 >= 0.0
            && self.c5 >= 0.0
            && self.c6 > 0.0
    }
}

impl Default for Calibration {
    fn default() -> Self {
        Self::PAPER
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table2_is_self_consistent() {
        let c = Calibration::PAPER.consistency();
        // C1 C5 = 0.2347 N mm s/rad against C3 = 0.235.
        assert!((c.c3_implied * 1e3 - 0.2347).abs() < 1e-4);
        assert!(c.c3_rel_error < 0.005, "{}", c.c3_rel_error);
        // C1 C6 + C2 = 1.725 N mm against C4 = 1.69: a small difference of large numbers.
        assert!((c.c4_implied * 1e3 - 1.725).abs() < 1e-3);
        assert!(c.c4_rel_error < 0.03, "{}", c.c4_rel_error);
    }

    #[test]
    fn loss_torque_is_the_torque_of_the_no_load_current() {
        let c = Calibration::PAPER;
        for w in [10.0, 31.4, 62.8, 94.2] {
            let via_current = c.gross_torque(c.no_load_current(w));
            assert!((via_current - c.loss_torque(w)).abs() < 1e-4, "w {w}");
            // At no load the cam torque is (nearly) zero.
            assert!(c.cam_torque(c.no_load_current(w), w).abs() < 1e-4);
        }
    }

    #[test]
    fn current_for_inverts_cam_torque() {
        let c = Calibration::PAPER;
        let i = c.current_for(0.0535, 31.4);
        assert!((c.cam_torque(i, 31.4) - 0.0535).abs() < 1e-12);
        // ~3.2 A for the full 3.68 N m load at 5 Hz.
        assert!(i > 3.0 && i < 3.5, "{i}");
    }

    #[test]
    fn paper_units_round_trip() {
        let p = Calibration::PAPER.to_paper_units();
        let expected = [62.1, -138.0, 0.235, 1.69, 0.00378, 2.25];
        for (a, b) in p.iter().zip(expected) {
            assert!((a - b).abs() < 1e-9);
        }
        assert_eq!(
            Calibration::from_torque_and_no_load(1.0, -1.0, 2.0, 3.0).c4,
            2.0
        );
        assert!(Calibration::PAPER.is_plausible());
    }
}
