//! A room's cluster side on one replica: [`RoomLink`], which is also the room's fan-out. On the
//! owner it hands each level's frame to the local subscribers and, while another replica is
//! interested, to NATS (`crease.frames.<room>.<channel>`, one copy per frame however many
//! relay it; a channel is a level in an encoding, `crate::fanout::Channel`); it takes relays'
//! interest and keyframe requests. On a relay it subscribes to the frames of the channels its
//! local subscribers watch, decodes them (so that it holds the lanes a late
//! viewer's keyframe is made from, `crate::frames`) and fans them out through the same local,
//! latest-wins channel; it announces its interest so that the owner synthesises detail only
//! while someone watches it.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crease_core::codec::{CodecError, FrameDecoder, FrameHeader};
use crease_proto::cluster::interest;
use crease_proto::{
    ActorPlace, Encoding, Level, actor_frame, actors_frame_message, frame_message, v1,
};
use futures_util::StreamExt;
use futures_util::future::BoxFuture;
use prost::Message as _;
use tokio::sync::{Notify, mpsc};
use tokio::task::JoinHandle;

use super::trust::{self, EpochGate, Refusal};
use super::{Cluster, Host, subject};
use crate::fanout::{Channel, Fanout, LocalFanout, Receiver};
use crate::frames::{FramePool, MeshUpdate};

/// How long an interest announcement holds; relays repeat theirs every [`ANNOUNCE`].
pub(crate) const INTEREST_TTL: Duration = Duration::from_secs(3);
/// How often a relay with subscribers repeats its interest.
const ANNOUNCE: Duration = Duration::from_secs(1);
/// A relay stops relaying a level this long after its last local subscriber of it left.
const RELAY_LINGER: Duration = Duration::from_secs(2);
/// Frames queued for NATS per room before the newest are dropped (the relays' decoders then
/// ask for a keyframe).
const OUT_QUEUE: usize = 8;
/// Relayed frames up to this size are decoded on the relay's task; larger ones on the
/// blocking pool.
const INLINE_DECODE_BYTES: usize = 32 << 10;
/// A relay asks the owner for a keyframe at most this often per level.
const KEY_REQUEST_EVERY: Duration = Duration::from_millis(200);

/// What a relay keeps per channel: per actor of the room (one in a one-actor room), the
/// decoder of the owner's stream (a palette stream is a codec stream of lanes too) and the
/// pool its frames are republished from.
#[derive(Debug)]
struct RelayLevel {
    decoders: Vec<FrameDecoder>,
    pools: Vec<FramePool>,
    /// A room of several actors' frame: its actors' headers and the others' frames while it
    /// is republished (reused per frame).
    headers: Vec<FrameHeader>,
    others: Vec<Arc<MeshUpdate>>,
}

/// A room's cluster side (module docs).
#[derive(Debug)]
pub struct RoomLink {
    room: String,
    cluster: Arc<Cluster>,
    local: LocalFanout,
    /// This replica predicts the room's frames.
    owner: AtomicBool,
    /// The owner's lease is confirmed since the last (re)connection to NATS: only then may it
    /// publish frames into the cluster (fencing: a replica back from a partition renews, or
    /// learns it was replaced, before it sends anything).
    confirmed: AtomicBool,
    /// The registry revision this replica last wrote or saw for the room (compare-and-set).
    revision: AtomicU64,
    /// The registry entry, as this replica last wrote or read it.
    entry: Mutex<v1::RoomEntry>,
    /// The newest ownership epoch seen of the room (the registry's, believed frames'): older
    /// frames and acks are refused (`trust`).
    gate: EpochGate,
    /// When this replica last renewed (or took) its lease as owner: past a lease since, it
    /// sends no frame (it may have been paused or cut off, and replaced meanwhile).
    renewed: Mutex<Instant>,
    /// Other replicas' interest per channel: replica -> until when.
    remote: Mutex<[HashMap<String, Instant>; Channel::COUNT]>,
    key_wanted: [AtomicBool; Channel::COUNT],
    out: mpsc::Sender<(Channel, Arc<MeshUpdate>)>,
    relay: [Mutex<RelayLevel>; Channel::COUNT],
    wake: Notify,
    /// The tasks of the room's cluster side: the frame sender and the relay loop (always), the
    /// owner's services (while it owns the room), a relay's subscriptions.
    tasks: Mutex<Vec<JoinHandle<()>>>,
    owner_tasks: Mutex<Vec<JoinHandle<()>>>,
}

/// Why a relayed frame was not fanned out.
#[derive(Debug, thiserror::Error)]
pub(crate) enum RelayError {
    /// Not a `MeshFrame` with a frame.
    #[error("relayed message: {0}")]
    Message(String),
    /// The frame does not decode against what this relay holds (a frame was lost, or the
    /// relay joined mid-stream): it needs a keyframe.
    #[error("relayed frame: {0}")]
    Codec(#[from] CodecError),
}

impl RoomLink {
    /// The cluster side of room `room`, with `vertices` per actor and channel (its frames'
    /// vertex or lane vertex count, `crate::pipeline::frame_vertices`), as `owner`
    /// or relay, at registry `revision`; its background tasks start with [`RoomLink::start`].
    pub(crate) fn new(
        cluster: &Arc<Cluster>,
        room: &str,
        vertices: &[[usize; Channel::COUNT]],
        entry: v1::RoomEntry,
        owner: bool,
        revision: u64,
    ) -> (Arc<RoomLink>, mpsc::Receiver<(Channel, Arc<MeshUpdate>)>) {
        let (out, rx) = mpsc::channel(OUT_QUEUE);
        let relay = std::array::from_fn(|c| {
            Mutex::new(RelayLevel {
                decoders: vertices.iter().map(|v| FrameDecoder::new(v[c])).collect(),
                pools: vertices.iter().map(|_| FramePool::default()).collect(),
                headers: Vec::with_capacity(vertices.len()),
                others: Vec::with_capacity(vertices.len()),
            })
        });
        let link = Arc::new(RoomLink {
            room: room.to_owned(),
            cluster: Arc::clone(cluster),
            local: LocalFanout::default(),
            owner: AtomicBool::new(owner),
            confirmed: AtomicBool::new(owner),
            revision: AtomicU64::new(revision),
            gate: {
                let gate = EpochGate::default();
                gate.note(entry.epoch);
                gate
            },
            entry: Mutex::new(entry),
            renewed: Mutex::new(Instant::now()),
            remote: Mutex::new(std::array::from_fn(|_| HashMap::new())),
            key_wanted: std::array::from_fn(|_| AtomicBool::new(false)),
            out,
            relay,
            wake: Notify::new(),
            tasks: Mutex::new(Vec::new()),
            owner_tasks: Mutex::new(Vec::new()),
        });
        (link, rx)
    }

    /// Starts the frame sender (frames from `rx` to NATS) and the relay loop; and the owner's
    /// services if this replica owns the room.
    pub(crate) fn start(
        self: &Arc<Self>,
        host: &Arc<dyn Host>,
        rx: mpsc::Receiver<(Channel, Arc<MeshUpdate>)>,
    ) {
        let sender = tokio::spawn(Arc::clone(self).send_frames(rx));
        let relay = tokio::spawn(Arc::clone(self).relay_loop());
        lock(&self.tasks).extend([sender, relay]);
        if self.is_owner() {
            self.start_owner(host);
        }
    }

    /// The room id.
    pub fn room(&self) -> &str {
        &self.room
    }

    /// Whether this replica predicts the room's frames.
    pub fn is_owner(&self) -> bool {
        self.owner.load(Ordering::Acquire)
    }

    /// The registry entry as this replica last wrote or read it, and its revision.
    pub fn entry(&self) -> (v1::RoomEntry, u64) {
        (
            lock(&self.entry).clone(),
            self.revision.load(Ordering::Acquire),
        )
    }

    /// Records the registry's `entry` at `revision` (a renewal, or what the watch saw).
    pub(crate) fn set_entry(&self, entry: v1::RoomEntry, revision: u64) {
        self.gate.note(entry.epoch);
        *lock(&self.entry) = entry;
        self.revision.store(revision, Ordering::Release);
    }

    /// The owner renewed its lease just now.
    pub(crate) fn renewed(&self) {
        *lock(&self.renewed) = Instant::now();
    }

    /// Whether this replica, as owner, last renewed its lease a lease ago or longer (fencing:
    /// it was paused or cut off, and may have been replaced).
    pub(crate) fn lease_lapsed(&self) -> bool {
        lock(&self.renewed).elapsed() >= self.cluster.lease
    }

    /// The newest ownership epoch this replica has seen of the room.
    pub(crate) fn epoch_seen(&self) -> u64 {
        self.gate.seen()
    }

    /// Notes an epoch a believed message (an ack) carried.
    pub(crate) fn note_epoch(&self, epoch: u64) {
        self.gate.note(epoch);
    }

    /// Whether the owner's lease is confirmed since the last reconnection.
    pub(crate) fn is_confirmed(&self) -> bool {
        self.confirmed.load(Ordering::Acquire)
    }

    /// The lease is confirmed (a renewal succeeded) or unconfirmed (NATS reconnected).
    pub(crate) fn set_confirmed(&self, confirmed: bool) {
        self.confirmed.store(confirmed, Ordering::Release);
    }

    /// This replica now owns the room, at registry `revision`: it predicts, publishes into the
    /// cluster, serves forwarded controls; the next frame of each level is a keyframe (the
    /// relays' decoders hold the previous owner's frames).
    pub(crate) fn become_owner(
        self: &Arc<Self>,
        host: &Arc<dyn Host>,
        entry: v1::RoomEntry,
        revision: u64,
    ) {
        self.set_entry(entry, revision);
        for w in &self.key_wanted {
            w.store(true, Ordering::Release);
        }
        self.renewed();
        self.confirmed.store(true, Ordering::Release);
        if !self.owner.swap(true, Ordering::AcqRel) {
            self.start_owner(host);
        }
        self.wake.notify_one();
    }

    /// This replica no longer owns the room (another adopted it): it stops publishing into the
    /// cluster and relays the new owner's frames to its local subscribers.
    pub(crate) fn yield_ownership(&self) {
        if self.owner.swap(false, Ordering::AcqRel) {
            self.confirmed.store(false, Ordering::Release);
            for t in lock(&self.owner_tasks).drain(..) {
                t.abort();
            }
            tracing::warn!(room = %self.room, replica = %self.cluster.replica, "room adopted by another replica: relaying it");
        }
        self.wake.notify_one();
    }

    /// Stops every task of the room's cluster side (the room was closed).
    pub(crate) fn shutdown(&self) {
        for t in lock(&self.owner_tasks)
            .drain(..)
            .chain(lock(&self.tasks).drain(..))
        {
            t.abort();
        }
    }

    fn remote_interest(&self, channel: Channel) -> bool {
        let now = Instant::now();
        let mut remote = lock(&self.remote);
        let map = &mut remote[channel.index()];
        map.retain(|_, until| *until > now);
        !map.is_empty()
    }

    /// Owner: the services of an owned room: other replicas' interest, their keyframe requests
    /// and their forwarded control frames.
    fn start_owner(self: &Arc<Self>, host: &Arc<dyn Host>) {
        let interest = tokio::spawn(Arc::clone(self).take_interest());
        let keyframes = tokio::spawn(Arc::clone(self).take_keyframe_requests());
        let controls = tokio::spawn(super::control::serve(
            Arc::clone(host),
            Arc::clone(&self.cluster),
            self.room.clone(),
        ));
        lock(&self.owner_tasks).extend([interest, keyframes, controls]);
    }

    async fn take_interest(self: Arc<Self>) {
        let client = &self.cluster.client;
        let Ok(mut sub) = client.subscribe(subject::interest(&self.room)).await else {
            return;
        };
        while let Some(msg) = sub.next().await {
            let Ok(i) = v1::Interest::decode(msg.payload.as_ref()) else {
                continue;
            };
            let (Ok(level), Ok(encoding)) = (
                Level::from_wire("Interest", i.level),
                Encoding::from_wire("Interest", i.encoding),
            ) else {
                continue;
            };
            let channel = Channel::new(level, encoding);
            let ttl = Duration::from_millis(u64::from(i.ttl_ms)).min(INTEREST_TTL * 2);
            lock(&self.remote)[channel.index()].insert(i.replica, Instant::now() + ttl);
        }
    }

    async fn take_keyframe_requests(self: Arc<Self>) {
        let client = &self.cluster.client;
        let Ok(mut sub) = client.subscribe(subject::keyframe(&self.room, "*")).await else {
            return;
        };
        while let Some(msg) = sub.next().await {
            let name = msg.subject.rsplit('.').next().unwrap_or_default();
            if let Some(c) = Channel::ALL.iter().find(|c| c.name() == name) {
                self.key_wanted[c.index()].store(true, Ordering::Release);
            }
        }
    }

    /// Owner: sends each frame handed over by [`Fanout::publish`] to NATS.
    async fn send_frames(self: Arc<Self>, mut rx: mpsc::Receiver<(Channel, Arc<MeshUpdate>)>) {
        let subjects = Channel::ALL.map(|c| subject::frames(&self.room, c));
        let metrics = &self.cluster.metrics;
        while let Some((channel, update)) = rx.recv().await {
            // Checked again here: a frame queued before NATS went away must not be sent after
            // it comes back (async-nats would buffer it), when this replica may have been
            // replaced.
            if !(self.is_owner() && self.is_confirmed() && self.cluster.is_connected()) {
                continue;
            }
            // Fencing (issue 40): an owner whose last renewal is a lease old was paused or cut
            // off and may have been replaced; it sends nothing until it renews (or learns it
            // lost the room). Relays drop a replaced owner's epoch anyway.
            if self.lease_lapsed() {
                metrics.fenced_frames.inc();
                continue;
            }
            let latency = update.received.elapsed().as_micros().min(u32::MAX as u128) as u32;
            let msg = if update.actor_count() > 1 {
                // A room of several actors: every actor's frame of the instant in one message.
                let actors = (0..update.actor_count())
                    .map(|i| {
                        let a = update.actor(i);
                        actor_frame(i, a.encoded(), a.held, a.placement)
                    })
                    .collect();
                actors_frame_message(update.seq, update.capture_time_us, latency, 0, actors)
            } else {
                frame_message(
                    update.seq,
                    update.capture_time_us,
                    latency,
                    0,
                    update.encoded(),
                )
            };
            drop(update);
            let payload = msg.encode_to_vec();
            metrics.nats_frames_out.inc();
            metrics.nats_bytes_out.inc_by(payload.len() as u64);
            let subject = &subjects[channel.index()];
            let epoch = lock(&self.entry).epoch;
            let headers = trust::frame_headers(
                self.cluster.key.as_ref(),
                subject,
                &self.cluster.replica,
                epoch,
                &payload,
            );
            if self
                .cluster
                .client
                .publish_with_headers(subject.clone(), headers, payload.into())
                .await
                .is_err()
            {
                tracing::debug!(room = %self.room, "frame not sent: NATS unavailable");
            }
        }
    }

    /// Relay: keeps a subscription to each channel its local subscribers watch (ending it a
    /// little after the last leaves), and announces that interest to the owner.
    async fn relay_loop(self: Arc<Self>) {
        let mut relays: [Option<JoinHandle<()>>; Channel::COUNT] = Default::default();
        let mut announced = [None::<Instant>; Channel::COUNT];
        let mut watched = [None::<Instant>; Channel::COUNT];
        let mut tick = tokio::time::interval(Duration::from_millis(250));
        loop {
            tokio::select! {
                _ = tick.tick() => {}
                () = self.wake.notified() => {}
            }
            let owner = self.is_owner();
            for channel in Channel::ALL {
                let i = channel.index();
                let now = Instant::now();
                let local = self.local.interest(channel);
                if local {
                    watched[i] = Some(now);
                }
                let wanted = !owner && watched[i].is_some_and(|t| now - t < RELAY_LINGER);
                if wanted && relays[i].as_ref().is_none_or(JoinHandle::is_finished) {
                    relays[i] = Some(tokio::spawn(Arc::clone(&self).relay_channel(channel)));
                    announced[i] = None;
                } else if !wanted && let Some(task) = relays[i].take() {
                    task.abort();
                    lock(&self.relay[i])
                        .decoders
                        .iter_mut()
                        .for_each(FrameDecoder::reset);
                }
                if wanted && local && announced[i].is_none_or(|t| now - t >= ANNOUNCE) {
                    announced[i] = Some(now);
                    let interest = interest(
                        &self.cluster.replica,
                        channel.level,
                        channel.encoding,
                        INTEREST_TTL.as_millis() as u32,
                    );
                    let _ = self
                        .cluster
                        .client
                        .publish(
                            subject::interest(&self.room),
                            interest.encode_to_vec().into(),
                        )
                        .await;
                }
            }
        }
    }

    /// Relay: the owner's frames of `channel`, decoded and fanned out locally.
    async fn relay_channel(self: Arc<Self>, channel: Channel) {
        let client = &self.cluster.client;
        let Ok(mut sub) = client.subscribe(subject::frames(&self.room, channel)).await else {
            return;
        };
        let key_subject = subject::keyframe(&self.room, channel.name());
        let mut asked: Option<Instant> = None;
        // Joining mid-stream: the next frame is most likely a delta.
        let _ = client.publish(key_subject.clone(), "".into()).await;
        let subject = subject::frames(&self.room, channel);
        while let Some(msg) = sub.next().await {
            if let Err(refusal) = self.believe_frame(&subject, &msg) {
                let m = &self.cluster.metrics;
                match refusal {
                    Refusal::Forged => m.refused_forged_frames.inc(),
                    Refusal::Stale => m.refused_stale_frames.inc(),
                };
                continue;
            }
            let bytes = msg.payload.len() as u64;
            // A small frame decodes in tens of microseconds (the horse: 12 KB, ~30 µs), less
            // than a hand-off to the blocking pool costs in latency; a large one (a detail
            // frame) goes to the blocking pool.
            let relayed = if msg.payload.len() <= INLINE_DECODE_BYTES {
                Ok(self.relay_frame(channel, msg.payload))
            } else {
                let link = Arc::clone(&self);
                tokio::task::spawn_blocking(move || link.relay_frame(channel, msg.payload)).await
            };
            match relayed {
                Ok(Ok(())) => {
                    self.cluster.metrics.relayed_frames.inc();
                    self.cluster.metrics.relayed_bytes.inc_by(bytes);
                }
                Ok(Err(RelayError::Codec(_))) => {
                    if asked.is_none_or(|t| t.elapsed() >= KEY_REQUEST_EVERY) {
                        asked = Some(Instant::now());
                        let _ = client.publish(key_subject.clone(), "".into()).await;
                    }
                }
                Ok(Err(e)) => tracing::warn!(room = %self.room, "{e}"),
                Err(e) => tracing::error!(room = %self.room, "relay task: {e}"),
            }
        }
    }

    /// Relay: whether a frame from NATS is the room's owner's (`trust`): its tag holds (with a
    /// cluster key), its epoch is not older than one seen, and at the registry's epoch it
    /// names the registry's owner (a newer epoch is an adoption this replica has not read
    /// yet).
    fn believe_frame(&self, subject: &str, msg: &async_nats::Message) -> Result<(), Refusal> {
        let (owner, epoch) = trust::check_frame(
            self.cluster.key.as_ref(),
            subject,
            msg.headers.as_ref(),
            &msg.payload,
        )?;
        {
            let entry = lock(&self.entry);
            if epoch <= entry.epoch && owner != entry.owner {
                return Err(if epoch < entry.epoch {
                    Refusal::Stale
                } else {
                    Refusal::Forged
                });
            }
        }
        self.gate.admit(epoch)
    }

    /// Relay: decodes one of the owner's frames and fans it out (blocking: run it on the
    /// blocking pool).
    ///
    /// # Errors
    /// [`RelayError`]; nothing is fanned out then.
    pub(crate) fn relay_frame(
        &self,
        channel: Channel,
        payload: prost::bytes::Bytes,
    ) -> Result<(), RelayError> {
        // Decoded from the message's own `Bytes`: `Frame.data` is a `Bytes` field, so it is a
        // slice of the payload, not a copy (the pool below copies it once, into its slot).
        let msg = v1::MeshFrame::decode(payload).map_err(|e| RelayError::Message(e.to_string()))?;
        let Some(v1::mesh_frame::Body::Frame(frame)) = msg.body else {
            return Err(RelayError::Message("not a frame".into()));
        };
        let mut guard = lock(&self.relay[channel.index()]);
        let relay = &mut *guard;
        // The frame's age at the owner, carried on: a viewer here sees the owner's latency plus
        // the relay's.
        let received = Instant::now()
            .checked_sub(Duration::from_micros(u64::from(frame.server_latency_us)))
            .unwrap_or_else(Instant::now);
        let stamp = |u: &mut MeshUpdate| {
            u.seq = frame.seq;
            u.capture_time_us = frame.capture_time_us;
            u.received = received;
        };
        let update = if frame.actors.is_empty() {
            let header = relay.decoders[0].decode(&frame.data)?;
            relay.pools[0].fill(header.qbox, &frame.data, relay.decoders[0].lanes(), |u| {
                stamp(u);
                u.set_codec_header(&header);
            })
        } else {
            // A room of several actors: every actor decoded by its own decoder (all of them,
            // before anything is fanned out), republished from its own pool; actor 0's frame
            // carries the others', as the owner's pipeline hands them out.
            let n = relay.decoders.len();
            if frame.actors.len() != n
                || frame
                    .actors
                    .iter()
                    .enumerate()
                    .any(|(i, a)| a.actor as usize != i)
            {
                return Err(RelayError::Message(format!(
                    "a frame of {} actors, the room has {n}",
                    frame.actors.len()
                )));
            }
            let RelayLevel {
                decoders,
                pools,
                headers,
                others,
            } = relay;
            headers.clear();
            others.clear();
            for (a, decoder) in frame.actors.iter().zip(decoders.iter_mut()) {
                headers.push(decoder.decode(&a.data)?);
            }
            for k in 1..n {
                let (a, h) = (&frame.actors[k], &headers[k]);
                others.push(pools[k].fill(h.qbox, &a.data, decoders[k].lanes(), |u| {
                    stamp(u);
                    u.held = a.held;
                    u.placement = a.placement.as_ref().and_then(ActorPlace::from_wire);
                    u.set_codec_header(h);
                }));
            }
            let (a, h) = (&frame.actors[0], &headers[0]);
            pools[0].fill(h.qbox, &a.data, decoders[0].lanes(), |u| {
                stamp(u);
                u.held = a.held;
                u.placement = a.placement.as_ref().and_then(ActorPlace::from_wire);
                u.set_codec_header(h);
                u.others.append(others);
            })
        };
        drop(guard);
        self.local.publish(channel, update);
        Ok(())
    }
}

impl Fanout for RoomLink {
    fn publish(&self, channel: Channel, frame: Arc<MeshUpdate>) {
        // A frame this replica predicted is the room's only while it owns it: one that
        // finishes after another replica adopted the room (this one was stopped mid-frame)
        // would reach the local viewers after the adopter's newer ones, and so would one of an
        // owner whose lease lapsed while connected (paused, not cut off: a cut-off owner keeps
        // serving its own clients). Found by the chaos soak.
        if !self.is_owner() || (self.cluster.is_connected() && self.lease_lapsed()) {
            self.cluster.metrics.fenced_frames.inc();
            return;
        }
        if self.is_confirmed()
            && self.cluster.is_connected()
            && self.remote_interest(channel)
            && self.out.try_send((channel, Arc::clone(&frame))).is_err()
        {
            self.cluster.metrics.nats_frames_dropped.inc();
        }
        self.local.publish(channel, frame);
    }

    fn clear(&self, channel: Channel) {
        self.local.clear(channel);
    }

    fn subscribe(&self, channel: Channel) -> Receiver {
        let r = self.local.subscribe(channel);
        self.wake.notify_one();
        r
    }

    fn interest(&self, channel: Channel) -> bool {
        self.local.interest(channel) || (self.is_owner() && self.remote_interest(channel))
    }

    fn wants_keyframe(&self, channel: Channel) -> bool {
        self.key_wanted[channel.index()].swap(false, Ordering::AcqRel)
    }

    fn relays(&self) -> bool {
        !self.is_owner()
    }

    fn forward(
        &self,
        frame: v1::ControlFrame,
    ) -> BoxFuture<'static, Result<v1::PublishAck, String>> {
        Box::pin(super::control::forward(
            Arc::clone(&self.cluster),
            self.room.clone(),
            frame,
        ))
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
