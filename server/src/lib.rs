//! crease-server: hosts live rooms on loaded models and streams predicted meshes (issue 6).
//!
//! Layout, in the order a control frame crosses it:
//! - [`admission`]: caps on the connections and streams one client address, and everyone,
//!   may hold (the listeners and every long-lived call pass through it first).
//! - [`grpc`] / [`ws`]: the transports: the `crease.v1.Crease` service (tonic, with gRPC
//!   health and reflection) and `/ws/rooms/{id}` (subscribe and publish over WebSocket).
//! - [`ingest`]: the one publish path of both: room lookup, token, rate, the wire frame
//!   read, a typed [`ingest::PublishError`] mapped once per transport.
//! - [`room`]: a live room, tying together its [`session`] (identity, token in constant
//!   time, rate limit, counters), its [`pipeline`] (One Euro filter, predictor, encoders,
//!   frame pools; blocking work, run on the blocking pool) and its [`fanout`] (latest-wins
//!   delivery per level behind a trait).
//! - [`frames`]: the encoded frame a room hands out ([`frames::MeshUpdate`], with its
//!   on-demand keyframe from the encoder's lanes) and the pool that recycles them.
//! - [`stream`]: subscribers' mesh streams (topology, then frames; on-demand keyframes) and
//!   batches.
//! - [`registry`]: the models of a model directory, loaded once (and, in a cluster, the
//!   models fetched from it).
//! - [`cluster`]: rooms across replicas over NATS (`--nats`): the room registry, relayed
//!   frames, forwarded controls, leases and failover, models in the cluster's store.
//! - [`takes`]: a room's recordings (issue 22) in the takes folder: the recorder in the
//!   pipeline, its writer thread, listing and reading takes; [`take_service`]: the take
//!   operations both transports call (start, stop, list, export, replay rooms).
//! - [`http`]: `/healthz`, `/readyz`, `/metrics`, `/api/rooms` (axum); [`metrics`]: the
//!   Prometheus metrics.
//! - [`serve`]: binds the listeners and runs until shut down.
//!
//! Every wire shape (protobuf conversions, the JSON of the HTTP side, error codes) is
//! `crease-proto`'s. Depends on `crease-core` and `crease-proto` only (ARCHITECTURE.md); the
//! embedded demo and the `crease-server` binary are in `crease-demo`.

pub mod admission;
pub mod capture;
pub mod cluster;
pub mod fanout;
pub mod frames;
pub mod grpc;
pub mod http;
pub mod ingest;
pub(crate) mod mailbox;
pub mod metrics;
pub mod pipeline;
pub mod registry;
pub mod room;
pub mod session;
pub mod stream;
pub mod take_service;
pub mod takes;
pub mod ws;

use std::collections::HashMap;
use std::future::IntoFuture;
use std::net::SocketAddr;
use std::sync::{Arc, OnceLock, RwLock};

use registry::ModelRegistry;
use room::Room;

/// Limits that protect the server from its clients.
#[derive(Clone, Debug)]
pub struct Limits {
    /// Most rooms open at once.
    pub rooms: usize,
    /// Largest gRPC or WebSocket message accepted, bytes.
    pub message_bytes: usize,
    /// Most live subscriptions per room (gRPC and WebSocket together).
    pub subscribers_per_room: usize,
    /// Most control frames per second a room accepts (bursts of a quarter second's worth);
    /// frames over it are refused with RESOURCE_EXHAUSTED and change nothing.
    pub publish_hz: f64,
    /// TCP connections, per client address and in total, on each listener's count together
    /// ([`admission`]).
    pub connections: admission::Caps,
    /// Long-lived calls (gRPC Publish, Subscribe, Synthesize; WebSocket sessions), per client
    /// address and in total ([`admission`]).
    pub streams: admission::Caps,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            rooms: 64,
            message_bytes: 4 << 20,
            subscribers_per_room: 512,
            // Twice the fastest mocap rigs we expect (120 Hz).
            publish_hz: 240.0,
            // A classroom behind one NAT address stays well inside these; one client opening
            // sockets in a loop does not.
            connections: admission::Caps {
                per_address: 256,
                total: 4096,
            },
            streams: admission::Caps {
                per_address: 256,
                total: 8192,
            },
        }
    }
}

/// Server configuration.
#[derive(Clone, Debug)]
pub struct Config {
    /// gRPC listen address (port 0: any free port).
    pub grpc: SocketAddr,
    /// HTTP listen address (port 0: any free port).
    pub http: SocketAddr,
    /// Token required to open and close rooms (`None`: nobody can).
    pub admin_token: Option<String>,
    /// Limits.
    pub limits: Limits,
    /// How live rooms stream their meshes (bits, vertex order).
    pub stream: room::StreamSettings,
    /// Static files served at `/` (the browser viewer), if any.
    pub web: Option<std::path::PathBuf>,
    /// Serve gRPC and HTTP (and so WebSocket) over TLS with this certificate and key.
    pub tls: Option<TlsFiles>,
    /// Folder of marker maps (`*.toml`) a retargeting room may name (`Retarget.map_name`).
    pub maps: Option<std::path::PathBuf>,
    /// Folder rooms record their takes into (`StartTake`); `None`: no takes.
    pub takes: Option<std::path::PathBuf>,
}

/// A TLS certificate chain and its private key, PEM files.
#[derive(Clone, Debug)]
pub struct TlsFiles {
    /// The certificate chain (leaf first).
    pub cert: std::path::PathBuf,
    /// The private key (PKCS#8, PKCS#1 or SEC1).
    pub key: std::path::PathBuf,
}

/// The contents of [`TlsFiles`].
#[derive(Clone)]
pub struct TlsPem {
    /// The certificate chain, PEM.
    pub cert: Vec<u8>,
    /// The private key, PEM.
    pub key: Vec<u8>,
}

impl std::fmt::Debug for TlsPem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TlsPem").finish_non_exhaustive()
    }
}

impl TlsFiles {
    /// Reads both files.
    ///
    /// # Errors
    /// The I/O error, naming the file.
    pub fn load(&self) -> std::io::Result<TlsPem> {
        let read = |what: &str, path: &std::path::Path| {
            std::fs::read(path).map_err(|e| {
                std::io::Error::new(e.kind(), format!("TLS {what} {}: {e}", path.display()))
            })
        };
        Ok(TlsPem {
            cert: read("certificate", &self.cert)?,
            key: read("key", &self.key)?,
        })
    }
}

/// The default gRPC address: every interface, port 50051.
pub const DEFAULT_GRPC: &str = "0.0.0.0:50051";
/// The default HTTP (and WebSocket) address: every interface, port 8080.
pub const DEFAULT_HTTP: &str = "0.0.0.0:8080";

impl Default for Config {
    fn default() -> Self {
        Self {
            grpc: DEFAULT_GRPC.parse().expect("a valid address"),
            http: DEFAULT_HTTP.parse().expect("a valid address"),
            admin_token: None,
            limits: Limits::default(),
            stream: room::StreamSettings::default(),
            web: None,
            tls: None,
            maps: None,
            takes: None,
        }
    }
}

/// What the services share: the models and the open rooms.
#[derive(Debug)]
pub struct AppState {
    /// The hosted models.
    pub models: ModelRegistry,
    /// Open rooms by id.
    pub rooms: RwLock<HashMap<String, Arc<Room>>>,
    /// The configuration.
    pub config: Config,
    /// Set to `true` when the server shuts down: streams end.
    closing: tokio::sync::watch::Sender<bool>,
    /// Prometheus metrics.
    pub metrics: metrics::Metrics,
    /// The cluster this server joined (`cluster::join`), if any.
    cluster: OnceLock<Arc<cluster::Cluster>>,
    /// TCP connections held, per client address (`Limits::connections`).
    pub connections: Arc<admission::Admission>,
    /// Long-lived calls held, per client address (`Limits::streams`).
    pub streams: Arc<admission::Admission>,
    /// The takes folder (`Config::takes`), or why it cannot be used.
    takes: Option<Result<takes::Takes, String>>,
}

impl AppState {
    /// State with `models` and no rooms.
    pub fn new(models: ModelRegistry, config: Config) -> Arc<Self> {
        let connections = admission::Admission::new("connections", config.limits.connections);
        let streams = admission::Admission::new("streams", config.limits.streams);
        let mut metrics = metrics::Metrics::default();
        metrics.register_admission(&connections, &streams);
        let takes = config.takes.as_ref().map(|dir| {
            takes::Takes::new(dir).map_err(|e| {
                tracing::error!(error = %e, "takes folder unusable: rooms cannot record");
                e.to_string()
            })
        });
        Arc::new(Self {
            takes,
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

    /// The takes folder.
    ///
    /// # Errors
    /// [`takes::TakeError::NoFolder`] without one; [`takes::TakeError::Io`] when it could not
    /// be created.
    pub fn takes(&self) -> Result<&takes::Takes, takes::TakeError> {
        match &self.takes {
            None => Err(takes::TakeError::NoFolder),
            Some(Ok(takes)) => Ok(takes),
            Some(Err(why)) => Err(takes::TakeError::Io {
                path: self.config.takes.clone().unwrap_or_default(),
                error: std::io::Error::other(why.clone()),
            }),
        }
    }

    /// The ids of the takes rooms of this server record now.
    pub fn recording_takes(&self) -> Vec<String> {
        self.rooms
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .values()
            .filter_map(|r| r.pipeline().take_id())
            .collect()
    }

    /// The cluster this server joined, if any.
    pub fn cluster(&self) -> Option<&Arc<cluster::Cluster>> {
        self.cluster.get()
    }

    /// Room `id`: the local one, or in a cluster a relay of the cluster's room of that id,
    /// opened here now (`cluster::Cluster::local_room`).
    ///
    /// # Errors
    /// [`ingest::PublishError::NoRoom`], or in a cluster
    /// [`ingest::PublishError::Unavailable`] when the room's model cannot be had here.
    pub async fn find_room(self: &Arc<Self>, id: &str) -> Result<Arc<Room>, ingest::PublishError> {
        if let Some(room) = self.room(id) {
            return Ok(room);
        }
        match self.cluster() {
            Some(cluster) => Ok(Arc::clone(cluster).local_room(self, id).await?),
            None => Err(ingest::PublishError::NoRoom(id.to_owned())),
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

    /// Adds an opened room, within the room limit.
    ///
    /// # Errors
    /// [`AddRoomError`] when a room of that id is open or the limit is reached.
    pub fn add_room(&self, room: Room) -> Result<Arc<Room>, AddRoomError> {
        let mut rooms = self.rooms.write().unwrap_or_else(|e| e.into_inner());
        if rooms.contains_key(&room.id) {
            return Err(AddRoomError::Exists(room.id.clone()));
        }
        if rooms.len() >= self.config.limits.rooms {
            return Err(AddRoomError::Limit(rooms.len()));
        }
        let room = Arc::new(room);
        rooms.insert(room.id.clone(), Arc::clone(&room));
        self.metrics.rooms.set(rooms.len() as i64);
        tracing::info!(room = %room.id, model = %room.model.name, beta = room.beta(), "room opened");
        Ok(room)
    }

    /// Removes room `id` from this server (its streams end as their subscribers leave).
    pub fn remove_room(&self, id: &str) -> Option<Arc<Room>> {
        let mut rooms = self.rooms.write().unwrap_or_else(|e| e.into_inner());
        let removed = rooms.remove(id);
        self.metrics.rooms.set(rooms.len() as i64);
        removed
    }

    /// The room `id`.
    pub fn room(&self, id: &str) -> Option<Arc<Room>> {
        self.rooms
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .get(id)
            .cloned()
    }
}

/// Joins the cluster of `options` (`crease-server --nats`): [`cluster::join`] with the server's
/// publish path for the control frames other replicas forward to this one's rooms.
///
/// # Errors
/// [`cluster::ClusterError`]: NATS unreachable, JetStream missing.
pub async fn join_cluster(
    state: &Arc<AppState>,
    options: cluster::ClusterOptions,
) -> Result<Arc<cluster::Cluster>, cluster::ClusterError> {
    cluster::join(state, options, Arc::new(ingest::ack_forwarded)).await
}

/// Why a room could not be added.
#[derive(Debug, thiserror::Error)]
pub enum AddRoomError {
    /// A room of this id is open.
    #[error("room: {0:?} is open")]
    Exists(String),
    /// The room limit is reached.
    #[error("rooms: {0} open, the limit")]
    Limit(usize),
}

/// A running server: its bound addresses and a handle to stop it.
#[derive(Debug)]
pub struct Running {
    /// The gRPC address actually bound.
    pub grpc: SocketAddr,
    /// The HTTP address actually bound.
    pub http: SocketAddr,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    task: tokio::task::JoinHandle<Result<(), tonic::transport::Error>>,
    http_task: tokio::task::JoinHandle<std::io::Result<()>>,
}

impl Running {
    /// Stops accepting, ends the mesh streams, lets in-flight calls finish for up to `drain`,
    /// then drops what is left (a client that stopped reading cannot hold the server up).
    pub async fn shutdown(
        mut self,
        drain: std::time::Duration,
    ) -> Result<(), tonic::transport::Error> {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        let deadline = tokio::time::Instant::now() + drain;
        if tokio::time::timeout_at(deadline, &mut self.http_task)
            .await
            .is_err()
        {
            self.http_task.abort();
        }
        match tokio::time::timeout_at(deadline, &mut self.task).await {
            Ok(done) => done.unwrap_or(Ok(())),
            Err(_) => {
                tracing::warn!(?drain, "calls still open after the drain period: dropped");
                self.task.abort();
                Ok(())
            }
        }
    }
}

/// How long the HTTPS server lets open connections finish after shutdown starts.
const HTTPS_DRAIN: std::time::Duration = std::time::Duration::from_secs(5);

/// Binds the gRPC and HTTP listeners and serves `state` until [`Running::shutdown`], over TLS
/// when `state.config.tls` is set.
///
/// # Errors
/// Binding, reading the TLS files, or a certificate or key rustls refuses.
pub async fn serve(state: Arc<AppState>) -> std::io::Result<Running> {
    let tls = state.config.tls.as_ref().map(TlsFiles::load).transpose()?;
    let listener = tokio::net::TcpListener::bind(state.config.grpc).await?;
    let grpc = listener.local_addr()?;
    let http_listener = tokio::net::TcpListener::bind(state.config.http).await?;
    let http = http_listener.local_addr()?;
    let closing = state.closing();
    let app = http::router(Arc::clone(&state));
    let http_task = match &tls {
        None => tokio::spawn(
            axum::serve(
                admission::AdmittedListener::new(http_listener, Arc::clone(&state.connections)),
                app.into_make_service_with_connect_info::<admission::Peer>(),
            )
            .with_graceful_shutdown(closing)
            .into_future(),
        ),
        Some(pem) => {
            // rustls needs a process-wide crypto provider; ring, as tonic's TLS uses. A second
            // install (another server in this process) fails harmlessly.
            let _ = rustls::crypto::ring::default_provider().install_default();
            let config =
                axum_server::tls_rustls::RustlsConfig::from_pem(pem.cert.clone(), pem.key.clone())
                    .await
                    .map_err(|e| {
                        std::io::Error::new(e.kind(), format!("TLS certificate or key: {e}"))
                    })?;
            let handle = axum_server::Handle::new();
            let stop = handle.clone();
            tokio::spawn(async move {
                closing.await;
                stop.graceful_shutdown(Some(HTTPS_DRAIN));
            });
            let server = axum_server::from_tcp_rustls(http_listener.into_std()?, config)?;
            // The connection caps are not applied here (axum-server accepts on its own); the
            // stream caps are, as everywhere.
            tokio::spawn(
                server
                    .handle(handle)
                    .serve(app.into_make_service_with_connect_info::<admission::Peer>()),
            )
        }
    };
    tracing::info!(%http, "HTTP listening");
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let router = grpc::router(Arc::clone(&state), tls.as_ref())?;
    // Nagle off on every accepted socket (`admission::incoming` sets it): frames are small and
    // latency-bound (with it on, a frame could wait for the client's delayed ACK: ~27 ms p99 at
    // the client in `crease bench-net`, BENCHMARKS.md). tonic's own `tcp_nodelay` does not
    // apply to an incoming stream we hand it.
    let incoming = admission::incoming(listener, Arc::clone(&state.connections));
    let task = tokio::spawn(router.serve_with_incoming_shutdown(incoming, async move {
        let _ = rx.await;
        state.closing.send_replace(true);
    }));
    tracing::info!(%grpc, "gRPC listening");
    Ok(Running {
        grpc,
        http,
        shutdown: Some(tx),
        task,
        http_task,
    })
}
