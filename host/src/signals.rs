//! The signals that end a procedure: Ctrl-C (SIGINT), SIGTERM (a service manager, `kill`)
//! and SIGHUP (the terminal closed). Each raises the procedure's stop flag so the procedure
//! locks the gear on its own path; a second one of the same kind ends the process at once.
//! The signal is remembered, so messages name what happened and the exit code is 128 + its
//! number (130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP).

use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

/// The signals that stop a procedure.
pub const STOP_SIGNALS: [i32; 3] = [SIGINT, SIGTERM, SIGHUP];

fn last_signal() -> &'static Arc<AtomicUsize> {
    static LAST: OnceLock<Arc<AtomicUsize>> = OnceLock::new();
    LAST.get_or_init(|| Arc::new(AtomicUsize::new(0)))
}

/// A flag raised by Ctrl-C (SIGINT), SIGTERM or SIGHUP; a second one ends the process at
/// once (exit 128 + the signal's number).
pub fn interrupt_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    for signal in STOP_SIGNALS {
        // Registration only fails for forbidden signals; without it the signal still ends
        // the process, and the device stops at its comms timeout (the safe state).
        let code = 128 + signal as u32;
        let _ = signal_hook::flag::register_conditional_shutdown(
            signal,
            code as i32,
            Arc::clone(&flag),
        );
        let _ =
            signal_hook::flag::register_usize(signal, Arc::clone(last_signal()), signal as usize);
        let _ = signal_hook::flag::register(signal, Arc::clone(&flag));
    }
    flag
}

/// The signal that stopped the procedure, as the user knows it: `Ctrl-C`, `SIGTERM`
/// or `SIGHUP (the terminal closed)`.
pub fn interrupt_name() -> &'static str {
    name_of(last_signal().load(Ordering::SeqCst))
}

fn name_of(signal: usize) -> &'static str {
    match i32::try_from(signal).unwrap_or(0) {
        SIGTERM => "SIGTERM",
        SIGHUP => "SIGHUP (the terminal closed)",
        _ => "Ctrl-C",
    }
}

/// Whether a stop signal arrived since the process started (after [`interrupt_flag`]).
pub fn interrupted() -> bool {
    last_signal().load(Ordering::SeqCst) != 0
}

/// `ExitCode::SUCCESS`, or 128 + the signal's number when a stop signal ended the verb:
/// every verb that runs until stopped ends this way, so a script tells a signal from a
/// normal end.
pub fn exit_code() -> ExitCode {
    if interrupted() {
        interrupt_exit_code()
    } else {
        ExitCode::SUCCESS
    }
}

/// The exit code of a procedure stopped by a signal: 128 + its number (130 for Ctrl-C).
pub fn interrupt_exit_code() -> ExitCode {
    exit_code_of(last_signal().load(Ordering::SeqCst))
}

fn exit_code_of(signal: usize) -> ExitCode {
    let number = match i32::try_from(signal) {
        Ok(s) if STOP_SIGNALS.contains(&s) => s,
        _ => SIGINT,
    };
    ExitCode::from(128 + number as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_signal_is_named_as_what_it_is() {
        assert_eq!(name_of(SIGINT as usize), "Ctrl-C");
        assert_eq!(name_of(0), "Ctrl-C");
        assert_eq!(name_of(SIGTERM as usize), "SIGTERM");
        assert!(name_of(SIGHUP as usize).starts_with("SIGHUP"));
        assert_eq!(exit_code_of(SIGTERM as usize), ExitCode::from(143));
        assert_eq!(exit_code_of(SIGHUP as usize), ExitCode::from(129));
        assert_eq!(exit_code_of(0), ExitCode::from(130));
    }
}
