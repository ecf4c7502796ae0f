//! The texts that tell a user how to get a debug probe working: what `rig` searched, what
//! to check, the Linux udev rules, and how to get a `rig` that can flash.

/// What `rig flash` and `rig log` look for.
pub const SEARCHED: &str = "USB debug probes: ST-LINK V2, V2-1 and V3 (the Nucleo's on-board \
probe is one), CMSIS-DAP v2 (DAPLink, Raspberry Pi Debug Probe), SEGGER J-Link, FTDI-based \
JTAG probes, ESP32 USB-JTAG, WCH-Link and Black Magic Probe";

/// udev rules for Linux: access to ST-LINK and CMSIS-DAP probes for the logged-in user.
pub const UDEV_RULES: &str = r#"# /etc/udev/rules.d/69-probe-rs.rules: debug probes for rig flash / rig log
# ST-LINK V2
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="3748", MODE="660", GROUP="plugdev", TAG+="uaccess"
# ST-LINK V2-1 (Nucleo-64 boards)
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="374b", MODE="660", GROUP="plugdev", TAG+="uaccess"
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="3752", MODE="660", GROUP="plugdev", TAG+="uaccess"
# ST-LINK V3 (newer Nucleo boards, STLINK-V3SET/MINI)
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="374d", MODE="660", GROUP="plugdev", TAG+="uaccess"
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="374e", MODE="660", GROUP="plugdev", TAG+="uaccess"
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="374f", MODE="660", GROUP="plugdev", TAG+="uaccess"
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="3753", MODE="660", GROUP="plugdev", TAG+="uaccess"
SUBSYSTEM=="usb", ATTRS{idVendor}=="0483", ATTRS{idProduct}=="3754", MODE="660", GROUP="plugdev", TAG+="uaccess"
# CMSIS-DAP probes of any vendor (DAPLink, Raspberry Pi Debug Probe, ...)
ATTRS{product}=="*CMSIS-DAP*", MODE="660", GROUP="plugdev", TAG+="uaccess"
# SEGGER J-Link
SUBSYSTEM=="usb", ATTRS{idVendor}=="1366", MODE="660", GROUP="plugdev", TAG+="uaccess"
"#;

/// How to install [`UDEV_RULES`].
pub const UDEV_INSTALL: &str = "rig flash --udev-rules | sudo tee /etc/udev/rules.d/69-probe-rs.rules\n    \
sudo udevadm control --reload\n    sudo udevadm trigger\n    then unplug and replug the probe";

/// What to check when no probe was found.
pub fn no_probe(found: &[String]) -> String {
    let found = if found.is_empty() {
        "none".to_owned()
    } else {
        found.join(", ")
    };
    format!(
        "no debug probe found.\n  searched: {SEARCHED}\n  found: {found}\n  check:\n  \
         - the USB cable goes to the Nucleo's ST-LINK USB port (the connector on the ST-LINK part of the board) and carries data (not a charge-only cable)\n  \
         - the board is powered (the ST-LINK's COM LED and the power LED are lit)\n  \
         - the ST-LINK jumpers connect it to the on-board target (their default position)\n  \
         - `lsusb` lists the probe (ST-LINK: 0483:3748, 0483:374b, 0483:374e, 0483:374f, 0483:3752, 0483:3753 or 0483:3754)\n  \
         - on Linux, udev rules let your user open it; install them with\n    {UDEV_INSTALL}"
    )
}

/// A probe the user may not open.
pub fn permission_denied(probe: &str) -> String {
    format!(
        "the debug probe {probe} is plugged in but this user may not open it (permission denied).\n  \
         Install the udev rules and replug the probe:\n    {UDEV_INSTALL}\n  \
         (or add yourself to the plugdev group: sudo usermod -aG plugdev $USER, then log in again)"
    )
}

/// How to get a `rig` that can flash.
pub const FEATURE_MISSING: &str = "this rig was built without the `probe` feature, so it cannot talk to a debug probe: \
install it with the default features (`cargo install --path host --locked` from the workspace) or build it with \
`cargo build -p host --release --features probe`";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_no_probe_text_says_what_was_searched_found_and_to_check() {
        let t = no_probe(&[]);
        assert!(t.contains("ST-LINK") && t.contains("CMSIS-DAP") && t.contains("J-Link"));
        assert!(t.contains("found: none"));
        assert!(t.contains("udevadm control --reload"));
        assert!(t.contains("cable"));
        for pid in ["3748", "374b", "374e", "374f", "3752", "3753", "3754"] {
            assert!(UDEV_RULES.contains(pid), "{pid}");
        }
        assert!(UDEV_RULES.contains("CMSIS-DAP"));
        assert!(permission_denied("ST-LINK V3").contains("permission denied"));
    }
}
