//! Property tests: every message survives encode -> deframe, whatever the chunking and
//! whatever garbage precedes it.
#![allow(missing_docs)]

mod common;

use common::*;
use proptest::collection::vec;
use proptest::prelude::*;
use protocol::*;

/// Decoded frames re-encode to identical bytes (compares floats bit-exactly, NaN too).
fn assert_same_wire<M: serde::Serialize>(sent: &[(u16, M)], got: &[Frame<M>]) {
    assert_eq!(sent.len(), got.len());
    for ((seq, msg), decoded) in sent.iter().zip(got) {
        assert_eq!(frame(*seq, msg), frame_bytes(decoded));
    }
}

fn frame_bytes<M: serde::Serialize>(f: &Frame<M>) -> Vec<u8> {
    frame(f.seq, &f.msg)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn device_messages_survive_any_chunking(
        msgs in vec((any::<u16>(), device_message()), 1..8),
        cuts in vec(any::<usize>(), 0..12),
        garbage in vec(any::<u8>(), 0..64),
    ) {
        let mut stream = garbage.clone();
        stream.push(FRAME_DELIMITER);
        for (seq, msg) in &msgs {
            let bytes = frame(*seq, msg);
            prop_assert!(bytes.len() <= MAX_DEVICE_FRAME_SIZE);
            stream.extend(bytes);
        }
        let mut deframer = DeviceDeframer::new();
        let mut got = Vec::new();
        for part in split(&stream, &cuts) {
            deframer.push(part, |r| {
                if let Ok(f) = r {
                    got.push(f);
                }
            });
        }
        // Garbage could only form a frame by beating CRC-32; the sent frames all arrive.
        prop_assert_eq!(deframer.stats().frames_ok as usize, msgs.len());
        assert_same_wire(&msgs, &got);
        prop_assert_eq!(deframer.pending(), 0);
    }

    #[test]
    fn requests_survive_any_chunking(
        msgs in vec((any::<u16>(), request()), 1..8),
        cuts in vec(any::<usize>(), 0..12),
    ) {
        let stream: Vec<u8> = msgs.iter().flat_map(|(seq, m)| frame(*seq, m)).collect();
        let mut deframer = RequestDeframer::new();
        let mut got = Vec::new();
        for part in split(&stream, &cuts) {
            deframer.push(part, |r| got.push(r.unwrap()));
        }
        assert_same_wire(&msgs, &got);
        prop_assert_eq!(deframer.stats().errors(), 0);
    }

    #[test]
    fn garbage_without_delimiter_costs_only_the_first_frame(
        garbage in vec(1u8..=255, 1..32),
        msgs in vec((any::<u16>(), device_message()), 2..5),
    ) {
        let mut stream = garbage;
        for (seq, msg) in &msgs {
            stream.extend(frame(*seq, msg));
        }
        let mut deframer = DeviceDeframer::new();
        let mut got = Vec::new();
        deframer.push(&stream, |r| got.push(r));
        prop_assert!(got[0].is_err());
        let ok: Vec<_> = got.into_iter().skip(1).map(Result::unwrap).collect();
        assert_same_wire(&msgs[1..], &ok);
    }

    #[test]
    fn corrupted_byte_never_yields_a_wrong_message(
        msgs in vec((any::<u16>(), device_message()), 2..5),
        position in any::<usize>(),
        xor in 1u8..=255,
    ) {
        let frames: Vec<Vec<u8>> = msgs.iter().map(|(s, m)| frame(*s, m)).collect();
        let mut stream = frames.concat();
        let hit = position % stream.len();
        stream[hit] ^= xor;
        let mut deframer = DeviceDeframer::new();
        let mut got = Vec::new();
        deframer.push(&stream, |r| {
            if let Ok(f) = r {
                got.push(frame_bytes(&f));
            }
        });
        // Every decoded frame is one of the sent ones, in order, and all but the hit
        // frame (and, when the delimiter itself was hit, its neighbour) arrive.
        let mut rest = frames.iter();
        for g in &got {
            prop_assert!(rest.any(|f| f == g), "decoded a frame that was never sent");
        }
        prop_assert!(got.len() + 2 >= frames.len());
        // A hit on the very last delimiter leaves that frame pending instead of failed.
        prop_assert!(deframer.stats().errors() >= 1 || deframer.pending() > 0);
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in vec(any::<u8>(), 0..1024), cuts in vec(any::<usize>(), 0..8)) {
        let mut host = DeviceDeframer::new();
        let mut device = RequestDeframer::new();
        let mut small: Deframer<DeviceMessage, 8> = Deframer::new();
        let mut results = 0u32;
        for part in split(&bytes, &cuts) {
            host.push(part, |_| results += 1);
            device.push(part, |_| {});
            small.push(part, |_| {});
        }
        let s = host.stats();
        prop_assert_eq!(s.frames_ok + s.errors(), results);
        let mut copy = bytes.clone();
        let _ = decode_frame::<Request>(&mut copy);
    }

    #[test]
    fn flags_round_trip_unknown_bits(bits in any::<u16>()) {
        let msg = DeviceMessage::Faults {
            active: FaultFlags::from_bits_retain(bits),
            latched: FaultFlags::empty(),
        };
        let mut bytes = frame(1, &msg);
        let back: Frame<DeviceMessage> = decode_frame(&mut bytes).unwrap();
        prop_assert_eq!(back.msg, msg);
    }
}

#[test]
fn wrong_message_type_is_a_decode_error_with_seq() {
    // A device message fed to the device's request deframer: CRC fine, layout unknown.
    let big = DeviceMessage::Calibration(Calibration::paper());
    let mut bytes = frame(77, &big);
    assert_eq!(
        decode_frame::<Request>(&mut bytes),
        Err(Error::Decode { seq: Some(77) })
    );
}

/// A hand-built `Info` frame whose board name has `len` bytes.
fn forged_info(len: u8) -> Vec<u8> {
    // seq 7, tag Info, version 0.1.2, protocol 1, schema hash 0xDEADBEEF (varint).
    let mut body = vec![
        0x07, 0x00, 0x00, 0x01, 0x02, 0x01, 0xef, 0xfd, 0xb6, 0xf5, 0x0d, len,
    ];
    body.extend((0..len).map(|i| b'a' + i));
    body.push(0x00); // calibration_status: Valid
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&body);
    body.extend_from_slice(&crc.to_le_bytes());
    let mut encoded = vec![0; cobs_max_encoded_len(body.len())];
    let n = cobs::encode(&body, &mut encoded);
    encoded.truncate(n);
    encoded
}

#[test]
fn oversized_board_name_is_rejected_not_truncated() {
    let ok = decode_frame::<DeviceMessage>(&mut forged_info(16)).unwrap();
    assert!(
        matches!(ok.msg, DeviceMessage::Info(DeviceInfo { ref board, .. }) if board.len() == 16)
    );
    assert_eq!(
        decode_frame::<DeviceMessage>(&mut forged_info(17)),
        Err(Error::Decode { seq: Some(7) })
    );
}
