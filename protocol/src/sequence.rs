//! Lost-frame detection from the frame sequence numbers (host side).

/// Tracks a peer's frame sequence numbers and counts the frames that never arrived.
///
/// A serial link does not reorder, so any jump is loss; a repeat counts as a duplicate
/// (e.g. a device that restarted and reused the number).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SeqTracker {
    last: Option<u16>,
    /// Frames observed.
    pub received: u32,
    /// Frames skipped over (sum of all gaps).
    pub lost: u32,
    /// Number of gaps (loss events).
    pub gaps: u32,
    /// Frames whose number repeated the previous one.
    pub duplicates: u32,
}

impl SeqTracker {
    /// A tracker that has seen nothing yet.
    pub const fn new() -> Self {
        Self {
            last: None,
            received: 0,
            lost: 0,
            gaps: 0,
            duplicates: 0,
        }
    }

    /// Records `seq` and returns how many frames were missed just before it.
    pub fn observe(&mut self, seq: u16) -> u16 {
        self.received = self.received.saturating_add(1);
        let missed = match self.last.replace(seq) {
            None => 0,
            Some(last) if last == seq => {
                self.duplicates = self.duplicates.saturating_add(1);
                0
            }
            Some(last) => seq.wrapping_sub(last).wrapping_sub(1),
        };
        if missed > 0 {
            self.gaps = self.gaps.saturating_add(1);
            self.lost = self.lost.saturating_add(u32::from(missed));
        }
        missed
    }

    /// Forgets the last number (after a reconnect) but keeps the counters.
    pub fn resync(&mut self) {
        self.last = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_gaps_across_wrap() {
        let mut t = SeqTracker::new();
        assert_eq!(t.observe(65_533), 0);
        assert_eq!(t.observe(65_534), 0);
        assert_eq!(t.observe(1), 2); // 65535 and 0 lost
        assert_eq!(t.observe(1), 0);
        assert_eq!(t.observe(5), 3);
        assert_eq!((t.received, t.lost, t.gaps, t.duplicates), (5, 5, 2, 1));
        t.resync();
        assert_eq!(t.observe(100), 0);
    }
}
