//! The protocol server: every [`Request`] gets exactly one reply (`SetCalibration`'s comes
//! after the flash write), echoing the request's `seq` in `Ack`/`Nack`.
//!
//! Garbled frames are counted by the deframer and otherwise ignored; an intact frame of an
//! unknown message is refused with `UnknownMessage`. Any intact frame counts as a heartbeat.

use protocol::{
    CalibrationStatus, DeviceInfo, DeviceMessage, Error, FirmwareVersion, Frame,
    MAX_TELEMETRY_RATE_HZ, NackCode, PROTOCOL_VERSION, Request, SCHEMA_HASH, SupervisorState,
};

use crate::controller::{Core, Derived, Persist};

/// This firmware's version, from the crate version.
pub const FIRMWARE_VERSION: FirmwareVersion = parse_version(env!("CARGO_PKG_VERSION"));

/// `major.minor.patch` (anything after a `-` or `+` ignored) as a [`FirmwareVersion`].
const fn parse_version(text: &str) -> FirmwareVersion {
    let bytes = text.as_bytes();
    let mut parts = [0u8; 3];
    let (mut part, mut i) = (0, 0);
    while i < bytes.len() && part < 3 {
        match bytes[i] {
            b'.' => part += 1,
            b @ b'0'..=b'9' => parts[part] = parts[part] * 10 + (b - b'0'),
            _ => break,
        }
        i += 1;
    }
    FirmwareVersion {
        major: parts[0],
        minor: parts[1],
        patch: parts[2],
    }
}

impl Core {
    /// Takes bytes from the host link, in chunks of any size, and answers complete requests.
    pub fn receive(&mut self, now_us: u64, bytes: &[u8]) {
        for &byte in bytes {
            match self.deframer.push_byte(byte) {
                Some(Ok(Frame { seq, msg })) => {
                    self.last_request_us = now_us;
                    self.handle(now_us, seq, msg);
                }
                Some(Err(Error::Decode { seq: Some(seq) })) => {
                    self.last_request_us = now_us;
                    self.reply_nack(seq, NackCode::UnknownMessage);
                }
                // Counted in the deframer's stats; nothing to answer.
                Some(Err(_)) | None => {}
            }
        }
    }

    fn reply(&mut self, msg: DeviceMessage) {
        self.tx.push(&msg, 0);
    }

    fn ack(&mut self, seq: u16) {
        self.reply(DeviceMessage::Ack { seq });
    }

    fn info(&self) -> DeviceInfo {
        let mut board = heapless::String::new();
        for c in self.config.board_name.chars() {
            if board.push(c).is_err() {
                break;
            }
        }
        DeviceInfo {
            firmware_version: FIRMWARE_VERSION,
            protocol_version: PROTOCOL_VERSION,
            schema_hash: SCHEMA_HASH,
            board,
            calibration_status: self.calibration_status,
        }
    }

    fn faults_reply(&self) -> DeviceMessage {
        DeviceMessage::Faults {
            active: self.active_faults(),
            latched: self.faults.latched(),
        }
    }

    fn motor_idle(&self) -> bool {
        matches!(
            self.supervisor.state(),
            SupervisorState::Locked | SupervisorState::Fault
        )
    }

    fn handle(&mut self, now: u64, seq: u16, msg: Request) {
        let status_or_clear = matches!(
            msg,
            Request::Hello { .. } | Request::GetInfo | Request::GetFaults | Request::ClearFaults
        );
        if !status_or_clear && self.faults.in_hold(now) {
            self.reply_nack(seq, NackCode::InFaultHold);
            return;
        }
        match msg {
            Request::Hello {
                protocol_version,
                schema_hash,
            } => {
                if protocol_version == PROTOCOL_VERSION && schema_hash == SCHEMA_HASH {
                    self.reply(DeviceMessage::Info(self.info()));
                } else {
                    self.reply_nack(seq, NackCode::VersionMismatch);
                }
            }
            Request::GetInfo => self.reply(DeviceMessage::Info(self.info())),
            Request::Release { on, target_hz } => self.release(seq, on, target_hz),
            Request::Heartbeat => self.ack(seq),
            Request::GetCalibration => self.reply(DeviceMessage::Calibration(self.calibration)),
            Request::SetCalibration(calibration) => {
                if !self.motor_idle() || self.persist != Persist::Idle {
                    self.reply_nack(seq, NackCode::Busy);
                } else if Derived::new(&calibration, &self.config).is_none() {
                    self.reply_nack(seq, NackCode::CalibrationRejected);
                } else {
                    // Activated and acknowledged once the binary reports the flash write.
                    self.persist = Persist::Requested { calibration, seq };
                }
            }
            Request::StartTelemetry { rate_hz } => {
                if rate_hz == 0 {
                    self.reply_nack(seq, NackCode::BadArgument);
                } else {
                    let max = MAX_TELEMETRY_RATE_HZ.min(self.config.control_hz as u16);
                    let rate = u32::from(rate_hz.min(max));
                    self.telemetry_period = (self.config.control_hz / rate).max(1);
                    self.ack(seq);
                }
            }
            Request::StopTelemetry => {
                self.telemetry_period = 0;
                self.ack(seq);
            }
            Request::StartCapture {
                sample_rate_hz,
                samples,
            } => {
                let adc_hz = self.config.sample_rate_hz();
                match self.capture.start(sample_rate_hz, samples, adc_hz) {
                    Ok(_) => self.ack(seq),
                    Err(code) => self.reply_nack(seq, code),
                }
            }
            Request::GetFaults => self.reply(self.faults_reply()),
            Request::ClearFaults => {
                let active = self.active_faults();
                self.faults.clear(active);
                self.reply(self.faults_reply());
            }
            Request::RezeroCurrent => {
                if self.motor_idle() && !self.current.zeroing() {
                    self.current.begin_zero();
                    self.ack(seq);
                } else {
                    self.reply_nack(seq, NackCode::Busy);
                }
            }
            Request::OpenLoop { volts } => self.open_loop(seq, volts),
            // `Request` is non-exhaustive: a newer host's request this firmware lacks.
            _ => self.reply_nack(seq, NackCode::UnknownMessage),
        }
    }

    fn open_loop(&mut self, seq: u16, volts: f32) {
        if volts == 0.0 {
            self.open_loop_volts = None;
            self.ack(seq);
        } else if !(volts.is_finite()
            && volts.abs() <= self.config.supply_v * self.config.motor.max_duty)
        {
            self.reply_nack(seq, NackCode::BadArgument);
        } else if !self.faults.latched().is_empty()
            || self.calibration_status == CalibrationStatus::Invalid
        {
            self.reply_nack(seq, NackCode::InFaultHold);
        } else if self.host_release || self.button_held {
            self.reply_nack(seq, NackCode::Busy);
        } else {
            self.open_loop_volts = Some(volts);
            self.ack(seq);
        }
    }

    fn release(&mut self, seq: u16, on: bool, target_hz: f32) {
        if !on {
            self.host_release = false;
            self.ack(seq);
            return;
        }
        let s = self.config.supervisor;
        if !(target_hz.is_finite() && (s.min_freq_hz..=s.max_freq_hz).contains(&target_hz)) {
            self.reply_nack(seq, NackCode::BadArgument);
        } else if !self.faults.latched().is_empty()
            || self.calibration_status == CalibrationStatus::Invalid
        {
            self.reply_nack(seq, NackCode::InFaultHold);
        } else if self.open_loop_volts.is_some() {
            self.reply_nack(seq, NackCode::Busy);
        } else {
            self.host_release = true;
            // Within the allowed range but above the calibration's limit: clamped.
            self.host_target_hz = target_hz.min(self.derived.max_hz);
            self.ack(seq);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_parses() {
        let v = parse_version("1.22.3-rc1");
        assert_eq!((v.major, v.minor, v.patch), (1, 22, 3));
        let v = FIRMWARE_VERSION;
        assert_eq!(
            format!("{v}"),
            env!("CARGO_PKG_VERSION").split('-').next().unwrap()
        );
    }
}
