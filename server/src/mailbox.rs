//! Latest wins on the way in: a room's control frames wait for its pipeline in a `Mailbox`
//! of one. While a frame runs, at most one more waits; a newer frame supersedes the waiting
//! one, whose sender learns so at once (its publisher gets an ABORTED ack, `crate::ingest`).
//!
//! The fan-out is latest-wins on the way out (`crate::fanout`); this is the same rule for
//! the way in. Without it, a room given frames faster than its pipeline runs them queued
//! every one: under the soak's 20 rooms at 60 Hz on two cores, the overlapping streams of
//! reconnecting publishers each held a backlog of stale frames, tasks and sockets grew, the
//! blocking pool filled with frames waiting for their room, and the viewers' keyframes
//! starved behind them (RELIABILITY.md, the soak). With it, a room runs at its pipeline's
//! pace on its freshest frame and holds one blocking thread at most. A single publisher that
//! waits for each ack before its next frame never supersedes itself; a second publisher into
//! the room, a reconnection's overlap or a replica's forwards can.

use std::sync::Mutex;

use tokio::sync::oneshot;

/// What a submitter hears: `Some(result)` once its item ran, `None` when a newer item
/// superseded it before it ran.
pub(crate) type Outcome<R> = oneshot::Receiver<Option<R>>;

/// One running item and at most one waiting (module docs).
#[derive(Debug)]
pub(crate) struct Mailbox<T, R> {
    state: Mutex<Slot<T, R>>,
}

#[derive(Debug)]
struct Slot<T, R> {
    /// A drain is running (it takes `waiting` before it stops).
    running: bool,
    waiting: Option<(T, oneshot::Sender<Option<R>>)>,
}

impl<T, R> Default for Mailbox<T, R> {
    fn default() -> Self {
        Self {
            state: Mutex::new(Slot {
                running: false,
                waiting: None,
            }),
        }
    }
}

impl<T, R> Mailbox<T, R> {
    fn slot(&self) -> std::sync::MutexGuard<'_, Slot<T, R>> {
        // The slot is consistent at every unlock, so a panic elsewhere cannot leave it torn.
        self.state
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Puts `item` in, superseding the item waiting (if any). `true` when no drain runs: the
    /// caller must start one ([`Mailbox::next`] in a loop until `None`).
    pub(crate) fn submit(&self, item: T) -> (Outcome<R>, bool) {
        let (tx, rx) = oneshot::channel();
        let mut slot = self.slot();
        if let Some((_, superseded)) = slot.waiting.replace((item, tx)) {
            let _ = superseded.send(None);
        }
        let start = !slot.running;
        slot.running = true;
        (rx, start)
    }

    /// The drain's next item with where its result goes, or `None` (and the drain stops) when
    /// nothing waits.
    pub(crate) fn next(&self) -> Option<(T, oneshot::Sender<Option<R>>)> {
        let mut slot = self.slot();
        let next = slot.waiting.take();
        slot.running = next.is_some();
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_waiting_item_is_superseded_by_a_newer_one_and_the_newest_runs() {
        let mailbox: Mailbox<u32, u32> = Mailbox::default();
        let (mut first, start) = mailbox.submit(1);
        assert!(start, "an idle mailbox asks for a drain");
        // The drain takes 1 and runs it; 2, 3 and 4 arrive meanwhile.
        let (one, done_one) = mailbox.next().unwrap();
        assert_eq!(one, 1);
        let (mut second, start2) = mailbox.submit(2);
        let (mut third, start3) = mailbox.submit(3);
        let (mut fourth, start4) = mailbox.submit(4);
        assert!(!start2 && !start3 && !start4, "one drain at a time");
        assert_eq!(second.try_recv().unwrap(), None, "2 superseded by 3");
        assert_eq!(third.try_recv().unwrap(), None, "3 superseded by 4");
        assert!(fourth.try_recv().is_err(), "4 waits");
        done_one.send(Some(10)).unwrap();
        assert_eq!(first.try_recv().unwrap(), Some(10));
        // 4 runs next, then the drain stops and the next submit starts a new one.
        let (four, done_four) = mailbox.next().unwrap();
        assert_eq!(four, 4);
        done_four.send(Some(40)).unwrap();
        assert_eq!(fourth.try_recv().unwrap(), Some(40));
        assert!(mailbox.next().is_none());
        let (_fifth, start5) = mailbox.submit(5);
        assert!(start5, "the drain stopped: a new one starts");
    }

    /// Many submitters on many threads against one drain: every item is answered, once, and
    /// the last item submitted always runs.
    #[test]
    fn every_submitter_is_answered_and_the_last_item_runs() {
        let mailbox: std::sync::Arc<Mailbox<u32, u32>> = std::sync::Arc::default();
        let ran = std::sync::Arc::new(Mutex::new(Vec::new()));
        let drain = |mailbox: &Mailbox<u32, u32>, ran: &Mutex<Vec<u32>>| {
            while let Some((item, done)) = mailbox.next() {
                ran.lock().unwrap().push(item);
                let _ = done.send(Some(item));
            }
        };
        let mut outcomes = Vec::new();
        std::thread::scope(|scope| {
            for item in 0..2000u32 {
                let (outcome, start) = mailbox.submit(item);
                outcomes.push((item, outcome));
                if start {
                    let (mailbox, ran) = (&mailbox, &ran);
                    scope.spawn(move || drain(mailbox, ran));
                }
            }
        });
        let ran = ran.lock().unwrap().clone();
        assert_eq!(ran.last(), Some(&1999), "the newest item ran last");
        assert!(ran.windows(2).all(|w| w[0] < w[1]), "in order");
        for (item, mut outcome) in outcomes {
            match outcome.try_recv().unwrap() {
                Some(r) => assert!(r == item && ran.contains(&item)),
                None => assert!(!ran.contains(&item), "{item} superseded and run"),
            }
        }
    }
}
