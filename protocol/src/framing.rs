//! Frame encoding and single-frame decoding.
//!
//! ```text
//! frame = 0x00 ++ COBS(body ++ CRC-32/ISO-HDLC(body) as 4 bytes LE) ++ 0x00
//! body  = postcard(seq: u16, msg)
//! ```
//!
//! The delimiter both opens and closes every frame, so a stray byte on the line between
//! two frames is cut off by the next frame's opening delimiter instead of corrupting it.
//!
//! Encoding needs no scratch buffer beyond the output and does bounded, byte-linear work
//! (it runs under the firmware's core lock): postcard writes the body into the back of the
//! output, the CRC is appended, and COBS then encodes that in place, front to back, into
//! the output's start (see [`encode_frame`]).

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::Error;

/// A message with the sender's frame sequence number (wraps at `u16::MAX`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct Frame<M> {
    /// The sender's frame counter. Each side numbers its own frames; a reply names the
    /// request it answers by that request's `seq` ([`crate::DeviceMessage::reply_to`]).
    pub seq: u16,
    /// The message.
    pub msg: M,
}

/// Byte that opens and closes every frame (COBS guarantees it appears nowhere else).
pub const FRAME_DELIMITER: u8 = 0x00;

/// Delimiters per frame: one before, one after.
pub const FRAME_DELIMITERS: usize = 2;

/// Length of the CRC-32 trailer, bytes.
pub const CRC_LEN: usize = 4;

/// Longest run of non-zero bytes one COBS block carries.
const COBS_BLOCK: usize = 254;

/// Encodes `msg` with sequence number `seq` into `out` and returns the frame, both
/// delimiters included. An `out` of [`crate::MAX_FRAME_SIZE`] bytes always suffices for
/// [`crate::Request`] and [`crate::DeviceMessage`].
///
/// The body (postcard of `(seq, msg)`) and its CRC are written at offset
/// `2 + out.len() / 254` and COBS-encoded in place into `out[1..]`: the encoder writes at
/// most one byte ahead of what it reads per 254-byte block, so that head start keeps the
/// write position behind the read position. Nothing is zeroed, nothing copied twice.
pub fn encode_frame<'o, M: Serialize + ?Sized>(
    seq: u16,
    msg: &M,
    out: &'o mut [u8],
) -> Result<&'o [u8], Error> {
    let start = 2 + out.len() / COBS_BLOCK;
    let raw = out.get_mut(start..).ok_or(Error::BufferTooSmall)?;
    let body = postcard::to_slice(&(seq, msg), raw)
        .map_err(|e| match e {
            postcard::Error::SerializeBufferFull => Error::BufferTooSmall,
            _ => Error::Serialize,
        })?
        .len();
    seal_frame(out, start, body)
}

/// The part of [`encode_frame`] that does not depend on the message type (one copy in a
/// firmware image however many message types it sends): appends the CRC to the body at
/// `out[start..start + body]`, COBS-encodes it in place and adds the delimiters.
fn seal_frame(out: &mut [u8], start: usize, body: usize) -> Result<&[u8], Error> {
    let raw = &mut out[start..];
    let crc = crate::crc32::checksum(&raw[..body]).to_le_bytes();
    raw.get_mut(body..body + CRC_LEN)
        .ok_or(Error::BufferTooSmall)?
        .copy_from_slice(&crc);
    let len = cobs_encode_in_place(out, start, body + CRC_LEN);
    out[0] = FRAME_DELIMITER;
    *out.get_mut(len + 1).ok_or(Error::BufferTooSmall)? = FRAME_DELIMITER;
    Ok(&out[..len + FRAME_DELIMITERS])
}

/// COBS-encodes `buf[src..src + len]` into `buf[1..]` (byte for byte what `cobs::encode`
/// writes: a full 254-byte block at the end gets no empty block after it) and returns the
/// encoded length. Needs `src >= 2 + len / 254`, which keeps every write at or behind the
/// byte just read.
fn cobs_encode_in_place(buf: &mut [u8], src: usize, len: usize) -> usize {
    debug_assert!(src >= 2 + len / COBS_BLOCK);
    let mut code_at = 1;
    let mut w = 2;
    let mut code: u8 = 1;
    for r in src..src + len {
        if code == 0xFF {
            buf[code_at] = code;
            code_at = w;
            w += 1;
            code = 1;
        }
        let b = buf[r];
        if b == 0 {
            buf[code_at] = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            buf[w] = b;
            w += 1;
            code += 1;
        }
    }
    buf[code_at] = code;
    w - 1
}

/// Encodes a frame into a new `Vec` of exactly the frame's length (host side).
#[cfg(any(test, feature = "std"))]
pub fn encode_frame_vec<M: Serialize + ?Sized>(seq: u16, msg: &M) -> Result<Vec<u8>, Error> {
    let size = postcard::ser_flavors::Size::default();
    let body = postcard::serialize_with_flavor(&(seq, msg), size).map_err(|_| Error::Serialize)?;
    let mut out = vec![0; crate::cobs_max_encoded_len(body + CRC_LEN) + FRAME_DELIMITERS];
    let len = encode_frame(seq, msg, &mut out)?.len();
    out.truncate(len);
    Ok(out)
}

/// Decodes one frame (with or without its delimiters), in place: `frame` is overwritten
/// with the COBS-decoded bytes.
pub fn decode_frame<M: DeserializeOwned>(frame: &mut [u8]) -> Result<Frame<M>, Error> {
    decode_body(frame_body(frame)?)
}

/// Checks one frame (with or without its delimiters) and returns its body, `seq` and
/// message still postcard-encoded, CRC removed. Decodes in place: `frame` is overwritten
/// with the COBS-decoded bytes.
pub fn frame_body(frame: &mut [u8]) -> Result<&[u8], Error> {
    let start = usize::from(frame.first() == Some(&FRAME_DELIMITER));
    let end =
        frame.len() - usize::from(frame.len() > start && frame.last() == Some(&FRAME_DELIMITER));
    let frame = &mut frame[start..end];
    if frame.is_empty() || frame.contains(&FRAME_DELIMITER) {
        return Err(Error::Framing);
    }
    let len = cobs_decode_in_place(frame).ok_or(Error::Framing)?;
    let decoded = frame.get(..len).ok_or(Error::Framing)?;
    let Some(body_len) = len.checked_sub(CRC_LEN).filter(|&n| n > 0) else {
        return Err(Error::Framing);
    };
    let (body, crc) = decoded.split_at(body_len);
    let crc = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if crate::crc32::checksum(body) != crc {
        return Err(Error::Crc);
    }
    Ok(body)
}

/// COBS-decodes `buf` (no delimiters in it) in place, block by block (one tight copy loop
/// per block rather than a state machine per byte: receive runs under the firmware's core
/// lock); the decoded length, or `None` when a block runs past the end or is empty.
fn cobs_decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let (mut r, mut w) = (0, 0);
    while r < buf.len() {
        let code = usize::from(buf[r]);
        let end = r + code;
        if code == 0 || end > buf.len() {
            return None;
        }
        // Forward byte copy (`w <= r`: the write never overtakes the read) instead of
        // `copy_within`, whose `memmove` is 1.5 KB of the firmware's flash.
        for i in r + 1..end {
            buf[w + i - (r + 1)] = buf[i];
        }
        w += code - 1;
        r = end;
        if code != 0xFF && r < buf.len() {
            buf[w] = 0;
            w += 1;
        }
    }
    Some(w)
}

/// Decodes a CRC-checked body (from [`frame_body`]) into a frame of `M`.
pub fn decode_body<M: DeserializeOwned>(body: &[u8]) -> Result<Frame<M>, Error> {
    let (seq, rest) =
        postcard::take_from_bytes::<u16>(body).map_err(|_| Error::Decode { seq: None })?;
    let bad = Error::Decode { seq: Some(seq) };
    match postcard::take_from_bytes::<M>(rest) {
        // Trailing bytes mean the peer's layout differs: refuse rather than guess.
        Ok((msg, [])) => Ok(Frame { seq, msg }),
        _ => Err(bad),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{DeviceMessage, MAX_FRAME_SIZE, Request};

    /// The frame built step by step with one-shot calls, to check the streaming path.
    fn reference_frame(body: &[u8]) -> Vec<u8> {
        let mut raw = body.to_vec();
        raw.extend_from_slice(&crate::crc32::checksum(body).to_le_bytes());
        let mut out = vec![0; crate::cobs_max_encoded_len(raw.len())];
        let len = cobs::encode(&raw, &mut out);
        out.truncate(len);
        out
    }

    fn body<T: Serialize>(value: &T) -> Vec<u8> {
        let mut buf = [0u8; 512];
        postcard::to_slice(value, &mut buf).unwrap().to_vec()
    }

    #[test]
    fn crc_is_iso_hdlc() {
        // The catalogue's check value: the CRC of "123456789".
        assert_eq!(crate::crc32::checksum(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn round_trip_and_delimiter() {
        let mut buf = [0u8; MAX_FRAME_SIZE];
        let frame = encode_frame(7, &Request::Heartbeat { session: 9 }, &mut buf).unwrap();
        assert_eq!(frame.first(), Some(&FRAME_DELIMITER));
        assert_eq!(frame.last(), Some(&FRAME_DELIMITER));
        assert!(!frame[1..frame.len() - 1].contains(&0));
        let mut copy = frame.to_vec();
        let decoded: Frame<Request> = decode_frame(&mut copy).unwrap();
        assert_eq!(
            decoded,
            Frame {
                seq: 7,
                msg: Request::Heartbeat { session: 9 }
            }
        );
    }

    #[test]
    fn small_buffer_is_an_error_not_a_panic() {
        let msg = DeviceMessage::reply(1, crate::Reply::Parameters(crate::RigParameters::paper()));
        let full = encode_frame_vec(1, &msg).unwrap();
        for len in 0..full.len() {
            let mut buf = vec![0u8; len];
            assert_eq!(
                encode_frame(1, &msg, &mut buf),
                Err(Error::BufferTooSmall),
                "len {len}"
            );
        }
        let mut buf = vec![0u8; full.len()];
        assert_eq!(encode_frame(1, &msg, &mut buf).unwrap(), &full[..]);
    }

    #[test]
    fn streaming_encoder_matches_one_shot_cobs() {
        let msg = Request::SetParameters(crate::RigParameters::paper());
        let frame = encode_frame_vec(513, &msg).unwrap();
        let mut expected = vec![0];
        expected.extend(reference_frame(&body(&(513u16, &msg))));
        expected.push(0);
        assert_eq!(frame, expected);
    }

    #[test]
    fn in_place_cobs_matches_the_cobs_crate() {
        // Long non-zero runs (full blocks, a block ending the data) and zeros anywhere.
        let mut cases: Vec<Vec<u8>> = vec![vec![], vec![0], vec![1], vec![0, 0]];
        for n in [253, 254, 255, 300, 507, 508, 509, 600] {
            cases.push((0..n).map(|k| u8::try_from(k % 255 + 1).unwrap()).collect());
            let mut v: Vec<u8> = (0..n).map(|k| u8::try_from(k % 255 + 1).unwrap()).collect();
            v[n / 2] = 0;
            cases.push(v.clone());
            v.push(0);
            cases.push(v);
        }
        for data in cases {
            let mut want = vec![0; crate::cobs_max_encoded_len(data.len())];
            let want_len = cobs::encode(&data, &mut want);
            want.truncate(want_len);
            let start = 2 + data.len() / COBS_BLOCK;
            let mut buf = vec![0xAA; start + data.len()];
            buf[start..].copy_from_slice(&data);
            let len = cobs_encode_in_place(&mut buf, start, data.len());
            assert_eq!(&buf[1..1 + len], &want[..], "{} bytes", data.len());
        }
    }

    #[test]
    fn in_place_decode_matches_the_cobs_crate() {
        for n in [0usize, 1, 2, 100, 253, 254, 255, 300, 508, 509] {
            for zero_every in [0usize, 1, 3, 97, 254] {
                let data: Vec<u8> = (0..n)
                    .map(|k| {
                        if zero_every > 0 && k % zero_every == 0 {
                            0
                        } else {
                            u8::try_from(k % 255 + 1).unwrap()
                        }
                    })
                    .collect();
                let mut enc = vec![0; crate::cobs_max_encoded_len(n)];
                let len = cobs::encode(&data, &mut enc);
                enc.truncate(len);
                let got = cobs_decode_in_place(&mut enc).expect("valid COBS");
                assert_eq!(&enc[..got], &data[..], "{n} bytes, zero every {zero_every}");
            }
        }
        assert_eq!(
            cobs_decode_in_place(&mut [3, 1]),
            None,
            "block past the end"
        );
        assert_eq!(cobs_decode_in_place(&mut [1, 0]), None, "a zero code");
        assert_eq!(cobs_decode_in_place(&mut []), Some(0));
    }

    proptest::proptest! {
        #[test]
        fn frames_round_trip_through_any_buffer(
            seq: u16,
            text in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..120),
            extra in 0usize..40,
        ) {
            // A capture chunk carries arbitrary bytes through the varints.
            let samples = text
                .chunks(2)
                .map(|c| crate::CaptureSample {
                    current_adc: u16::from(c[0]) << 4,
                    encoder_count: i32::from(*c.last().unwrap_or(&0)) * 1000 - 9,
                    output_count: (c[0] % 2 == 0).then(|| i32::from(c[0]) * -77),
                })
                .take(crate::CAPTURE_CHUNK_SAMPLES)
                .collect();
            let msg = DeviceMessage::CaptureChunk(crate::CaptureChunk {
                capture_id: seq,
                first_sample: 7,
                total_samples: 1_000_000,
                samples,
            });
            let mut expected = vec![0];
            expected.extend(reference_frame(&body(&(seq, &msg))));
            expected.push(0);
            let mut buf = vec![0x55; expected.len() + extra];
            let frame = encode_frame(seq, &msg, &mut buf).unwrap();
            proptest::prop_assert_eq!(frame, &expected[..]);
            let mut short = vec![0x55; expected.len() - 1];
            proptest::prop_assert_eq!(encode_frame(seq, &msg, &mut short), Err(Error::BufferTooSmall));
        }
    }

    #[test]
    fn frames_decode_with_or_without_delimiters() {
        let frame = encode_frame_vec(9, &Request::GetInfo).unwrap();
        let n = frame.len();
        for part in [&frame[..], &frame[1..], &frame[..n - 1], &frame[1..n - 1]] {
            let decoded: Frame<Request> = decode_frame(&mut part.to_vec()).unwrap();
            assert_eq!(
                decoded,
                Frame {
                    seq: 9,
                    msg: Request::GetInfo
                }
            );
        }
        // The body is the postcard encoding of (seq, msg).
        assert_eq!(
            frame_body(&mut frame.clone()).unwrap(),
            &body(&(9u16, Request::GetInfo))[..]
        );
        assert_eq!(frame_body(&mut [0, 0]), Err(Error::Framing));
    }

    #[test]
    fn decode_rejects_short_and_trailing() {
        assert_eq!(decode_frame::<Request>(&mut []), Err(Error::Framing));
        assert_eq!(decode_frame::<Request>(&mut [0]), Err(Error::Framing));
        assert_eq!(decode_frame::<Request>(&mut [1]), Err(Error::Framing));
        assert_eq!(decode_frame::<Request>(&mut [1, 0, 1]), Err(Error::Framing));
        // A valid CRC over a body with an extra byte after the message.
        let mut long = body(&(3u16, Request::GetInfo));
        long.push(0x42);
        let mut frame = reference_frame(&long);
        assert_eq!(
            decode_frame::<Request>(&mut frame),
            Err(Error::Decode { seq: Some(3) })
        );
    }
}
