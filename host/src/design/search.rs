//! `rig design search`: tooth numbers in ranges and profile shifts on a grid, under the
//! hold and stop margins, a ratio range, a centre-distance range and every buildability
//! check of [`super::checks`]; the Pareto front of the feasible designs over the
//! objectives a designer trades: required cam torque (vibrator size, minimised), |rho|
//! (minimised: the same stop with less reduction keeps the output fast) and the root
//! strength margin (maximised).
//!
//! x1 and x2 run over the grid; the G1-G2 mesh fixes the working centre distance, which
//! fixes x3 + x4 ([`model::involute::shift_sum_for_centre_distance`]); x3 runs over the grid
//! and x4 is the rest, so every candidate shares the carrier's centre distance exactly.
//! Parallel over the tooth-number sets with `std::thread::scope`.

use core::f64::consts::PI;

use model::GearSet;
use model::involute::{self, Mesh, MeshSummary};
use serde::Serialize;

use super::{CamDrive, DesignReport, RigParams, checks};

/// Where and under which constraints to search (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchSpace {
    /// Smallest and largest tooth count of every gear.
    pub teeth: (u32, u32),
    /// Largest tooth difference n = |Z1 - Z4|.
    pub max_tooth_difference: u32,
    /// Largest |(Z1 + Z2) - (Z3 + Z4)| (profile shift closes the gap).
    pub max_sum_difference: u32,
    /// Smallest and largest shift coefficient.
    pub shift: (f64, f64),
    /// Step of the shift grid.
    pub shift_step: f64,
    /// Range of |rho|.
    pub ratio: (f64, f64),
    /// Range of the working centre distance, m.
    pub centre_distance: (f64, f64),
    /// Hold margin m_s: mu_s Lambda >= 1 + m_s.
    pub hold_margin: f64,
    /// Stop margin m_d: mu_d Lambda >= 1 + m_d.
    pub stop_margin: f64,
}

impl Default for SearchSpace {
    /// Around the paper's gear: 45-55 teeth, n <= 2, sums within 2, shifts -0.5..1.0 in
    /// steps of 0.1, |rho| 5-60, centre distance 48-52 mm, margins 0.05 (hold) and 0.15
    /// (stop: with mu_d Lambda = 1.15 the paper's 2.79 kg m^2 output stops within seconds;
    /// just above 1 it coasts for minutes).
    fn default() -> Self {
        Self {
            teeth: (45, 55),
            max_tooth_difference: 2,
            max_sum_difference: 2,
            shift: (-0.5, 1.0),
            shift_step: 0.1,
            ratio: (5.0, 60.0),
            centre_distance: (48e-3, 52e-3),
            hold_margin: 0.05,
            stop_margin: 0.15,
        }
    }
}

/// What the search returns.
#[derive(Debug, Clone, Serialize)]
pub struct SearchResult {
    /// Complete candidates (tooth counts and all four shifts) evaluated.
    pub candidates: u64,
    /// Candidates that passed every constraint and check.
    pub feasible: u64,
    /// The Pareto front, by required cam torque then |rho|.
    pub designs: Vec<DesignReport>,
}

/// One feasible candidate on the way to the front.
#[derive(Debug, Clone, Copy)]
struct Candidate {
    z: [u32; 4],
    x: [f64; 4],
    tau_cam: f64,
    ratio: f64,
    strength: f64,
    mu_d_lambda: f64,
}

impl Candidate {
    /// `self` is at least as good in every objective and better in one.
    fn dominates(&self, o: &Candidate) -> bool {
        let ge = self.tau_cam <= o.tau_cam && self.ratio <= o.ratio && self.strength >= o.strength;
        let gt = self.tau_cam < o.tau_cam || self.ratio < o.ratio || self.strength > o.strength;
        ge && (gt || self.mu_d_lambda > o.mu_d_lambda)
    }
}

/// Adds `c` to the non-dominated set `front`.
fn insert(front: &mut Vec<Candidate>, c: Candidate) {
    if front
        .iter()
        .any(|f| f.dominates(&c) || same_objectives(f, &c))
    {
        return;
    }
    front.retain(|f| !c.dominates(f));
    front.push(c);
}

fn same_objectives(a: &Candidate, b: &Candidate) -> bool {
    a.tau_cam == b.tau_cam
        && a.ratio == b.ratio
        && a.strength == b.strength
        && a.mu_d_lambda >= b.mu_d_lambda
}

/// The shift grid: from `shift.0` to `shift.1` in `shift_step`s (both ends included).
fn grid(space: &SearchSpace) -> Vec<f64> {
    let (lo, hi) = space.shift;
    if !(space.shift_step > 0.0 && hi >= lo) {
        return vec![lo];
    }
    let steps = ((hi - lo) / space.shift_step + 1e-9).floor();
    #[allow(
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss,
        reason = "small, >= 0"
    )]
    let count = steps as usize + 1;
    // Rounded to 1e-9 so grid values print as typed (0.9, not 0.9000000000000001).
    (0..count)
        .map(|k| ((lo + k as f64 * space.shift_step) * 1e9).round() / 1e9 + 0.0)
        .collect()
}

/// The tooth-number sets worth shifting: n and the sum gap in range, |rho| in range.
fn tooth_sets(space: &SearchSpace) -> Vec<[u32; 4]> {
    let (lo, hi) = space.teeth;
    let mut out = Vec::new();
    for z1 in lo..=hi {
        for z2 in lo..=hi {
            for z4 in lo..=hi {
                let n = z1.abs_diff(z4);
                if n == 0 || n > space.max_tooth_difference {
                    continue;
                }
                for z3 in lo..=hi {
                    if (z1 + z2).abs_diff(z3 + z4) > space.max_sum_difference
                        || u64::from(z1) * u64::from(z3) == u64::from(z2) * u64::from(z4)
                    {
                        continue;
                    }
                    let (a, b) = (f64::from(z1 * z3), f64::from(z2 * z4));
                    let rho = (b / (b - a)).abs();
                    if rho >= space.ratio.0 && rho <= space.ratio.1 {
                        out.push([z1, z2, z3, z4]);
                    }
                }
            }
        }
    }
    out
}

/// The mesh checks of [`checks::buildability`] on a summary, without building messages.
fn mesh_ok(s: &MeshSummary, params: &RigParams) -> bool {
    s.alpha_w.is_finite()
        && !s.undercut[0]
        && !s.undercut[1]
        && !s.interference[0]
        && !s.interference[1]
        && s.tip_thickness_modules[0] >= params.limits.min_tip_thickness_modules
        && s.tip_thickness_modules[1] >= params.limits.min_tip_thickness_modules
        && s.contact_ratio[0] + s.contact_ratio[1] >= params.limits.min_contact_ratio
}

/// Searches `space` at `params`; `threads` workers (at least one).
pub fn search(space: &SearchSpace, params: &RigParams, threads: usize) -> SearchResult {
    let sets = tooth_sets(space);
    let shifts = grid(space);
    let threads = threads.max(1);
    let chunk = sets.len().div_ceil(threads).max(1);
    let parts: Vec<(u64, u64, Vec<Candidate>)> = std::thread::scope(|scope| {
        let handles: Vec<_> = sets
            .chunks(chunk)
            .map(|part| scope.spawn(|| search_sets(part, &shifts, space, params)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a search worker panicked"))
            .collect()
    });
    let (mut candidates, mut feasible, mut front) = (0, 0, Vec::new());
    for (c, f, part) in parts {
        candidates += c;
        feasible += f;
        for cand in part {
            insert(&mut front, cand);
        }
    }
    front.sort_by(|a, b| {
        a.tau_cam
            .total_cmp(&b.tau_cam)
            .then(a.ratio.total_cmp(&b.ratio))
    });
    let designs = front
        .iter()
        .filter_map(|c| GearSet::shifted(c.z, c.x, params.module, params.pressure_angle).ok())
        .map(|g| super::report(&g, params, None))
        .collect();
    SearchResult {
        candidates,
        feasible,
        designs,
    }
}

/// One worker: its tooth-number sets over the whole shift grid.
fn search_sets(
    sets: &[[u32; 4]],
    shifts: &[f64],
    space: &SearchSpace,
    params: &RigParams,
) -> (u64, u64, Vec<Candidate>) {
    let (m, alpha) = (params.module, params.pressure_angle);
    let omega_n = 2.0 * PI * params.vibration_hz;
    let available = checks::available_cam_torque(params, omega_n);
    let (mut candidates, mut feasible, mut front) = (0u64, 0u64, Vec::new());
    for &z in sets {
        let [z1, z2, z3, z4] = z.map(f64::from);
        let ratio = (z2 * z4 / (z2 * z4 - z1 * z3)).abs();
        for &x1 in shifts {
            for &x2 in shifts {
                let m12 = Mesh {
                    z: [z[0], z[1]],
                    x: [x1, x2],
                    module: m,
                    alpha,
                }
                .summary();
                let a_w = m12.centre_distance;
                let in_range = a_w >= space.centre_distance.0 && a_w <= space.centre_distance.1;
                if !(in_range && mesh_ok(&m12, params)) {
                    continue;
                }
                let x34 = involute::shift_sum_for_centre_distance(z[2] + z[3], m, alpha, a_w);
                if !x34.is_finite() {
                    continue;
                }
                for &x3 in shifts {
                    candidates += 1;
                    // Rounded like the grid (1e-9: far inside the 1e-3 module tolerance).
                    let x4 = ((x34 - x3) * 1e9).round() / 1e9 + 0.0; // + 0.0: no -0
                    if !(x4 >= space.shift.0 && x4 <= space.shift.1) {
                        continue;
                    }
                    let m34 = Mesh {
                        z: [z[2], z[3]],
                        x: [x3, x4],
                        module: m,
                        alpha,
                    }
                    .summary();
                    if !mesh_ok(&m34, params) {
                        continue;
                    }
                    let [general, willis] = model::gear::lambdas_of_meshes(z, m, alpha, &m12, &m34);
                    let lambda = general.min(willis);
                    if params.mu_s * lambda < 1.0 + space.hold_margin
                        || params.mu_d * lambda < 1.0 + space.stop_margin
                    {
                        continue;
                    }
                    let x = [x1, x2, x3, x4];
                    let Ok(gear) = GearSet::shifted(z, x, m, alpha) else {
                        continue;
                    };
                    let tau_cam = CamDrive {
                        gear,
                        eccentricity: params.eccentricity,
                        carrier_mass: params.carrier_mass,
                    }
                    .required_cam_torque(params.mu_s, params.tau_rot, omega_n);
                    if tau_cam > available {
                        continue;
                    }
                    let strength = gear.strength_margin(params.tau_rot);
                    if strength < params.limits.min_strength_margin {
                        continue;
                    }
                    if let Some(mat) = params.limits.material
                        && checks::root_stress(&gear, params.tau_rot, mat.face_width)
                            > mat.root_stress_limit
                    {
                        continue;
                    }
                    feasible += 1;
                    insert(
                        &mut front,
                        Candidate {
                            z,
                            x,
                            tau_cam,
                            ratio,
                            strength,
                            mu_d_lambda: params.mu_d * lambda,
                        },
                    );
                }
            }
        }
    }
    (candidates, feasible, front)
}

/// The front as a table: one line per design.
pub fn render_table(r: &SearchResult) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} candidates, {} feasible, {} on the Pareto front (cam torque, |rho|, strength margin)",
        r.candidates,
        r.feasible,
        r.designs.len()
    );
    let _ = writeln!(
        s,
        "{:<16} {:<28} {:>7} {:>8} {:>8} {:>8} {:>9} {:>8} {:>13} {:>9}",
        "Z1,Z2,Z3,Z4",
        "x1,x2,x3,x4",
        "rho",
        "a_w mm",
        "aw12 deg",
        "aw34 deg",
        "mu_s*Lam",
        "mu_d*Lam",
        "τ_cam, N mm",
        "strength"
    );
    if r.designs.is_empty() {
        let _ = writeln!(
            s,
            "no design passed every constraint: widen --teeth or --shift, lower --stop-margin or --hold-margin, or allow --max-sum-difference"
        );
    }
    for d in &r.designs {
        let [z1, z2, z3, z4] = d.z;
        let [x1, x2, x3, x4] = d.x;
        let _ = writeln!(
            s,
            "{:<16} {:<28} {:>7.2} {:>8.3} {:>8.3} {:>8.3} {:>9.3} {:>8.3} {:>13.1} {:>9.3}",
            format!("{z1},{z2},{z3},{z4}"),
            format!("{x1:.3},{x2:.3},{x3:.3},{x4:.3}"),
            d.rho,
            d.centre_distance_mm,
            d.working_pressure_angles_deg[0],
            d.working_pressure_angles_deg[1],
            d.mu_s_lambda_conservative,
            d.mu_d_lambda_conservative,
            d.tau_cam_hat_nm * 1e3,
            d.strength_margin
        );
    }
    s
}

/// Draws the front into the SVG file `path` printed at `size`: required cam torque against
/// |ρ|, and μ_d Λ against the strength margin.
pub fn plot(
    path: &std::path::Path,
    r: &SearchResult,
    size: reporting::figure::FigureSize,
) -> Result<(), crate::RigError> {
    use reporting::plot::{PALETTE, Series, XyPanel, axis_label, columns_figure};
    let cam: Vec<(f64, f64)> = r
        .designs
        .iter()
        .map(|d| (d.rho.abs(), d.tau_cam_hat_nm * 1e3))
        .collect();
    let stop: Vec<(f64, f64)> = r
        .designs
        .iter()
        .map(|d| (d.strength_margin, d.mu_d_lambda_conservative))
        .collect();
    let panels = [
        XyPanel {
            caption: Some("required cam torque (Eq. 10)".into()),
            x_label: axis_label("|ρ|", ""),
            y_label: axis_label("τ_cam", "N mm"),
            series: vec![Series::points(PALETTE[0], 4, cam)],
            ..XyPanel::default()
        },
        XyPanel {
            caption: Some("stop after vibration vs tooth strength".into()),
            x_label: axis_label("strength margin", ""),
            y_label: axis_label("μ_d Λ", ""),
            series: vec![Series::points(PALETTE[1], 4, stop)],
            ..XyPanel::default()
        },
    ];
    columns_figure(
        path,
        size,
        (520, 400),
        Some("rig design search: Pareto front"),
        &panels,
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> SearchSpace {
        SearchSpace {
            teeth: (48, 52),
            max_tooth_difference: 1,
            max_sum_difference: 1,
            ..SearchSpace::default()
        }
    }

    #[test]
    fn grid_includes_both_ends_exactly() {
        let g = grid(&SearchSpace::default());
        assert_eq!(g.len(), 16);
        assert_eq!((g[0], g[15]), (-0.5, 1.0));
        assert_eq!(g[14], 0.9);
    }

    #[test]
    fn front_is_non_dominated_and_every_design_passes_its_constraints() {
        let params = RigParams::default();
        let r = search(&small(), &params, 2);
        assert!(r.feasible >= r.designs.len() as u64 && !r.designs.is_empty());
        for d in &r.designs {
            assert!(d.checks.iter().all(|c| c.passed), "{:?}", d.checks);
            assert!(d.mu_d_lambda_conservative >= 1.0 && d.mu_s_lambda_conservative >= 1.05);
            assert!(d.rho.abs() >= 5.0 && d.rho.abs() <= 60.0);
            assert!(d.centre_distance_mm >= 48.0 && d.centre_distance_mm <= 52.0);
        }
        for a in &r.designs {
            for b in &r.designs {
                let dominates = a.tau_cam_hat_nm <= b.tau_cam_hat_nm
                    && a.rho.abs() <= b.rho.abs()
                    && a.strength_margin >= b.strength_margin
                    && (a.tau_cam_hat_nm < b.tau_cam_hat_nm
                        || a.rho.abs() < b.rho.abs()
                        || a.strength_margin > b.strength_margin);
                assert!(!dominates, "{:?} dominates {:?}", a.z, b.z);
            }
        }
    }

    #[test]
    fn threads_do_not_change_the_result() {
        let params = RigParams::default();
        let one = search(&small(), &params, 1);
        let three = search(&small(), &params, 3);
        assert_eq!(one.candidates, three.candidates);
        assert_eq!(one.feasible, three.feasible);
        let key = |r: &SearchResult| {
            let mut k: Vec<_> = r
                .designs
                .iter()
                .map(|d| (d.z, d.x.map(f64::to_bits)))
                .collect();
            k.sort();
            k
        };
        assert_eq!(key(&one), key(&three));
    }

    #[test]
    fn the_paper_s_gear_is_not_feasible_when_it_must_stop() {
        // mu_d Lambda = 0.858: the standard (49, 51, 50, 50) never passes the stop margin.
        let params = RigParams::default();
        let r = search(&small(), &params, 2);
        assert!(
            !r.designs
                .iter()
                .any(|d| d.z == model::paper::RIG_Z && d.x == [0.0; 4])
        );
    }
}
