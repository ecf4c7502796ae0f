//! The vendored embassy-stm32 (`patches/embassy-stm32`, used through `[patch.crates-io]`) is
//! the published 0.6.0 plus the clock-switch diff and nothing else: `patches/verify.sh`,
//! offline (see `patches/README.md`).

use std::path::Path;
use std::process::Command;

#[test]
fn vendored_embassy_stm32_is_the_published_crate_plus_the_clock_switch_diff() {
    let patches = Path::new(env!("CARGO_MANIFEST_DIR")).join("../patches");
    let out = Command::new("sh")
        .arg(patches.join("verify.sh"))
        .output()
        .expect("`sh` runs patches/verify.sh (it needs sha256sum and patch)");
    assert!(
        out.status.success(),
        "patches/verify.sh failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn the_diff_keeps_the_ahb_at_half_across_the_switch_and_waits_before_the_target() {
    let diff = include_str!("../../patches/embassy-stm32-g4-clock-switch.diff");
    let added: Vec<&str> = diff
        .lines()
        .filter(|l| l.starts_with('+') && !l.starts_with("+++"))
        .collect();
    let at = |needle: &str| {
        added
            .iter()
            .position(|l| l.contains(needle))
            .unwrap_or_else(|| panic!("the diff adds no line with `{needle}`"))
    };
    // The switch's write carries /2; the wait and the target prescaler come after it.
    let switch = at("AHBPrescaler::DIV2 } else { config.ahb_pre }");
    let wait = at("cortex_m::asm::delay(sys.0 / 1_000_000)");
    let target = at("w.set_hpre(config.ahb_pre)");
    assert!(switch < wait && wait < target, "{added:#?}");
    // The one-write switch to the target prescaler is gone.
    assert!(
        diff.lines()
            .any(|l| l == "-        w.set_hpre(config.ahb_pre);")
    );
}
