//! Fan-out: how a room's encoded frames reach its subscribers. The pipeline publishes one
//! frame per level; every subscriber of that level receives the newest one (latest wins: a
//! slow subscriber skips frames, it never delays the room or the others, and memory is one
//! frame per level however many subscribe).
//!
//! [`Fanout`] is the interface, [`LocalFanout`] the in-process implementation (a
//! `tokio::sync::watch` per level). The interface is object-safe so that a room can hold a
//! `dyn Fanout` and a networked implementation can stand behind it: a cluster's room
//! (`crate::cluster::RoomLink`) wraps a [`LocalFanout`] and also sends each frame to the
//! replicas that relay it, and hands out the same [`Receiver`].

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use crease_proto::Level;
use tokio::sync::watch;

use crate::frames::MeshUpdate;
use crate::session::CountGuard;

/// A level's frames as a subscriber sees them: the newest, or `None` before the first.
pub type Latest = Option<Arc<MeshUpdate>>;

/// A subscription to one level's frames. While it lives, the level has interest
/// ([`Fanout::interest`]).
#[derive(Debug)]
pub struct Receiver {
    /// The channel; `borrow_and_update` gives the newest frame, `changed` waits for one.
    pub rx: watch::Receiver<Latest>,
    _interest: CountGuard,
}

/// Publishes a room's frames to its subscribers, per level (module docs).
pub trait Fanout: Send + Sync + std::fmt::Debug {
    /// Hands `frame` to `level`'s subscribers in place of the previous one (which goes back to
    /// the pipeline's pool once nobody holds it: the pool keeps its own handle).
    fn publish(&self, level: Level, frame: Arc<MeshUpdate>);

    /// A subscription to `level`: the current frame (if any), then every newer one.
    fn subscribe(&self, level: Level) -> Receiver;

    /// Whether anyone subscribes to `level`: the pipeline synthesises the detail layer only
    /// while someone does.
    fn interest(&self, level: Level) -> bool;

    /// Whether `level`'s next frame should be a keyframe (asked once, then cleared): a
    /// networked fan-out whose far end lost a frame asks for one. The local fan-out never
    /// does (its subscribers get on-demand keyframes, `crate::frames`).
    fn wants_keyframe(&self, _level: Level) -> bool {
        false
    }

    /// Whether another replica predicts the room and this one only relays its frames (then
    /// control frames are forwarded to the owner, `crate::cluster::control`).
    fn relays(&self) -> bool {
        false
    }
}

/// The in-process fan-out: one `watch` channel and one subscriber count per level.
#[derive(Debug)]
pub struct LocalFanout {
    channels: [watch::Sender<Latest>; 2],
    subscribers: [Arc<AtomicUsize>; 2],
}

impl Default for LocalFanout {
    fn default() -> Self {
        Self {
            channels: [watch::channel(None).0, watch::channel(None).0],
            subscribers: [Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0))],
        }
    }
}

impl Fanout for LocalFanout {
    fn publish(&self, level: Level, frame: Arc<MeshUpdate>) {
        self.channels[level as usize].send_replace(Some(frame));
    }

    fn subscribe(&self, level: Level) -> Receiver {
        Receiver {
            _interest: CountGuard::new(&self.subscribers[level as usize]),
            rx: self.channels[level as usize].subscribe(),
        }
    }

    fn interest(&self, level: Level) -> bool {
        self.subscribers[level as usize].load(Ordering::Relaxed) > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interest_follows_subscriptions_and_the_latest_frame_wins() {
        let f = LocalFanout::default();
        assert!(!f.interest(Level::Detail) && !f.interest(Level::Base));
        let mut sub = f.subscribe(Level::Detail);
        assert!(f.interest(Level::Detail) && !f.interest(Level::Base));
        for seq in 0..3 {
            f.publish(Level::Detail, Arc::new(MeshUpdate::empty_for_test(seq)));
        }
        // Only the newest is there to read: the subscriber skipped 0 and 1.
        let latest = sub.rx.borrow_and_update().clone().unwrap();
        assert_eq!(latest.seq, 2);
        // A new subscriber starts at the newest frame too.
        f.publish(Level::Detail, Arc::new(MeshUpdate::empty_for_test(3)));
        let late = f.subscribe(Level::Detail);
        assert_eq!(late.rx.borrow().as_ref().unwrap().seq, 3);
        drop(late);
        drop(sub);
        assert!(!f.interest(Level::Detail));
    }
}
