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
    fn garbage_without_delimiter_before_a_frame_costs_nothing(
        garbage in vec(1u8..=255, 1..32),
        msgs in vec((any::<u16>(), device_message()), 2..5),
    ) {
        // v1 lost the first frame here; the opening delimiter now ends the garbage.
        let mut stream = garbage;
        for (seq, msg) in &msgs {
            stream.extend(frame(*seq, msg));
        }
        let mut deframer = DeviceDeframer::new();
        let mut got = Vec::new();
        deframer.push(&stream, |r| got.push(r));
        prop_assert!(got[0].is_err());
        let ok: Vec<_> = got.into_iter().skip(1).map(Result::unwrap).collect();
        assert_same_wire(&msgs, &ok);
    }

    #[test]
    fn noise_between_frames_loses_no_frame(
        msgs in vec((any::<u16>(), device_message()), 2..8),
        noise in vec(vec(any::<u8>(), 10), 7),
        cuts in vec(any::<usize>(), 0..12),
    ) {
        // Ten random bytes (delimiters included) between every pair of frames.
        let mut stream = Vec::new();
        for (i, (seq, msg)) in msgs.iter().enumerate() {
            if i > 0 {
                stream.extend(&noise[i - 1]);
            }
            stream.extend(frame(*seq, msg));
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
        // Noise could only form a frame by beating CRC-32; every sent frame arrives.
        assert_same_wire(&msgs, &got);
        prop_assert_eq!(deframer.pending(), 0);
    }

    #[test]
    fn requests_survive_noise_between_frames(
        msgs in vec((any::<u16>(), request()), 2..8),
        noise in vec(vec(any::<u8>(), 10), 7),
    ) {
        let mut stream = Vec::new();
        for (i, (seq, msg)) in msgs.iter().enumerate() {
            if i > 0 {
                stream.extend(&noise[i - 1]);
            }
            stream.extend(frame(*seq, msg));
        }
        let mut deframer = RequestDeframer::new();
        let mut got = Vec::new();
        deframer.push(&stream, |r| {
            if let Ok(f) = r {
                got.push(f);
            }
        });
        assert_same_wire(&msgs, &got);
    }

    #[test]
    fn a_noise_byte_inside_a_frame_loses_only_that_frame(
        msgs in vec((any::<u16>(), device_message()), 2..6),
        victim in any::<usize>(),
        position in any::<usize>(),
        byte in any::<u8>(),
    ) {
        // One byte inserted anywhere between the delimiters of one frame.
        let frames: Vec<Vec<u8>> = msgs.iter().map(|(s, m)| frame(*s, m)).collect();
        let victim = victim % frames.len();
        let mut stream = Vec::new();
        for (i, f) in frames.iter().enumerate() {
            if i == victim {
                // A delimiter right after the frame's leading one or right before its
                // trailing one only adds an empty frame (skipped): the frame stays whole. So a
                // noise delimiter goes between two body bytes; any other byte anywhere inside.
                let at = if byte == FRAME_DELIMITER {
                    2 + position % (f.len() - 3)
                } else {
                    1 + position % (f.len() - 1)
                };
                stream.extend(&f[..at]);
                stream.push(byte);
                stream.extend(&f[at..]);
            } else {
                stream.extend(f);
            }
        }
        let mut deframer = DeviceDeframer::new();
        let mut got = Vec::new();
        deframer.push(&stream, |r| {
            if let Ok(f) = r {
                got.push(f);
            }
        });
        let others: Vec<_> = msgs
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != victim)
            .map(|(_, m)| m.clone())
            .collect();
        assert_same_wire(&others, &got);
        prop_assert!(deframer.stats().errors() >= 1);
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
        // frame arrive (a hit delimiter costs only its own frame: the neighbour has one too).
        let mut rest = frames.iter();
        for g in &got {
            prop_assert!(rest.any(|f| f == g), "decoded a frame that was never sent");
        }
        prop_assert!(got.len() + 1 >= frames.len());
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
    fn flags_round_trip_unknown_bits(bits in any::<u32>()) {
        let msg = DeviceMessage::reply(2, Reply::Faults {
            active: FaultFlags::from_bits_retain(bits),
            latched: FaultFlags::empty(),
        });
        let mut bytes = frame(1, &msg);
        let back: Frame<DeviceMessage> = decode_frame(&mut bytes).unwrap();
        prop_assert_eq!(back.msg, msg);
    }
}

#[test]
fn wrong_message_type_is_a_decode_error_with_seq() {
    // A device message fed to the device's request deframer: CRC fine, layout unknown.
    let big = DeviceMessage::reply(3, Reply::Parameters(RigParameters::paper()));
    let mut bytes = frame(77, &big);
    assert_eq!(
        decode_frame::<Request>(&mut bytes),
        Err(Error::Decode { seq: Some(77) })
    );
}

/// A hand-built `Reply { Info }` frame whose build and board names have the given lengths.
fn forged_info(build_len: u8, board_len: u8) -> Vec<u8> {
    // seq 7, tag Reply, request_seq 1, tag Info, protocol 3, schema hash 0xDEADBEEF
    // (varint), version 0.1.2.
    let mut body = vec![
        0x07, 0x00, 0x01, 0x00, 0x03, 0xef, 0xfd, 0xb6, 0xf5, 0x0d, 0x00, 0x01, 0x02,
    ];
    body.push(build_len);
    body.extend((0..build_len).map(|i| b'0' + i % 10));
    body.push(board_len);
    body.extend((0..board_len).map(|i| b'a' + i));
    // parameters_status Valid, reset_cause PowerOn, uptime 300 s, capabilities SIMULATION,
    // time scale 1.0 (f32 little-endian), max baud 921,600 (varint).
    body.extend([0x00, 0x00, 0xac, 0x02, 0x08]);
    body.extend(1.0f32.to_le_bytes());
    body.extend([0x80, 0xa0, 0x38]);
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&body);
    body.extend_from_slice(&crc.to_le_bytes());
    let mut encoded = vec![0; cobs_max_encoded_len(body.len())];
    let n = cobs::encode(&body, &mut encoded);
    encoded.truncate(n);
    encoded
}

#[test]
fn oversized_names_are_rejected_not_truncated() {
    let ok = decode_frame::<DeviceMessage>(&mut forged_info(20, 16)).unwrap();
    let Some(Reply::Info(info)) = ok.msg.as_reply() else {
        panic!("not an Info reply");
    };
    assert_eq!((info.firmware_build.len(), info.board.len()), (20, 16));
    assert_eq!(info.uptime_s, 300);
    assert_eq!(info.capabilities, Capabilities::SIMULATION);
    assert_eq!(info.time_scale, 1.0);
    assert_eq!(info.max_baud, 921_600);
    assert_eq!(ok.msg.reply_to(), Some(1));
    for (build, board) in [(21, 16), (20, 17)] {
        assert_eq!(
            decode_frame::<DeviceMessage>(&mut forged_info(build, board)),
            Err(Error::Decode { seq: Some(7) }),
            "build {build}, board {board}"
        );
    }
}
