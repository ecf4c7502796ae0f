//! Build script of the target-bench image: hands the board's `memory.x` to the linker.
//!
//! cortex-m-rt's `link.x` does `INCLUDE memory.x`, so the workspace's `memory.x` is copied
//! into `OUT_DIR` and that directory is put on the link search path, as for the firmware.
//! The workspace's thumb rustflags also pass `-Tdefmt.x` (the firmware's logger); the bench
//! image has no logger, so an empty `defmt.x` stands in for it. Host builds (the stub
//! binary) skip all of this.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest_dir =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let memory_x = manifest_dir.join("../../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={}", memory_x.display());

    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }

    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy(&memory_x, out_dir.join("memory.x"))
        .unwrap_or_else(|e| panic!("cannot copy {} into OUT_DIR: {e}", memory_x.display()));
    fs::write(
        out_dir.join("defmt.x"),
        "/* empty: the target-bench image has no defmt logger */\n",
    )
    .unwrap_or_else(|e| panic!("cannot write defmt.x into OUT_DIR: {e}"));
    println!("cargo:rustc-link-search={}", out_dir.display());
}
