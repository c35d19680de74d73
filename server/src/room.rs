//! A room: a live session on one or more actors, the small struct that ties its parts
//! together: the [`Session`] (token, limits, counters), one [`Pipeline`] per actor (filter,
//! predictor, encoders, frame pools) and the [`Fanout`] (latest-wins delivery per level).
//! Control frames reach it through [`crate::ingest`]; subscribers leave it through
//! [`crate::stream`].
//!
//! A room of several actors (issue 38: both hands of a performer, several performers) runs
//! each control frame's actors together (`Room::process`): every actor's part is checked
//! first (so a bad frame changes nothing), then the actors are predicted and encoded in
//! parallel where the machine has cores (rayon), an actor missing from the frame holding its
//! last pose; then one frame per channel goes to the fan-out, actor 0's, carrying the others'
//! of the same instant (`MeshUpdate::actor`), so a subscriber never sees one instant's left
//! hand beside another's right. A one-actor room is the same path with one actor and the
//! frame's own fields as its part.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Instant;

use crease_core::runtime::filter::OneEuroParams;
use crease_proto::room::{ActorSpec, RoomSettings};
use crease_proto::{WireError, v1};

pub use crate::fanout::Channel;
pub use crate::frames::MeshUpdate;
pub use crate::pipeline::{ActorPublished, BuildError, Published, RoomOptions, StreamSettings};
pub use crate::session::{RoomFull, new_token, valid_room_id};
pub use crease_proto::{Encoding, Level};

use crate::capture::CaptureSpec;
use crate::fanout::{self, Fanout, LocalFanout};
use crate::mailbox::{Mailbox, Outcome};
use crate::performer::Performers;
use crate::pipeline::{Demand, Pipeline, PipelineError};
use crate::registry::LoadedModel;
use crate::session::{CountGuard, Session};
use crate::takes::Recorder;

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

/// What one actor of a room is built from (`crate::state` resolves it from a `RoomSpec`).
#[derive(Debug)]
pub(crate) struct ActorParts {
    /// The actor as requested; `None` for a one-actor room's (the room's own fields).
    pub spec: Option<ActorSpec>,
    /// Its model (mirrored already, where the spec asks).
    pub model: Arc<LoadedModel>,
    /// The model as trained (`model` unless mirrored).
    pub source: Arc<LoadedModel>,
    /// Beta, filter, refinement, skinning.
    pub options: RoomOptions,
    /// A retargeting actor's map and markers (issue 19).
    pub capture: Option<Arc<CaptureSpec>>,
}

/// One actor of a room: its spec, model and pipeline.
#[derive(Debug)]
pub struct Actor {
    /// The actor as requested (`None` in a one-actor room).
    spec: Option<ActorSpec>,
    /// Its name (`Arc` so an ack's per-actor parts share it).
    name: Arc<str>,
    /// Its model (mirrored where the spec asks).
    pub model: Arc<LoadedModel>,
    /// The model as trained (`model` itself unless mirrored): what a cluster's registry names.
    source: Arc<LoadedModel>,
    pipeline: Pipeline,
    /// Its palette header of each level named for its room (a room of several actors),
    /// encoded once on first need and shared by every WebSocket subscriber
    /// ([`Actor::named_palette_encoded`]).
    named_palette: [std::sync::OnceLock<Result<prost::bytes::Bytes, String>>; 2],
}

impl Actor {
    /// Its name ("" in a one-actor room).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The actor as requested; `None` in a one-actor room.
    pub fn spec(&self) -> Option<&ActorSpec> {
        self.spec.as_ref()
    }

    /// Its pipeline: its streams' boxes, orders, triangles.
    pub fn pipeline(&self) -> &Pipeline {
        &self.pipeline
    }

    /// The model as trained: its model, or the one its model mirrors.
    pub fn source(&self) -> &Arc<LoadedModel> {
        &self.source
    }

    /// Its palette header at `level` named as actor `index` of `count`
    /// (`crease_proto::name_actor`), protobuf-encoded: built and encoded by the first call
    /// (blocking, megabytes at the detail level: call it on the blocking pool), shared after.
    ///
    /// # Errors
    /// Why the model has no palette header at that level.
    pub fn named_palette_encoded(
        &self,
        level: crease_proto::Level,
        index: usize,
        count: usize,
    ) -> Result<prost::bytes::Bytes, String> {
        self.named_palette[level as usize]
            .get_or_init(|| {
                let mut message = self.model.palette_topology(level)?;
                crease_proto::name_actor(&mut message, &self.name, index, count);
                Ok(prost::Message::encode_to_vec(&message).into())
            })
            .clone()
    }

    /// The actor as it runs, with its model as it uses it (`RoomInfo.actors`); `None` in a
    /// one-actor room.
    pub fn info(&self) -> Option<v1::ActorInfo> {
        let p = &self.pipeline;
        self.spec
            .as_ref()
            .map(|spec| spec.info(p.beta(), p.skinning(), self.model.info.clone()))
    }
}

/// What a frame's run needs besides the actors, reused per frame (one frame runs at a time).
#[derive(Default)]
struct Work {
    /// Whether a channel holds a frame of the current pose (else it was cleared).
    live: [bool; Channel::COUNT],
    /// A room of several actors: each actor's part of the frame being run, its fields moved
    /// in from `ControlFrame.actors` and back afterwards (nothing copied).
    parts: Vec<v1::ControlFrame>,
    /// Where actor `k`'s part is in `ControlFrame.actors`; `None`: missing, it holds.
    slots: Vec<Option<usize>>,
    /// Each actor's outcome, then its frames per channel.
    results: Vec<Option<Result<Published, PipelineError>>>,
    out: Vec<[Option<Arc<MeshUpdate>>; Channel::COUNT]>,
    /// The take being recorded (`crate::takes`), if any.
    take: Option<Recorder>,
    /// Where each actor of a performer sits this frame (`crate::performer`).
    performers: Performers,
}

/// A live session on one or more actors (module docs).
pub struct Room {
    /// The room id.
    pub id: String,
    /// The model (the first actor's).
    pub model: Arc<LoadedModel>,
    session: Session,
    actors: Vec<Actor>,
    work: std::sync::Mutex<Work>,
    fanout: Arc<dyn Fanout>,
    /// Control frames waiting for the pipeline, latest wins ([`Room::submit`]).
    mailbox: Mailbox<(v1::ControlFrame, Instant), Result<Published, PipelineError>>,
    /// A private room (a take's replay, `crate::takes`): not listed in `/api/rooms`.
    private: bool,
    /// Set when the room leaves the server's room table: a publisher holding the room (a
    /// WebSocket session) is refused from then on, as one looking it up would be.
    closed: AtomicBool,
    /// Becomes `true` with `closed`: what a subscriber's stream waits on to end
    /// ([`Room::closed`]).
    closed_signal: tokio::sync::watch::Sender<bool>,
    /// Frames the pipeline ran through (counted here, after the pipeline: the session is
    /// entered once per frame, before it).
    published: AtomicU64,
    /// Bumped by every subscription here ([`Room::joins`]): what a room's own source (the
    /// demo's animation) waits on while nobody watches ([`Room::watched`]).
    joined: tokio::sync::watch::Sender<u64>,
}

impl std::fmt::Debug for Room {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Room")
            .field("id", &self.id)
            .field("model", &self.model.name)
            .finish_non_exhaustive()
    }
}

/// Fills in a frame's room part: the control frame's sequence number and capture time, and
/// when it arrived.
fn stamp(u: &mut MeshUpdate, frame: &v1::ControlFrame, received: Instant) {
    u.seq = frame.seq;
    u.capture_time_us = frame.capture_time_us;
    u.received = received;
}

/// Swaps an actor's part of a control frame between the wire's `ActorControls` and the
/// `ControlFrame` its pipeline reads (moving the buffers, copying nothing).
fn swap_part(wire: &mut v1::ActorControls, part: &mut v1::ControlFrame) {
    std::mem::swap(&mut wire.positions, &mut part.positions);
    std::mem::swap(&mut wire.valid, &mut part.valid);
    std::mem::swap(&mut wire.markers, &mut part.markers);
    std::mem::swap(&mut wire.markers_valid, &mut part.markers_valid);
}

/// A live subscription: the latest mesh of its level, and a subscriber slot of its room.
#[derive(Debug)]
pub struct Subscription {
    /// The level's frames.
    pub frames: fanout::Receiver,
    _slot: CountGuard,
}

impl Room {
    /// Builds a room of `actors` (one, for a room opened without actors) with a fresh random
    /// publish token, streaming as `settings` says, its frames handed to `fanout` (a
    /// cluster's room link) or else a [`LocalFanout`]. The predictors' factorisations run on
    /// the blocking pool, not on the caller's async thread. Only `crate::state` builds rooms
    /// (`AppState::open_room`, and a batch's private room).
    ///
    /// # Errors
    /// [`RoomError`]: a bad id, the predictor's or the encoder's.
    ///
    /// # Panics
    /// With no actors, or if an actor's `options` holds an invalid filter or refinement
    /// (`crease_proto::room::RoomSpec` checks what users send).
    pub(crate) async fn build(
        id: &str,
        actors: Vec<ActorParts>,
        settings: StreamSettings,
        fanout: Option<Arc<dyn Fanout>>,
    ) -> Result<Room, RoomError> {
        assert!(!actors.is_empty(), "a room has at least one actor");
        if !valid_room_id(id) {
            return Err(RoomError::BadId(id.to_owned()));
        }
        let id = id.to_owned();
        tokio::task::spawn_blocking(move || {
            let actors = actors
                .into_iter()
                .map(|parts| {
                    let mut pipeline =
                        Pipeline::build(Arc::clone(&parts.model), parts.options, settings)?;
                    if let Some(capture) = parts.capture {
                        pipeline.set_capture(capture);
                    }
                    let name = parts.spec.as_ref().map_or("", |s| s.name.as_str()).into();
                    Ok(Actor {
                        spec: parts.spec,
                        name,
                        model: parts.model,
                        source: parts.source,
                        pipeline,
                        named_palette: Default::default(),
                    })
                })
                .collect::<Result<Vec<_>, BuildError>>()?;
            let n = actors.len();
            Ok(Room {
                id,
                model: Arc::clone(&actors[0].model),
                session: Session::new(),
                work: std::sync::Mutex::new(Work {
                    parts: std::iter::repeat_with(Default::default).take(n).collect(),
                    slots: vec![None; n],
                    results: std::iter::repeat_with(|| None).take(n).collect(),
                    out: vec![Default::default(); n],
                    performers: Performers::new(actors.iter().map(|a| {
                        let spec = a.spec.as_ref();
                        (
                            spec.map_or("", |s| s.performer.as_str()),
                            a.pipeline.capture().is_some(),
                        )
                    })),
                    ..Work::default()
                }),
                actors,
                fanout: fanout.unwrap_or_else(|| Arc::new(LocalFanout::default())),
                mailbox: Mailbox::default(),
                private: false,
                closed: AtomicBool::new(false),
                closed_signal: tokio::sync::watch::Sender::new(false),
                published: AtomicU64::new(0),
                joined: tokio::sync::watch::Sender::new(0),
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
    /// filter, retargeting, refinement, skinning (no token); a room of several actors' id and
    /// actors as they run. What a take's header keeps.
    pub fn settings(&self) -> v1::OpenRoomRequest {
        if self.has_actors() {
            let actors = self
                .actors
                .iter()
                .filter_map(|a| {
                    let p = &a.pipeline;
                    a.spec.as_ref().map(|s| s.running(p.beta(), p.skinning()))
                })
                .collect();
            return crease_proto::room::actors_room_settings(&self.id, actors);
        }
        crease_proto::room::room_settings(self.settings_parts(false))
    }

    /// The room's settings in use, its retarget as sent or (`resolved`) with the map's TOML
    /// filled in (what a cluster's registry carries).
    pub fn settings_parts(&self, resolved: bool) -> RoomSettings<'_> {
        let capture = self.pipeline().capture();
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
        self.closed_signal.send_replace(true);
    }

    /// Resolves once the room is closed (at once if it already is): a subscriber's stream ends
    /// then, as `CloseRoom` promises, though its task still holds the room.
    pub fn closed(&self) -> impl std::future::Future<Output = ()> + Send + 'static {
        let mut rx = self.closed_signal.subscribe();
        async move {
            // An error means the room itself is gone: closed as well.
            let _ = rx.wait_for(|closed| *closed).await;
        }
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

    /// Replaces the publish token (an operator's fixed token, e.g. `--demo-token`).
    pub(crate) fn with_token(mut self, token: &str) -> Self {
        self.session.set_token(token);
        self
    }

    /// The room's session: token, rate limit, counters.
    pub fn session(&self) -> &Session {
        &self.session
    }

    /// The first actor's pipeline (a one-actor room's): its streams' boxes, orders, triangles.
    pub fn pipeline(&self) -> &Pipeline {
        &self.actors[0].pipeline
    }

    /// The room's actors, in order (one, unnamed, in a room opened without actors).
    pub fn actors(&self) -> &[Actor] {
        &self.actors
    }

    /// Whether the room was opened with actors (`OpenRoomRequest.actors`): its streams name
    /// them and its control frames carry `ControlFrame.actors`.
    pub fn has_actors(&self) -> bool {
        self.actors[0].spec.is_some()
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

    /// Whether anyone wants this room's frames: a subscriber of any channel here or, for a
    /// room this replica owns in a cluster, on another replica (the fan-out's interest), or a
    /// take being recorded. A room's own source (the demo's animation) publishes nothing
    /// while nobody does (issue 41: nothing computed for nobody).
    pub fn watched(&self) -> bool {
        Channel::ALL.iter().any(|&c| self.fanout.interest(c))
            || self
                .work
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .take
                .is_some()
    }

    /// Changes whenever a subscription starts here ([`Room::subscribe`]): a paused source
    /// wakes on it within the frame period of its first viewer. Another replica's viewers
    /// reach the owner as interest announcements, not through this: a paused source also
    /// looks at [`Room::watched`] now and then.
    pub fn joins(&self) -> tokio::sync::watch::Receiver<u64> {
        self.joined.subscribe()
    }

    /// The room's control-point filter.
    pub fn filter(&self) -> Option<OneEuroParams> {
        self.pipeline().filter()
    }

    /// The translation-solve beta of this room.
    pub fn beta(&self) -> f32 {
        self.pipeline().beta()
    }

    /// The room's bone-level refinement, when on (issue 20).
    pub fn refinement(&self) -> Option<crease_core::predictor::Refinement> {
        self.pipeline().refinement()
    }

    /// How the room skins (issue 22).
    pub fn skinning(&self) -> crease_core::runtime::skin::Skinning {
        self.pipeline().skinning()
    }

    /// A subscription on `channel` the room cannot serve (a palette stream of a DQS room,
    /// [`Pipeline::check_encoding`]), naming the room and its skinning.
    ///
    /// # Errors
    /// [`ChannelRefused`] (gRPC's FAILED_PRECONDITION, HTTP's 409: `crate::status`).
    pub fn check_channel(&self, channel: Channel) -> Result<(), ChannelRefused> {
        for a in &self.actors {
            a.pipeline.check_encoding(channel.encoding).map_err(|e| {
                let actor = match a.spec {
                    Some(_) => format!(" actor {:?}", a.name()),
                    None => String::new(),
                };
                ChannelRefused(format!("room {:?}{actor}: {e}", self.id))
            })?;
        }
        Ok(())
    }

    /// Whether the model (every actor's) has a detail layer.
    pub fn has_detail(&self) -> bool {
        self.actors.iter().all(|a| a.pipeline.has_detail())
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
                while let Some(((mut frame, received), done)) = room.mailbox.next() {
                    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        room.process(&mut frame, received)
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

    /// Runs one control frame through the actors' pipelines into the fan-out and counts it
    /// (module docs). Blocking (run it on the blocking pool). A bad frame changes nothing;
    /// `frame` is as it came once this returns.
    ///
    /// # Errors
    /// The pipeline's; a room of several actors names the actor (`PipelineError::in_actor`).
    pub(crate) fn process(
        &self,
        frame: &mut v1::ControlFrame,
        received: Instant,
    ) -> Result<Published, PipelineError> {
        let mut guard = self.work.lock().unwrap_or_else(|e| e.into_inner());
        let work = &mut *guard;
        let demand = Demand::of(self.fanout.as_ref(), self.has_detail());
        let published = if self.has_actors() {
            let run = self
                .split(frame, work)
                .and_then(|()| self.run_actors(frame, work, received, &demand));
            // The actors' fields go back to the frame, whatever happened (a take records it).
            for (k, slot) in work.slots.iter().enumerate() {
                if let Some(i) = slot {
                    swap_part(&mut frame.actors[*i], &mut work.parts[k]);
                }
            }
            run?
        } else {
            if !frame.actors.is_empty() {
                return Err(WireError::new(
                    "ControlFrame",
                    "actors",
                    format!(
                        "{} actors: room {:?} was opened without actors; send its points in the frame's own fields",
                        frame.actors.len(),
                        self.id
                    ),
                )
                .into());
            }
            let p = self.actors[0]
                .pipeline
                .run(Some(frame), received, &demand)?;
            self.actors[0].pipeline.frames(&mut work.out[0], |_, u| {
                stamp(u, frame, received);
            });
            p
        };
        self.publish(work, &demand);
        if let Some(take) = &mut work.take {
            self.record(take, frame, received);
        }
        self.published.fetch_add(1, Ordering::Relaxed);
        Ok(published)
    }

    /// Records the frame just run into `take`: the control frame and every actor's pose.
    fn record(&self, take: &mut Recorder, frame: &v1::ControlFrame, received: Instant) {
        if !self.has_actors() {
            self.actors[0]
                .pipeline
                .pose(|controls, transforms| take.record(frame, received, controls, transforms));
            return;
        }
        take.record_actors(frame, received, self.actors.len(), |record| {
            for (k, actor) in self.actors.iter().enumerate() {
                actor.pipeline.pose(|controls, transforms| {
                    crease_proto::take::fill_actor_pose(record, k, controls, transforms);
                });
            }
        });
    }

    /// Starts recording into `recorder` (`crate::takes`); gives it back when a take runs.
    pub(crate) fn start_take(&self, recorder: Recorder) -> Result<(), Box<Recorder>> {
        let mut work = self.work.lock().unwrap_or_else(|e| e.into_inner());
        if work.take.is_some() {
            return Err(Box::new(recorder));
        }
        work.take = Some(recorder);
        Ok(())
    }

    /// Stops the take, if one runs, and hands it over (to [`Recorder::finish`]).
    pub(crate) fn stop_take(&self) -> Option<Recorder> {
        self.work
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take
            .take()
    }

    /// The running take's id, if one runs (no summary built).
    pub fn take_id(&self) -> Option<String> {
        let work = self.work.lock().unwrap_or_else(|e| e.into_inner());
        work.take.as_ref().map(|t| t.id().to_owned())
    }

    /// What a take of this room records of its actors (`TakeHeader.actors`): each one's
    /// model file's digest as trained, bones and control points; empty in a one-actor room.
    pub fn take_actors(&self) -> Vec<v1::TakeActor> {
        self.actors
            .iter()
            .filter(|a| a.spec.is_some())
            .map(|a| {
                let m = &a.model.model;
                crease_proto::take_info::take_actor(
                    a.name(),
                    a.source.sha256(),
                    m.rig.bone_count,
                    m.controls.len(),
                )
            })
            .collect()
    }

    /// A room of several actors: checks `frame`'s actor list against the room's actors, then
    /// moves each listed actor's part into `work.parts` (the room's actor order; recorded in
    /// `work.slots`, for the way back) and checks it against the actor's model.
    fn split(&self, frame: &mut v1::ControlFrame, work: &mut Work) -> Result<(), PipelineError> {
        let wire = |field: String, message: String| -> PipelineError {
            WireError::new("ControlFrame", field, message).into()
        };
        work.slots.fill(None);
        if !frame.positions.is_empty() || !frame.markers.is_empty() {
            let field = if frame.positions.is_empty() {
                "markers"
            } else {
                "positions"
            };
            return Err(wire(
                field.into(),
                format!(
                    "room {:?} is a room of actors: send each actor's points in ControlFrame.actors",
                    self.id
                ),
            ));
        }
        if frame.actors.is_empty() {
            return Err(wire(
                "actors".into(),
                format!(
                    "empty: room {:?} expects points for some of its actors ({})",
                    self.id,
                    self.actor_names()
                ),
            ));
        }
        for (i, part) in frame.actors.iter().enumerate() {
            let found = self.actors.iter().position(|a| *a.name == *part.actor);
            let error = match found {
                None => format!(
                    "{:?} is not an actor of room {:?} ({})",
                    part.actor,
                    self.id,
                    self.actor_names()
                ),
                Some(k) if work.slots[k].is_some() => format!("{:?} is listed twice", part.actor),
                Some(k) => {
                    work.slots[k] = Some(i);
                    continue;
                }
            };
            work.slots.fill(None);
            return Err(wire(format!("actors[{i}].actor"), error));
        }
        for (k, slot) in work.slots.iter().enumerate() {
            if let Some(i) = slot {
                let part = &mut work.parts[k];
                swap_part(&mut frame.actors[*i], part);
                part.seq = frame.seq;
                part.capture_time_us = frame.capture_time_us;
            }
        }
        // Every part checked before any actor runs: a bad frame changes nothing.
        for (k, slot) in work.slots.iter().enumerate() {
            if slot.is_some() {
                let actor = &self.actors[k];
                actor
                    .pipeline
                    .check(&work.parts[k])
                    .map_err(|e| PipelineError::from(e).in_actor(actor.name()))?;
            }
        }
        Ok(())
    }

    /// The room's actors' names, for errors: `left, right`.
    fn actor_names(&self) -> String {
        let names: Vec<&str> = self.actors.iter().map(Actor::name).collect();
        names.join(", ")
    }

    /// Runs every actor on its part of `frame` (split into `work.parts`; a missing actor
    /// holds), in parallel where the machine has cores, then hands their frames to the
    /// pools, actor 0's last, carrying the others' of the same channel.
    fn run_actors(
        &self,
        frame: &v1::ControlFrame,
        work: &mut Work,
        received: Instant,
        demand: &Demand,
    ) -> Result<Published, PipelineError> {
        let Work {
            parts,
            slots,
            results,
            out,
            performers,
            ..
        } = work;
        let run = |k: usize| {
            let actor = &self.actors[k];
            let part = slots[k].map(|_| &parts[k]);
            actor
                .pipeline
                .run(part, received, demand)
                .map_err(|e| e.in_actor(actor.name()))
        };
        if rayon::current_num_threads() > 1 {
            use rayon::prelude::*;
            results
                .par_iter_mut()
                .enumerate()
                .for_each(|(k, r)| *r = Some(run(k)));
        } else {
            for (k, r) in results.iter_mut().enumerate() {
                *r = Some(run(k));
            }
        }
        let mut published = Published {
            held: 0,
            latency_us: 0,
            control_rms: 0.0,
            detail: false,
            control_rms_capture: 0.0,
            confidence: 0.0,
            actors: Vec::with_capacity(self.actors.len()),
        };
        for (k, result) in results.iter_mut().enumerate() {
            let p = result.take().expect("every actor ran")?;
            published.held += p.held;
            published.control_rms = published.control_rms.max(p.control_rms);
            published.detail |= p.detail;
            published.control_rms_capture =
                published.control_rms_capture.max(p.control_rms_capture);
            published.confidence = published.confidence.max(p.confidence);
            published.actors.push(ActorPublished {
                name: Arc::clone(&self.actors[k].name),
                held: slots[k].is_none(),
                published: p,
            });
        }
        if performers.any() {
            performers.place(|k| self.actors[k].pipeline.registration());
        }
        let (first, others) = out.split_first_mut().expect("a room has an actor");
        for (k, (actor, out)) in self.actors[1..].iter().zip(others.iter_mut()).enumerate() {
            actor.pipeline.frames(out, |_, u| {
                stamp(u, frame, received);
                u.placement = performers.get(k + 1);
            });
        }
        self.actors[0].pipeline.frames(first, |channel, u| {
            stamp(u, frame, received);
            u.placement = performers.get(0);
            u.others
                .extend(others.iter().filter_map(|o| o[channel.index()].clone()));
        });
        published.latency_us = received.elapsed().as_micros().min(u32::MAX as u128) as u32;
        Ok(published)
    }

    /// Hands each channel's frame of this run to the fan-out, where every actor has one
    /// (actor 0's, carrying the others'); clears a channel nobody computes any more.
    fn publish(&self, work: &mut Work, demand: &Demand) {
        let n = self.actors.len();
        for channel in Channel::ALL {
            let i = channel.index();
            let frame = work.out[0][i].take();
            let complete = frame.as_ref().is_some_and(|f| f.actor_count() == n);
            for out in &mut work.out[1..] {
                out[i] = None;
            }
            if let (true, Some(frame)) = (complete, frame) {
                self.fanout.publish(channel, frame);
                work.live[i] = true;
            } else if !demand.computes(channel) && std::mem::take(&mut work.live[i]) {
                self.fanout.clear(channel);
            }
        }
    }

    /// A subscription to `channel` (the latest frame, then every frame as it comes, skipping
    /// what the subscriber was too slow for), if fewer than `max` subscriptions are live. A
    /// subscription switches its channel's work on while it lives (`crate::pipeline`).
    ///
    /// # Errors
    /// [`RoomFull`] at `max` live subscriptions.
    pub fn subscribe(&self, channel: Channel, max: usize) -> Result<Subscription, RoomFull> {
        let slot = self.session.take_slot(max)?;
        let subscription = Subscription {
            frames: self.fanout.subscribe(channel),
            _slot: slot,
        };
        self.joined.send_modify(|n| *n = n.wrapping_add(1));
        Ok(subscription)
    }
}
