//! A parameter record on its way to flash: handed to the binary at the next step, made
//! active and acknowledged when the binary reports the write.

use protocol::{NackCode, ParametersStatus, Reply, RigParameters};

use super::Core;
use super::derived::Derived;

/// How long the binary may take to report a flash write before it counts as failed, us.
const PERSIST_TIMEOUT_US: u64 = 5_000_000;

/// A parameter record on its way to flash.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Persist {
    Idle,
    /// Handed to the binary at the next step; `seq` is the `SetParameters` request's.
    Requested {
        parameters: RigParameters,
        seq: u16,
    },
    /// Handed over at `since_us`; waiting for [`Core::persist_result`].
    Writing {
        parameters: RigParameters,
        seq: u16,
        since_us: u64,
    },
}

impl Core {
    /// The record to hand to the binary this step, if one waits; refuses a write the
    /// binary never reported with `StorageFailed`.
    pub(super) fn take_persist(&mut self, now: u64) -> Option<RigParameters> {
        match self.persist {
            Persist::Requested { parameters, seq } => {
                self.persist = Persist::Writing {
                    parameters,
                    seq,
                    since_us: now,
                };
                Some(parameters)
            }
            Persist::Writing { seq, since_us, .. }
                if now.saturating_sub(since_us) > PERSIST_TIMEOUT_US =>
            {
                self.persist = Persist::Idle;
                self.send_reply(seq, Reply::Nack(NackCode::StorageFailed));
                None
            }
            _ => None,
        }
    }

    /// The binary's report of the flash write handed out in [`crate::Outputs::persist`]: on
    /// success the record becomes active and the request is acknowledged, otherwise it is
    /// refused with `StorageFailed` and the old record stays.
    pub fn persist_result(&mut self, ok: bool) {
        let Persist::Writing {
            parameters, seq, ..
        } = self.persist
        else {
            return;
        };
        self.persist = Persist::Idle;
        if !ok {
            self.send_reply(seq, Reply::Nack(NackCode::StorageFailed));
            return;
        }
        match Derived::new(&parameters, &self.config) {
            Ok(derived) => {
                self.parameters = parameters;
                self.parameters_status = ParametersStatus::Valid;
                self.derived = derived;
                self.speed_loop.set_feed_forward(derived.feed_forward);
                self.supervisor.set_max_hz(derived.max_hz);
                self.send_reply(seq, Reply::Ack);
            }
            Err(rejection) => {
                self.send_reply(seq, Reply::Nack(NackCode::ParametersRejected(rejection)));
            }
        }
    }
}
