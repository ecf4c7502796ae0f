//! The bridge's supply bus: a capacitance fed through the supply's internal resistance by
//! a supply that sources current but cannot sink it (a bench supply, as the paper's).
//!
//! ```text
//!   V_supply --[R_s]--|>|--+-- V_bus --> bridge: i_bridge = d i (sign-magnitude: the
//!                          |               winding current flows in the on-time only)
//!                          C
//! ```
//!
//! While the bridge draws (i_bridge > 0) the bus settles at V_supply - R_s i_bridge with the
//! time constant R_s C. When the bridge returns power (i_bridge < 0: braking decay with the
//! cam overrunning the drive) the supply stops conducting at V_supply and the returned
//! current charges C alone: dV/dt = -i_bridge / C, the rise the firmware's
//! `BUS_OVERVOLTAGE` check watches for. The bus divider (110 kOhm) bleeds C slowly.
//!
//! One step holds i_bridge constant and is solved exactly on each side of V_supply, so the
//! stiff R_s C (23.5 us at 0.05 Ohm and 470 uF) needs no sub-stepping at the plant's 0.1 ms.

use crate::hardware::bus_divider;

/// The bleed of the bus divider, ohm (100 k + 10 k).
const BLEED_OHM: f64 = bus_divider::R_TOP_OHM + bus_divider::R_BOTTOM_OHM;

/// The bus voltage after `dt` seconds from `v0`, with the bridge drawing `i_bridge` amperes
/// (negative: returning) from a capacitance `c` fed by `supply` volts through `r_s` ohms
/// that cannot sink current. `c` must be positive.
pub fn step(v0: f64, supply: f64, r_s: f64, c: f64, i_bridge: f64, dt: f64) -> f64 {
    // The divider's bleed as a current at the step's start (its time constant is ~50 s).
    let i_out = i_bridge + v0.max(0.0) / BLEED_OHM;
    let mut v = v0;
    let mut t = dt;
    let tau = r_s * c;
    if v < supply || (v == supply && i_out > 0.0) {
        // The supply conducts: V tends to V_eq = supply - r_s i_out with time constant tau.
        if tau <= 0.0 {
            // An ideal source: the bus sits at the supply (it cannot rise above it here).
            return if i_out >= 0.0 {
                supply - r_s * i_out
            } else {
                supply
            };
        }
        let v_eq = supply - r_s * i_out;
        if v_eq <= supply {
            return v_eq + (v - v_eq) * libm::exp(-t / tau);
        }
        // Returning: V rises past the supply, where the supply stops conducting.
        let t_cross = tau * libm::log((v - v_eq) / (supply - v_eq));
        if t_cross >= t {
            return v_eq + (v - v_eq) * libm::exp(-t / tau);
        }
        v = supply;
        t -= t_cross;
    }
    // At or above the supply: only the bridge (and the bleed) move the bus.
    let slope = -i_out / c;
    let v_end = v + slope * t;
    if v_end >= supply || slope >= 0.0 {
        return v_end;
    }
    // Drawn back down to the supply within the step: from there the supply conducts again.
    let t_down = (v - supply) / -slope;
    let v_eq = supply - r_s * i_out;
    if tau <= 0.0 {
        return v_eq;
    }
    v_eq + (supply - v_eq) * libm::exp(-(t - t_down) / tau)
}

#[cfg(test)]
mod tests {
    use super::*;

    const C: f64 = 470e-6;
    const RS: f64 = 0.05;

    #[test]
    fn drawing_settles_at_the_resistive_sag() {
        // 3 A from 12 V through 0.05 ohm: 11.85 V (the bleed adds 0.1 mA).
        let mut v = 12.0;
        for _ in 0..100 {
            v = step(v, 12.0, RS, C, 3.0, 1e-4);
        }
        assert!(
            (v - (12.0 - 0.05 * (3.0 + 12.0 / BLEED_OHM))).abs() < 1e-6,
            "{v}"
        );
        // One long step gives the same as many short ones (exact within the step).
        let once = step(12.0, 12.0, RS, C, 3.0, 1e-2);
        assert!((once - v).abs() < 1e-6);
    }

    #[test]
    fn returned_charge_raises_the_bus_by_q_over_c() {
        // 2 A returned for 1 ms: 2 mC on 470 uF is 4.26 V above the supply.
        let mut v = 12.0;
        for _ in 0..10 {
            v = step(v, 12.0, RS, C, -2.0, 1e-4);
        }
        let want = 12.0 + 2.0e-3 / C;
        assert!((v - want).abs() < 0.01, "{v} vs {want}");
        // Energy: C (V^2 - V0^2) / 2 is what the bridge put in, ~ V I t.
        let stored = 0.5 * C * (v * v - 144.0);
        assert!((stored / (0.5 * (12.0 + v) * 2.0 * 1e-3) - 1.0).abs() < 0.01);
        // Left alone it stays up (the supply cannot sink; the bleed takes ~50 s).
        let later = step(v, 12.0, RS, C, 0.0, 0.1);
        assert!(later > v - 0.05 && later < v);
        // Drawing again brings it back to the supply's sag.
        let back = step(v, 12.0, RS, C, 3.0, 0.01);
        assert!((back - (12.0 - 0.05 * 3.0)).abs() < 0.01, "{back}");
    }

    #[test]
    fn below_the_supply_a_returning_bridge_first_charges_to_it() {
        // From 11 V the supply and the bridge together lift the bus to 12 V at once
        // (tau = 23.5 us), then only the returned current: 1 A for 1 ms = 2.13 V.
        let v = step(11.0, 12.0, RS, C, -1.0, 1e-3);
        let want = 12.0 + (1e-3 - 23.5e-6 * libm::log(1.0 / (1.0 - 1.0 / 1.05))) * 1.0 / C;
        assert!((v - want).abs() < 0.02, "{v} vs {want}");
        assert!(v > 12.0 && v < 12.0 + 1e-3 / C);
    }
}
