//! Rooms across replicas (issue 17): `crease-server --nats URL` joins a cluster in which every
//! replica serves every room. NATS (through `async-nats`) carries it; each job has its file:
//!
//! - **The registry** ([`registry`]): a JetStream key-value bucket (`crease-rooms`): room id ->
//!   its [`RoomEntry`](crease_proto::v1::RoomEntry) (model and its digest, beta, filter, stream settings, owner, the
//!   publish token's digest, the lease). Every replica watches it into its [`Cluster::rooms`]
//!   view, so `OpenRoom`/`CloseRoom`/`GetRoom`, `/api/rooms` and the viewer's picker see the
//!   cluster's rooms and owners.
//! - **Relays** ([`relay`]): a room a replica touches (a viewer, a publisher, an adoption) is
//!   opened locally, through the server's one way of opening a room ([`Host::open_relay`]),
//!   as a full room whose fan-out is its [`RoomLink`]: one code path for owners and relays,
//!   and an adopter is ready at once.
//! - **Frames** ([`link`]): the owner predicts and encodes once and publishes each level's
//!   frame once to `crease.frames.<room>.<channel>` while another replica wants it; relays
//!   decode and fan out locally.
//! - **Controls** ([`control`]): a relay checks the token's digest and its room's fan-out
//!   forwards the frame to the owner, whose server takes it on its publish path
//!   ([`control::Ingest`]); the ack comes back.
//! - **Leases and failover** ([`leases`]): owners renew, a replica adopts a room whose owner
//!   was silent for a lease; a replica that loses NATS keeps serving its own clients and sends
//!   nothing into the cluster until a renewal succeeds (fencing by the revision).
//! - **Models** ([`models`]): a JetStream object store (`crease-models`) holds every replica's
//!   models; a replica that lacks a room's model fetches it and checks its digest first.
//! - **Batch jobs** ([`work`], issue 45): a JetStream work queue every replica pulls job
//!   chunks from, the jobs' records in a key-value bucket, their results in an object store;
//!   the worker that runs the chunks is the server's (`crate::job_service`).
//! - **Metrics** ([`metrics`]): `crease_cluster_*`.
//!
//! This file: joining ([`connect`], [`Cluster::start`]), the connection watcher, the options
//! and the errors. The cluster sits below the server's state: what it needs of the server (its
//! models and rooms, opening a relay, the owner's publish path) comes through the [`Host`]
//! trait, which the server implements, so the cluster never names the state.

pub mod control;
pub mod leases;
pub mod link;
pub mod metrics;
pub mod models;
pub mod registry;
pub mod relay;
pub mod stall;
pub mod trust;
pub mod work;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use async_nats::jetstream::{self, kv};
use crease_proto::room::RoomSpec;
use futures_util::future::BoxFuture;

pub use control::Ingest;
pub use link::RoomLink;
pub use metrics::ClusterMetrics;
pub use registry::Known;

use crate::registry::ModelRegistry;
use crate::room::Room;

/// The frames a room link's owner side hands to its NATS sender.
pub type LinkFrames =
    tokio::sync::mpsc::Receiver<(crate::fanout::Channel, Arc<crate::frames::MeshUpdate>)>;

/// The NATS connection's events, for the connection watcher.
type Events = tokio::sync::mpsc::UnboundedReceiver<async_nats::Event>;

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
    /// How this replica authenticates to NATS (issue 40).
    pub auth: trust::NatsAuth,
    /// The file of the cluster's shared key (`--cluster-key-file`): frames, controls and room
    /// entries are tagged with it and believed only with a good tag (`trust` module docs).
    /// None: believed as they come.
    pub key_file: Option<std::path::PathBuf>,
    /// How long a pulled job chunk may go unacknowledged before another replica gets it
    /// (the work queue's `ack_wait`, `--job-ack-wait`; set by whichever replica starts last).
    pub job_ack_wait: Duration,
}

/// The default `ack_wait` of the jobs' work queue: a worker renews it every third while it
/// runs a chunk, so it bounds how long a dead replica's chunk waits, not a chunk's length.
pub const DEFAULT_JOB_ACK_WAIT: Duration = Duration::from_secs(30);

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
            auth: trust::NatsAuth::default(),
            key_file: None,
            job_ack_wait: DEFAULT_JOB_ACK_WAIT,
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
    /// The NATS authentication options could not be applied (a credentials or password
    /// file).
    #[error("NATS authentication: {0}")]
    Auth(String),
    /// The cluster key file was refused.
    #[error("{0}")]
    Key(trust::KeyError),
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

/// Why a cluster's registry refused an operation.
#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    /// A room of this id is open in the cluster.
    #[error("room: {0:?} is open in the cluster")]
    Exists(String),
    /// The cluster has no room of this id.
    #[error("room: no room {0:?}")]
    NotFound(String),
    /// The registry cannot be read or written (NATS).
    #[error("registry: {0}")]
    Unavailable(String),
}

/// What the cluster needs of the server that joined it (module docs): its models, its rooms,
/// opening a relay through its one way of opening rooms, closing a room's local side, and
/// (the supertrait [`Ingest`]) the owner's publish path for forwarded control frames.
pub trait Host: Ingest + Send + Sync + 'static {
    /// The server's models (a fetched model is added to them).
    fn models(&self) -> &ModelRegistry;
    /// The server's open room `id`.
    fn room(&self, id: &str) -> Option<Arc<Room>>;
    /// Opens the relay `spec` describes (`RoomSpec::from_entry`) in the server's table.
    fn open_relay(
        self: Arc<Self>,
        spec: RoomSpec,
    ) -> BoxFuture<'static, Result<Arc<Room>, LookupError>>;
    /// Removes room `id` from the server (closed in the cluster).
    fn close_local(&self, id: &str);
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
    /// Rooms this replica could not serve (its model absent or corrupt): not retried before
    /// `relay::REFUSAL_BACKOFF`.
    refused: Mutex<BTreeMap<String, (String, Instant)>>,
    /// The cluster side of every local room, by id.
    links: Mutex<BTreeMap<String, Arc<RoomLink>>>,
    /// The connection's events, until [`Cluster::start`] hands them to the watcher.
    events: Mutex<Option<Events>>,
    /// The cluster's shared key (`trust`).
    pub(crate) key: Option<trust::ClusterKey>,
    /// The watchdog that tells a relay its process was stalled (`stall`).
    pub(crate) stall: Arc<stall::StallWatch>,
    /// The cluster metrics.
    pub metrics: ClusterMetrics,
    /// Batch jobs (`work`).
    work: work::WorkQueue,
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

/// Connects to the cluster at `options.url` and opens its buckets; `metrics` are the server's
/// cluster metrics. Nothing runs until [`Cluster::start`].
///
/// # Errors
/// [`ClusterError`]: NATS unreachable, JetStream missing.
pub async fn connect(
    options: ClusterOptions,
    metrics: ClusterMetrics,
) -> Result<Arc<Cluster>, ClusterError> {
    let key = match &options.key_file {
        Some(path) => Some(trust::ClusterKey::from_file(path).map_err(ClusterError::Key)?),
        None => None,
    };
    let (events_tx, events) = tokio::sync::mpsc::unbounded_channel();
    let connect = options
        .auth
        .apply(async_nats::ConnectOptions::new())
        .await
        .map_err(ClusterError::Auth)?;
    let client = connect
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
    let rooms_kv = registry::open_kv(&js).await?;
    let models_store = models::open_object_store(&js).await?;
    let work = work::WorkQueue::open(&js, key.clone(), options.job_ack_wait).await?;
    metrics.nats_connected.set(1);
    tracing::info!(
        replica = %options.replica,
        url = %options.url,
        auth = %options.auth.describe(),
        key = key.is_some(),
        "joined the cluster"
    );
    Ok(Arc::new(Cluster {
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
        events: Mutex::new(Some(events)),
        key,
        stall: stall::StallWatch::start(),
        metrics,
        work,
    }))
}

impl Cluster {
    /// Starts this replica's part on behalf of `host`: offers its models, and starts watching
    /// the registry, keeping leases and following the connection.
    pub async fn start(self: Arc<Self>, host: Arc<dyn Host>) {
        // Every local model's digest is set here, off the async threads, before any room
        // reads it.
        let serialised = models::serialise_local(host.models()).await;
        tokio::spawn(models::offer(Arc::clone(&self), serialised));
        tokio::spawn(Arc::clone(&self).watch_registry(Arc::clone(&host)));
        tokio::spawn(Arc::clone(&self).keep_leases(host));
        if let Some(events) = lock(&self.events).take() {
            tokio::spawn(Arc::clone(&self).follow_connection(events));
        }
    }

    /// Seals room `id`'s `entry` with the cluster key, if there is one (`trust`), before it is
    /// written.
    pub(crate) fn seal(&self, id: &str, entry: &mut crease_proto::v1::RoomEntry) {
        if let Some(key) = &self.key {
            key.seal_entry(id, entry);
        }
    }

    /// Whether room `id`'s `entry`, as read from the registry, is believed: always without a
    /// key, with one only when its seal holds.
    pub(crate) fn believed(&self, id: &str, entry: &crease_proto::v1::RoomEntry) -> bool {
        self.key.as_ref().is_none_or(|k| k.check_entry(id, entry))
    }

    /// The largest message the NATS server takes (a job chunk must fit in one).
    pub fn max_payload(&self) -> usize {
        self.client.server_info().max_payload
    }

    /// Whether this replica is connected to NATS.
    pub fn is_connected(&self) -> bool {
        self.connected.load(Ordering::Acquire)
    }

    /// The cluster side of local room `id`.
    pub fn link(&self, id: &str) -> Option<Arc<RoomLink>> {
        lock(&self.links).get(id).cloned()
    }

    fn links(&self) -> Vec<Arc<RoomLink>> {
        lock(&self.links).values().cloned().collect()
    }

    /// Connection events: while disconnected nothing is judged or sent; on reconnection every
    /// owned room must renew before it publishes again, and every lease restarts its clock.
    async fn follow_connection(self: Arc<Self>, mut events: Events) {
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
