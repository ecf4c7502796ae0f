//! CRC-32/ISO-HDLC (the frame trailer's and the firmware's calibration record's checksum).
//!
//! Parameters: polynomial 0x04C11DB7 reflected (0xEDB88320), init and final XOR 0xFFFFFFFF,
//! input and output reflected; check value `0xCBF43926` over `"123456789"`.
//!
//! On the firmware target ([`checksum`] with `target_os = "none"`) the CRC runs from a
//! 16-entry (64-byte) nibble table instead of the `crc` crate's 1 KiB byte table: the
//! firmware's flash budget is 48 KiB, and two lookups per byte cost a few cycles more.
//! The host keeps the `crc` crate's byte table. Both give the same value for every input
//! (tested below); the wire format does not depend on which one ran.

/// The reflected CRC-32 polynomial.
const POLY_REFLECTED: u32 = 0xEDB8_8320;

/// CRC of every 4-bit value: the nibble-at-a-time table.
const NIBBLE_TABLE: [u32; 16] = nibble_table();

/// Builds [`NIBBLE_TABLE`] at compile time.
const fn nibble_table() -> [u32; 16] {
    let mut table = [0u32; 16];
    let mut i: u32 = 0;
    while i < 16 {
        let mut crc = i;
        let mut bit = 0;
        while bit < 4 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ POLY_REFLECTED
            } else {
                crc >> 1
            };
            bit += 1;
        }
        table[i as usize] = crc;
        i += 1;
    }
    table
}

/// CRC-32/ISO-HDLC of `bytes`, a nibble (4 bits) at a time from a 16-entry table.
pub fn checksum_nibble(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        crc = (crc >> 4) ^ NIBBLE_TABLE[(crc & 0xF) as usize];
        crc = (crc >> 4) ^ NIBBLE_TABLE[(crc & 0xF) as usize];
    }
    !crc
}

/// CRC-32/ISO-HDLC of `bytes`: [`checksum_nibble`] on the firmware target, the `crc`
/// crate's byte table on the host (the same value either way).
pub fn checksum(bytes: &[u8]) -> u32 {
    #[cfg(target_os = "none")]
    {
        checksum_nibble(bytes)
    }
    #[cfg(not(target_os = "none"))]
    {
        static CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        CRC32.checksum(bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn check_value() {
        assert_eq!(checksum_nibble(b"123456789"), 0xCBF4_3926);
        assert_eq!(checksum(b"123456789"), 0xCBF4_3926);
        assert_eq!(checksum_nibble(b""), 0);
    }

    proptest! {
        #[test]
        fn nibble_table_matches_the_crc_crate(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let reference = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&bytes);
            prop_assert_eq!(checksum_nibble(&bytes), reference);
            prop_assert_eq!(checksum(&bytes), reference);
        }
    }
}
