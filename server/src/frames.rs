//! The encoded frames a room hands out, and their pool. The pipeline fills a [`MeshUpdate`]
//! per level and frame, the fan-out passes it on, each subscriber's stream sends it; a
//! subscriber that lacks a delta's base gets a keyframe of that same frame, encoded on demand
//! from the quantised lanes the encoder kept with it ([`MeshUpdate::frame_for`]), so it is
//! bit-identical to what the deltas' decoders hold.
//!
//! A level's `FramePool` recycles a frame's encoded bytes and lanes once nobody holds it:
//! after warm-up a frame allocates nothing, even while a slow subscriber still holds an older
//! frame (it simply holds another slot).

use std::sync::{Arc, OnceLock};
use std::time::Instant;

use crease_core::codec::{
    CodecError, FrameHeader, FrameKind, QuantBox, encode_keyframe_from_lanes,
};
use prost::bytes::{Bytes, BytesMut};

/// Most frames a level's pool keeps. A frame is held by the fan-out (the newest) and by each
/// subscriber task while it sends one (a stalled one holds its frame until it reads again), so
/// a pool needs about two slots plus one per stalled subscriber; past this many, frames are
/// allocated and dropped as before (counted in [`FramePool::fresh`]).
const POOL_SLOTS: usize = 32;
/// Every this many frames (30 s at 60 Hz) a pool gives back the free slots above what that
/// stretch needed at most ([`TRIM_SLACK`] more): a burst of lagging subscribers (a fault's CPU
/// spike, viewers arriving from a dead replica) grows a pool, and without this its memory
/// stayed at the burst's high-water for the room's life (the chaos soak's RSS steps,
/// RELIABILITY.md). At a steady load the need does not change, so nothing is given back and
/// nothing allocated.
const TRIM_EVERY: u32 = 1800;
/// See [`TRIM_EVERY`].
const TRIM_SLACK: usize = 2;

/// One predicted mesh, encoded once and shared by every subscriber of its level.
#[derive(Debug)]
pub struct MeshUpdate {
    /// The publisher's sequence number.
    pub seq: u64,
    /// The publisher's capture time, microseconds since the Unix epoch.
    pub capture_time_us: i64,
    /// When the control frame arrived.
    pub received: Instant,
    /// The room encoder's frame: a keyframe, or a delta against codec frame `base_seq`.
    pub(crate) frame: Bytes,
    /// Where `frame` lives: the rest of the slot's buffer, reclaimed for the next frame once
    /// nobody holds `frame` any more.
    pub(crate) buffer: BytesMut,
    /// This frame's codec sequence number.
    pub(crate) codec_seq: u32,
    /// The codec frame a delta applies to (`codec_seq` for a keyframe).
    pub(crate) base_seq: u32,
    pub(crate) qbox: QuantBox,
    /// The encoder's quantised lanes of this frame, for the on-demand keyframe.
    pub(crate) lanes: Vec<[u16; 4]>,
    pub(crate) key: OnceLock<Result<Bytes, CodecError>>,
    /// The actor was missing from the control frame and holds its last pose (a room of
    /// several actors, issue 38).
    pub held: bool,
    /// Where the actor's mesh sits in its performer's frame this instant (a retargeting actor
    /// of a named performer, once the performer's registration is fixed; `crate::room`).
    pub placement: Option<crease_proto::ActorPlace>,
    /// A room of several actors: this is actor 0's frame, and these are the other actors'
    /// frames of the same instant, in the room's actor order (each a frame of its own actor's
    /// stream, with its own codec sequence). Empty in a one-actor room.
    pub(crate) others: Vec<Arc<MeshUpdate>>,
}

impl MeshUpdate {
    /// An empty slot for frames in `qbox` (filled by [`FramePool::fill`]).
    fn empty(qbox: QuantBox) -> MeshUpdate {
        MeshUpdate {
            seq: 0,
            capture_time_us: 0,
            received: Instant::now(),
            frame: Bytes::new(),
            buffer: BytesMut::new(),
            codec_seq: 0,
            base_seq: 0,
            qbox,
            lanes: Vec::new(),
            key: OnceLock::new(),
            held: false,
            placement: None,
            others: Vec::new(),
        }
    }

    /// A frame with only a sequence number (fan-out tests).
    #[cfg(test)]
    pub(crate) fn empty_for_test(seq: u64) -> MeshUpdate {
        let qbox = QuantBox::from_min_step(
            crease_core::glam::Vec3::ZERO,
            crease_core::glam::Vec3::ONE,
            16,
        )
        .expect("a valid box");
        MeshUpdate {
            seq,
            ..MeshUpdate::empty(qbox)
        }
    }

    /// The room encoder's frame as it was encoded (a keyframe or a delta), shared.
    pub(crate) fn encoded(&self) -> Bytes {
        self.frame.clone()
    }

    /// Takes the codec sequence numbers of the encoded frame's `header`.
    pub(crate) fn set_codec_header(&mut self, header: &FrameHeader) {
        self.codec_seq = header.seq;
        self.base_seq = match header.kind {
            FrameKind::Key => header.seq,
            FrameKind::Delta => header.base_seq,
        };
    }

    /// Actor `i`'s frame of this instant (0: this one).
    ///
    /// # Panics
    /// Past [`MeshUpdate::actor_count`].
    pub fn actor(self: &Arc<Self>, i: usize) -> &Arc<MeshUpdate> {
        match i {
            0 => self,
            i => &self.others[i - 1],
        }
    }

    /// How many actors' frames this holds (1 in a one-actor room).
    pub fn actor_count(&self) -> usize {
        1 + self.others.len()
    }

    /// This frame's codec sequence number (what a subscriber passes back as `last_sent`).
    pub fn codec_seq(&self) -> u32 {
        self.codec_seq
    }

    /// Whether a subscriber whose last received codec frame is `last_sent` can take the shared
    /// frame (a keyframe, or a delta against `last_sent`); else it needs the keyframe.
    pub fn fits(&self, last_sent: Option<u32>) -> bool {
        self.base_seq == self.codec_seq || last_sent == Some(self.base_seq)
    }

    /// The bytes to send a subscriber whose last received codec frame is `last_sent`: the
    /// shared frame when it [fits](Self::fits), else a keyframe of this frame's lanes (encoded
    /// once, on first need; blocking, so callers off the executor when it may be needed).
    pub fn frame_for(&self, last_sent: Option<u32>) -> Result<Bytes, CodecError> {
        if self.fits(last_sent) {
            return Ok(self.frame.clone());
        }
        self.key
            .get_or_init(|| {
                let mut out = Vec::new();
                encode_keyframe_from_lanes(&self.qbox, self.codec_seq, &self.lanes, false, &mut out)
                    .map(|_| Bytes::from(out))
            })
            .clone()
    }
}

/// A level's pool of frames (module docs).
#[derive(Debug, Default)]
pub(crate) struct FramePool {
    slots: Vec<Arc<MeshUpdate>>,
    /// Slot to try first: the one after the last used, so a just-published frame (held by the
    /// fan-out) is not looked at first.
    next: usize,
    /// Frames, byte buffers and lane buffers allocated (or grown) so far.
    fresh: u64,
    /// Frames filled since the last trim, and the most slots held at once meanwhile (counting
    /// the one being filled).
    fills: u32,
    /// See `fills`.
    peak_held: usize,
}

impl FramePool {
    /// Allocations so far: flat after warm-up (what the pool's test observes).
    #[cfg(test)]
    pub(crate) fn fresh(&self) -> u64 {
        self.fresh
    }

    /// Notes how many slots are held now (plus the one about to be filled) and, every
    /// [`TRIM_EVERY`] frames, drops the free slots above the stretch's need. Only a slot no one
    /// else holds is dropped (its count is 1: nobody can clone it meanwhile).
    fn trim(&mut self) {
        let held = self
            .slots
            .iter()
            .filter(|s| Arc::strong_count(s) > 1)
            .count();
        self.peak_held = self.peak_held.max(held + 1);
        self.fills += 1;
        if self.fills < TRIM_EVERY {
            return;
        }
        let keep = self.peak_held + TRIM_SLACK;
        let mut extra = self.slots.len().saturating_sub(keep);
        if extra > 0 {
            self.slots.retain(|s| {
                let drop = extra > 0 && Arc::strong_count(s) == 1 && Arc::weak_count(s) == 0;
                extra -= usize::from(drop);
                !drop
            });
            self.next = 0;
        }
        self.fills = 0;
        self.peak_held = 0;
    }

    /// Fills a frame nobody holds with `encoded` (the encoder's output) and `lanes` (its
    /// quantised lanes) and returns it to publish.
    pub(crate) fn fill(
        &mut self,
        qbox: QuantBox,
        encoded: &[u8],
        lanes: &[[u16; 4]],
        fill: impl FnOnce(&mut MeshUpdate),
    ) -> Arc<MeshUpdate> {
        self.trim();
        let n = self.slots.len();
        let free = (0..n)
            .map(|k| (self.next + k) % n.max(1))
            .find(|&i| Arc::get_mut(&mut self.slots[i]).is_some());
        let i = match free {
            Some(i) => i,
            None if n < POOL_SLOTS => {
                self.fresh += 1;
                self.slots.push(Arc::new(MeshUpdate::empty(qbox)));
                n
            }
            None => {
                // Every slot held: replace one (its holders keep theirs).
                self.fresh += 1;
                let i = self.next % n;
                self.slots[i] = Arc::new(MeshUpdate::empty(qbox));
                i
            }
        };
        self.next = i + 1;
        let u = Arc::get_mut(&mut self.slots[i]).expect("a free slot: checked or made above");
        // Give back this slot's old frame, then reuse its buffer if nobody holds any of it.
        u.frame = Bytes::new();
        u.key.take();
        u.others.clear();
        u.held = false;
        u.placement = None;
        if !u.buffer.try_reclaim(encoded.len()) {
            self.fresh += 1;
            // Room for a few frames of this size: the buffer is split per frame and reclaimed
            // whole; spare room lets a slightly larger frame fit without a new buffer.
            u.buffer = BytesMut::with_capacity(2 * encoded.len());
        }
        u.buffer.extend_from_slice(encoded);
        u.frame = u.buffer.split().freeze();
        if u.lanes.capacity() < lanes.len() {
            self.fresh += 1;
        }
        u.lanes.clear();
        u.lanes.extend_from_slice(lanes);
        u.qbox = qbox;
        fill(u);
        Arc::clone(&self.slots[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fanout::{Channel, Fanout, LocalFanout};
    use crease_proto::Level;

    #[test]
    fn the_pool_allocates_nothing_after_warm_up_while_a_subscriber_holds_an_old_frame() {
        let qbox = QuantBox::from_min_step(
            crease_core::glam::Vec3::ZERO,
            crease_core::glam::Vec3::ONE,
            16,
        )
        .unwrap();
        let fanout = LocalFanout::default();
        let mut slow = fanout.subscribe(Channel::vertices(Level::Base));
        let mut fast = fanout.subscribe(Channel::vertices(Level::Base));
        let mut pool = FramePool::default();
        // Frame `i`: its bytes are `i` repeated (a size that varies), its lanes `i` too.
        let encoded = |i: u64| vec![i as u8; 200 + (i as usize * 37) % 100];
        let lanes = |i: u64| vec![[i as u16, 1, 2, 0]; 64];
        let publish = |pool: &mut FramePool, i: u64| {
            let u = pool.fill(qbox, &encoded(i), &lanes(i), |u| u.seq = i);
            fanout.publish(Channel::vertices(Level::Base), u);
        };
        for i in 0..4 {
            publish(&mut pool, i);
        }
        // The slow subscriber takes frame 3 and holds it (and its bytes, as a message in
        // flight would) from here on.
        let old = slow.rx.borrow_and_update().clone().unwrap();
        let old_bytes = old.frame_for(Some(old.codec_seq())).unwrap();
        for i in 4..8 {
            publish(&mut pool, i);
        }
        let warm = pool.fresh();
        assert!(warm > 0, "the pool allocated its first frames");
        for i in 8..200 {
            publish(&mut pool, i);
            // A fast subscriber reads every frame and lets it go.
            let f = fast.rx.borrow_and_update().clone().unwrap();
            assert_eq!(f.seq, i);
            assert_eq!(f.frame_for(Some(f.codec_seq())).unwrap(), encoded(i));
            assert_eq!(f.lanes, lanes(i));
        }
        assert_eq!(pool.fresh(), warm, "allocations after warm-up");
        // The held frame was never overwritten.
        assert_eq!(old.seq, 3);
        assert_eq!(old_bytes, encoded(3));
        assert_eq!(old.lanes, lanes(3));
        assert!(pool.slots.len() <= 4, "{} slots", pool.slots.len());
    }

    #[test]
    fn a_pool_gives_back_what_a_burst_took_and_never_a_held_frame() {
        let qbox = QuantBox::from_min_step(
            crease_core::glam::Vec3::ZERO,
            crease_core::glam::Vec3::ONE,
            16,
        )
        .unwrap();
        let mut pool = FramePool::default();
        let fill = |pool: &mut FramePool, i: u64| {
            pool.fill(qbox, &[i as u8; 100], &[[i as u16, 0, 0, 0]; 16], |u| {
                u.seq = i
            })
        };
        let mut seq = 0;
        // A burst: 12 frames held at once (subscribers lagging), then let go, except one that
        // a stalled subscriber keeps.
        let mut burst: Vec<Arc<MeshUpdate>> = (0..12)
            .map(|_| {
                seq += 1;
                fill(&mut pool, seq)
            })
            .collect();
        assert_eq!(pool.slots.len(), 12);
        let stalled = burst.remove(5);
        let stalled_seq = stalled.seq;
        drop(burst);
        // Steady again: one frame held at a time (the fan-out's newest). The period the burst
        // fell in keeps what it needed; the next one gives it back.
        let mut newest = None;
        for _ in 0..2 * TRIM_EVERY {
            seq += 1;
            newest = Some(fill(&mut pool, seq));
        }
        // Kept: the stretch's most held at once (the stalled frame, the newest and the one
        // being filled, 3) plus the slack; the burst's other slots are gone.
        assert!(
            pool.slots.len() <= 3 + TRIM_SLACK,
            "{} slots after the trim",
            pool.slots.len()
        );
        assert!(pool.slots.len() >= 3);
        // The stalled subscriber's frame is still its own, and still in the pool.
        assert_eq!(stalled.seq, stalled_seq);
        assert!(pool.slots.iter().any(|s| Arc::ptr_eq(s, &stalled)));
        // At this steady load the next trim period allocates nothing.
        let before = pool.fresh();
        for _ in 0..TRIM_EVERY + 10 {
            seq += 1;
            newest = Some(fill(&mut pool, seq));
        }
        assert_eq!(pool.fresh(), before, "allocations at a steady load");
        assert_eq!(newest.map(|n| n.seq), Some(seq));
    }
}
