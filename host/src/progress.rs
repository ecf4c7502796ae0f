//! How far a long procedure has come and when it will end: points done of all, time
//! elapsed and an estimate of the time left, from the mean time of the points this run
//! has measured (rests and prompts included).

use std::time::{Duration, Instant};

/// Progress of a procedure of `total` points, `done_before` of them done by an earlier
/// run (a resumed sweep).
#[derive(Debug, Clone)]
pub struct Progress {
    started: Instant,
    total: usize,
    done_before: usize,
}

impl Progress {
    /// Starts counting now.
    pub fn start(total: usize, done_before: usize) -> Self {
        Self {
            started: Instant::now(),
            total,
            done_before,
        }
    }

    /// `12/150 done, 2 min 36 s elapsed, about 29 min left` once `done` points (of all,
    /// the earlier run's included) are done.
    pub fn line(&self, done: usize) -> String {
        progress_text(self.started.elapsed(), done, self.done_before, self.total)
    }
}

/// The points done and all points (`12`, `150`) of a line that carries a
/// [`Progress::line`]; `None` for any other line.
pub fn counts(line: &str) -> Option<(usize, usize)> {
    let head = &line[..line.find(" done, ")?];
    let (done, total) = head.rsplit(' ').next()?.split_once('/')?;
    Some((done.parse().ok()?, total.parse().ok()?))
}

/// [`Progress::line`] for `elapsed` wall time since this run's start.
fn progress_text(elapsed: Duration, done: usize, done_before: usize, total: usize) -> String {
    let here = done.saturating_sub(done_before);
    let left = total.saturating_sub(done);
    let estimate = if left == 0 {
        "done".to_string()
    } else if here == 0 {
        "time left not known yet".to_string()
    } else {
        let per_point = elapsed.as_secs_f64() / here as f64;
        format!("about {} left", duration_text(per_point * left as f64))
    };
    format!(
        "{done}/{total} done, {} elapsed, {estimate}",
        duration_text(elapsed.as_secs_f64())
    )
}

/// A duration as a person reads it: `36 s`, `2 min 36 s`, `29 min`, `1 h 05 min`.
pub fn duration_text(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    match s {
        0..60 => format!("{s} s"),
        60..600 => format!("{} min {} s", s / 60, s % 60),
        600..3600 => format!("{} min", (s + 30) / 60),
        _ => {
            let m = (s + 30) / 60;
            format!("{} h {:02} min", m / 60, m % 60)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimate_is_the_mean_point_time_times_the_points_left() {
        // 12 of 150 points in 156 s: 13 s a point, 138 left: 1,794 s, about 30 min.
        let line = progress_text(Duration::from_secs(156), 12, 0, 150);
        assert_eq!(line, "12/150 done, 2 min 36 s elapsed, about 30 min left");
        // A resumed run counts only its own points for the rate.
        let line = progress_text(Duration::from_secs(20), 102, 100, 150);
        assert_eq!(line, "102/150 done, 20 s elapsed, about 8 min 0 s left");
        assert!(progress_text(Duration::ZERO, 0, 0, 5).ends_with("time left not known yet"));
        assert!(progress_text(Duration::from_secs(5), 5, 0, 5).ends_with("done"));
        assert_eq!(duration_text(3900.0), "1 h 05 min");
        let line = format!(
            "point 3/150: 1.1 N m, 6.2 V: i = 1.234 A; {}",
            progress_text(Duration::from_secs(39), 3, 0, 150)
        );
        assert_eq!(counts(&line), Some((3, 150)));
        assert_eq!(counts("round 2: 12 test points (proposed)"), None);
    }
}
