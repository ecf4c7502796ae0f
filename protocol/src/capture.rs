//! High-rate raw capture, recorded on the device and uploaded in chunks afterwards
//! (10 kHz of samples does not fit the link live).

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::sizes::{I32, TAG, U16, U32};

/// Samples per [`CaptureChunk`], at most: what the firmware sends in every chunk but a
/// capture's last. The one place this size is stated. Ten samples keep framing one chunk
/// (done by the firmware in `Core::transmit`, under its core lock) within the Cortex-M4's
/// lock budget of 10,000 cycles (`cargo xtask target-bench`); a host takes chunks of any
/// length up to this.
pub const CAPTURE_CHUNK_SAMPLES: usize = 10;

/// One raw capture sample; the host converts with the board's scale factors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct CaptureSample {
    /// Current-sensor ADC reading, raw counts (12-bit, zero current near mid-scale).
    pub current_adc: u16,
    /// Vibrator encoder position, quadrature counts since the capture started.
    pub encoder_count: i32,
    /// Output-shaft encoder position, quadrature counts since the capture started; `None`
    /// when the device has no output encoder. Read at a control step and held, never
    /// interpolated: every step at 10 kHz, every 6 samples at 1 kHz and below
    /// (`LAYOUT.md`).
    pub output_count: Option<i32>,
}

impl CaptureSample {
    /// Largest serialised size, bytes.
    pub const MAX_WIRE_SIZE: usize = U16 + I32 + TAG + I32;
}

/// A run of consecutive capture samples.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CaptureChunk {
    /// Identifies the capture (increments per `StartCapture`).
    pub capture_id: u16,
    /// Index of `samples[0]` within the capture.
    pub first_sample: u32,
    /// Number of samples in the whole capture.
    pub total_samples: u32,
    /// The samples, at most [`CAPTURE_CHUNK_SAMPLES`].
    pub samples: Vec<CaptureSample, CAPTURE_CHUNK_SAMPLES>,
}

impl CaptureChunk {
    /// Largest serialised size, bytes (a full chunk of worst-case samples).
    pub const MAX_WIRE_SIZE: usize =
        U16 + 2 * U32 + TAG + CAPTURE_CHUNK_SAMPLES * CaptureSample::MAX_WIRE_SIZE;
}
