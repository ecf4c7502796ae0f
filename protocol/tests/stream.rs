//! The continuous stream end to end: blocks survive packing and framing, and line damage
//! costs only the samples of the frames it hits, each reported by sequence number.
#![allow(missing_docs)]

mod common;

use std::collections::BTreeSet;

use common::*;
use proptest::prelude::*;
use protocol::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn blocks_round_trip(first_seq in any::<u32>(), samples in stream_samples()) {
        let block = StreamBlock::pack(first_seq, &samples);
        prop_assert!(block.packed.len() <= STREAM_PACKED_MAX);
        prop_assert_eq!(&block.unpack().unwrap()[..], &samples[..]);
        let bytes = frame(7, &DeviceMessage::StreamBlock(block.clone()));
        prop_assert!(bytes.len() <= MAX_DEVICE_FRAME_SIZE);
        let mut got = None;
        DeviceDeframer::new().push(&bytes, |r| got = Some(r));
        let decoded = got.unwrap().unwrap();
        prop_assert_eq!(decoded.msg, DeviceMessage::StreamBlock(block));
    }
}

/// Sample `n` of a synthetic 10 kHz recording: a vibrating cam, a swinging current, the
/// step's fields changing every 10 samples.
fn truth(n: u32) -> StreamSample {
    let t = n as f32 / 10_000.0;
    let swing = 230.0 * (std::f32::consts::TAU * 20.0 * t).sin();
    StreamSample {
        current_adc: (2300.0 + swing) as u16 + (n.wrapping_mul(2_654_435_761) >> 30) as u16,
        cam_count: (n as f32 * 16.384) as u32 as u16,
        output_count: (n / 40) as u16,
        duty: (4_000 + (n / 10) % 77) as i16,
        tau_cam: 300 + ((n / 5_000) % 20) as i16,
        status: if (n / 20_000).is_multiple_of(2) {
            0x0004
        } else {
            0x0006
        },
        state: 2,
    }
}

/// Ten seconds of stream frames and, per frame, its byte range on the line.
fn recording(blocks: u32) -> (Vec<u8>, Vec<std::ops::Range<usize>>) {
    let mut line = Vec::new();
    let mut ranges = Vec::new();
    for b in 0..blocks {
        let first = b * STREAM_BLOCK_SAMPLES as u32;
        let samples: Vec<_> = (first..first + STREAM_BLOCK_SAMPLES as u32)
            .map(truth)
            .collect();
        let msg = DeviceMessage::StreamBlock(StreamBlock::pack(first, &samples));
        let start = line.len();
        line.extend(frame(b as u16, &msg));
        ranges.push(start..line.len());
    }
    (line, ranges)
}

#[derive(Clone, Copy, Debug)]
enum Damage {
    Flip,
    Drop,
}

/// Damages one byte every `every` bytes; decodes; checks that every sample is either
/// exact or reported lost, that only hit frames lose samples, and returns (lost, hit).
fn damaged_stream(damage: Damage, every: usize) -> (u64, usize) {
    const BLOCKS: u32 = 10_000; // 10 s at 10 kHz.
    let (line, ranges) = recording(BLOCKS);
    let mut noise: u32 = 0x9E37_79B9;
    let mut damaged = Vec::with_capacity(line.len());
    let mut hit_frames = BTreeSet::new();
    for (i, &byte) in line.iter().enumerate() {
        // Never the last frame: a loss at the very end shows only against the expected count.
        if i % every == every - 1 && i < ranges[ranges.len() - 1].start {
            let frame_index = ranges.partition_point(|r| r.end <= i);
            hit_frames.insert(frame_index);
            noise = noise.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            match damage {
                Damage::Flip => damaged.push(byte ^ (1 << (noise >> 29))),
                Damage::Drop => {}
            }
        } else {
            damaged.push(byte);
        }
    }
    let mut deframer = DeviceDeframer::new();
    let mut decoder = StreamDecoder::new();
    let mut seen = BTreeSet::new();
    let mut lost = BTreeSet::new();
    // In chunks, as a serial port delivers them.
    for chunk in damaged.chunks(97) {
        deframer.push(chunk, |r| {
            let Ok(Frame {
                msg: DeviceMessage::StreamBlock(block),
                ..
            }) = r
            else {
                return;
            };
            decoder.push(&block, |event| match event {
                StreamEvent::Sample { seq, sample } => {
                    assert_eq!(sample, truth(seq), "sample {seq} is wrong");
                    assert!(seen.insert(seq), "sample {seq} twice");
                }
                StreamEvent::Lost { first_seq, count } => {
                    lost.extend(first_seq..first_seq + count);
                }
            });
        });
    }
    let total = BLOCKS * STREAM_BLOCK_SAMPLES as u32;
    // Every sample is accounted for exactly once: received or reported lost.
    assert_eq!(decoder.expected_seq(), Some(total));
    assert!(seen.is_disjoint(&lost));
    assert_eq!(seen.len() + lost.len(), total as usize);
    assert_eq!(decoder.lost, lost.len() as u64);
    // Only hit frames lost samples, and a lost frame loses all of its samples.
    let lost_frames: BTreeSet<usize> = lost
        .iter()
        .map(|&s| (s / STREAM_BLOCK_SAMPLES as u32) as usize)
        .collect();
    assert!(
        lost_frames.is_subset(&hit_frames),
        "{:?}",
        lost_frames.difference(&hit_frames).collect::<Vec<_>>()
    );
    assert_eq!(lost.len(), lost_frames.len() * STREAM_BLOCK_SAMPLES);
    (decoder.lost, hit_frames.len())
}

#[test]
fn a_flipped_byte_every_10000_loses_only_the_hit_frames() {
    let (lost, hit) = damaged_stream(Damage::Flip, 10_000);
    // ~470 kB: 46 damaged bytes, each in its own frame; a flipped bit always fails the
    // frame (CRC-32 catches every single-bit error), so each hit frame loses its 10 samples.
    assert!(hit >= 40, "{hit}");
    assert_eq!(lost, hit as u64 * STREAM_BLOCK_SAMPLES as u64);
}

#[test]
fn a_dropped_byte_every_10000_loses_only_the_hit_frames() {
    let (lost, hit) = damaged_stream(Damage::Drop, 10_000);
    // A dropped body byte fails the frame; a dropped delimiter may cost nothing (a frame's
    // leading delimiter follows the previous one's trailing one).
    assert!(hit >= 40, "{hit}");
    assert!(lost <= hit as u64 * STREAM_BLOCK_SAMPLES as u64);
    assert!(
        lost >= (hit as u64 - 10) * STREAM_BLOCK_SAMPLES as u64,
        "{lost} of {hit}"
    );
}
