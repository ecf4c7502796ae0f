//! The H-bridge gate: the order in which the binary switches the bridge on and off around
//! the timer's hardware break, as a state machine over the few register operations it uses
//! ([`BridgeHw`]), so that the order is tested on the host against a break landing between
//! any two of them.
//!
//! The hardware (STM32G474, `firmware/src/board.rs`): COMP3 drives TIM1's break input. A
//! break clears BDTR.MOE in hardware and sets SR.BIF; the break interrupt drops the bridge
//! enable pin and latches the trip for software ([`BridgeHw::break_seen`] reads SR.BIF or
//! that latch). MOE is level-sensitive: once the comparator falls back, software can set MOE
//! again, and nothing in the hardware stops it. So every switch-on checks for a break right
//! before setting MOE and again after the enable pin is up, and a trip is only ever
//! cleared by [`BridgeGate::rearm`], which the binary calls only once the core has latched
//! the fault (a deliberate re-arm; `ClearFaults` then clears the core's latch).
//!
//! The compare register is preloaded (it takes a new value at the timer's update event,
//! every 100 us at the rig's repetition counter); a switch-on from off loads the duty into
//! the active register first ([`BridgeHw::load_duty_now`]), so the bridge never starts on
//! a stale compare value (0 = both low = motor shorted, or the old duty after a reversal).

/// The register operations the gate uses. The binary implements them on TIM1, COMP3 and
/// the enable pin; tests on a model of them.
pub trait BridgeHw {
    /// A break happened since the last [`BridgeHw::clear_break`]: TIM1 SR.BIF, or the latch
    /// the break interrupt sets.
    fn break_seen(&mut self) -> bool;
    /// The comparator sees an overcurrent now (COMP3's output).
    fn overcurrent_now(&mut self) -> bool;
    /// Clears the break flag and the interrupt's latch, and unmasks the break interrupt.
    fn clear_break(&mut self);
    /// Writes the compare value into the active register at once (CCR1 with its preload
    /// off for the write), for a switch-on from off.
    fn load_duty_now(&mut self, compare: u16);
    /// Writes the compare value through its preload (taken at the next update event).
    fn set_duty(&mut self, compare: u16);
    /// Sets or clears the timer's main output enable (BDTR.MOE).
    fn set_main_output(&mut self, on: bool);
    /// Drives the bridge enable pin.
    fn set_enable(&mut self, on: bool);
}

/// What [`BridgeGate::enable`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EnableResult {
    /// The bridge drives at the commanded duty.
    Driving,
    /// Refused: a trip is latched (now or just now); the bridge is off until
    /// [`BridgeGate::rearm`].
    Tripped,
    /// Refused for this step: the comparator is over its threshold but the (filtered)
    /// break has not fired yet; the bridge stays off.
    OverThreshold,
}

/// The bridge's switch-on and switch-off sequences around the hardware break.
#[derive(Debug, Clone, Default)]
pub struct BridgeGate {
    tripped: bool,
    driving: bool,
}

impl BridgeGate {
    /// Off and not tripped (call [`BridgeGate::stop`] once to put the hardware there).
    pub const fn new() -> Self {
        Self {
            tripped: false,
            driving: false,
        }
    }

    /// Whether a trip is latched (until [`BridgeGate::rearm`]).
    pub fn tripped(&self) -> bool {
        self.tripped
    }

    /// Whether the last [`BridgeGate::enable`] left the bridge driving.
    pub fn driving(&self) -> bool {
        self.driving
    }

    /// Reads the break (once per control step, before the core's step): true while a trip
    /// is latched. A new trip switches the bridge off.
    pub fn poll(&mut self, hw: &mut impl BridgeHw) -> bool {
        if !self.tripped && hw.break_seen() {
            self.trip(hw);
        }
        self.tripped
    }

    /// The safe state: enable pin low, main output off, compare value 0.
    pub fn stop(&mut self, hw: &mut impl BridgeHw) {
        hw.set_enable(false);
        hw.set_main_output(false);
        hw.set_duty(0);
        self.driving = false;
    }

    /// Drives the bridge at `compare`: from off, loads it into the active register, then
    /// checks for a break right before MOE and after the enable pin is up. Refused while a
    /// trip is latched, whatever the comparator says now.
    pub fn enable(&mut self, hw: &mut impl BridgeHw, compare: u16) -> EnableResult {
        if self.tripped || hw.break_seen() {
            self.trip(hw);
            return EnableResult::Tripped;
        }
        if self.driving {
            hw.set_duty(compare);
            // MOE and the pin are already up; a break since the check above is caught by
            // the next step's `poll` (the hardware and the interrupt have switched off).
            return EnableResult::Driving;
        }
        if hw.overcurrent_now() {
            self.stop(hw);
            return EnableResult::OverThreshold;
        }
        hw.load_duty_now(compare);
        hw.set_main_output(true);
        if hw.break_seen() {
            // A break between the check and MOE: MOE may have been set again after the
            // comparator fell back. Off, latched.
            self.trip(hw);
            return EnableResult::Tripped;
        }
        hw.set_enable(true);
        if hw.break_seen() {
            // A break between MOE and the pin: the interrupt's pin write may have come
            // before ours.
            self.trip(hw);
            return EnableResult::Tripped;
        }
        self.driving = true;
        EnableResult::Driving
    }

    /// Clears a latched trip once the comparator is back under its threshold: call only
    /// when the core no longer drives and has latched the fault. Returns whether the trip
    /// is cleared (the bridge stays off until the next [`BridgeGate::enable`]).
    pub fn rearm(&mut self, hw: &mut impl BridgeHw) -> bool {
        if hw.overcurrent_now() {
            return false;
        }
        self.stop(hw);
        hw.clear_break();
        self.tripped = false;
        true
    }

    fn trip(&mut self, hw: &mut impl BridgeHw) {
        self.tripped = true;
        self.stop(hw);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// TIM1, COMP3 and the enable pin as the gate sees them, with a break that lands right
    /// before the register operation number `break_at` (counting every call), and a
    /// comparator that falls back `comparator_ops` operations later (0: at once, the worst
    /// case: MOE may be set again by software).
    #[derive(Debug, Default)]
    struct ModelHw {
        ops: u32,
        break_at: Option<u32>,
        comparator_ops: u32,
        comparator_high_until: Option<u32>,
        bif: bool,
        isr_latch: bool,
        bie: bool,
        moe: bool,
        pin: bool,
        ccr_active: u16,
        ccr_preload: u16,
        /// Operations at which the bridge drove (MOE and the pin both up) after a break
        /// that had not been re-armed.
        drove_after_break: Vec<u32>,
        /// Switch-ons (MOE and pin up from off) and the active compare value then.
        switch_ons: Vec<u16>,
        was_driving: bool,
        break_pending_rearm: bool,
    }

    impl ModelHw {
        fn comparator_high(&self) -> bool {
            self.comparator_high_until.is_some_and(|u| self.ops < u)
        }

        /// Advances one operation; the break lands first when it is due.
        fn tick(&mut self) {
            if self.break_at == Some(self.ops) {
                self.comparator_high_until = Some(self.ops + self.comparator_ops);
                // The break: MOE cleared in hardware, BIF set; the interrupt (if unmasked)
                // drops the pin, masks itself and latches.
                self.moe = false;
                self.bif = true;
                if self.bie {
                    self.pin = false;
                    self.bie = false;
                    self.isr_latch = true;
                }
                self.break_pending_rearm = true;
            }
            self.ops += 1;
        }

        fn observe(&mut self) {
            let driving = self.moe && self.pin;
            if driving && self.break_pending_rearm {
                self.drove_after_break.push(self.ops);
            }
            if driving && !self.was_driving {
                self.switch_ons.push(self.ccr_active);
            }
            self.was_driving = driving;
        }

        /// The timer's update event: the preload reaches the active register.
        fn update_event(&mut self) {
            self.ccr_active = self.ccr_preload;
        }
    }

    impl BridgeHw for ModelHw {
        fn break_seen(&mut self) -> bool {
            self.tick();
            self.bif || self.isr_latch
        }
        fn overcurrent_now(&mut self) -> bool {
            self.tick();
            self.comparator_high()
        }
        fn clear_break(&mut self) {
            self.tick();
            self.bif = false;
            self.isr_latch = false;
            self.bie = true;
            self.break_pending_rearm = false;
        }
        fn load_duty_now(&mut self, compare: u16) {
            self.tick();
            self.ccr_active = compare;
            self.ccr_preload = compare;
            self.observe();
        }
        fn set_duty(&mut self, compare: u16) {
            self.tick();
            self.ccr_preload = compare;
            self.observe();
        }
        fn set_main_output(&mut self, on: bool) {
            self.tick();
            // MOE cannot be set while the break input is active; it can once it falls.
            self.moe = on && !self.comparator_high();
            self.observe();
        }
        fn set_enable(&mut self, on: bool) {
            self.tick();
            self.pin = on;
            self.observe();
        }
    }

    /// One control step of the binary: poll, then drive or stop, then the timer's update.
    fn step(gate: &mut BridgeGate, hw: &mut ModelHw, drive: Option<u16>) -> bool {
        let tripped = gate.poll(hw);
        match drive {
            Some(compare) if !tripped => {
                gate.enable(hw, compare);
            }
            _ => gate.stop(hw),
        }
        hw.update_event();
        tripped
    }

    fn armed() -> (BridgeGate, ModelHw) {
        let mut hw = ModelHw {
            bie: true,
            ..ModelHw::default()
        };
        let mut gate = BridgeGate::new();
        gate.stop(&mut hw);
        (gate, hw)
    }

    #[test]
    fn a_break_anywhere_in_a_step_keeps_the_bridge_off_until_a_deliberate_rearm() {
        // Steps: drive from off, keep driving, reverse-like re-enable from off, drive on.
        let plan = [
            Some(1000),
            Some(1200),
            None,
            Some(3000),
            Some(3100),
            Some(3200),
        ];
        // Count the operations of the clean run, then land the break before each of them.
        let (mut gate, mut hw) = armed();
        let first = hw.ops;
        for d in plan {
            step(&mut gate, &mut hw, d);
        }
        let total = hw.ops;
        assert!(hw.drove_after_break.is_empty() && !gate.tripped());
        for comparator_ops in [0, 1, 3, 1000] {
            for at in first..total {
                let (mut gate, mut hw) = armed();
                hw.break_at = Some(at);
                hw.comparator_ops = comparator_ops;
                // The core keeps commanding drive the whole time (it has not seen the
                // trip yet, or ignores it): only the gate stands in the way.
                for d in plan.into_iter().chain([Some(2000); 20]) {
                    step(&mut gate, &mut hw, d);
                }
                assert!(
                    hw.drove_after_break.is_empty(),
                    "break before op {at} (comparator {comparator_ops} ops): the bridge drove \
                     again at ops {:?}",
                    hw.drove_after_break
                );
                assert!(gate.tripped(), "break before op {at}: the trip was lost");
                assert!(!hw.moe || !hw.pin);
                // A deliberate re-arm once the comparator is low, then the bridge may drive.
                while hw.comparator_high() {
                    hw.tick();
                }
                assert!(gate.rearm(&mut hw), "break before op {at}");
                step(&mut gate, &mut hw, Some(2500));
                assert!(gate.driving() && hw.moe && hw.pin, "break before op {at}");
            }
        }
    }

    #[test]
    fn rearm_is_refused_while_the_comparator_is_over_its_threshold() {
        let (mut gate, mut hw) = armed();
        hw.break_at = Some(hw.ops + 2);
        hw.comparator_ops = 50;
        step(&mut gate, &mut hw, Some(1000));
        step(&mut gate, &mut hw, Some(1000));
        assert!(gate.tripped());
        assert!(!gate.rearm(&mut hw));
        assert!(gate.tripped() && hw.bif);
        while hw.comparator_high() {
            hw.tick();
        }
        assert!(gate.rearm(&mut hw) && !gate.tripped() && !hw.bif && hw.bie);
    }

    #[test]
    fn a_switch_on_starts_at_the_commanded_duty_never_a_stale_one() {
        let (mut gate, mut hw) = armed();
        // Off (compare 0 preloaded and active), then on at 3000: the first instant the
        // bridge drives, the active register already holds 3000.
        step(&mut gate, &mut hw, None);
        step(&mut gate, &mut hw, Some(3000));
        step(&mut gate, &mut hw, Some(3100));
        // Off (as for a reversal), then on again at 500: not the old 3100.
        step(&mut gate, &mut hw, None);
        step(&mut gate, &mut hw, Some(500));
        assert_eq!(hw.switch_ons, vec![3000, 500]);
    }

    #[test]
    fn an_over_threshold_comparator_without_a_break_refuses_the_step_only() {
        let (mut gate, mut hw) = armed();
        hw.comparator_high_until = Some(hw.ops + 3);
        assert_eq!(gate.enable(&mut hw, 1000), EnableResult::OverThreshold);
        assert!(!hw.moe && !hw.pin && !gate.tripped());
        assert_eq!(gate.enable(&mut hw, 1000), EnableResult::Driving);
    }
}
