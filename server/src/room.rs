//! A room: a live session on one model. Publishers send control frames; each frame is predicted
//! once (off the async threads: [`Room::publish`] is blocking and runs in `spawn_blocking`) and
//! handed to every subscriber through a `watch` channel, which keeps only the latest frame: a
//! slow or stalled subscriber skips frames and never delays the room or the others, and memory
//! stays one frame per level however many subscribers there are. The detail layer is
//! synthesised only while at least one subscriber asked for it, once per frame for all of them.
//!
//! Frames are encoded once, in the room, for everyone (`core::codec`): each [`MeshUpdate`]
//! carries the room encoder's frame (a keyframe, or a delta against the room's previous frame),
//! and a keyframe of the same frame made on demand (once, shared) for subscribers that did not
//! receive that previous frame (they joined late, or skipped it).

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Instant;

use crease_core::codec::{
    CodecError, DEFAULT_KEYFRAME_INTERVAL, FrameEncoder, FrameKind, QuantBox, encode_indices,
    encode_keyframe,
};
use crease_core::glam::Vec3;
use crease_core::model::ControlPoint;
use crease_core::predictor::{FrameContext, PredictError, Predictor};
use crease_core::runtime::filter::{OneEuro, OneEuroParams};
use crease_proto::{WireError, read_control_frame, v1};
use prost::bytes::Bytes;
use tokio::sync::watch;

use crate::registry::LoadedModel;

/// Quantisation box margin around the box of the model's training poses, as a fraction of its
/// largest side: new poses leave it a little (a position outside the box is clamped to it).
const BOX_MARGIN: f32 = 0.25;

/// How a room's meshes are streamed: quantisation bits per level and the vertex order.
///
/// Live rooms default to 12 bits for the base mesh: its half-step error (1/8190 of the padded
/// box, ~2e-4 of the model's size) is ~50x below the horse's prediction error (9.3e-3 RMS,
/// BENCHMARKS.md) and invisible at any viewing distance, and it brings the gallop to ~1.5
/// bytes per vertex per frame where 16 bits need ~3 (meshopt's vertex codec stores the low bits
/// of every moving vertex nearly verbatim: each bit costs ~3/8 byte per vertex). The detail
/// mesh carries wrinkles a few 1e-3 deep, so it keeps 14 bits. Batches (`Synthesize`) are for
/// pipelines and default to the full 16.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StreamSettings {
    /// Bits per coordinate of base frames, 1..=16.
    pub base_bits: u8,
    /// Bits per coordinate of detail frames, 1..=16.
    pub detail_bits: u8,
    /// Stream vertices in a spatial order (`Topology.vertex_order`): 7-10% smaller frames.
    pub spatial_order: bool,
    /// A keyframe every this many frames (0: only the first). Live rooms need few: a
    /// subscriber without the base of a delta (joined late, skipped frames) gets a keyframe of
    /// that frame on demand ([`MeshUpdate::frame_for`]), so periodic keyframes only bound how
    /// long a client that lost its state by itself waits.
    pub keyframe_interval: u32,
}

impl Default for StreamSettings {
    fn default() -> Self {
        Self {
            base_bits: 12,
            detail_bits: 14,
            spatial_order: true,
            // 10 s at 60 Hz: +0.1% bytes on the horse gallop, where every 30 frames costs +1%.
            keyframe_interval: 600,
        }
    }
}

impl StreamSettings {
    /// Full 16-bit precision at both levels (batches).
    pub fn full() -> Self {
        Self {
            base_bits: 16,
            detail_bits: 16,
            keyframe_interval: DEFAULT_KEYFRAME_INTERVAL,
            ..Self::default()
        }
    }
}

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
    frame: Bytes,
    /// This frame's codec sequence number.
    codec_seq: u32,
    /// The codec frame a delta applies to (`codec_seq` for a keyframe).
    base_seq: u32,
    qbox: QuantBox,
    /// The vertices, for the on-demand keyframe.
    positions: Vec<Vec3>,
    key: OnceLock<Result<Bytes, CodecError>>,
}

impl MeshUpdate {
    /// This frame's codec sequence number (what a subscriber passes back as `last_sent`).
    pub fn codec_seq(&self) -> u32 {
        self.codec_seq
    }

    /// The bytes to send a subscriber whose last received codec frame is `last_sent`: the
    /// shared frame when it is a keyframe or a delta against `last_sent`, else a keyframe of
    /// this frame (encoded once, on first need).
    pub fn frame_for(&self, last_sent: Option<u32>) -> Result<Bytes, CodecError> {
        if self.base_seq == self.codec_seq || last_sent == Some(self.base_seq) {
            return Ok(self.frame.clone());
        }
        self.key
            .get_or_init(|| {
                let mut out = Vec::new();
                encode_keyframe(&self.qbox, self.codec_seq, &self.positions, None, &mut out)
                    .map(|_| Bytes::from(out))
            })
            .clone()
    }
}

/// What publishing one frame did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Published {
    /// Control points held (invalid or occluded).
    pub held: u32,
    /// Microseconds from arrival to the meshes being handed to the subscribers.
    pub latency_us: u32,
    /// RMS distance between the frame's valid control points (as received, before any
    /// filter) and the predicted mesh's control vertices, model units; 0 with none valid.
    pub control_rms: f32,
}

/// Errors of opening a room.
#[derive(Debug, thiserror::Error)]
pub enum RoomError {
    /// The room id is not 1-64 characters of `[A-Za-z0-9_-]`.
    #[error("room id {0:?}: expected 1-64 characters of A-Z, a-z, 0-9, _ and -")]
    BadId(String),
    /// The model's meshes cannot be encoded (a degenerate box, too many vertices).
    #[error("frame encoder: {0}")]
    Codec(#[from] CodecError),
    /// The predictor could not be built (e.g. beta out of range).
    #[error(transparent)]
    Predictor(#[from] PredictError),
}

/// Which mesh a subscriber wants.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// The skinned base mesh.
    Base,
    /// The detail layer on top (models with one).
    Detail,
}

struct RoomState {
    ctx: FrameContext,
    controls: Vec<Vec3>,
    valid: Vec<bool>,
    base_encoder: FrameEncoder,
    detail_encoder: FrameEncoder,
    /// One filter per control point (empty when the room does not filter).
    filters: Vec<OneEuro>,
    /// The previous frame's capture time and arrival, for the filter's time step.
    last_time: Option<(i64, Instant)>,
    /// Per level, the positions buffer of a frame no subscriber holds any more, reused for
    /// the next frame (a detail frame is 1.8 MB: allocating it per frame costs page faults).
    spare: [Vec<Vec3>; 2],
}

/// A live session on one model (module docs).
pub struct Room {
    /// The room id.
    pub id: String,
    /// The model.
    pub model: Arc<LoadedModel>,
    token: String,
    base_qbox: QuantBox,
    detail_qbox: QuantBox,
    /// Whether vertices stream in the model's spatial orders ([`LoadedModel::spatial`],
    /// [`LoadedModel::detail_spatial`]).
    spatial: bool,
    /// The One Euro filter on control points, if the room smooths them.
    filter: Option<OneEuroParams>,
    predictor: Predictor,
    state: Mutex<RoomState>,
    base: watch::Sender<Option<Arc<MeshUpdate>>>,
    detail: watch::Sender<Option<Arc<MeshUpdate>>>,
    /// Live subscriptions of both levels (the subscriber limit).
    subscribers: Arc<AtomicUsize>,
    /// Accepted control frames.
    published: AtomicU64,
    detail_subscribers: Arc<AtomicUsize>,
    /// The publish rate limit's token bucket.
    budget: Mutex<Budget>,
    /// Each level's index buffer, meshopt-encoded once on first need (every subscriber's
    /// topology message carries it).
    indices: [OnceLock<Result<Bytes, CodecError>>; 2],
}

/// A token bucket: `tokens` frames may be published now; it refills at the rate limit, up to a
/// quarter second's worth.
#[derive(Debug)]
struct Budget {
    tokens: f64,
    at: Instant,
}

/// The room is full: its subscriber limit is reached.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("room is full: {0} subscribers, the limit")]
pub struct RoomFull(pub usize);

impl std::fmt::Debug for Room {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Room")
            .field("id", &self.id)
            .field("model", &self.model.name)
            .finish_non_exhaustive()
    }
}

/// Keeps the positions buffer of `old` in `spare` when nobody else holds the frame (a
/// subscriber still sending it keeps its `Arc`; the buffer is then freed with the last one).
fn recycle(old: Option<Arc<MeshUpdate>>, spare: &mut Vec<Vec3>) {
    if let Some(update) = old.and_then(|u| Arc::try_unwrap(u).ok()) {
        *spare = update.positions;
    }
}

/// RMS over the valid control points of the distance between the received point `i`
/// (`x, y, z` in `targets`, the frame's wire positions) and the predicted position of control
/// vertex `i`; 0 when none is valid.
fn control_residual(
    controls: &[ControlPoint],
    predicted: &[Vec3],
    targets: &[f32],
    valid: &[bool],
) -> f32 {
    let (sum, n) = controls
        .iter()
        .zip(targets.chunks_exact(3).zip(valid))
        .filter(|(_, (_, ok))| **ok)
        .fold((0.0f64, 0usize), |(s, n), (c, (t, _))| {
            let d = predicted[c.vertex as usize].distance_squared(Vec3::new(t[0], t[1], t[2]));
            (s + f64::from(d), n + 1)
        });
    if n == 0 {
        0.0
    } else {
        (sum / n as f64).sqrt() as f32
    }
}

/// Whether `id` is a valid room id.
pub fn valid_room_id(id: &str) -> bool {
    (1..=64).contains(&id.len())
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
}

impl Room {
    /// Opens a room on `model` with `beta` (the model's default when `None`) and a fresh random
    /// publish token, streaming as `settings` says.
    pub fn open(
        id: &str,
        model: Arc<LoadedModel>,
        beta: Option<f32>,
        settings: StreamSettings,
    ) -> Result<Room, RoomError> {
        if !valid_room_id(id) {
            return Err(RoomError::BadId(id.to_owned()));
        }
        let predictor = Predictor::new(Arc::clone(&model.model), beta)?;
        let ctx = predictor.new_context();
        let n = model.model.controls.len();
        let (lo, hi) = model.pose_bounds;
        let base_qbox = QuantBox::from_bounds(lo, hi, BOX_MARGIN, settings.base_bits)?;
        let detail_qbox = QuantBox::from_bounds(lo, hi, BOX_MARGIN, settings.detail_bits)?;
        let encoder =
            |vertices, qbox| FrameEncoder::new(vertices, qbox, settings.keyframe_interval);
        let rest = &model.model.rig.rest;
        let base_encoder = encoder(rest.vertex_count(), base_qbox)?;
        let detail_encoder = encoder(model.model.detail_vertex_count().unwrap_or(0), detail_qbox)?;
        Ok(Room {
            id: id.to_owned(),
            token: new_token(),
            base_qbox,
            detail_qbox,
            spatial: settings.spatial_order,
            filter: None,
            state: Mutex::new(RoomState {
                ctx,
                controls: vec![Vec3::ZERO; n],
                valid: vec![true; n],
                base_encoder,
                detail_encoder,
                filters: Vec::new(),
                last_time: None,
                spare: [Vec::new(), Vec::new()],
            }),
            predictor,
            model,
            base: watch::channel(None).0,
            detail: watch::channel(None).0,
            subscribers: Arc::new(AtomicUsize::new(0)),
            published: AtomicU64::new(0),
            detail_subscribers: Arc::new(AtomicUsize::new(0)),
            budget: Mutex::new(Budget {
                tokens: f64::INFINITY,
                at: Instant::now(),
            }),
            indices: [OnceLock::new(), OnceLock::new()],
        })
    }

    /// Replaces the publish token (an operator's fixed token, e.g. `--demo-token`).
    pub fn with_token(mut self, token: &str) -> Self {
        token.clone_into(&mut self.token);
        self
    }

    /// Smooths every frame's control points with a One Euro filter (mocap rooms; `None`, the
    /// default, passes them through as UI rooms need).
    ///
    /// # Panics
    /// If `params` is not [valid](OneEuroParams::is_valid) (callers check what users send).
    pub fn with_filter(mut self, params: Option<OneEuroParams>) -> Self {
        assert!(
            params.is_none_or(|p| p.is_valid()),
            "invalid filter {params:?}"
        );
        self.filter = params;
        let n = self.model.model.controls.len();
        let state = self.state.get_mut().unwrap_or_else(|e| e.into_inner());
        state.filters = params.map_or_else(Vec::new, |p| vec![OneEuro::new(p); n]);
        self
    }

    /// The room's control-point filter.
    pub fn filter(&self) -> Option<OneEuroParams> {
        self.filter
    }

    /// Frames published into this room so far (accepted ones).
    pub fn published(&self) -> u64 {
        self.published.load(Ordering::Relaxed)
    }

    /// The publish token.
    pub fn token(&self) -> &str {
        &self.token
    }

    /// Whether `presented` is this room's publish token (compared in constant time).
    pub fn accepts(&self, presented: Option<&str>) -> bool {
        presented.is_some_and(|p| constant_time_eq(p.as_bytes(), self.token.as_bytes()))
    }

    /// The translation-solve beta of this room.
    pub fn beta(&self) -> f32 {
        self.predictor.beta()
    }

    /// The quantisation box of `level`'s frames.
    pub fn qbox(&self, level: Level) -> &QuantBox {
        match level {
            Level::Base => &self.base_qbox,
            Level::Detail => &self.detail_qbox,
        }
    }

    /// Streamed vertex `i` of `level` is model vertex `order[i]`; empty: the model's order.
    pub fn vertex_order(&self, level: Level) -> &[u32] {
        match level {
            Level::Base if self.spatial => &self.model.spatial().order,
            Level::Detail if self.spatial => self
                .model
                .detail_spatial()
                .map_or(&[], |s| s.order.as_slice()),
            Level::Base | Level::Detail => &[],
        }
    }

    /// Vertices of `level`'s mesh.
    pub fn vertex_count(&self, level: Level) -> usize {
        match level {
            Level::Base => self.model.model.rig.rest.vertex_count(),
            Level::Detail => self.model.model.detail_vertex_count().unwrap_or(0),
        }
    }

    /// Predicts one control frame and hands the meshes to the subscribers. Blocking (run it off
    /// the async threads). A bad frame changes nothing.
    ///
    /// # Errors
    /// The [`WireError`] of the frame (count, non-finite valid point, mask length).
    pub fn publish(
        &self,
        frame: &v1::ControlFrame,
        received: Instant,
    ) -> Result<Published, WireError> {
        let mut guard = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let state = &mut *guard;
        let held = read_control_frame(frame, &mut state.controls, &mut state.valid)?;
        if !state.filters.is_empty() {
            // The time step: capture times when the publisher sends increasing ones, else
            // arrival times.
            let dt = match state.last_time {
                Some((t, _)) if frame.capture_time_us > t => {
                    (frame.capture_time_us - t) as f32 * 1e-6
                }
                Some((_, at)) => received.duration_since(at).as_secs_f32(),
                None => 0.0,
            };
            state.last_time = Some((frame.capture_time_us, received));
            for ((f, p), ok) in state
                .filters
                .iter_mut()
                .zip(state.controls.iter_mut())
                .zip(&state.valid)
            {
                if *ok {
                    *p = f.filter(*p, dt);
                } else {
                    f.reset();
                }
            }
        }
        let internal = |what: &str, e: &dyn std::fmt::Display| WireError {
            field: what.into(),
            message: e.to_string(),
        };
        let predicted = self
            .predictor
            .predict(&mut state.ctx, &state.controls, Some(&state.valid))
            .map_err(|e| internal("positions", &e))?;
        let control_rms = control_residual(
            &self.model.model.controls,
            predicted,
            &frame.positions,
            &state.valid,
        );
        // One level's frame: the mesh in the streamed order (into the level's spare buffer;
        // the vector stays with the frame for on-demand keyframes), encoded and handed to the
        // level's subscribers; the frame it replaces gives its buffer back when nobody holds it.
        let send = |tx: &watch::Sender<Option<Arc<MeshUpdate>>>,
                    encoder: &mut FrameEncoder,
                    spare: &mut Vec<Vec3>,
                    order: &[u32],
                    mesh: &[Vec3]| {
            let mut positions = std::mem::take(spare);
            positions.clear();
            if order.is_empty() {
                positions.extend_from_slice(mesh);
            } else {
                positions.extend(order.iter().map(|&m| mesh[m as usize]));
            }
            let qbox = *encoder.qbox();
            let mut bytes = Vec::new();
            let header = encoder
                .encode(&positions, None, &mut bytes)
                .map_err(|e| internal("encoding", &e))?;
            let old = tx.send_replace(Some(Arc::new(MeshUpdate {
                seq: frame.seq,
                capture_time_us: frame.capture_time_us,
                received,
                frame: Bytes::from(bytes),
                codec_seq: header.seq,
                base_seq: match header.kind {
                    FrameKind::Key => header.seq,
                    FrameKind::Delta => header.base_seq,
                },
                qbox,
                positions,
                key: OnceLock::new(),
            })));
            recycle(old, spare);
            Ok::<_, WireError>(())
        };
        let [base_spare, detail_spare] = &mut state.spare;
        send(
            &self.base,
            &mut state.base_encoder,
            base_spare,
            self.vertex_order(Level::Base),
            predicted,
        )?;
        if self.detail_subscribers.load(Ordering::Relaxed) > 0
            && let Ok(detail) = self.predictor.predict_detail(&mut state.ctx)
        {
            send(
                &self.detail,
                &mut state.detail_encoder,
                detail_spare,
                self.vertex_order(Level::Detail),
                detail,
            )?;
        }
        self.published.fetch_add(1, Ordering::Relaxed);
        Ok(Published {
            held: held as u32,
            latency_us: received.elapsed().as_micros().min(u32::MAX as u128) as u32,
            control_rms,
        })
    }

    /// Whether one more frame may be published now under a limit of `rate_hz` frames per
    /// second (bursts up to a quarter second's worth, at least one frame). Counts the frame.
    pub fn admit(&self, rate_hz: f64) -> bool {
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return true;
        }
        let burst = (rate_hz / 4.0).max(1.0);
        let mut b = self.budget.lock().unwrap_or_else(|e| e.into_inner());
        let now = Instant::now();
        b.tokens = (b.tokens + now.duration_since(b.at).as_secs_f64() * rate_hz).min(burst);
        b.at = now;
        if b.tokens >= 1.0 {
            b.tokens -= 1.0;
            true
        } else {
            false
        }
    }

    /// Live subscriptions (both levels).
    pub fn subscriber_count(&self) -> usize {
        self.subscribers.load(Ordering::Relaxed)
    }

    /// A subscription to `level` (the latest frame, then every frame as it comes, skipping what
    /// the subscriber was too slow for), if fewer than `max` subscriptions are live. Detail
    /// subscriptions switch the detail layer on while they live.
    ///
    /// # Errors
    /// [`RoomFull`] at `max` live subscriptions.
    pub fn subscribe(&self, level: Level, max: usize) -> Result<Subscription, RoomFull> {
        let taken = self
            .subscribers
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < max).then_some(n + 1)
            });
        if let Err(n) = taken {
            return Err(RoomFull(n));
        }
        let slot = CountGuard(Arc::clone(&self.subscribers));
        Ok(match level {
            Level::Base => Subscription {
                rx: self.base.subscribe(),
                _slot: slot,
                _detail: None,
            },
            Level::Detail => {
                self.detail_subscribers.fetch_add(1, Ordering::Relaxed);
                Subscription {
                    rx: self.detail.subscribe(),
                    _slot: slot,
                    _detail: Some(CountGuard(Arc::clone(&self.detail_subscribers))),
                }
            }
        })
    }

    /// Whether the model has a detail layer.
    pub fn has_detail(&self) -> bool {
        self.model.model.detail.is_some()
    }

    /// `level`'s triangles through meshopt's index codec (encoded once, then shared).
    ///
    /// # Errors
    /// The codec's, if a triangle indexes past the vertex count.
    pub fn encoded_indices(&self, level: Level) -> Result<Bytes, CodecError> {
        let slot = match level {
            Level::Base => &self.indices[0],
            Level::Detail => &self.indices[1],
        };
        slot.get_or_init(|| {
            let mut out = Vec::new();
            encode_indices(self.triangles(level), self.vertex_count(level), &mut out)
                .map(|()| Bytes::from(out))
        })
        .clone()
    }

    /// The triangles of `level`'s mesh, in the streamed vertex order.
    pub fn triangles(&self, level: Level) -> &[[u32; 3]] {
        match level {
            Level::Base if self.spatial => &self.model.spatial().triangles,
            Level::Base => &self.model.model.rig.rest.triangles,
            Level::Detail => match self.model.detail_spatial() {
                Some(s) if self.spatial => &s.triangles,
                _ => self.predictor.detail_triangles().unwrap_or_default(),
            },
        }
    }
}

/// A live subscription: the latest mesh of its level.
#[derive(Debug)]
pub struct Subscription {
    /// The channel; `borrow_and_update` gives the newest frame.
    pub rx: watch::Receiver<Option<Arc<MeshUpdate>>>,
    _slot: CountGuard,
    _detail: Option<CountGuard>,
}

/// Holds one unit of a counter while it lives.
#[derive(Debug)]
struct CountGuard(Arc<AtomicUsize>);

impl Drop for CountGuard {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// A random 128-bit token, hex.
pub fn new_token() -> String {
    let bytes: [u8; 16] = rand::random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn room_ids_and_tokens() {
        assert!(valid_room_id("demo"));
        assert!(valid_room_id("a-b_C9"));
        assert!(!valid_room_id(""));
        assert!(!valid_room_id("a b"));
        assert!(!valid_room_id(&"x".repeat(65)));
        let (a, b) = (new_token(), new_token());
        assert_eq!(a.len(), 32);
        assert_ne!(a, b);
        assert!(constant_time_eq(a.as_bytes(), a.as_bytes()));
        assert!(!constant_time_eq(a.as_bytes(), b.as_bytes()));
        assert!(!constant_time_eq(b"ab", b"abc"));
    }
}
