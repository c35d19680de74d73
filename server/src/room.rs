//! A room: a live session on one model. Publishers send control frames; each frame is predicted
//! once (off the async threads: [`Room::publish`] is blocking and runs in `spawn_blocking`) and
//! handed to every subscriber through a `watch` channel, which keeps only the latest frame: a
//! slow or stalled subscriber skips frames and never delays the room or the others, and memory
//! stays one frame per level however many subscribers there are. The detail layer is
//! synthesised only while at least one subscriber asked for it, once per frame for all of them.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::runtime::predictor::{FrameContext, PredictError, Predictor};
use crease_proto::{WireError, read_control_frame, v1};
use tokio::sync::watch;

use crate::registry::LoadedModel;

/// One predicted mesh, shared by every subscriber of its level.
#[derive(Debug)]
pub struct MeshUpdate {
    /// The publisher's sequence number.
    pub seq: u64,
    /// The publisher's capture time, microseconds since the Unix epoch.
    pub capture_time_us: i64,
    /// When the control frame arrived.
    pub received: Instant,
    /// The vertices.
    pub positions: Vec<Vec3>,
}

/// What publishing one frame did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Published {
    /// Control points held (invalid or occluded).
    pub held: u32,
    /// Microseconds from arrival to the meshes being handed to the subscribers.
    pub latency_us: u32,
}

/// Errors of opening a room.
#[derive(Debug, thiserror::Error)]
pub enum RoomError {
    /// The room id is not 1-64 characters of `[A-Za-z0-9_-]`.
    #[error("room id {0:?}: expected 1-64 characters of A-Z, a-z, 0-9, _ and -")]
    BadId(String),
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
}

/// A live session on one model (module docs).
pub struct Room {
    /// The room id.
    pub id: String,
    /// The model.
    pub model: Arc<LoadedModel>,
    token: String,
    predictor: Predictor,
    state: Mutex<RoomState>,
    base: watch::Sender<Option<Arc<MeshUpdate>>>,
    detail: watch::Sender<Option<Arc<MeshUpdate>>>,
    detail_subscribers: Arc<AtomicUsize>,
    frames: AtomicU64,
}

impl std::fmt::Debug for Room {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Room")
            .field("id", &self.id)
            .field("model", &self.model.name)
            .field("frames", &self.frames.load(Ordering::Relaxed))
            .finish_non_exhaustive()
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
    /// publish token.
    pub fn open(id: &str, model: Arc<LoadedModel>, beta: Option<f32>) -> Result<Room, RoomError> {
        if !valid_room_id(id) {
            return Err(RoomError::BadId(id.to_owned()));
        }
        let predictor = Predictor::new(Arc::clone(&model.model), beta)?;
        let ctx = predictor.new_context();
        let n = model.model.controls.len();
        Ok(Room {
            id: id.to_owned(),
            token: new_token(),
            state: Mutex::new(RoomState {
                ctx,
                controls: vec![Vec3::ZERO; n],
                valid: vec![true; n],
            }),
            predictor,
            model,
            base: watch::channel(None).0,
            detail: watch::channel(None).0,
            detail_subscribers: Arc::new(AtomicUsize::new(0)),
            frames: AtomicU64::new(0),
        })
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

    /// Frames published so far.
    pub fn frames(&self) -> u64 {
        self.frames.load(Ordering::Relaxed)
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
        let positions = self
            .predictor
            .predict(&mut state.ctx, &state.controls, Some(&state.valid))
            .map_err(|e| WireError {
                field: "positions".into(),
                message: e.to_string(),
            })?
            .to_vec();
        let update = |positions| {
            Some(Arc::new(MeshUpdate {
                seq: frame.seq,
                capture_time_us: frame.capture_time_us,
                received,
                positions,
            }))
        };
        self.base.send_replace(update(positions));
        if self.detail_subscribers.load(Ordering::Relaxed) > 0
            && let Ok(detail) = self.predictor.predict_detail(&mut state.ctx)
        {
            self.detail.send_replace(update(detail.to_vec()));
        }
        self.frames.fetch_add(1, Ordering::Relaxed);
        Ok(Published {
            held: held as u32,
            latency_us: received.elapsed().as_micros().min(u32::MAX as u128) as u32,
        })
    }

    /// A subscription to `level` (the latest frame, then every frame as it comes, skipping what
    /// the subscriber was too slow for). Detail subscriptions switch the detail layer on while
    /// they live.
    pub fn subscribe(&self, level: Level) -> Subscription {
        match level {
            Level::Base => Subscription {
                rx: self.base.subscribe(),
                _detail: None,
            },
            Level::Detail => {
                self.detail_subscribers.fetch_add(1, Ordering::Relaxed);
                Subscription {
                    rx: self.detail.subscribe(),
                    _detail: Some(DetailGuard(Arc::clone(&self.detail_subscribers))),
                }
            }
        }
    }

    /// Whether the model has a detail layer.
    pub fn has_detail(&self) -> bool {
        self.model.model.detail.is_some()
    }

    /// The triangles of `level`'s mesh.
    pub fn triangles(&self, level: Level) -> &[[u32; 3]] {
        match level {
            Level::Base => &self.model.model.rig.rest.triangles,
            Level::Detail => self.predictor.detail_triangles().unwrap_or_default(),
        }
    }

    /// Subscribers currently receiving frames, per level (base, detail).
    pub fn subscriber_counts(&self) -> (usize, usize) {
        (self.base.receiver_count(), self.detail.receiver_count())
    }
}

/// A live subscription: the latest mesh of its level.
#[derive(Debug)]
pub struct Subscription {
    /// The channel; `borrow_and_update` gives the newest frame.
    pub rx: watch::Receiver<Option<Arc<MeshUpdate>>>,
    _detail: Option<DetailGuard>,
}

/// Counts a detail subscriber while it lives.
#[derive(Debug)]
struct DetailGuard(Arc<AtomicUsize>);

impl Drop for DetailGuard {
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
