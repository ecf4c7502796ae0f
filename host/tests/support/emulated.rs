//! Whether the tests of the firmware image on the emulated board can run here.
#![allow(dead_code)]

/// Whether the release image and the emulator are here (else the test skips, saying why;
/// `cargo xtask test` sets RIG_REQUIRE_EMULATOR, which makes their absence a failure).
pub fn ready() -> bool {
    match host::virtual_device::emulated_board_ready() {
        Ok(_) => true,
        Err(why) if std::env::var_os("RIG_REQUIRE_EMULATOR").is_some() => panic!("{why}"),
        Err(why) => {
            eprintln!("skipped: {why}");
            false
        }
    }
}
