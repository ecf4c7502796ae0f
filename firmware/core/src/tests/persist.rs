//! A calibration save as the binary runs it: the flash write stalls thread mode (the
//! `host_rx` task among it) for a page erase, while the control steps go on in their
//! interrupt executor and the host keeps sending into the UART's receive ring.

use protocol::{MAX_FRAME_SIZE, Reply, Request, RigParameters, encode_frame};

use super::Rig;

/// Control steps one save stalls thread mode for: the firmware's `SAVE_STALL_MAX_US`
/// (a page erase at DS12288's maximum and the record's programming), rounded up.
const SAVE_STALL_MS: u64 = 27;

#[test]
fn requests_sent_during_a_save_are_answered_after_it() {
    let mut rig = Rig::new(0.0);
    rig.run_ms(150);
    rig.persist_answer = None;
    let new = RigParameters {
        c1_nmm_per_a: 62.0,
        ..RigParameters::paper()
    };
    let save = rig.send(&Request::SetParameters(new));
    rig.step();
    assert_eq!(rig.persisted, [new], "handed to the persist task");

    // The erase runs; the host keeps sending into the ring, as a client that keeps to the
    // request window does: with the save outstanding, `REQUEST_WINDOW - 1` more (a heartbeat
    // and a GetInfo every 10 ms), then one request beyond the window, which must still get
    // exactly one reply (`Busy`).
    let mut ring = Vec::new();
    let mut sent = Vec::new();
    // Sequence numbers of their own, apart from the rig's.
    let mut seq = 1000u16;
    let schedule = [
        Request::Heartbeat { session: 0 },
        Request::GetInfo,
        Request::Heartbeat { session: 0 },
    ];
    assert_eq!(schedule.len(), protocol::REQUEST_WINDOW - 1);
    let mut next = schedule.iter().cloned();
    for ms in 0..SAVE_STALL_MS {
        if ms % 10 == 0 {
            for request in next.by_ref().take(2) {
                let mut buf = [0u8; MAX_FRAME_SIZE];
                ring.extend_from_slice(encode_frame(seq, &request, &mut buf).unwrap());
                sent.push((seq, request));
                seq += 1;
            }
        }
        rig.step();
    }
    let beyond = seq;
    let mut buf = [0u8; MAX_FRAME_SIZE];
    ring.extend_from_slice(encode_frame(beyond, &Request::GetInfo, &mut buf).unwrap());
    assert!(
        ring.len() <= 4096,
        "{} bytes: more than the ring holds",
        ring.len()
    );
    // The save ends, then `host_rx` drains the ring in 64-byte reads.
    rig.core.persist_result(true);
    for chunk in ring.chunks(64) {
        rig.core.receive(rig.now_us, chunk);
    }
    rig.step();
    assert!(
        rig.answered(save, |r| *r == Reply::Ack),
        "the save is acknowledged"
    );
    for (seq, request) in sent {
        let answered = match request {
            Request::GetInfo => rig.answered(seq, |r| matches!(r, Reply::Info(_))),
            _ => rig.answered(seq, |r| *r == Reply::Ack),
        };
        assert!(
            answered,
            "{} (seq {seq}) sent during the save: no answer",
            request.name()
        );
    }
    let replies = rig
        .received
        .iter()
        .filter(|m| m.reply_to() == Some(beyond))
        .count();
    assert_eq!(replies, 1, "one reply to the request beyond the window");
    assert!(
        rig.answered(beyond, |r| matches!(
            r,
            Reply::Nack(protocol::NackCode::Busy)
        )),
        "the request beyond the window is refused Busy"
    );
}
