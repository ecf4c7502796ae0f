//! Frame encoding and single-frame decoding.
//!
//! ```text
//! frame = 0x00 ++ COBS(body ++ CRC-32/ISO-HDLC(body) as 4 bytes LE) ++ 0x00
//! body  = postcard(seq: u16, msg)
//! ```
//!
//! The delimiter both opens and closes every frame, so a stray byte on the line between
//! two frames is cut off by the next frame's opening delimiter instead of corrupting it.
//! Postcard streams the body through a CRC digest into a COBS encoder, so encoding needs
//! no scratch buffer beyond the output.

use cobs::CobsEncoder;
use crc::{CRC_32_ISO_HDLC, Crc, Digest};
use postcard::ser_flavors::Flavor;
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

static CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Postcard flavor: CRC over the body, COBS into the output slice.
struct CobsCrc<'a> {
    cobs: CobsEncoder<'a>,
    crc: Digest<'static, u32>,
}

impl Flavor for CobsCrc<'_> {
    type Output = usize;

    fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
        self.try_extend(&[byte])
    }

    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        self.crc.update(bytes);
        self.cobs
            .push(bytes)
            .map_err(|_| postcard::Error::SerializeBufferFull)
    }

    fn finalize(mut self) -> postcard::Result<usize> {
        let crc = self.crc.finalize().to_le_bytes();
        self.cobs
            .push(&crc)
            .map_err(|_| postcard::Error::SerializeBufferFull)?;
        Ok(self.cobs.finalize())
    }
}

/// Encodes `msg` with sequence number `seq` into `out` and returns the frame, both
/// delimiters included. An `out` of [`crate::MAX_FRAME_SIZE`] bytes always suffices for
/// [`crate::Request`] and [`crate::DeviceMessage`].
pub fn encode_frame<'o, M: Serialize + ?Sized>(
    seq: u16,
    msg: &M,
    out: &'o mut [u8],
) -> Result<&'o [u8], Error> {
    let (first, rest) = out.split_first_mut().ok_or(Error::BufferTooSmall)?;
    *first = FRAME_DELIMITER;
    let flavor = CobsCrc {
        cobs: CobsEncoder::new(&mut *rest),
        crc: CRC32.digest(),
    };
    let len = postcard::serialize_with_flavor(&(seq, msg), flavor).map_err(|e| match e {
        postcard::Error::SerializeBufferFull => Error::BufferTooSmall,
        _ => Error::Serialize,
    })?;
    // The COBS encoder reports lengths up to one past a full buffer.
    *rest.get_mut(len).ok_or(Error::BufferTooSmall)? = FRAME_DELIMITER;
    Ok(&out[..len + FRAME_DELIMITERS])
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
    let len = cobs::decode_in_place(frame).map_err(|_| Error::Framing)?;
    let decoded = frame.get(..len).ok_or(Error::Framing)?;
    let Some(body_len) = len.checked_sub(CRC_LEN).filter(|&n| n > 0) else {
        return Err(Error::Framing);
    };
    let (body, crc) = decoded.split_at(body_len);
    let crc = u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]);
    if CRC32.checksum(body) != crc {
        return Err(Error::Crc);
    }
    Ok(body)
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
        raw.extend_from_slice(&CRC32.checksum(body).to_le_bytes());
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
        assert_eq!(CRC32.checksum(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn round_trip_and_delimiter() {
        let mut buf = [0u8; MAX_FRAME_SIZE];
        let frame = encode_frame(7, &Request::Heartbeat, &mut buf).unwrap();
        assert_eq!(frame.first(), Some(&FRAME_DELIMITER));
        assert_eq!(frame.last(), Some(&FRAME_DELIMITER));
        assert!(!frame[1..frame.len() - 1].contains(&0));
        let mut copy = frame.to_vec();
        let decoded: Frame<Request> = decode_frame(&mut copy).unwrap();
        assert_eq!(
            decoded,
            Frame {
                seq: 7,
                msg: Request::Heartbeat
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
