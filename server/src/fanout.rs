//! Fan-out: how a room's encoded frames reach its subscribers. The pipeline publishes one
//! frame per [`Channel`] (a level in an encoding: vertex or palette frames of the base or the
//! detail mesh); every subscriber of that channel receives the newest one (latest wins: a
//! slow subscriber skips frames, it never delays the room or the others, and memory is one
//! frame per channel however many subscribe).
//!
//! [`Fanout`] is the interface, [`LocalFanout`] the in-process implementation (a
//! `tokio::sync::watch` per channel). The interface is object-safe so that a room can hold a
//! `dyn Fanout` and a networked implementation can stand behind it: a cluster's room
//! (`crate::cluster::RoomLink`) wraps a [`LocalFanout`] and also sends each frame to the
//! replicas that relay it, and hands out the same [`Receiver`].

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use crease_proto::{Encoding, Level, v1};
use futures_util::future::BoxFuture;
use tokio::sync::watch;

use crate::frames::MeshUpdate;
use crate::session::CountGuard;

/// A channel's frames as a subscriber sees them: the newest, or `None` before the first (and
/// while nobody computes them).
pub type Latest = Option<Arc<MeshUpdate>>;

/// What a subscriber receives: one level of the room's meshes in one encoding.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Channel {
    /// Base or detail mesh.
    pub level: Level,
    /// Vertex frames or palette frames.
    pub encoding: Encoding,
}

impl Channel {
    /// The number of channels.
    pub const COUNT: usize = 4;
    /// Every channel, in [`Channel::index`] order.
    pub const ALL: [Channel; Channel::COUNT] = [
        Channel::new(Level::Base, Encoding::Vertices),
        Channel::new(Level::Detail, Encoding::Vertices),
        Channel::new(Level::Base, Encoding::Palette),
        Channel::new(Level::Detail, Encoding::Palette),
    ];

    /// The channel of `level` in `encoding`.
    pub const fn new(level: Level, encoding: Encoding) -> Channel {
        Channel { level, encoding }
    }

    /// `level`'s vertex frames.
    pub const fn vertices(level: Level) -> Channel {
        Channel::new(level, Encoding::Vertices)
    }

    /// `level`'s palette frames.
    pub const fn palette(level: Level) -> Channel {
        Channel::new(level, Encoding::Palette)
    }

    /// Its position in [`Channel::ALL`].
    pub const fn index(self) -> usize {
        self.level as usize + 2 * self.encoding as usize
    }

    /// Its name in NATS subjects: `base`, `detail`, `base-palette`, `detail-palette`.
    pub fn name(self) -> &'static str {
        match (self.level, self.encoding) {
            (Level::Base, Encoding::Vertices) => "base",
            (Level::Detail, Encoding::Vertices) => "detail",
            (Level::Base, Encoding::Palette) => "base-palette",
            (Level::Detail, Encoding::Palette) => "detail-palette",
        }
    }
}

/// A subscription to one channel's frames. While it lives, the channel has interest
/// ([`Fanout::interest`]).
#[derive(Debug)]
pub struct Receiver {
    /// The channel; `borrow_and_update` gives the newest frame, `changed` waits for one.
    pub rx: watch::Receiver<Latest>,
    _interest: CountGuard,
}

/// Publishes a room's frames to its subscribers, per channel (module docs).
pub trait Fanout: Send + Sync + std::fmt::Debug {
    /// Hands `frame` to `channel`'s subscribers in place of the previous one (which goes back
    /// to the pipeline's pool once nobody holds it: the pool keeps its own handle).
    fn publish(&self, channel: Channel, frame: Arc<MeshUpdate>);

    /// Drops `channel`'s current frame (the pipeline stopped computing it: a subscriber that
    /// comes later waits for the next one rather than seeing an old pose).
    fn clear(&self, channel: Channel);

    /// A subscription to `channel`: the current frame (if any), then every newer one.
    fn subscribe(&self, channel: Channel) -> Receiver;

    /// Whether anyone subscribes to `channel`: the pipeline computes a channel's frames only
    /// while someone does (module docs of `crate::pipeline`).
    fn interest(&self, channel: Channel) -> bool;

    /// Whether `channel`'s next frame should be a keyframe (asked once, then cleared): a
    /// networked fan-out whose far end lost a frame asks for one. The local fan-out never
    /// does (its subscribers get on-demand keyframes, `crate::frames`).
    fn wants_keyframe(&self, _channel: Channel) -> bool {
        false
    }

    /// Whether another replica predicts the room and this one only relays its frames (then
    /// control frames are forwarded to the owner: [`Fanout::forward`]).
    fn relays(&self) -> bool {
        false
    }

    /// A relay's way in, the fan-out's reverse: forwards `frame` (its token checked here) to
    /// the replica that predicts the room and resolves to its ack (`crate::cluster::control`).
    /// Asked only of a fan-out that [relays](Fanout::relays); a local room has no owner
    /// elsewhere, so the local fan-out refuses.
    fn forward(
        &self,
        _frame: v1::ControlFrame,
    ) -> BoxFuture<'static, Result<v1::PublishAck, String>> {
        Box::pin(async { Err("this room is predicted here: nothing to forward to".to_owned()) })
    }
}

/// The in-process fan-out: one `watch` channel and one subscriber count per [`Channel`].
#[derive(Debug)]
pub struct LocalFanout {
    channels: [watch::Sender<Latest>; Channel::COUNT],
    subscribers: [Arc<AtomicUsize>; Channel::COUNT],
}

impl Default for LocalFanout {
    fn default() -> Self {
        Self {
            channels: std::array::from_fn(|_| watch::channel(None).0),
            subscribers: std::array::from_fn(|_| Arc::new(AtomicUsize::new(0))),
        }
    }
}

impl Fanout for LocalFanout {
    fn publish(&self, channel: Channel, frame: Arc<MeshUpdate>) {
        self.channels[channel.index()].send_replace(Some(frame));
    }

    fn clear(&self, channel: Channel) {
        self.channels[channel.index()].send_if_modified(|latest| latest.take().is_some());
    }

    fn subscribe(&self, channel: Channel) -> Receiver {
        Receiver {
            _interest: CountGuard::new(&self.subscribers[channel.index()]),
            rx: self.channels[channel.index()].subscribe(),
        }
    }

    fn interest(&self, channel: Channel) -> bool {
        self.subscribers[channel.index()].load(Ordering::Relaxed) > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn channels_are_four_distinct_indices() {
        for (i, c) in Channel::ALL.iter().enumerate() {
            assert_eq!(c.index(), i, "{c:?}");
        }
        let names: std::collections::HashSet<_> = Channel::ALL.iter().map(|c| c.name()).collect();
        assert_eq!(names.len(), Channel::COUNT);
    }

    #[test]
    fn interest_follows_subscriptions_and_the_latest_frame_wins() {
        let f = LocalFanout::default();
        let detail = Channel::vertices(Level::Detail);
        let base = Channel::vertices(Level::Base);
        assert!(!f.interest(detail) && !f.interest(base));
        let mut sub = f.subscribe(detail);
        assert!(f.interest(detail) && !f.interest(base));
        assert!(
            !f.interest(Channel::palette(Level::Detail)),
            "another encoding"
        );
        for seq in 0..3 {
            f.publish(detail, Arc::new(MeshUpdate::empty_for_test(seq)));
        }
        // Only the newest is there to read: the subscriber skipped 0 and 1.
        let latest = sub.rx.borrow_and_update().clone().unwrap();
        assert_eq!(latest.seq, 2);
        // A new subscriber starts at the newest frame too.
        f.publish(detail, Arc::new(MeshUpdate::empty_for_test(3)));
        let late = f.subscribe(detail);
        assert_eq!(late.rx.borrow().as_ref().unwrap().seq, 3);
        drop(late);
        // A cleared channel holds nothing for the next subscriber.
        f.clear(detail);
        assert!(f.subscribe(detail).rx.borrow().is_none());
        drop(sub);
        assert!(!f.interest(detail));
    }
}
