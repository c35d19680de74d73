//! Rooms across replicas (issue 17): `crease-server --nats URL` joins a cluster in which every
//! replica serves every room. NATS (through `async-nats`) carries it:
//!
//! - **The registry**, a JetStream key-value bucket (`crease-rooms`): room id -> its
//!   [`v1::RoomEntry`] (model and its digest, beta, filter, stream settings, owner, the publish
//!   token's digest, the lease). Every replica watches it into its [`Cluster::rooms`] view, so
//!   `OpenRoom`/`CloseRoom`/`GetRoom`, `/api/rooms` and the viewer's picker see the cluster's
//!   rooms and owners.
//! - **Frames** ([`link`]): the owner predicts and encodes once and publishes each level's frame
//!   once to `crease.frames.<room>.<channel>` while another replica wants it; relays decode and fan
//!   out locally.
//! - **Controls** ([`control`]): a relay checks the token's digest and forwards the frame to the
//!   owner; the ack comes back.
//! - **Leases and failover** (this module): the owner renews its entry (compare-and-set on the
//!   revision) every quarter lease; a replica that sees no new revision of a room for a whole
//!   lease, and has (or can fetch) its model, adopts it by a compare-and-set from the revision
//!   it saw, so exactly one wins. A replica that loses NATS keeps serving its rooms to its own
//!   clients but sends nothing into the cluster until a renewal succeeds; if another replica
//!   adopted a room meanwhile, the renewal fails and it yields (fencing by the revision).
//! - **Models** ([`models`]): a JetStream object store (`crease-models`) holds every replica's
//!   models; a replica that lacks a room's model fetches it and checks its digest first.
//!
//! A room a replica touches (a viewer, a publisher, an adoption) is opened locally as a full
//! [`Room`] whose fan-out is its [`RoomLink`]: one code path for owners and relays, and an
//! adopter is ready at once.

pub mod control;
pub mod link;
pub mod models;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use async_nats::jetstream::{self, kv};
use crease_core::predictor::Refinement;
use crease_core::runtime::filter::OneEuroParams;
use crease_proto::v1;
use futures_util::StreamExt;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prost::Message as _;

pub use link::RoomLink;

/// The frames a room link's owner side hands to its NATS sender.
type LinkFrames =
    tokio::sync::mpsc::Receiver<(crate::fanout::Channel, Arc<crate::frames::MeshUpdate>)>;

use crate::AppState;
use crate::fanout::Fanout;
use crate::pipeline::{RoomOptions, StreamSettings};
use crate::room::Room;

/// The registry's bucket.
pub const ROOMS_BUCKET: &str = "crease-rooms";
/// The models' object store.
pub const MODELS_BUCKET: &str = "crease-models";
/// The default lease: an owner silent this long loses its rooms.
pub const DEFAULT_LEASE: Duration = Duration::from_secs(2);

/// NATS subjects of a room (`cluster.proto` lists them).
pub mod subject {
    use crate::fanout::Channel;

    /// The encoded frames of `room`'s `channel`.
    pub fn frames(room: &str, channel: Channel) -> String {
        format!("crease.frames.{room}.{}", channel.name())
    }
    /// Relays' interest in `room`.
    pub fn interest(room: &str) -> String {
        format!("crease.interest.{room}")
    }
    /// Forwarded control frames of `room` (request/reply).
    pub fn control(room: &str) -> String {
        format!("crease.control.{room}")
    }
    /// Keyframe requests for `room`'s channel named `channel` (`*`: any channel).
    pub fn keyframe(room: &str, channel: &str) -> String {
        format!("crease.keyframe.{room}.{channel}")
    }
}

/// How to join a cluster.
#[derive(Clone, Debug)]
pub struct ClusterOptions {
    /// The NATS server(s), e.g. `nats://127.0.0.1:4222` (comma-separated for several).
    pub url: String,
    /// This replica's id (unique in the cluster).
    pub replica: String,
    /// The owner's lease.
    pub lease: Duration,
}

impl ClusterOptions {
    /// Options for `url`, with `replica` or else the host name (a pod's name in Kubernetes)
    /// and a random suffix.
    pub fn new(url: &str, replica: Option<String>) -> ClusterOptions {
        let replica = replica.unwrap_or_else(|| {
            let host = std::env::var("HOSTNAME").unwrap_or_else(|_| "replica".into());
            format!("{host}-{}", &crate::room::new_token()[..6])
        });
        ClusterOptions {
            url: url.to_owned(),
            replica,
            lease: DEFAULT_LEASE,
        }
    }
}

/// Why a cluster room could not be had as a local room.
#[derive(Debug, thiserror::Error)]
pub enum LookupError {
    /// The cluster has no room of that id.
    #[error("room: no room {0:?}")]
    NoRoom(String),
    /// Its model cannot be had here (absent, or failing its digest), or the room limit.
    #[error("{0}")]
    Unavailable(String),
    /// The registry's entry cannot be used (a server bug or a foreign writer).
    #[error("{0}")]
    Internal(String),
}

/// Errors of joining a cluster.
#[derive(Debug, thiserror::Error)]
pub enum ClusterError {
    /// NATS could not be reached.
    #[error("NATS at {url}: {source}")]
    Connect {
        /// The URL.
        url: String,
        /// What failed.
        source: async_nats::ConnectError,
    },
    /// A JetStream bucket could not be opened or created (is JetStream enabled, `-js`?).
    #[error(
        "JetStream bucket {bucket}: {message} (is JetStream enabled on the NATS server, `nats-server -js`?)"
    )]
    Bucket {
        /// The bucket.
        bucket: &'static str,
        /// What failed.
        message: String,
    },
}

/// The per-replica cluster metrics (in `/metrics`, `crease_cluster_*`).
#[derive(Clone, Debug, Default)]
pub struct ClusterMetrics {
    /// Frames this replica published into NATS (owner).
    pub nats_frames_out: Counter,
    /// Their bytes.
    pub nats_bytes_out: Counter,
    /// Frames dropped on their way to NATS (the sender fell behind).
    pub nats_frames_dropped: Counter,
    /// Frames received from an owner and fanned out here (relay).
    pub relayed_frames: Counter,
    /// Their bytes.
    pub relayed_bytes: Counter,
    /// Control frames this replica forwarded to an owner.
    pub forwarded_controls: Counter,
    /// Rooms this replica adopted from a dead owner.
    pub adoptions: Counter,
    /// 1 while connected to NATS.
    pub nats_connected: Gauge,
}

impl ClusterMetrics {
    /// Registers the metrics in `registry`.
    pub(crate) fn register(&self, registry: &mut prometheus_client::registry::Registry) {
        let r = registry.sub_registry_with_prefix("cluster");
        let counters = [
            (
                "nats_frames_out",
                "Frames published into NATS (owner)",
                &self.nats_frames_out,
            ),
            (
                "nats_bytes_out",
                "Bytes of frames published into NATS",
                &self.nats_bytes_out,
            ),
            (
                "nats_frames_dropped",
                "Frames dropped on their way to NATS",
                &self.nats_frames_dropped,
            ),
            (
                "relayed_frames",
                "Frames received from an owner and fanned out here",
                &self.relayed_frames,
            ),
            (
                "relayed_bytes",
                "Bytes of relayed frames",
                &self.relayed_bytes,
            ),
            (
                "forwarded_controls",
                "Control frames forwarded to an owner",
                &self.forwarded_controls,
            ),
            (
                "adoptions",
                "Rooms adopted from a dead owner",
                &self.adoptions,
            ),
        ];
        for (name, help, counter) in counters {
            r.register(name, help, counter.clone());
        }
        r.register(
            "nats_connected",
            "1 while connected to NATS",
            self.nats_connected.clone(),
        );
    }
}

/// What the registry says of a room, as this replica's watch last saw it.
#[derive(Clone, Debug)]
pub struct Known {
    /// The entry.
    pub entry: v1::RoomEntry,
    /// Its revision.
    pub revision: u64,
    /// When this replica saw that revision (leases go by this clock, not the owner's).
    seen: Instant,
}

/// This replica's membership of a cluster (module docs).
pub struct Cluster {
    /// This replica's id.
    pub replica: String,
    pub(crate) client: async_nats::Client,
    rooms_kv: kv::Store,
    pub(crate) models_store: jetstream::object_store::ObjectStore,
    lease: Duration,
    directory: Mutex<BTreeMap<String, Known>>,
    connected: AtomicBool,
    /// When the connection last came up: leases are judged only after a whole lease of it.
    connected_at: Mutex<Instant>,
    /// One room is opened (or adopted) at a time here.
    opening: tokio::sync::Mutex<()>,
    /// Rooms this replica could not serve (its model absent or corrupt): not retried before.
    refused: Mutex<BTreeMap<String, (String, Instant)>>,
    /// The cluster side of every local room, by id.
    links: Mutex<BTreeMap<String, Arc<RoomLink>>>,
    /// The owner's handling of forwarded control frames.
    pub(crate) controls: control::ControlHandler,
    /// The cluster metrics.
    pub metrics: ClusterMetrics,
}

impl std::fmt::Debug for Cluster {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Cluster")
            .field("replica", &self.replica)
            .field("lease", &self.lease)
            .field("connected", &self.is_connected())
            .finish_non_exhaustive()
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// How long a room whose model could not be had is left alone before trying again.
const REFUSAL_BACKOFF: Duration = Duration::from_secs(5);

/// Joins the cluster at `options.url` on behalf of `state`: opens the buckets, offers this
/// replica's models, and starts watching the registry and keeping leases. Forwarded control
/// frames of the rooms this replica owns go to `controls` (`crate::join_cluster` passes the
/// server's publish path).
///
/// # Errors
/// [`ClusterError`]: NATS unreachable, JetStream missing.
pub async fn join(
    state: &Arc<AppState>,
    options: ClusterOptions,
    controls: control::ControlHandler,
) -> Result<Arc<Cluster>, ClusterError> {
    let (events_tx, events) = tokio::sync::mpsc::unbounded_channel();
    let client = async_nats::ConnectOptions::new()
        .name(format!("crease-server {}", options.replica))
        .max_reconnects(None)
        .event_callback(move |event| {
            let tx = events_tx.clone();
            async move {
                let _ = tx.send(event);
            }
        })
        .connect(&options.url)
        .await
        .map_err(|source| ClusterError::Connect {
            url: options.url.clone(),
            source,
        })?;
    let js = jetstream::new(client.clone());
    let rooms_kv = open_kv(&js).await?;
    let models_store = open_object_store(&js).await?;
    let metrics = state.metrics.cluster.clone();
    metrics.nats_connected.set(1);
    let cluster = Arc::new(Cluster {
        replica: options.replica,
        client,
        rooms_kv,
        models_store,
        lease: options.lease,
        directory: Mutex::new(BTreeMap::new()),
        connected: AtomicBool::new(true),
        connected_at: Mutex::new(Instant::now()),
        opening: tokio::sync::Mutex::new(()),
        refused: Mutex::new(BTreeMap::new()),
        links: Mutex::new(BTreeMap::new()),
        controls,
        metrics,
    });
    if state.cluster.set(Arc::clone(&cluster)).is_err() {
        tracing::warn!("this server already joined a cluster");
    }
    // Every local model's digest is set here, off the async threads, before any room reads it.
    let serialised = models::serialise_local(state).await;
    tokio::spawn(models::offer(Arc::clone(&cluster), serialised));
    tokio::spawn(Arc::clone(&cluster).watch_registry(Arc::clone(state)));
    tokio::spawn(Arc::clone(&cluster).keep_leases(Arc::clone(state)));
    tokio::spawn(Arc::clone(&cluster).follow_connection(events));
    tracing::info!(replica = %cluster.replica, url = %options.url, "joined the cluster");
    Ok(cluster)
}

async fn open_kv(js: &jetstream::Context) -> Result<kv::Store, ClusterError> {
    if let Ok(store) = js.get_key_value(ROOMS_BUCKET).await {
        return Ok(store);
    }
    // The bucket's stream, as `create_key_value` would make it (history 1). Made directly:
    // `create_key_value` first reads the account's info, which async-nats 0.51 cannot parse
    // from nats-server 2.9 (Debian's), while the stream calls work with both.
    let created = js
        .create_stream(jetstream::stream::Config {
            name: format!("KV_{ROOMS_BUCKET}"),
            description: Some("crease rooms: id -> RoomEntry (crease.v1, cluster.proto)".into()),
            subjects: vec![format!("$KV.{ROOMS_BUCKET}.>")],
            max_messages_per_subject: 1,
            allow_rollup: true,
            deny_delete: true,
            allow_direct: true,
            discard: jetstream::stream::DiscardPolicy::New,
            num_replicas: 1,
            ..Default::default()
        })
        .await;
    let created = created.map_err(|e| e.to_string());
    // Made here, or by another replica at the same time.
    js.get_key_value(ROOMS_BUCKET)
        .await
        .map_err(|e| ClusterError::Bucket {
            bucket: ROOMS_BUCKET,
            message: created.err().unwrap_or_else(|| e.to_string()),
        })
}

async fn open_object_store(
    js: &jetstream::Context,
) -> Result<jetstream::object_store::ObjectStore, ClusterError> {
    if let Ok(store) = js.get_object_store(MODELS_BUCKET).await {
        return Ok(store);
    }
    let created = js
        .create_object_store(jetstream::object_store::Config {
            bucket: MODELS_BUCKET.into(),
            description: Some(
                "crease models: name -> .crease file (sha256 in its metadata)".into(),
            ),
            ..Default::default()
        })
        .await;
    match created {
        Ok(store) => Ok(store),
        Err(e) => js
            .get_object_store(MODELS_BUCKET)
            .await
            .map_err(|_| ClusterError::Bucket {
                bucket: MODELS_BUCKET,
                message: e.to_string(),
            }),
    }
}

fn now_unix_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// The stream settings an entry names.
fn settings_of(entry: &v1::RoomEntry) -> StreamSettings {
    StreamSettings {
        base_bits: entry.base_bits.min(16) as u8,
        detail_bits: entry.detail_bits.min(16) as u8,
        spatial_order: entry.spatial_order,
        keyframe_interval: entry.keyframe_interval,
    }
}

impl Cluster {
    /// Whether this replica is connected to NATS.
    pub fn is_connected(&self) -> bool {
        self.connected.load(Ordering::Acquire)
    }

    /// The cluster's rooms as this replica's registry watch sees them, by id.
    pub fn rooms(&self) -> BTreeMap<String, Known> {
        lock(&self.directory).clone()
    }

    /// What the registry says of room `id`.
    pub fn known(&self, id: &str) -> Option<Known> {
        lock(&self.directory).get(id).cloned()
    }

    /// The replica that owns room `id`, as the registry says.
    pub fn owner_of(&self, id: &str) -> Option<String> {
        lock(&self.directory).get(id).map(|k| k.entry.owner.clone())
    }

    /// The cluster side of local room `id`.
    pub fn link(&self, id: &str) -> Option<Arc<RoomLink>> {
        lock(&self.links).get(id).cloned()
    }

    fn links(&self) -> Vec<Arc<RoomLink>> {
        lock(&self.links).values().cloned().collect()
    }

    /// Opens room `id` on `model` here, as its owner, and registers it; the compare-and-set
    /// create makes the id the cluster's (a room of that id anywhere is `AlreadyExists`).
    ///
    /// # Errors
    /// The status to return: a bad id or beta, the id taken, NATS unavailable.
    pub async fn open_room(
        self: &Arc<Self>,
        state: &Arc<AppState>,
        id: &str,
        model: Arc<crate::registry::LoadedModel>,
        options: RoomOptions,
        capture: Option<Arc<crate::capture::CaptureSpec>>,
    ) -> Result<Arc<Room>, tonic::Status> {
        if self.known(id).is_some() {
            return Err(tonic::Status::already_exists(format!(
                "room: {id:?} is open in the cluster"
            )));
        }
        let settings = state.config.stream;
        let mut entry = v1::RoomEntry {
            model: model.name.clone(),
            model_sha256: model.sha256().to_owned(),
            beta: 0.0,
            filter: options.filter.map(v1::MarkerFilter::from),
            owner: self.replica.clone(),
            token_sha256: Vec::new(),
            base_bits: u32::from(settings.base_bits),
            detail_bits: u32::from(settings.detail_bits),
            spatial_order: settings.spatial_order,
            keyframe_interval: settings.keyframe_interval,
            lease_ms: self.lease.as_millis() as u32,
            renewed_unix_ms: now_unix_ms(),
            adoptions: 0,
            retarget: capture.as_ref().map(|c| c.resolved().clone()),
            refine: options.refine.map(v1::Refine::from),
            // The value in use, set once the room is built (as beta).
            skinning: 0,
        };
        let (room, link, rx) = self
            .open_linked(id, model, options, settings, &entry, true, 0)
            .await
            .map_err(|e| e.status())?;
        let room = match capture {
            Some(c) => room.with_capture(c),
            None => room,
        };
        entry.beta = room.beta();
        entry.skinning = v1::Skinning::from(room.skinning()) as i32;
        entry.token_sha256 = room.session().token_sha256().to_vec();
        let revision = self
            .rooms_kv
            .create(id, entry.encode_to_vec().into())
            .await
            .map_err(|e| match e.kind() {
                kv::CreateErrorKind::AlreadyExists => {
                    tonic::Status::already_exists(format!("room: {id:?} is open in the cluster"))
                }
                _ => tonic::Status::unavailable(format!("registry: {e}")),
            })?;
        link.set_entry(entry.clone(), revision);
        self.note(id, entry, revision);
        self.install(state, room, link, rx)
            .map_err(|e| tonic::Status::resource_exhausted(e.to_string()))
    }

    /// Closes room `id` in the whole cluster (every replica's watch then closes it locally).
    ///
    /// # Errors
    /// `NotFound`, or `Unavailable` when the registry cannot be written.
    pub async fn close_room(&self, state: &Arc<AppState>, id: &str) -> Result<(), tonic::Status> {
        if self.known(id).is_none() && state.room(id).is_none() {
            return Err(tonic::Status::not_found(format!("room: no room {id:?}")));
        }
        self.rooms_kv
            .delete(id)
            .await
            .map_err(|e| tonic::Status::unavailable(format!("registry: {e}")))?;
        lock(&self.directory).remove(id);
        self.close_local(state, id);
        Ok(())
    }

    fn note(&self, id: &str, entry: v1::RoomEntry, revision: u64) {
        lock(&self.directory).insert(
            id.to_owned(),
            Known {
                entry,
                revision,
                seen: Instant::now(),
            },
        );
    }

    /// Room `id` as a local room: the open one, or (when the registry has it) a relay of it
    /// opened now, its model fetched from the cluster if this replica lacks it.
    ///
    /// # Errors
    /// [`LookupError::NoRoom`] when the cluster has no such room; [`LookupError::Unavailable`]
    /// when its model cannot be had here (absent, or failing its checksum).
    pub async fn local_room(
        self: &Arc<Self>,
        state: &Arc<AppState>,
        id: &str,
    ) -> Result<Arc<Room>, LookupError> {
        if let Some(room) = state.room(id) {
            return Ok(room);
        }
        let _opening = self.opening.lock().await;
        if let Some(room) = state.room(id) {
            return Ok(room);
        }
        let known = self
            .known(id)
            .ok_or_else(|| LookupError::NoRoom(id.to_owned()))?;
        if let Some((why, at)) = lock(&self.refused).get(id)
            && at.elapsed() < REFUSAL_BACKOFF
        {
            return Err(LookupError::Unavailable(why.clone()));
        }
        let opened = self.open_relay(state, id, &known).await;
        if let Err(LookupError::Unavailable(why)) = &opened {
            lock(&self.refused).insert(id.to_owned(), (why.clone(), Instant::now()));
        }
        opened
    }

    /// Builds room `id` (on the blocking pool) with its cluster side as its fan-out: as
    /// `owner` or relay, at registry `revision`. [`Cluster::install`] then makes it live.
    #[allow(clippy::too_many_arguments)] // a room's settings and its registry position
    async fn open_linked(
        self: &Arc<Self>,
        id: &str,
        model: Arc<crate::registry::LoadedModel>,
        options: RoomOptions,
        settings: StreamSettings,
        entry: &v1::RoomEntry,
        owner: bool,
        revision: u64,
    ) -> Result<(Room, Arc<RoomLink>, LinkFrames), crate::room::RoomError> {
        let vertices = vertex_counts(&model);
        let (link, rx) = RoomLink::new(self, id, vertices, entry.clone(), owner, revision);
        let fanout = Arc::clone(&link) as Arc<dyn Fanout>;
        let room = Room::open_with(id, model, options, settings, Some(fanout)).await?;
        Ok((room, link, rx))
    }

    /// Adds a room built by [`Cluster::open_linked`] to this server and starts its cluster
    /// side.
    fn install(
        &self,
        state: &Arc<AppState>,
        room: Room,
        link: Arc<RoomLink>,
        rx: LinkFrames,
    ) -> Result<Arc<Room>, crate::AddRoomError> {
        let room = state.add_room(room)?;
        lock(&self.links).insert(room.id.clone(), Arc::clone(&link));
        link.start(state, rx);
        Ok(room)
    }

    /// Opens a local relay of room `id` as the registry describes it.
    async fn open_relay(
        self: &Arc<Self>,
        state: &Arc<AppState>,
        id: &str,
        known: &Known,
    ) -> Result<Arc<Room>, LookupError> {
        let entry = &known.entry;
        let model = models::ensure(state, self, &entry.model, &entry.model_sha256)
            .await
            .map_err(|e| LookupError::Unavailable(format!("room {id:?}: {e}")))?;
        let filter = entry.filter.map(OneEuroParams::from);
        if filter.is_some_and(|f| !f.is_valid()) {
            return Err(LookupError::Internal(format!(
                "room {id:?}: the registry's filter {filter:?} is invalid"
            )));
        }
        let refine = entry.refine.map(Refinement::from);
        if let Some(e) = refine.and_then(|r| r.validate().err()) {
            return Err(LookupError::Internal(format!(
                "room {id:?}: the registry's refine is invalid: {e}"
            )));
        }
        // Unspecified (an entry of a replica older than issue 22): the model's default, which
        // is what that owner skinned with.
        let skinning = crease_proto::convert::skinning_from_wire("RoomEntry", entry.skinning)
            .map_err(|e| LookupError::Internal(format!("room {id:?}: the registry's {e}")))?;
        let digest = <[u8; 32]>::try_from(entry.token_sha256.as_slice()).map_err(|_| {
            LookupError::Internal(format!(
                "room {id:?}: the registry's token digest has {} bytes, a SHA-256 has 32",
                entry.token_sha256.len()
            ))
        })?;
        // A retargeting room: rebuilt from the entry's resolved map (an adopter then
        // retargets the publishers' markers as the owner did).
        let capture = match &entry.retarget {
            Some(r) => {
                let spec = crate::capture::CaptureSpec::build(r.clone(), None, Arc::clone(&model))
                    .await
                    .map_err(|e| {
                        LookupError::Internal(format!("room {id:?}: the registry's {e}"))
                    })?;
                Some(Arc::new(spec))
            }
            None => None,
        };
        let (room, link, rx) = self
            .open_linked(
                id,
                model,
                RoomOptions {
                    beta: Some(entry.beta),
                    filter,
                    refine,
                    skinning,
                },
                settings_of(entry),
                entry,
                false,
                known.revision,
            )
            .await
            .map_err(|e| LookupError::Internal(format!("room {id:?}: {e}")))?;
        let room = match capture {
            Some(c) => room.with_capture(c),
            None => room,
        };
        let room = self
            .install(state, room.with_token_sha256(digest), link, rx)
            .map_err(|e| LookupError::Unavailable(e.to_string()))?;
        tracing::info!(room = %id, owner = %entry.owner, "relaying room");
        Ok(room)
    }

    /// Follows the registry into [`Cluster::rooms`]: new rooms, renewals, new owners (a local
    /// owner that sees another owner yields), closed rooms (closed here too). The watch is
    /// re-made if it ends.
    async fn watch_registry(self: Arc<Self>, state: Arc<AppState>) {
        loop {
            match self.rooms_kv.watch_with_history(">").await {
                Ok(mut watch) => {
                    while let Some(entry) = watch.next().await {
                        match entry {
                            Ok(entry) => self.apply(&state, entry),
                            Err(e) => {
                                tracing::warn!("registry watch: {e}");
                                break;
                            }
                        }
                    }
                }
                Err(e) => tracing::warn!("registry watch: {e}"),
            }
            tokio::time::sleep(Duration::from_millis(250)).await;
        }
    }

    fn apply(&self, state: &Arc<AppState>, e: kv::Entry) {
        match e.operation {
            kv::Operation::Put => {
                let Ok(entry) = v1::RoomEntry::decode(e.value.as_ref()) else {
                    tracing::warn!(room = %e.key, "registry: not a RoomEntry, ignored");
                    return;
                };
                if let Some(link) = self.link(&e.key) {
                    let (_, mine) = link.entry();
                    if e.revision >= mine {
                        if link.is_owner() && entry.owner != self.replica {
                            link.yield_ownership();
                        }
                        link.set_entry(entry.clone(), e.revision);
                    }
                }
                self.note(&e.key, entry, e.revision);
            }
            kv::Operation::Delete | kv::Operation::Purge => {
                lock(&self.directory).remove(&e.key);
                self.close_local(state, &e.key);
            }
        }
    }

    /// Renews this replica's leases, and adopts rooms whose owner went silent for a lease.
    async fn keep_leases(self: Arc<Self>, state: Arc<AppState>) {
        let mut tick = tokio::time::interval(self.lease / 8);
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let mut renewed: BTreeMap<String, Instant> = BTreeMap::new();
        loop {
            tick.tick().await;
            if !self.is_connected() {
                continue;
            }
            let local = self.links();
            for link in local.iter().filter(|l| l.is_owner()) {
                let due = renewed
                    .get(link.room())
                    .is_none_or(|t| t.elapsed() >= self.lease / 4);
                if due || !link.is_confirmed() {
                    renewed.insert(link.room().to_owned(), Instant::now());
                    self.renew(link).await;
                }
            }
            renewed.retain(|id, _| local.iter().any(|l| l.room() == id));
            if lock(&self.connected_at).elapsed() < self.lease {
                continue;
            }
            // Silent for a whole lease and not owned here (a replica restarted under the same
            // id reclaims what it owned before).
            let owned_here = |id: &str| local.iter().any(|l| l.room() == id && l.is_owner());
            let expired: Vec<(String, Known)> = lock(&self.directory)
                .iter()
                .filter(|(id, k)| k.seen.elapsed() >= self.lease && !owned_here(id))
                .map(|(id, k)| (id.clone(), k.clone()))
                .collect();
            for (id, known) in expired {
                self.adopt(&state, &id, known).await;
            }
        }
    }

    /// Renews `link`'s lease: a compare-and-set on the revision this replica last wrote. A
    /// failed compare means another replica adopted the room: this one yields.
    async fn renew(&self, link: &Arc<RoomLink>) {
        let (mut entry, revision) = link.entry();
        entry.renewed_unix_ms = now_unix_ms();
        match self
            .rooms_kv
            .update(link.room(), entry.encode_to_vec().into(), revision)
            .await
        {
            Ok(rev) => {
                link.set_entry(entry, rev);
                link.set_confirmed(true);
            }
            Err(e) if e.kind() == kv::UpdateErrorKind::WrongLastRevision => {
                tracing::warn!(room = %link.room(), "lease lost: {e}");
                link.yield_ownership();
            }
            Err(e) => tracing::debug!(room = %link.room(), "lease renewal: {e}"),
        }
    }

    /// Adopts room `id`, whose owner was silent for a lease, if this replica has or can fetch
    /// its model: a compare-and-set from the revision seen, so that one replica wins.
    async fn adopt(self: &Arc<Self>, state: &Arc<AppState>, id: &str, known: Known) {
        if let Err(e) = self.local_room(state, id).await {
            tracing::debug!(room = %id, "cannot adopt: {e}");
            return;
        }
        let Some(link) = self.link(id) else {
            return;
        };
        let mut entry = known.entry.clone();
        let previous = std::mem::replace(&mut entry.owner, self.replica.clone());
        entry.adoptions += 1;
        entry.renewed_unix_ms = now_unix_ms();
        let silent = known.seen.elapsed();
        match self
            .rooms_kv
            .update(id, entry.encode_to_vec().into(), known.revision)
            .await
        {
            Ok(revision) => {
                self.note(id, entry.clone(), revision);
                link.become_owner(state, entry, revision);
                self.metrics.adoptions.inc();
                tracing::warn!(room = %id, from = %previous, silent_ms = silent.as_millis() as u64, "adopted room");
            }
            Err(e) => tracing::debug!(room = %id, "adoption lost: {e}"),
        }
    }

    /// Connection events: while disconnected nothing is judged or sent; on reconnection every
    /// owned room must renew before it publishes again, and every lease restarts its clock.
    async fn follow_connection(
        self: Arc<Self>,
        mut events: tokio::sync::mpsc::UnboundedReceiver<async_nats::Event>,
    ) {
        while let Some(event) = events.recv().await {
            match event {
                async_nats::Event::Disconnected => {
                    self.connected.store(false, Ordering::Release);
                    self.metrics.nats_connected.set(0);
                    tracing::warn!("NATS disconnected: serving local clients only");
                }
                async_nats::Event::Connected => {
                    for link in self.links() {
                        link.set_confirmed(false);
                    }
                    let now = Instant::now();
                    for k in lock(&self.directory).values_mut() {
                        k.seen = now;
                    }
                    *lock(&self.connected_at) = now;
                    self.connected.store(true, Ordering::Release);
                    self.metrics.nats_connected.set(1);
                    tracing::info!("NATS connected");
                }
                other => tracing::debug!("NATS: {other}"),
            }
        }
    }
}

/// The (lane) vertex counts of a model's channels' frames.
fn vertex_counts(model: &crate::registry::LoadedModel) -> [usize; crate::fanout::Channel::COUNT] {
    crate::fanout::Channel::ALL.map(|c| crate::pipeline::frame_vertices(&model.model, c))
}

impl Cluster {
    /// Removes room `id` from this replica (closed in the cluster), and stops its link.
    fn close_local(&self, state: &AppState, id: &str) {
        state.remove_room(id);
        if let Some(link) = lock(&self.links).remove(id) {
            link.shutdown();
        }
    }
}
