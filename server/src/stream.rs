//! Mesh streams: the topology message, then encoded frames (`core::codec`), for a live
//! subscription or a batch; or for a palette subscription or job (issues 18, 45) the palette header, then
//! palette frames (`core::codec::palette`: codec frames of lanes, keyframes and deltas like
//! vertex frames).
//!
//! A subscription waits on its level's fan-out receiver, polled by the transport's own task,
//! so it always sends the newest frame and skips what it was too slow for (`Frame.skipped`
//! counts them). Frames are encoded
//! once by the room's pipeline; the task sends the shared delta when it has the delta's base,
//! else the frame's shared keyframe ([`MeshUpdate::frame_for`], encoded on the blocking pool
//! the first time a subscriber needs it). A batch runs its frames through a private room, in
//! order, with a bounded response buffer; a refused frame ends it with a status naming the
//! frame by index in its details (`crate::status::batch`, whatever the refusal).
//!
//! A stream that ends early ends with a typed [`StreamError`]; the transports turn it into
//! their status (`crate::status::stream`).

use std::sync::Arc;
use std::time::Instant;

use crease_proto::{
    Level, TopologyParts, actor_frame, actors_frame_message, frame_message, name_actor,
    topology_message, v1,
};
use prost::bytes::Bytes;
use tokio::sync::mpsc;
use tokio_stream::Stream;
use tokio_stream::wrappers::ReceiverStream;

use crate::ingest::{self, PublishError};
use crate::pipeline::Pipeline;
use crate::room::{Channel, Encoding, MeshUpdate, Room, Subscription};
use crate::state::AppState;

/// Frames buffered per batch stream: one in flight, one ready.
const BUFFER: usize = 2;

/// Why a mesh stream ended early.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// The model's palette header at the stream's level cannot be built.
    #[error("{0}")]
    PaletteHeader(String),
    /// Encoding a frame or the index buffer failed, or its blocking task died: a server bug.
    #[error("{what}: {message}")]
    Internal {
        /// What was being built.
        what: &'static str,
        /// The failure.
        message: String,
    },
    /// A batch's frame `index` was refused.
    #[error("frame {index}: {error}")]
    Batch {
        /// The frame's index in the batch.
        index: usize,
        /// Why.
        error: PublishError,
    },
}

/// A [`StreamError::Internal`] of `what` from any error.
fn internal<E: std::fmt::Display>(what: &'static str) -> impl Fn(E) -> StreamError {
    move |e| StreamError::Internal {
        what,
        message: e.to_string(),
    }
}

/// The first messages of a mesh stream on `channel`: a vertex stream's topology, or a palette
/// stream's header (built once per model and level on the blocking pool, then shared); in a
/// room of several actors one per actor, named (`crease_proto::name_actor`).
async fn first_messages(
    room: &Arc<Room>,
    channel: Channel,
) -> Result<Vec<v1::MeshFrame>, StreamError> {
    let actors = room.actors();
    let mut messages = Vec::with_capacity(actors.len());
    for (i, actor) in actors.iter().enumerate() {
        let mut message = match channel.encoding {
            Encoding::Vertices => topology(actor.pipeline(), &actor.model.name, channel.level)?,
            Encoding::Palette => {
                let (model, level) = (Arc::clone(&actor.model), channel.level);
                tokio::task::spawn_blocking(move || model.palette_topology(level))
                    .await
                    .map_err(internal("palette header"))?
                    .map_err(StreamError::PaletteHeader)?
            }
        };
        if room.has_actors() {
            name_actor(&mut message, actor.name(), i, actors.len());
        }
        messages.push(message);
    }
    Ok(messages)
}

/// The first message of a vertex stream of `pipeline`'s frames on model `model`.
fn topology(pipeline: &Pipeline, model: &str, level: Level) -> Result<v1::MeshFrame, StreamError> {
    let p = pipeline;
    let indices = p.encoded_indices(level).map_err(internal("index buffer"))?;
    Ok(topology_message(TopologyParts {
        model,
        level,
        vertex_count: p.vertex_count(level),
        triangle_count: p.triangles(level).len(),
        indices: &indices,
        qbox: p.qbox(level),
        vertex_order: p.vertex_order(level),
    }))
}

/// The message of `update` for a subscriber whose last received codec frames (one per actor)
/// are `last_sent` (updated): one frame's data in a one-actor room, every actor's in a room of
/// several (`named`).
async fn frame_for(
    update: &Arc<MeshUpdate>,
    last_sent: &mut [Option<u32>],
    named: bool,
    latency: u32,
    skipped: u32,
) -> Result<v1::MeshFrame, StreamError> {
    if !named {
        let data = bytes_for(update, &mut last_sent[0]).await?;
        return Ok(frame_message(
            update.seq,
            update.capture_time_us,
            latency,
            skipped,
            data,
        ));
    }
    let mut actors = Vec::with_capacity(update.actor_count());
    for (i, last) in last_sent.iter_mut().enumerate().take(update.actor_count()) {
        let frame = update.actor(i);
        actors.push(actor_frame(
            i,
            bytes_for(frame, last).await?,
            frame.held,
            frame.placement,
        ));
    }
    Ok(actors_frame_message(
        update.seq,
        update.capture_time_us,
        latency,
        skipped,
        actors,
    ))
}

/// The bytes of `update` for a subscriber whose last received codec frame is `last_sent`
/// (updated): shared with the other subscribers, not copied. A keyframe the subscriber needs
/// is encoded on the blocking pool.
async fn bytes_for(
    update: &Arc<MeshUpdate>,
    last_sent: &mut Option<u32>,
) -> Result<Bytes, StreamError> {
    let bytes = if update.fits(*last_sent) {
        update.frame_for(*last_sent)
    } else {
        let (u, last) = (Arc::clone(update), *last_sent);
        tokio::task::spawn_blocking(move || u.frame_for(last))
            .await
            .map_err(internal("encoding"))?
    }
    .map_err(internal("encoding"))?;
    *last_sent = Some(update.codec_seq());
    Ok(bytes)
}

/// The encoded frame bytes a frame message carries (every actor's).
fn frame_bytes(msg: &v1::MeshFrame) -> usize {
    match &msg.body {
        Some(v1::mesh_frame::Body::Frame(f)) => {
            f.data.len() + f.actors.iter().map(|a| a.data.len()).sum::<usize>()
        }
        _ => 0,
    }
}

/// The live stream of a room's `channel` through `sub`, a subscription taken from the room
/// (module docs).
///
/// The stream is polled by the transport's own task (hyper's connection task for gRPC, the
/// WebSocket session's writer): a frame wakes that one task, which builds the message and
/// writes it, with no task or queue of its own between the room's channel and the socket
/// (issue 41: the fan-out's cost per viewer-frame against a plain write's). It ends when the
/// room closes (after a frame already waiting), when the server shuts down, and when the
/// transport drops it (the subscriber went away: its subscriber slot is given back then).
pub fn subscribe(
    state: Arc<AppState>,
    room: Arc<Room>,
    channel: Channel,
    sub: Subscription,
) -> impl Stream<Item = Result<v1::MeshFrame, StreamError>> + Send + 'static {
    let gauge = state.metrics().subscribers.clone();
    gauge.inc();
    let ended = {
        let (closing, closed) = (state.closing(), room.closed());
        Box::pin(async move {
            tokio::select! {
                () = closing => {}
                () = closed => {}
            }
        })
    };
    let live = Live {
        state,
        named: room.has_actors(),
        last_sent: vec![None; room.actors().len()],
        room,
        channel,
        sub,
        step: Step::First,
        first: Vec::new().into_iter(),
        last_seq: None,
        ended,
        _gauge: SubscriberGauge(gauge),
    };
    futures_util::stream::unfold(live, |mut live| async move {
        let item = live.next().await?;
        Some((item, live))
    })
}

/// Where a live stream is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    /// The first messages are still to be built.
    First,
    /// Sending the first messages, then frames.
    Frames,
    /// Ended.
    Done,
}

/// Holds one unit of the subscribers gauge while the stream lives.
#[derive(Debug)]
struct SubscriberGauge(prometheus_client::metrics::gauge::Gauge);

impl Drop for SubscriberGauge {
    fn drop(&mut self) {
        self.0.dec();
    }
}

/// A live stream's state between the frames it sends ([`subscribe`]).
struct Live {
    state: Arc<AppState>,
    room: Arc<Room>,
    channel: Channel,
    // The whole subscription is held: its subscriber slot is given back when the stream drops.
    sub: Subscription,
    step: Step,
    /// First messages not yet sent.
    first: std::vec::IntoIter<v1::MeshFrame>,
    /// A room of several actors: frames carry every actor's, named.
    named: bool,
    last_seq: Option<u64>,
    /// Per actor, the codec frame this subscriber received last.
    last_sent: Vec<Option<u32>>,
    /// The server shutting down or the room closing.
    ended: std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>,
    _gauge: SubscriberGauge,
}

impl Live {
    /// The stream's next message; `None` once it has ended.
    async fn next(&mut self) -> Option<Result<v1::MeshFrame, StreamError>> {
        loop {
            match self.step {
                Step::Done => return None,
                Step::First => match first_messages(&self.room, self.channel).await {
                    Ok(messages) => {
                        self.first = messages.into_iter();
                        self.step = Step::Frames;
                        // The current frame first (if any), then every change.
                        self.sub.frames.rx.mark_changed();
                    }
                    Err(e) => {
                        self.step = Step::Done;
                        return Some(Err(e));
                    }
                },
                Step::Frames => {
                    if let Some(m) = self.first.next() {
                        return Some(Ok(m));
                    }
                    let rx = &mut self.sub.frames.rx;
                    // A closed room ends the stream after a frame already waiting.
                    tokio::select! {
                        biased;
                        changed = rx.changed() => if changed.is_err() {
                            self.step = Step::Done;
                            return None;
                        },
                        () = &mut self.ended => {
                            self.step = Step::Done;
                            return None;
                        }
                    }
                    let Some(update) = rx.borrow_and_update().clone() else {
                        continue;
                    };
                    let skipped = self
                        .last_seq
                        .map_or(0, |s| update.seq.saturating_sub(s + 1))
                        as u32;
                    self.last_seq = Some(update.seq);
                    let latency =
                        update.received.elapsed().as_micros().min(u32::MAX as u128) as u32;
                    let msg =
                        frame_for(&update, &mut self.last_sent, self.named, latency, skipped).await;
                    return Some(match msg {
                        Ok(msg) => {
                            let metrics = self.state.metrics();
                            metrics.bytes_out.inc_by(frame_bytes(&msg) as u64);
                            metrics.frames_out.inc();
                            Ok(msg)
                        }
                        Err(e) => {
                            self.step = Step::Done;
                            Err(e)
                        }
                    });
                }
            }
        }
    }
}

/// A batch: every control frame in order through `room` (module docs). A bad frame ends the
/// stream with `InvalidArgument` naming the frame (`FrameError.frame` in the details) and field.
pub fn batch(
    state: Arc<AppState>,
    room: Room,
    channel: Channel,
    frames: Vec<v1::ControlFrame>,
) -> impl Stream<Item = Result<v1::MeshFrame, StreamError>> + Send + 'static {
    let (tx, rx) = mpsc::channel(BUFFER);
    let room = Arc::new(room);
    tokio::spawn(async move {
        // A batch room has one actor: one first message.
        let first = first_messages(&room, channel).await.and_then(|m| {
            m.into_iter()
                .next()
                .ok_or_else(|| internal("topology")("no actor"))
        });
        let failed = first.is_err();
        if tx.send(first).await.is_err() || failed {
            return;
        }
        // A private room: nobody else subscribes.
        let mut sub = match room.subscribe(channel, 1) {
            Ok(sub) => sub,
            Err(e) => {
                let _ = tx.send(Err(internal("subscription")(e))).await;
                return;
            }
        };
        let mut last_sent: Option<u32> = None;
        for (k, frame) in frames.into_iter().enumerate() {
            let seq = frame.seq;
            let outcome = ingest::process(Arc::clone(&room), frame, Instant::now()).await;
            let latency = match outcome {
                Ok(p) => p.latency_us,
                Err(error) => {
                    let _ = tx.send(Err(StreamError::Batch { index: k, error })).await;
                    return;
                }
            };
            let Some(update) = sub.frames.rx.borrow_and_update().clone() else {
                continue;
            };
            let data = match bytes_for(&update, &mut last_sent).await {
                Ok(data) => data,
                Err(e) => {
                    let _ = tx.send(Err(e)).await;
                    return;
                }
            };
            drop(update);
            state.metrics().bytes_out.inc_by(data.len() as u64);
            state.metrics().frames_out.inc();
            let msg = frame_message(seq, 0, latency, 0, data);
            if tx.send(Ok(msg)).await.is_err() {
                return;
            }
        }
    });
    ReceiverStream::new(rx)
}
