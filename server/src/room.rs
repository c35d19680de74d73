//! A room: a live session on one model, the small struct that ties its three parts together:
//! the [`Session`] (token, limits, counters), the [`Pipeline`] (filter, predictor,
//! encoders, frame pools) and the [`Fanout`] (latest-wins delivery per level). Control frames
//! reach it through [`crate::ingest`]; subscribers leave it through [`crate::stream`].

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use crease_core::runtime::filter::OneEuroParams;
use crease_proto::room::RoomSettings;
use crease_proto::v1;

pub use crate::fanout::Channel;
pub use crate::frames::MeshUpdate;
pub use crate::pipeline::{BuildError, Published, RoomOptions, StreamSettings};
pub use crate::session::{RoomFull, new_token, valid_room_id};
pub use crease_proto::{Encoding, Level};

use crate::fanout::{self, Fanout, LocalFanout};
use crate::mailbox::{Mailbox, Outcome};
use crate::pipeline::{Pipeline, PipelineError};
use crate::registry::LoadedModel;
use crate::session::{CountGuard, Session};

/// Errors of opening a room.
#[derive(Debug, thiserror::Error)]
pub enum RoomError {
    /// The room id is not 1-64 characters of `[A-Za-z0-9_-]`.
    #[error("room id {0:?}: expected 1-64 characters of A-Z, a-z, 0-9, _ and -")]
    BadId(String),
    /// The pipeline could not be built.
    #[error(transparent)]
    Build(#[from] BuildError),
    /// The blocking task building it panicked.
    #[error("building the room: {0}")]
    Panicked(String),
}

/// A channel a room cannot serve ([`Room::check_channel`]): says why.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct ChannelRefused(pub String);

/// A live session on one model (module docs).
pub struct Room {
    /// The room id.
    pub id: String,
    /// The model.
    pub model: Arc<LoadedModel>,
    session: Session,
    pipeline: Pipeline,
    fanout: Arc<dyn Fanout>,
    /// Control frames waiting for the pipeline, latest wins ([`Room::submit`]).
    mailbox: Mailbox<(v1::ControlFrame, Instant), Result<Published, PipelineError>>,
    /// A private room (a take's replay, `crate::takes`): not listed in `/api/rooms`.
    private: bool,
    /// Set when the room leaves the server's room table: a publisher holding the room (a
    /// WebSocket session) is refused from then on, as one looking it up would be.
    closed: AtomicBool,
    /// Frames the pipeline ran through (counted here, after the pipeline: the session is
    /// entered once per frame, before it).
    published: AtomicU64,
}

impl std::fmt::Debug for Room {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Room")
            .field("id", &self.id)
            .field("model", &self.model.name)
            .finish_non_exhaustive()
    }
}

/// A live subscription: the latest mesh of its level, and a subscriber slot of its room.
#[derive(Debug)]
pub struct Subscription {
    /// The level's frames.
    pub frames: fanout::Receiver,
    _slot: CountGuard,
}

impl Room {
    /// Builds a room on `model` with `options` (beta, filter, refinement, skinning) and a
    /// fresh random publish token, streaming as `settings` says, its frames handed to `fanout`
    /// (a cluster's room link) or else a [`LocalFanout`]. The predictor's factorisation runs on
    /// the blocking pool, not on the caller's async thread. Only `crate::state` builds rooms
    /// (`AppState::open_room`, and a batch's private room).
    ///
    /// # Errors
    /// [`RoomError`]: a bad id, the predictor's or the encoder's.
    ///
    /// # Panics
    /// If `options` holds an invalid filter or refinement (`crease_proto::room::RoomSpec`
    /// checks what users send).
    pub(crate) async fn build(
        id: &str,
        model: Arc<LoadedModel>,
        options: RoomOptions,
        settings: StreamSettings,
        fanout: Option<Arc<dyn Fanout>>,
    ) -> Result<Room, RoomError> {
        if !valid_room_id(id) {
            return Err(RoomError::BadId(id.to_owned()));
        }
        let id = id.to_owned();
        tokio::task::spawn_blocking(move || {
            let pipeline = Pipeline::build(Arc::clone(&model), options, settings)?;
            Ok(Room {
                id,
                model,
                session: Session::new(),
                pipeline,
                fanout: fanout.unwrap_or_else(|| Arc::new(LocalFanout::default())),
                mailbox: Mailbox::default(),
                private: false,
                closed: AtomicBool::new(false),
                published: AtomicU64::new(0),
            })
        })
        .await
        .map_err(|e| RoomError::Panicked(e.to_string()))?
    }

    /// Makes this a private room: open to whoever knows its id, not listed.
    pub(crate) fn private(mut self) -> Self {
        self.private = true;
        self
    }

    /// Whether the room is private (a take's replay: `RoomSpec::private`).
    pub fn is_private(&self) -> bool {
        self.private
    }

    /// The room's settings as the request that would open it again: id, model, beta,
    /// filter, retargeting, refinement, skinning (no token). What a take's header keeps.
    pub fn settings(&self) -> v1::OpenRoomRequest {
        crease_proto::room::room_settings(self.settings_parts(false))
    }

    /// The room's settings in use, its retarget as sent or (`resolved`) with the map's TOML
    /// filled in (what a cluster's registry carries).
    pub fn settings_parts(&self, resolved: bool) -> RoomSettings<'_> {
        let capture = self.pipeline.capture();
        RoomSettings {
            room: &self.id,
            model: &self.model.name,
            beta: self.beta(),
            filter: self.filter(),
            retarget: capture.map(|c| if resolved { c.resolved() } else { c.wire() }),
            refine: self.refinement(),
            skinning: self.skinning(),
        }
    }

    /// Whether the room left the server's room table (closed).
    pub fn is_closed(&self) -> bool {
        self.closed.load(Ordering::Acquire)
    }

    /// Marks the room closed (it left the room table).
    pub(crate) fn mark_closed(&self) {
        self.closed.store(true, Ordering::Release);
    }

    /// In a cluster, a relay's room: forwards `frame` (its token checked here) to the room's
    /// owner through the fan-out ([`Fanout::forward`]) and returns the owner's ack.
    ///
    /// # Errors
    /// Why no owner answered.
    pub(crate) fn forward(
        &self,
        frame: v1::ControlFrame,
    ) -> futures_util::future::BoxFuture<'static, Result<v1::PublishAck, String>> {
        self.fanout.forward(frame)
    }

    /// In a cluster: whether another replica predicts this room (this one relays its frames
    /// and forwards its control frames).
    pub fn relays(&self) -> bool {
        self.fanout.relays()
    }

    /// Replaces the publish token by its digest (a room opened on another replica).
    pub(crate) fn with_token_sha256(mut self, digest: [u8; 32]) -> Self {
        self.session.set_token_sha256(digest);
        self
    }

    /// Makes this a retargeting room (issue 19): its publishers send `spec`'s markers, which
    /// the pipeline retargets to control points (`crate::capture`).
    pub(crate) fn with_capture(mut self, spec: Arc<crate::capture::CaptureSpec>) -> Self {
        self.pipeline.set_capture(spec);
        self
    }

    /// Replaces the publish token (an operator's fixed token, e.g. `--demo-token`).
    pub(crate) fn with_token(mut self, token: &str) -> Self {
        self.session.set_token(token);
        self
    }

    /// The room's session: token, rate limit, counters.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The room's pipeline: its streams' boxes, orders, triangles.
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// The publish token, where the room was opened on this replica (elsewhere in a cluster
    /// only its digest is known).
    pub fn token(&self) -> Option<&str> {
        self.session.token()
    }

    /// Frames published into this room so far (the ones its pipeline ran through).
    pub fn published(&self) -> u64 {
        self.published.load(Ordering::Relaxed)
    }

    /// Live subscriptions (both levels).
    pub fn subscriber_count(&self) -> usize {
        self.session.subscriber_count()
    }

    /// The room's control-point filter.
    pub fn filter(&self) -> Option<OneEuroParams> {
        self.pipeline.filter()
    }

    /// The translation-solve beta of this room.
    pub fn beta(&self) -> f32 {
        self.pipeline.beta()
    }

    /// The room's bone-level refinement, when on (issue 20).
    pub fn refinement(&self) -> Option<crease_core::predictor::Refinement> {
        self.pipeline.refinement()
    }

    /// How the room skins (issue 22).
    pub fn skinning(&self) -> crease_core::runtime::skin::Skinning {
        self.pipeline.skinning()
    }

    /// A subscription on `channel` the room cannot serve (a palette stream of a DQS room,
    /// [`Pipeline::check_encoding`]), naming the room and its skinning.
    ///
    /// # Errors
    /// [`ChannelRefused`] (gRPC's FAILED_PRECONDITION, HTTP's 409: `crate::status`).
    pub fn check_channel(&self, channel: Channel) -> Result<(), ChannelRefused> {
        self.pipeline
            .check_encoding(channel.encoding)
            .map_err(|e| ChannelRefused(format!("room {:?}: {e}", self.id)))
    }

    /// Whether the model has a detail layer.
    pub fn has_detail(&self) -> bool {
        self.pipeline.has_detail()
    }

    /// Hands `frame` to the pipeline, latest wins (`crate::mailbox`): the outcome comes once
    /// it ran, or `None` when a newer frame superseded it while it waited. The room's frames
    /// run one after another on the blocking pool, on one thread at a time; a panic in the
    /// pipeline is that frame's error ([`PipelineError::Panicked`]), and the room goes on.
    pub(crate) fn submit(
        self: &Arc<Self>,
        frame: v1::ControlFrame,
        received: Instant,
    ) -> Outcome<Result<Published, PipelineError>> {
        let (outcome, start) = self.mailbox.submit((frame, received));
        if start {
            let room = Arc::clone(self);
            tokio::task::spawn_blocking(move || {
                while let Some(((frame, received), done)) = room.mailbox.next() {
                    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        room.process(&frame, received)
                    }))
                    .unwrap_or_else(|panic| {
                        let why = panic
                            .downcast_ref::<&str>()
                            .map(|s| (*s).to_owned())
                            .or_else(|| panic.downcast_ref::<String>().cloned())
                            .unwrap_or_default();
                        Err(PipelineError::Panicked(why))
                    });
                    let _ = done.send(Some(result));
                }
            });
        }
        outcome
    }

    /// Runs one control frame through the pipeline into the fan-out and counts it. Blocking
    /// (run it on the blocking pool). A bad frame changes nothing.
    ///
    /// # Errors
    /// The pipeline's.
    pub(crate) fn process(
        &self,
        frame: &v1::ControlFrame,
        received: Instant,
    ) -> Result<Published, PipelineError> {
        let published = self
            .pipeline
            .process(frame, received, self.fanout.as_ref())?;
        self.published.fetch_add(1, Ordering::Relaxed);
        Ok(published)
    }

    /// A subscription to `channel` (the latest frame, then every frame as it comes, skipping
    /// what the subscriber was too slow for), if fewer than `max` subscriptions are live. A
    /// subscription switches its channel's work on while it lives (`crate::pipeline`).
    ///
    /// # Errors
    /// [`RoomFull`] at `max` live subscriptions.
    pub fn subscribe(&self, channel: Channel, max: usize) -> Result<Subscription, RoomFull> {
        let slot = self.session.take_slot(max)?;
        Ok(Subscription {
            frames: self.fanout.subscribe(channel),
            _slot: slot,
        })
    }
}
