//! The schema identity: a hash of the golden wire bytes, so host and device detect a
//! layout mismatch at `Hello` even when the version number was not bumped.
//!
//! `golden/wire.snap` holds the exact frame of one example of every message variant (every
//! request, reply, refusal code and simulation command), the encoding of every variant of
//! the enums inside messages, every named flag bit, and [`crate::PROTOCOL_VERSION`]. The
//! golden test (`src/golden/`) fails when the code encodes anything differently, until the
//! file is regenerated with `UPDATE_GOLDEN=1 cargo test -p protocol`; regenerating changes
//! [`SCHEMA_HASH`], which is computed from the file at compile time. So the hash cannot
//! drift from the types.

/// The golden wire snapshot (`golden/wire.snap`), one `name: hex bytes` line per example.
pub const WIRE_SNAPSHOT: &str = include_str!("../golden/wire.snap");

/// 32-bit FNV-1a hash of `bytes`, usable in constants.
pub const fn fnv1a_32(bytes: &[u8]) -> u32 {
    fnv1a_32_skipping(bytes, None)
}

/// FNV-1a of `bytes` without the bytes equal to `skip`.
const fn fnv1a_32_skipping(bytes: &[u8], skip: Option<u8>) -> u32 {
    let mut hash: u32 = 0x811C_9DC5;
    let mut i = 0;
    while i < bytes.len() {
        let byte = bytes[i];
        let skipped = match skip {
            Some(s) => s == byte,
            None => false,
        };
        if !skipped {
            hash ^= byte as u32;
            hash = hash.wrapping_mul(0x0100_0193);
        }
        i += 1;
    }
    hash
}

/// FNV-1a hash of the snapshot text with carriage returns skipped (a checkout with CRLF
/// line ends gives the same hash); exchanged in `Hello` and `Info`.
pub const SCHEMA_HASH: u32 = fnv1a_32_skipping(WIRE_SNAPSHOT.as_bytes(), Some(b'\r'));

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv_reference_values() {
        assert_eq!(fnv1a_32(b""), 0x811C_9DC5);
        assert_eq!(fnv1a_32(b"a"), 0xE40C_292C);
        assert_eq!(fnv1a_32(b"foobar"), 0xBF9C_F968);
    }

    #[test]
    fn hash_is_the_snapshots_and_ignores_line_ends() {
        assert_eq!(
            SCHEMA_HASH,
            fnv1a_32(WIRE_SNAPSHOT.replace('\r', "").as_bytes())
        );
        let crlf = WIRE_SNAPSHOT.replace('\r', "").replace('\n', "\r\n");
        assert_eq!(fnv1a_32_skipping(crlf.as_bytes(), Some(b'\r')), SCHEMA_HASH);
        // Any change to the snapshot changes the hash.
        let edited = WIRE_SNAPSHOT.replacen("00", "01", 1);
        assert_ne!(fnv1a_32(edited.as_bytes()), SCHEMA_HASH);
        // Protocol v1's hash (of its schema text) is not this version's.
        assert_ne!(SCHEMA_HASH, 0xBCD3_DE6D);
        // Pinned so a bump is deliberate; the snapshot records it, so the hash moves too.
        assert_eq!(crate::PROTOCOL_VERSION, 8);
        assert!(WIRE_SNAPSHOT.contains("\nprotocol_version: 8\n"));
    }
}
