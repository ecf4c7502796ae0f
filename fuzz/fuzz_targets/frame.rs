//! Arbitrary bytes, in arbitrary chunks, into both deframers and the one-shot decoder;
//! then the same bytes as a frame body with a valid CRC, so the message decoders see
//! arbitrary input too (random bytes almost never pass a CRC).
//! Nothing may panic, the stats must account for every result, and every frame that
//! decodes must re-encode to a frame that decodes to the same message.
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::{
    Deframer, DeviceDeframer, DeviceMessage, Frame, Request, RequestDeframer, decode_frame,
    encode_frame_vec,
};

fn check_round_trip<M>(frame: &Frame<M>)
where
    M: serde::Serialize + serde::de::DeserializeOwned + PartialEq + core::fmt::Debug,
{
    let mut bytes = encode_frame_vec(frame.seq, &frame.msg).expect("decoded frames re-encode");
    let again: Frame<M> = decode_frame(&mut bytes).expect("re-encoded frames decode");
    // Floats may be NaN, so compare the wire bytes rather than the values.
    let a = encode_frame_vec(again.seq, &again.msg).unwrap();
    let b = encode_frame_vec(frame.seq, &frame.msg).unwrap();
    assert_eq!(a, b);
}

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, bytes)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(chunk).max(1);

    let mut host = DeviceDeframer::new();
    let mut device = RequestDeframer::new();
    let mut tiny: Deframer<DeviceMessage, 5> = Deframer::new();
    let (mut host_results, mut device_results) = (0u32, 0u32);
    for part in bytes.chunks(chunk) {
        host.push(part, |r| {
            host_results += 1;
            if let Ok(f) = r {
                check_round_trip(&f);
            }
        });
        device.push(part, |r| {
            device_results += 1;
            if let Ok(f) = r {
                check_round_trip(&f);
            }
        });
        tiny.push(part, |_| {});
    }
    let (h, d) = (host.stats(), device.stats());
    assert_eq!(h.frames_ok + h.errors(), host_results);
    assert_eq!(d.frames_ok + d.errors(), device_results);

    let _ = decode_frame::<Request>(&mut bytes.to_vec());
    let _ = decode_frame::<DeviceMessage>(&mut bytes.to_vec());

    let framed = frame_with_valid_crc(bytes);
    if let Ok(f) = decode_frame::<Request>(&mut framed.clone()) {
        check_round_trip(&f);
    }
    if let Ok(f) = decode_frame::<DeviceMessage>(&mut framed.clone()) {
        check_round_trip(&f);
    }
});

/// `body` as the wire would carry it: CRC appended, COBS encoded.
fn frame_with_valid_crc(body: &[u8]) -> Vec<u8> {
    let mut raw = body.to_vec();
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(body);
    raw.extend_from_slice(&crc.to_le_bytes());
    let mut out = vec![0; protocol::cobs_max_encoded_len(raw.len())];
    let len = cobs::encode(&raw, &mut out);
    out.truncate(len);
    out
}
