//! Rig files (`rigfile::RigFile::parse`): arbitrary text. Parsing may never panic, and a
//! file it accepts must be written back (`to_toml`) as text it accepts again, unchanged:
//! a file written by one verb is read by every other.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rigfile::RigFile;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(rig) = RigFile::parse(text, "fuzz.toml") else {
        return;
    };
    let written = rig.to_toml().expect("an accepted rig file can be written");
    let again = RigFile::parse(&written, "fuzz.toml").expect("a written rig file reads back");
    assert_eq!(
        again.to_toml().expect("and writes again"),
        written,
        "the rig file changed on a round trip"
    );
});
