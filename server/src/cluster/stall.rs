//! Stalls (issue 40): a replica whose whole process was stopped (SIGSTOP, a VM paused, a long
//! stall) wakes with control frames buffered in its sockets from before it stopped. A relay
//! that forwarded them would hand the room's owner frames older than ones it has predicted
//! since (its publisher moved to another replica meanwhile): every viewer would see the room
//! jump back. So a watchdog thread ticks every [`TICK`]; a relay refuses to forward while the
//! last tick is older than [`STALL`] (it has not run since: the process was stopped) or for
//! [`GRACE`] after a tick that came late by more than that (what is read then was buffered
//! before).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// How often the watchdog ticks.
pub const TICK: Duration = Duration::from_millis(50);
/// A tick this late (or no tick for this long) means the process was stalled.
pub const STALL: Duration = Duration::from_millis(1000);
/// After a stall, frames read for this long are from before it.
pub const GRACE: Duration = Duration::from_millis(500);

/// The watchdog's view (module docs).
#[derive(Debug)]
pub struct StallWatch {
    start: Instant,
    last_tick_ms: AtomicU64,
    /// When the last stall was seen, ms since `start` (0: never).
    stalled_at_ms: AtomicU64,
}

impl StallWatch {
    /// A watch whose thread starts ticking now.
    pub fn start() -> Arc<StallWatch> {
        let watch = Arc::new(StallWatch {
            start: Instant::now(),
            last_tick_ms: AtomicU64::new(0),
            stalled_at_ms: AtomicU64::new(0),
        });
        let w = Arc::clone(&watch);
        let spawned = std::thread::Builder::new()
            .name("crease-stall-watch".into())
            .spawn(move || {
                loop {
                    std::thread::sleep(TICK);
                    w.tick();
                }
            });
        if let Err(e) = spawned {
            tracing::warn!("stall watchdog not started: {e}");
        }
        watch
    }

    fn now_ms(&self) -> u64 {
        self.start.elapsed().as_millis() as u64
    }

    /// One tick of the watchdog: a late one records a stall.
    fn tick(&self) {
        let now = self.now_ms();
        let last = self.last_tick_ms.swap(now, Ordering::AcqRel);
        if now.saturating_sub(last) >= STALL.as_millis() as u64 {
            self.stalled_at_ms.store(now.max(1), Ordering::Release);
            tracing::warn!(
                stalled_ms = now - last,
                "this process was stalled: control frames read in the next {} ms are not forwarded",
                GRACE.as_millis()
            );
        }
    }

    /// Whether what this replica reads now may be from before a stall (module docs).
    pub fn stale(&self) -> bool {
        let now = self.now_ms();
        let last = self.last_tick_ms.load(Ordering::Acquire);
        let stalled = self.stalled_at_ms.load(Ordering::Acquire);
        now.saturating_sub(last) >= STALL.as_millis() as u64
            || (stalled != 0 && now.saturating_sub(stalled) < GRACE.as_millis() as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_late_tick_or_no_tick_is_a_stall_and_the_grace_ends_it() {
        // Driven by hand: no thread, the clock moved by sleeping.
        let w = StallWatch {
            start: Instant::now(),
            last_tick_ms: AtomicU64::new(0),
            stalled_at_ms: AtomicU64::new(0),
        };
        w.tick();
        assert!(!w.stale(), "ticking on time");
        std::thread::sleep(STALL + Duration::from_millis(50));
        assert!(w.stale(), "no tick for longer than STALL");
        w.tick();
        assert!(w.stale(), "within the grace after a late tick");
        std::thread::sleep(GRACE + Duration::from_millis(50));
        w.tick();
        assert!(!w.stale(), "the grace is over");
    }
}
