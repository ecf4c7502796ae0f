//! Meeting a peer of another protocol version: recognising it, answering it, and telling
//! the user which side to update.
//!
//! # What stays fixed across versions
//! * `Request::Hello { protocol_version: u16, schema_hash: u32 }` is request variant 0 in
//!   every version (v1 included), so a device recognises any host's `Hello`.
//! * From v2 on, the answer to `Hello` starts the same way in every version: frame `seq`,
//!   `DeviceMessage::Reply` (tag 0), `request_seq`, then either `Reply::Info` (tag 0)
//!   whose `DeviceInfo` starts with `protocol_version, schema_hash`, or `Reply::Nack`
//!   (tag 1) with `NackCode::VersionMismatch` (tag 0) `{ device_protocol, device_schema_hash }`.
//!   [`identify_peer`] reads that prefix whatever follows it.
//!
//! # How a device answers `Hello` ([`hello_answer`])
//! * Same version and schema: `Reply::Info`.
//! * A v1 host (`protocol_version` 1): the v1 layout of `Nack { seq, VersionMismatch }`
//!   ([`LegacyV1Nack`]), the one refusal a v1 tool can decode, so it reports a version
//!   mismatch instead of garbled frames.
//! * Anything else: `Reply::Nack(NackCode::VersionMismatch { device_protocol,
//!   device_schema_hash })` with the device's own version and hash.
//!
//! # How a host reads the answer
//! Decode it as usual; if it is `Info` or `Nack(VersionMismatch)`, pass the device's
//! version and hash to [`check_peer`]. If the frame had a good CRC but did not decode
//! (`Error::Decode`: an older device's layout), pass the frame body
//! ([`crate::Deframer::last_body`]) to [`identify_peer`], then to [`check_peer`].

use core::fmt;

use serde::{Deserialize, Serialize};

use crate::{Error, PROTOCOL_VERSION, SCHEMA_HASH};

/// A device's protocol identity, as read from its answer to `Hello`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PeerIdentity {
    /// The device's protocol version.
    pub protocol_version: u16,
    /// The device's schema hash, when its answer carried one (a v1 refusal does not).
    pub schema_hash: Option<u32>,
}

/// Reads a device's protocol identity from the CRC-checked body (`seq` + message) of its
/// answer to `Hello`, whatever its protocol version: v2 and later through the fixed
/// prefix (`Info` or `Nack(VersionMismatch)`), v1 through its own `Info` and
/// `Nack(VersionMismatch)` layouts. `None` when the body is neither.
///
/// Use it on frames that did not decode as this version's [`crate::DeviceMessage`]: a
/// well-formed message of this version can match a v1 layout by accident.
pub fn identify_peer(body: &[u8]) -> Option<PeerIdentity> {
    let (_frame_seq, message) = postcard::take_from_bytes::<u16>(body).ok()?;
    match hello_answer_prefix(message) {
        Some(id) if id.protocol_version >= 2 => Some(id),
        _ => identify_v1(message),
    }
}

/// The v2+ fixed prefix: `Reply { request_seq, Info { protocol_version, schema_hash, .. } }`
/// or `Reply { request_seq, Nack(VersionMismatch { device_protocol, device_schema_hash }) }`.
fn hello_answer_prefix(message: &[u8]) -> Option<PeerIdentity> {
    let take_tag = |b| postcard::take_from_bytes::<u32>(b).ok();
    let (0, rest) = take_tag(message)? else {
        return None;
    };
    let (_request_seq, rest) = postcard::take_from_bytes::<u16>(rest).ok()?;
    let rest = match take_tag(rest)? {
        (0, rest) => rest,
        (1, rest) => match take_tag(rest)? {
            (0, rest) => rest,
            _ => return None,
        },
        _ => return None,
    };
    let ((protocol_version, schema_hash), _) =
        postcard::take_from_bytes::<(u16, u32)>(rest).ok()?;
    Some(PeerIdentity {
        protocol_version,
        schema_hash: Some(schema_hash),
    })
}

/// Protocol v1's device messages, as far as they identify a v1 device.
#[derive(Deserialize, Serialize)]
enum V1DeviceMessage {
    Info(V1Info),
    Ack { seq: u16 },
    Nack { seq: u16, code: V1NackCode },
}

#[derive(Deserialize, Serialize)]
struct V1Info {
    firmware_version: (u8, u8, u8),
    protocol_version: u16,
    schema_hash: u32,
    board: heapless::String<16>,
    calibration_status: V1CalibrationStatus,
}

#[derive(Deserialize, Serialize)]
enum V1CalibrationStatus {
    Valid,
    Defaults,
    Invalid,
}

#[derive(Deserialize, Serialize, PartialEq)]
enum V1NackCode {
    UnknownMessage,
    BadArgument,
    InFaultHold,
    VersionMismatch,
    CalibrationRejected,
    Busy,
    StorageFailed,
}

fn identify_v1(message: &[u8]) -> Option<PeerIdentity> {
    match postcard::take_from_bytes::<V1DeviceMessage>(message).ok()? {
        (V1DeviceMessage::Info(info), []) => Some(PeerIdentity {
            protocol_version: info.protocol_version,
            schema_hash: Some(info.schema_hash),
        }),
        (
            V1DeviceMessage::Nack {
                code: V1NackCode::VersionMismatch,
                ..
            },
            [],
        ) => Some(PeerIdentity {
            protocol_version: 1,
            schema_hash: None,
        }),
        _ => None,
    }
}

/// The refusal a v1 host understands: protocol v1's `Nack { seq: hello_seq,
/// code: VersionMismatch }`. Encode it with [`crate::encode_frame`] like any message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LegacyV1Nack {
    /// The v1 host's `Hello` frame sequence number.
    pub hello_seq: u16,
}

impl Serialize for LegacyV1Nack {
    /// The same bytes as `V1DeviceMessage::Nack { seq, code: V1NackCode::VersionMismatch }`
    /// (a test checks it), written variant by variant so a device's image carries only this
    /// one variant's encoder, not all of protocol v1's.
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStructVariant;
        let mut nack = serializer.serialize_struct_variant("V1DeviceMessage", 2, "Nack", 2)?;
        nack.serialize_field("seq", &self.hello_seq)?;
        nack.serialize_field("code", &V1VersionMismatch)?;
        nack.end()
    }
}

/// `V1NackCode::VersionMismatch` alone (see [`LegacyV1Nack`]'s `Serialize`).
struct V1VersionMismatch;

impl Serialize for V1VersionMismatch {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_unit_variant("V1NackCode", 3, "VersionMismatch")
    }
}

/// How a device answers `Hello` (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HelloAnswer {
    /// Same version and schema: `Reply::Info`.
    Info,
    /// A v1 host: send [`LegacyV1Nack`].
    LegacyV1Nack,
    /// Another version or schema: `Reply::Nack(NackCode::VersionMismatch { PROTOCOL_VERSION, SCHEMA_HASH })`.
    VersionMismatch,
}

/// How this device answers `Hello { protocol_version, schema_hash }`.
pub const fn hello_answer(protocol_version: u16, schema_hash: u32) -> HelloAnswer {
    if protocol_version == PROTOCOL_VERSION && schema_hash == SCHEMA_HASH {
        HelloAnswer::Info
    } else if protocol_version == 1 {
        HelloAnswer::LegacyV1Nack
    } else {
        HelloAnswer::VersionMismatch
    }
}

/// Whether this host can talk to a device of `device_protocol` and `device_schema_hash`
/// (`None`: not known); the error's message says which side to update.
pub const fn check_peer(
    device_protocol: u16,
    device_schema_hash: Option<u32>,
) -> Result<(), Error> {
    let same_schema = match device_schema_hash {
        Some(hash) => hash == SCHEMA_HASH,
        None => false,
    };
    if device_protocol == PROTOCOL_VERSION && same_schema {
        Ok(())
    } else {
        Err(Error::VersionMismatch {
            device_protocol,
            device_schema_hash,
        })
    }
}

/// What to do about a device of another protocol version: update the firmware when it is
/// older than this tool, the tool when it is newer.
pub const fn version_advice(device_protocol: u16) -> &'static str {
    if device_protocol < PROTOCOL_VERSION {
        "run `rig flash` to update the firmware"
    } else if device_protocol > PROTOCOL_VERSION {
        "update the rig tool (`cargo install --path host --locked` from the checkout that built the firmware), or run `rig flash` to put this tool's firmware on the rig"
    } else {
        "run `rig flash` from this tool's checkout, so firmware and tool are built from the same source"
    }
}

/// The text of [`Error::VersionMismatch`].
pub(crate) fn write_mismatch(
    f: &mut fmt::Formatter<'_>,
    device: u16,
    device_hash: Option<u32>,
) -> fmt::Result {
    let advice = version_advice(device);
    if device != PROTOCOL_VERSION {
        return write!(
            f,
            "the firmware speaks protocol {device}, this rig tool speaks {PROTOCOL_VERSION}: {advice}"
        );
    }
    match device_hash {
        Some(hash) if hash != SCHEMA_HASH => write!(
            f,
            "the firmware and this rig tool both speak protocol {device} but their message layouts differ (firmware schema {hash:#010x}, tool {SCHEMA_HASH:#010x}): {advice}"
        ),
        _ => write!(
            f,
            "the firmware refused this rig tool's protocol {device} although it reports the same version: {advice}"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        DeviceMessage, Frame, NackCode, Reply, decode_frame, encode_frame_vec, frame_body,
    };

    /// The body of a frame, as the deframer leaves it.
    fn body_of(frame: &[u8]) -> std::vec::Vec<u8> {
        let mut bytes = frame.to_vec();
        frame_body(&mut bytes).unwrap().to_vec()
    }

    /// Protocol v1's `Info` reply, byte for byte (from v1's golden bytes, seq 7).
    const V1_INFO_FRAME: &[u8] = &[
        0x02, 0x07, 0x01, 0x1c, 0x01, 0x02, 0x01, 0xef, 0xfd, 0xb6, 0xf5, 0x0d, 0x0d, 0x6e, 0x75,
        0x63, 0x6c, 0x65, 0x6f, 0x2d, 0x67, 0x34, 0x37, 0x34, 0x72, 0x65, 0x01, 0xfc, 0x5d, 0xda,
        0x0a, 0x00,
    ];
    /// Protocol v1's `Nack { seq: 301, code: InFaultHold }` (v1 golden bytes, seq 7).
    const V1_NACK_FAULT_FRAME: &[u8] = &[
        0x0a, 0x07, 0x02, 0xad, 0x02, 0x02, 0x1b, 0x2e, 0x93, 0xd3, 0x00,
    ];
    /// Protocol v1's `Hello { 1, 0xDEADBEEF }` request (v1 golden bytes, seq 0x1234).
    const V1_HELLO_FRAME: &[u8] = &[
        0x03, 0xb4, 0x24, 0x0b, 0x01, 0xef, 0xfd, 0xb6, 0xf5, 0x0d, 0xa5, 0x4f, 0xc0, 0x4d, 0x00,
    ];

    #[test]
    fn a_v1_hello_is_recognised() {
        let hello: Frame<crate::Request> = decode_frame(&mut V1_HELLO_FRAME.to_vec()).unwrap();
        let crate::Request::Hello {
            protocol_version,
            schema_hash,
        } = hello.msg
        else {
            panic!("not a Hello");
        };
        assert_eq!((protocol_version, schema_hash), (1, 0xDEAD_BEEF));
        assert_eq!(
            hello_answer(protocol_version, schema_hash),
            HelloAnswer::LegacyV1Nack
        );
        assert_eq!(
            hello_answer(PROTOCOL_VERSION, SCHEMA_HASH),
            HelloAnswer::Info
        );
        assert_eq!(
            hello_answer(PROTOCOL_VERSION, SCHEMA_HASH ^ 1),
            HelloAnswer::VersionMismatch
        );
        assert_eq!(hello_answer(3, 0), HelloAnswer::VersionMismatch);
    }

    #[test]
    fn the_legacy_nack_is_v1s_layout() {
        // v1: seq, tag 2 (Nack), seq, tag 3 (VersionMismatch); the same bytes as v1's
        // golden `Nack` frame with code 3 instead of 2.
        let frame = encode_frame_vec(7, &LegacyV1Nack { hello_seq: 301 }).unwrap();
        assert_eq!(body_of(&frame), [0x07, 0x02, 0xad, 0x02, 0x03]);
        // The hand-written encoder writes what v1's own type would.
        let derived = encode_frame_vec(
            7,
            &V1DeviceMessage::Nack {
                seq: 301,
                code: V1NackCode::VersionMismatch,
            },
        )
        .unwrap();
        assert_eq!(frame, derived);
        assert_eq!(
            identify_peer(&body_of(&frame)),
            Some(PeerIdentity {
                protocol_version: 1,
                schema_hash: None
            })
        );
        // It is not a message of this version.
        assert!(decode_frame::<DeviceMessage>(&mut frame.clone()).is_err());
    }

    #[test]
    fn v1_replies_identify_a_v1_device() {
        assert_eq!(
            identify_peer(&body_of(V1_INFO_FRAME)),
            Some(PeerIdentity {
                protocol_version: 1,
                schema_hash: Some(0xDEAD_BEEF)
            })
        );
        // Other v1 refusals do not say the device's version.
        assert_eq!(identify_peer(&body_of(V1_NACK_FAULT_FRAME)), None);
        assert_eq!(identify_peer(&[]), None);
        assert_eq!(identify_peer(&[0x07]), None);
    }

    #[test]
    fn v2_answers_to_hello_identify_the_device() {
        let info = crate::golden::examples::device_info();
        let frame =
            encode_frame_vec(9, &DeviceMessage::reply(4, Reply::Info(info.clone()))).unwrap();
        assert_eq!(
            identify_peer(&body_of(&frame)),
            Some(PeerIdentity {
                protocol_version: info.protocol_version,
                schema_hash: Some(info.schema_hash)
            })
        );
        let nack = NackCode::VersionMismatch {
            device_protocol: 3,
            device_schema_hash: 0x1234_5678,
        };
        let frame = encode_frame_vec(9, &DeviceMessage::nack(4, nack)).unwrap();
        assert_eq!(
            identify_peer(&body_of(&frame)),
            Some(PeerIdentity {
                protocol_version: 3,
                schema_hash: Some(0x1234_5678)
            })
        );
        // A later version's `Info` with fields this version lacks still identifies.
        let mut body =
            body_of(&encode_frame_vec(9, &DeviceMessage::reply(4, Reply::Info(info))).unwrap());
        body.extend_from_slice(&[0x55; 9]);
        assert_eq!(
            identify_peer(&body).map(|p| p.protocol_version),
            Some(PROTOCOL_VERSION)
        );
        // Other replies do not.
        let frame = encode_frame_vec(9, &DeviceMessage::ack(4)).unwrap();
        assert_eq!(identify_peer(&body_of(&frame)), None);
    }

    #[test]
    fn mismatch_messages_name_the_side_to_update() {
        let text = |d, h| check_peer(d, h).unwrap_err().to_string();
        assert_eq!(
            text(1, None),
            format!(
                "the firmware speaks protocol 1, this rig tool speaks {PROTOCOL_VERSION}: run `rig flash` to update the firmware"
            )
        );
        assert!(text(PROTOCOL_VERSION + 1, Some(0)).contains("update the rig tool"));
        let t = text(PROTOCOL_VERSION, Some(SCHEMA_HASH ^ 1));
        assert!(t.contains("message layouts differ"), "{t}");
        assert!(t.contains("rig flash"), "{t}");
        assert_eq!(check_peer(PROTOCOL_VERSION, Some(SCHEMA_HASH)), Ok(()));
        assert!(check_peer(PROTOCOL_VERSION, None).is_err());
        assert_eq!(version_advice(1), "run `rig flash` to update the firmware");
    }
}
