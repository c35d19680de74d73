//! Mesh streams: the topology message, then encoded frames (`core::codec`), for a live
//! subscription or a batch; or for a palette subscription (issue 18) the palette header, then
//! palette frames (`core::codec::palette`: codec frames of lanes, keyframes and deltas like
//! vertex frames).
//!
//! A subscription's task waits on its level's fan-out receiver, so it always sends the newest
//! frame and skips what it was too slow for (`Frame.skipped` counts them). Frames are encoded
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

/// Frames buffered per mesh stream: one in flight, one ready.
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
pub fn subscribe(
    state: Arc<AppState>,
    room: Arc<Room>,
    channel: Channel,
    sub: Subscription,
) -> impl Stream<Item = Result<v1::MeshFrame, StreamError>> + Send + 'static {
    let (tx, rx) = mpsc::channel(BUFFER);
    let receiver_gone = tx.clone();
    let closing = state.closing();
    let gauge = state.metrics().subscribers.clone();
    let stream = async move {
        // The whole subscription moves in (a closure would capture only `sub.frames.rx`, and
        // the subscriber slot would be given back at once).
        let mut sub = sub;
        let metrics = state.metrics();
        match first_messages(&room, channel).await {
            Ok(messages) => {
                for m in messages {
                    if tx.send(Ok(m)).await.is_err() {
                        return;
                    }
                }
            }
            Err(e) => {
                let _ = tx.send(Err(e)).await;
                return;
            }
        }
        let named = room.has_actors();
        let mut last_seq: Option<u64> = None;
        let mut last_sent = vec![None; room.actors().len()];
        let rx = &mut sub.frames.rx;
        // The current frame first (if any), then every change.
        rx.mark_changed();
        // A closed room ends the stream (after a frame already waiting).
        let closed = room.closed();
        tokio::pin!(closed);
        loop {
            tokio::select! {
                biased;
                changed = rx.changed() => if changed.is_err() { break },
                () = &mut closed => break,
            }
            let Some(update) = rx.borrow_and_update().clone() else {
                continue;
            };
            let skipped = last_seq.map_or(0, |s| update.seq.saturating_sub(s + 1)) as u32;
            last_seq = Some(update.seq);
            let latency = update.received.elapsed().as_micros().min(u32::MAX as u128) as u32;
            let msg = match frame_for(&update, &mut last_sent, named, latency, skipped).await {
                Ok(msg) => msg,
                Err(e) => {
                    let _ = tx.send(Err(e)).await;
                    return;
                }
            };
            metrics.bytes_out.inc_by(frame_bytes(&msg) as u64);
            metrics.frames_out.inc();
            // The frame goes back to its pool once sent, not while this task waits.
            drop(update);
            if tx.send(Ok(msg)).await.is_err() {
                return;
            }
        }
    };
    // The stream ends (and its sender drops) when the server shuts down, even while it waits
    // for a frame or for a subscriber who stopped reading; and when the subscriber goes away,
    // even while no frames come (its subscriber slot is given back then).
    tokio::spawn(async move {
        gauge.inc();
        tokio::select! {
            () = stream => {}
            () = closing => {}
            () = receiver_gone.closed() => {}
        }
        gauge.dec();
    });
    ReceiverStream::new(rx)
}

/// A batch: every control frame in order through `room` (module docs). A bad frame ends the
/// stream with `InvalidArgument` naming the frame (`FrameError.frame` in the details) and field.
pub fn batch(
    state: Arc<AppState>,
    room: Room,
    level: Level,
    frames: Vec<v1::ControlFrame>,
) -> impl Stream<Item = Result<v1::MeshFrame, StreamError>> + Send + 'static {
    let (tx, rx) = mpsc::channel(BUFFER);
    let room = Arc::new(room);
    tokio::spawn(async move {
        let first = topology(room.pipeline(), &room.model.name, level);
        let failed = first.is_err();
        if tx.send(first).await.is_err() || failed {
            return;
        }
        // A private room: nobody else subscribes.
        let Ok(mut sub) = room.subscribe(Channel::vertices(level), 1) else {
            return;
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
