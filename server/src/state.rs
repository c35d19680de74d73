//! What the services share: [`AppState`], the models and the table of open rooms, and the one
//! way a room is opened and closed ([`AppState::open_room`], [`AppState::close_room`]): from a
//! [`RoomSpec`] (`crease_proto::room`: built and checked once from a request, a cluster's
//! registry entry or a take), locally or in the cluster this server joined, failing with one
//! typed [`OpenRoomError`] that each transport maps once (`crate::status`).
//!
//! The room table is private: a room enters it only through [`AppState::open_room`], within
//! the room limit, and leaves it through [`AppState::close_room`] (or the cluster closing its
//! local side, through [`cluster::Host`]).

use std::collections::HashMap;
use std::sync::{Arc, OnceLock, RwLock};

use crease_proto::room::{Placement, RoomSpec, RoomToken, SpecError};
use futures_util::future::BoxFuture;

use crate::admission::Admission;
use crate::capture::{CaptureError, CaptureSpec};
use crate::cluster::{self, Cluster, LookupError};
use crate::config::Config;
use crate::fanout::Fanout;
use crate::metrics::Metrics;
use crate::pipeline::{RoomOptions, StreamSettings};
use crate::registry::{LoadedModel, ModelRegistry};
use crate::room::{ActorParts, Room, RoomError};
use crate::takes::{TakeError, Takes};

/// What the services share: the models and the open rooms (module docs).
#[derive(Debug)]
pub struct AppState {
    /// The hosted models.
    models: ModelRegistry,
    /// Open rooms by id.
    rooms: RwLock<HashMap<String, Arc<Room>>>,
    /// The configuration.
    config: Config,
    /// Set to `true` when the server shuts down: streams end.
    closing: tokio::sync::watch::Sender<bool>,
    /// Prometheus metrics.
    metrics: Metrics,
    /// The cluster this server joined ([`join_cluster`]), if any.
    cluster: OnceLock<Arc<Cluster>>,
    /// TCP connections held, per client address (`Limits::connections`).
    connections: Arc<Admission>,
    /// Long-lived calls held, per client address (`Limits::streams`).
    streams: Arc<Admission>,
    /// The takes folder (`Config::takes`), or why it cannot be used.
    takes: Option<Result<Takes, String>>,
    /// Batch jobs (issue 45).
    jobs: crate::jobs::Jobs,
}

/// Why a room could not be opened or closed; each transport maps it once (`crate::status`).
#[derive(Debug, thiserror::Error)]
pub enum OpenRoomError {
    /// The server has no model of that name.
    #[error("model: no model {0:?}")]
    NoModel(String),
    /// The room's options do not check out (names the field).
    #[error(transparent)]
    Spec(#[from] SpecError),
    /// The room's retarget does not fit its markers or model.
    #[error(transparent)]
    Capture(#[from] CaptureError),
    /// The room could not be built: its id, its beta, the model's encoders.
    #[error(transparent)]
    Room(#[from] RoomError),
    /// A room of this id is open on this server.
    #[error("room: {0:?} is open")]
    Exists(String),
    /// A room of this id is open in the cluster.
    #[error("room: {0:?} is open in the cluster")]
    ExistsInCluster(String),
    /// The room limit is reached.
    #[error("rooms: {0} open, the limit")]
    Limit(usize),
    /// In a cluster, the room was registered but this server's table refused it (its id is
    /// a local room's, or the limit): reported as the limit, as the cluster always did.
    #[error(transparent)]
    Install(Box<OpenRoomError>),
    /// No room of that id (closing).
    #[error("room: no room {0:?}")]
    NoRoom(String),
    /// The cluster's registry cannot be written.
    #[error("registry: {0}")]
    Registry(String),
    /// A relay's model cannot be had here (absent, or failing its digest).
    #[error("{0}")]
    ModelUnavailable(String),
    /// A relay asked of a server in no cluster (a server bug).
    #[error("room {0:?}: a relay needs a cluster")]
    NoCluster(String),
    /// More actors than a room may hold (`--max-actors`).
    #[error("actors: {count} listed, a room holds at most {limit} (--max-actors)")]
    TooManyActors {
        /// Actors asked for.
        count: usize,
        /// The limit.
        limit: usize,
    },
    /// An actor names a model this server does not have.
    #[error("actor {actor:?}: model: no model {model:?}")]
    NoActorModel {
        /// The actor.
        actor: String,
        /// The model it names.
        model: String,
    },
    /// Actor `actor`'s part of the room could not be made: its mirror, its retarget.
    #[error("actor {actor:?}: {error}")]
    Actor {
        /// The actor.
        actor: String,
        /// Why.
        error: Box<OpenRoomError>,
    },
    /// An actor's model could not be mirrored (a model that does not mirror: a server-side
    /// matter, reported as the model's).
    #[error("mirror: {0}")]
    Mirror(String),
}

impl From<cluster::RegistryError> for OpenRoomError {
    fn from(e: cluster::RegistryError) -> Self {
        match e {
            cluster::RegistryError::Exists(id) => OpenRoomError::ExistsInCluster(id),
            cluster::RegistryError::NotFound(id) => OpenRoomError::NoRoom(id),
            cluster::RegistryError::Unavailable(why) => OpenRoomError::Registry(why),
        }
    }
}

impl AppState {
    /// State with `models` and no rooms.
    pub fn new(models: ModelRegistry, config: Config) -> Arc<Self> {
        let connections = Admission::new("connections", config.limits.connections);
        let streams = Admission::new("streams", config.limits.streams);
        let mut metrics = Metrics::default();
        metrics.register_admission(&connections, &streams);
        let takes = config.takes.as_ref().map(|dir| {
            Takes::new(dir).map_err(|e| {
                tracing::error!(error = %e, "takes folder unusable: rooms cannot record");
                e.to_string()
            })
        });
        Arc::new(Self {
            takes,
            jobs: crate::jobs::Jobs::new(config.jobs.clone()),
            models,
            rooms: RwLock::new(HashMap::new()),
            config,
            closing: tokio::sync::watch::channel(false).0,
            metrics,
            cluster: OnceLock::new(),
            connections,
            streams,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Batch jobs (issue 45).
    pub fn jobs(&self) -> &crate::jobs::Jobs {
        &self.jobs
    }

    /// The hosted models.
    pub fn models(&self) -> &ModelRegistry {
        &self.models
    }

    /// The Prometheus metrics.
    pub fn metrics(&self) -> &Metrics {
        &self.metrics
    }

    /// TCP connections held, per client address (`Limits::connections`).
    pub fn connections(&self) -> Arc<Admission> {
        Arc::clone(&self.connections)
    }

    /// Long-lived calls held, per client address (`Limits::streams`).
    pub fn streams(&self) -> &Arc<Admission> {
        &self.streams
    }

    /// The takes folder.
    ///
    /// # Errors
    /// [`TakeError::NoFolder`] without one; [`TakeError::Io`] when it could not be created.
    pub fn takes(&self) -> Result<&Takes, TakeError> {
        match &self.takes {
            None => Err(TakeError::NoFolder),
            Some(Ok(takes)) => Ok(takes),
            Some(Err(why)) => Err(TakeError::Io {
                path: self.config.takes.clone().unwrap_or_default(),
                error: std::io::Error::other(why.clone()),
            }),
        }
    }

    fn table(&self) -> std::sync::RwLockReadGuard<'_, HashMap<String, Arc<Room>>> {
        self.rooms.read().unwrap_or_else(|e| e.into_inner())
    }

    /// The ids of the takes rooms of this server record now.
    pub fn recording_takes(&self) -> Vec<String> {
        self.table().values().filter_map(|r| r.take_id()).collect()
    }

    /// The ids of this server's listed (not private) rooms, in order.
    pub fn listed_rooms(&self) -> Vec<String> {
        let mut ids: Vec<String> = self
            .table()
            .values()
            .filter(|r| !r.is_private())
            .map(|r| r.id.clone())
            .collect();
        ids.sort();
        ids
    }

    /// The ids of this server's rooms (private ones too) with an actor on model `model`
    /// (as trained: a mirrored actor's source), in order.
    pub(crate) fn rooms_using(&self, model: &str) -> Vec<String> {
        let mut using: Vec<String> = self
            .table()
            .values()
            .filter(|r| r.actors().iter().any(|a| a.source().name == model))
            .map(|r| r.id.clone())
            .collect();
        using.sort();
        using
    }

    /// Every public room's id and the frames published into it so far (a batch job's worker
    /// tells live rooms by them, `crate::job_service`).
    pub fn published_counts(&self) -> Vec<(String, u64)> {
        self.table()
            .values()
            .filter(|r| !r.is_private())
            .map(|r| (r.id.clone(), r.published()))
            .collect()
    }

    /// How many private rooms (takes' replays) are open.
    pub fn private_rooms(&self) -> usize {
        self.table().values().filter(|r| r.is_private()).count()
    }

    /// The cluster this server joined, if any.
    pub fn cluster(&self) -> Option<&Arc<Cluster>> {
        self.cluster.get()
    }

    /// Room `id`: the local one, or in a cluster a relay of the cluster's room of that id,
    /// opened here now (`Cluster::local_room`).
    ///
    /// # Errors
    /// [`LookupError::NoRoom`], or in a cluster [`LookupError::Unavailable`] when the room's
    /// model cannot be had here.
    pub async fn find_room(self: &Arc<Self>, id: &str) -> Result<Arc<Room>, LookupError> {
        if let Some(room) = self.room(id) {
            return Ok(room);
        }
        match self.cluster() {
            Some(cluster) => Arc::clone(cluster).local_room(self.host(), id).await,
            None => Err(LookupError::NoRoom(id.to_owned())),
        }
    }

    /// Whether the server is shutting down.
    pub fn is_closing(&self) -> bool {
        *self.closing.borrow()
    }

    /// Resolves when the server starts shutting down (long-lived streams select on it).
    pub fn closing(&self) -> impl std::future::Future<Output = ()> + Send + 'static {
        let mut rx = self.closing.subscribe();
        async move {
            let _ = rx.wait_for(|closing| *closing).await;
        }
    }

    /// Starts shutting down: every long-lived stream ends (`crate::listen`).
    pub(crate) fn shut_down(&self) {
        self.closing.send_replace(true);
    }

    /// The room `id` open on this server.
    pub fn room(&self, id: &str) -> Option<Arc<Room>> {
        self.table().get(id).cloned()
    }

    /// The actors of a room opened with actors, resolved: within the cap, each actor's model
    /// (for a cluster's relay fetched by its digest, as a one-actor room's is; mirrored on the
    /// blocking pool where it asks: `ModelRegistry::mirrored`) and its retarget.
    ///
    /// # Errors
    /// Too many actors, a model this server lacks (or cannot have, in a cluster), a mirror or
    /// retarget that fails (naming the actor).
    async fn actor_parts(
        self: &Arc<Self>,
        spec: &RoomSpec,
        cluster: Option<&Arc<Cluster>>,
        maps: Option<std::path::PathBuf>,
    ) -> Result<Vec<ActorParts>, OpenRoomError> {
        let limit = self.config.limits.actors_per_room;
        if spec.actors.len() > limit {
            return Err(OpenRoomError::TooManyActors {
                count: spec.actors.len(),
                limit,
            });
        }
        let mut parts = Vec::with_capacity(spec.actors.len());
        for a in &spec.actors {
            let in_actor = |error: OpenRoomError| OpenRoomError::Actor {
                actor: a.name.clone(),
                error: Box::new(error),
            };
            let source = match (&a.model_sha256, cluster) {
                (Some(sha256), Some(cluster)) => cluster
                    .ensure_model(&self.models, &a.model, sha256)
                    .await
                    .map_err(|e| in_actor(OpenRoomError::ModelUnavailable(e)))?,
                (None, Some(cluster)) => cluster
                    .named_model(&self.models, &a.model)
                    .await
                    .map_err(|e| in_actor(OpenRoomError::ModelUnavailable(e)))?
                    .ok_or_else(|| OpenRoomError::NoActorModel {
                        actor: a.name.clone(),
                        model: a.model.clone(),
                    })?,
                _ => self
                    .models
                    .get(&a.model)
                    .ok_or_else(|| OpenRoomError::NoActorModel {
                        actor: a.name.clone(),
                        model: a.model.clone(),
                    })?,
            };
            let model = match a.mirror {
                None => Arc::clone(&source),
                Some(plane) => {
                    let (state, name) = (Arc::clone(self), a.model.clone());
                    tokio::task::spawn_blocking(move || state.models.mirrored(&name, &plane))
                        .await
                        .map_err(|e| in_actor(OpenRoomError::Mirror(e.to_string())))?
                        .transpose()
                        .map_err(|e| in_actor(OpenRoomError::Mirror(e.to_string())))?
                        .ok_or_else(|| OpenRoomError::NoActorModel {
                            actor: a.name.clone(),
                            model: a.model.clone(),
                        })?
                }
            };
            let capture = match a.retarget.clone() {
                Some(wire) => Some(Arc::new(
                    CaptureSpec::build(wire, maps.clone(), Arc::clone(&model))
                        .await
                        .map_err(|e| in_actor(e.into()))?,
                )),
                None => None,
            };
            parts.push(ActorParts {
                spec: Some(a.clone()),
                model,
                source,
                options: a.options,
                capture,
            });
        }
        Ok(parts)
    }

    fn host(self: &Arc<Self>) -> Arc<dyn cluster::Host> {
        Arc::clone(self) as Arc<dyn cluster::Host>
    }

    /// Opens the room `spec` describes: the one way a room opens. Its model is this server's
    /// (or, for a cluster's relay, fetched from the cluster and checked); its pipeline is
    /// built on the blocking pool. In a cluster a shared room is registered there first (its
    /// id is the cluster's), and every cluster room's fan-out is its cluster side; otherwise
    /// the room is this server's. Either way it then enters the room table, within the room
    /// limit.
    ///
    /// # Errors
    /// [`OpenRoomError`]: no such model, options or retarget that do not check out, a bad id
    /// or beta, the id taken (here or in the cluster), the limit, the registry.
    pub async fn open_room(self: &Arc<Self>, spec: RoomSpec) -> Result<Arc<Room>, OpenRoomError> {
        let settings = spec.stream.unwrap_or(self.config.stream);
        let cluster = match (&spec.placement, self.cluster()) {
            (Placement::Local, _) | (Placement::Shared, None) => None,
            (Placement::Relay { .. }, None) => return Err(OpenRoomError::NoCluster(spec.id)),
            (_, Some(cluster)) => Some(Arc::clone(cluster)),
        };
        // A relay's map is resolved already: it needs no maps folder.
        let maps = match spec.placement {
            Placement::Relay { .. } => None,
            _ => self.config.maps.clone(),
        };
        let parts = if spec.actors.is_empty() {
            vec![self.single_part(&spec, cluster.as_ref(), maps).await?]
        } else {
            self.actor_parts(&spec, cluster.as_ref(), maps).await?
        };
        let Some(cluster) = cluster else {
            let room = build(&spec, parts, settings, None).await?;
            return self.insert(room);
        };
        let (entry, owner, revision) = match &spec.placement {
            Placement::Relay { entry, revision } => ((**entry).clone(), false, *revision),
            _ => {
                if cluster.known(&spec.id).is_some() {
                    return Err(OpenRoomError::ExistsInCluster(spec.id));
                }
                // Written whole once the room is built (the values in use: beta, skinning,
                // the token's digest).
                (Default::default(), true, 0)
            }
        };
        let models: Vec<&LoadedModel> = parts.iter().map(|p| &*p.model).collect();
        let (link, rx) = cluster.new_link(&spec.id, &models, entry, owner, revision);
        let fanout = Arc::clone(&link) as Arc<dyn Fanout>;
        let room = build(&spec, parts, settings, Some(fanout)).await?;
        if owner {
            cluster.register(&room, settings, &link).await?;
        }
        let room = self
            .insert(room)
            .map_err(|e| OpenRoomError::Install(Box::new(e)))?;
        cluster.attach(self.host(), &room, link, rx);
        Ok(room)
    }

    /// The one actor of a room opened without actors: its model (for a cluster's relay
    /// fetched by its digest) and its retarget.
    async fn single_part(
        &self,
        spec: &RoomSpec,
        cluster: Option<&Arc<Cluster>>,
        maps: Option<std::path::PathBuf>,
    ) -> Result<ActorParts, OpenRoomError> {
        let model = match (&spec.model_sha256, cluster) {
            (Some(sha256), Some(cluster)) => cluster
                .ensure_model(&self.models, &spec.model, sha256)
                .await
                .map_err(OpenRoomError::ModelUnavailable)?,
            (None, Some(cluster)) => cluster
                .named_model(&self.models, &spec.model)
                .await
                .map_err(OpenRoomError::ModelUnavailable)?
                .ok_or_else(|| OpenRoomError::NoModel(spec.model.clone()))?,
            _ => self
                .models
                .get(&spec.model)
                .ok_or_else(|| OpenRoomError::NoModel(spec.model.clone()))?,
        };
        let capture = match spec.retarget.clone() {
            Some(wire) => Some(Arc::new(
                CaptureSpec::build(wire, maps, Arc::clone(&model)).await?,
            )),
            None => None,
        };
        Ok(ActorParts {
            spec: None,
            source: Arc::clone(&model),
            model,
            options: spec.options,
            capture,
        })
    }

    /// A batch's private room (`Synthesize`) on model `model` with `options`, streaming at full
    /// precision: built as every room is, never entered in the table.
    ///
    /// # Errors
    /// [`OpenRoomError::NoModel`], or the room's build error.
    pub async fn batch_room(
        &self,
        model: &str,
        options: RoomOptions,
    ) -> Result<Room, OpenRoomError> {
        let model = self
            .models
            .get(model)
            .ok_or_else(|| OpenRoomError::NoModel(model.to_owned()))?;
        let spec = RoomSpec {
            id: "batch".into(),
            options,
            private: true,
            placement: Placement::Local,
            ..RoomSpec::default()
        };
        let parts = vec![ActorParts {
            spec: None,
            source: Arc::clone(&model),
            model,
            options,
            capture: None,
        }];
        build(&spec, parts, StreamSettings::full(), None).await
    }

    /// Closes room `id`: in a cluster, in the whole cluster (every replica's watch then
    /// closes it locally); else here. A private room (a replay) is always this server's.
    ///
    /// # Errors
    /// [`OpenRoomError::NoRoom`], or in a cluster [`OpenRoomError::Registry`] when the
    /// registry cannot be written.
    pub async fn close_room(self: &Arc<Self>, id: &str) -> Result<(), OpenRoomError> {
        let (here, private) = self
            .room(id)
            .map_or((false, false), |r| (true, r.is_private()));
        match self.cluster() {
            Some(cluster) if !private => {
                cluster.close_room(self.host(), id, here).await?;
                Ok(())
            }
            _ => match self.remove(id) {
                Some(_) => Ok(()),
                None => Err(OpenRoomError::NoRoom(id.to_owned())),
            },
        }
    }

    /// Adds an opened room, within the room limit.
    fn insert(&self, room: Room) -> Result<Arc<Room>, OpenRoomError> {
        let mut rooms = self.rooms.write().unwrap_or_else(|e| e.into_inner());
        if rooms.contains_key(&room.id) {
            return Err(OpenRoomError::Exists(room.id.clone()));
        }
        if rooms.len() >= self.config.limits.rooms {
            return Err(OpenRoomError::Limit(rooms.len()));
        }
        let room = Arc::new(room);
        rooms.insert(room.id.clone(), Arc::clone(&room));
        self.metrics.rooms.set(rooms.len() as i64);
        tracing::info!(room = %room.id, model = %room.model.name, beta = room.beta(), "room opened");
        Ok(room)
    }

    /// Removes room `id` from this server (its streams end as their subscribers leave; its
    /// WebSocket publishers are refused from now on).
    fn remove(&self, id: &str) -> Option<Arc<Room>> {
        let mut rooms = self.rooms.write().unwrap_or_else(|e| e.into_inner());
        let removed = rooms.remove(id);
        self.metrics.rooms.set(rooms.len() as i64);
        if let Some(room) = &removed {
            room.mark_closed();
        }
        removed
    }
}

/// Builds the room `spec` describes on its actors' `parts` (the pipelines on the blocking
/// pool), with its token and privacy: the one constructor of every room.
async fn build(
    spec: &RoomSpec,
    parts: Vec<ActorParts>,
    settings: StreamSettings,
    fanout: Option<Arc<dyn Fanout>>,
) -> Result<Room, OpenRoomError> {
    let mut room = Room::build(&spec.id, parts, settings, fanout).await?;
    room = match &spec.token {
        RoomToken::Random => room,
        RoomToken::Fixed(token) => room.with_token(token),
        RoomToken::Digest(digest) => room.with_token_sha256(*digest),
    };
    Ok(if spec.private { room.private() } else { room })
}

/// What the cluster asks of this server (`cluster::Host`): its models, its rooms, opening a
/// relay and closing a room's local side. The owner's handling of forwarded control frames,
/// the other half of the trait, is the publish path's (`crate::ingest`).
impl cluster::Host for AppState {
    fn models(&self) -> &ModelRegistry {
        &self.models
    }

    fn room(&self, id: &str) -> Option<Arc<Room>> {
        AppState::room(self, id)
    }

    fn open_relay(
        self: Arc<Self>,
        spec: RoomSpec,
    ) -> BoxFuture<'static, Result<Arc<Room>, LookupError>> {
        Box::pin(async move {
            let id = spec.id.clone();
            self.open_room(spec).await.map_err(|e| match e {
                OpenRoomError::ModelUnavailable(why) => {
                    LookupError::Unavailable(format!("room {id:?}: {why}"))
                }
                e @ (OpenRoomError::Install(_)
                | OpenRoomError::Exists(_)
                | OpenRoomError::Limit(_)) => LookupError::Unavailable(e.to_string()),
                e @ (OpenRoomError::Spec(_) | OpenRoomError::Capture(_)) => {
                    LookupError::Internal(format!("room {id:?}: the registry's {e}"))
                }
                e => LookupError::Internal(format!("room {id:?}: {e}")),
            })
        })
    }

    fn close_local(&self, id: &str) {
        self.remove(id);
    }
}

/// Joins the cluster of `options` (`crease-server --nats`): connects, records the cluster in
/// `state`, then offers this server's models and starts following the registry and keeping
/// leases; control frames other replicas forward to this server's rooms take the server's
/// publish path (`crate::ingest`, through [`cluster::Host`]).
///
/// # Errors
/// [`cluster::ClusterError`]: NATS unreachable, JetStream missing.
pub async fn join_cluster(
    state: &Arc<AppState>,
    options: cluster::ClusterOptions,
) -> Result<Arc<Cluster>, cluster::ClusterError> {
    let cluster = cluster::connect(options, state.metrics.cluster.clone()).await?;
    if state.cluster.set(Arc::clone(&cluster)).is_err() {
        tracing::warn!("this server already joined a cluster");
    }
    Arc::clone(&cluster).start(state.host()).await;
    Ok(cluster)
}
