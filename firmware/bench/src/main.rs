//! Target-bench image: the firmware's control core (`firmware_core::Core`, the code the
//! firmware binary runs) in closed loop with the simulated plant (`model::plant::Plant`),
//! compiled for thumbv7em-none-eabihf with the release profile, for
//! `cargo xtask target-bench` to run in an instruction-set emulator of the Cortex-M4F.
//!
//! It plays one session as the sim's virtual rig does (`sim::SimRig`: plant at 10 kHz, the
//! core stepped at 1 kHz with the interval's ADC samples), with the binary's call pattern:
//! host bytes reach `Core::receive` in chunks of at most 64 bytes (the `host_rx` task),
//! `Core::transmit` fills a 256-byte buffer whenever the modelled UART (921,600 Bd, 8N1)
//! is free (the `host_tx` task), and a requested flash write is reported with
//! `Core::persist_result` (the `persist` task). The session: boot and current zero,
//! `Hello`, telemetry at 1 kHz, locked; release at 10 Hz (spin-up, vibrating), a 1 s
//! capture at 10 kHz recorded and uploaded while vibrating; 5 Hz; 15 Hz; the continuous
//! stream at 10 kHz for 1.5 s at 10 Hz with telemetry at 100 Hz (phase `stream`; the run
//! fails if the link made it skip a sample); lock;
//! `SetParameters` and its flash write, then again with a profile-shifted gear (its working
//! pressure angles solved under the lock). Heartbeats every 100 ms keep the release alive.
//! The plant's load is 2 N m, its noise seed fixed: the run is deterministic.
//!
//! Each call made under the firmware's core lock is wrapped by `bench_marker` calls:
//! `begin(kind, tag)`, the call, `end`, then `note(detail)`. The emulator stops at the
//! marker's entry, reads `r0` (code) and `r1` (argument), and returns for it, so the
//! marker's body never runs and only the code between the two markers is counted (the plant
//! is not). The codes are shared with `xtask/target_bench/driver.py`.
//!
//! On the host this builds as a stub that says how to run it.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "the target-bench image runs in an emulated Cortex-M4F; this host build is a stub.\n\
         run:  cargo xtask target-bench   (builds it for thumbv7em-none-eabihf and emulates it)"
    );
}

#[cfg(target_os = "none")]
mod image;
