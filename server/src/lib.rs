//! crease-server: hosts live rooms on loaded models and streams predicted meshes (issue 6).
//!
//! Layout, in the order a control frame crosses it:
//! - [`admission`]: caps on the connections and streams one client address, and everyone,
//!   may hold (the listeners and every long-lived call pass through it first).
//! - [`grpc`] / [`ws`]: the transports: the `crease.v1.Crease` service (tonic, with gRPC
//!   health and reflection) and `/ws/rooms/{id}` (subscribe and publish over WebSocket).
//!   [`status`]: the one mapping of every typed error to a gRPC status and an HTTP status.
//! - [`ingest`]: the one publish path of both: room lookup (a WebSocket session holds its
//!   room), the session entered once (token, rate), the wire frame read, a typed
//!   [`ingest::PublishError`]; in a cluster, a relay's frames go to the owner through the
//!   room's fan-out, and the owner takes them here.
//! - [`state`]: what the services share ([`state::AppState`]): the models, the private room
//!   table, and the one way to open and close a room ([`state::AppState::open_room`] from a
//!   `crease_proto::room::RoomSpec`, [`state::AppState::close_room`]; one
//!   [`state::OpenRoomError`]).
//! - [`room`]: a live room, tying together its [`session`] (identity, token in constant
//!   time, rate limit, subscriber slots), its [`pipeline`] (One Euro filter, predictor,
//!   encoders, frame pools; blocking work, run on the blocking pool), its [`mailbox`] (latest
//!   wins on the way in) and its [`fanout`] (latest-wins delivery per level behind a trait);
//!   [`capture`]: a retargeting room's markers to control points (issue 19);
//!   [`performer`]: a performer's actors placed where the capture put them (issue 38).
//! - [`frames`]: the encoded frame a room hands out ([`frames::MeshUpdate`], with its
//!   on-demand keyframe from the encoder's lanes) and the pool that recycles them.
//! - [`stream`]: subscribers' mesh streams (topology, then frames; on-demand keyframes) and
//!   batches.
//! - [`registry`]: the models of a model directory, loaded once (and, in a cluster, the
//!   models fetched from it).
//! - [`cluster`]: rooms across replicas over NATS (`--nats`): the room registry, relays,
//!   frames, forwarded controls, leases and failover, models in the cluster's store, the batch
//!   jobs' work queue (`cluster::work`); below [`state`], which it reaches through a trait.
//! - [`takes`]: a room's recordings (issue 22) in the takes folder: the recorder in the
//!   pipeline, its writer thread, listing and reading takes; [`take_service`]: the take
//!   operations both transports call (start, stop, list, export, replay rooms).
//! - [`jobs`]: batch jobs (issue 45) in this process, the store: a bounded queue of chunked
//!   jobs, their status, results in the jobs folder until they expire (in a cluster the store
//!   is `cluster::work`'s JetStream queue, bucket and object store); [`job_service`]: the one
//!   way to jobs for the transports, and the worker that runs each chunk as a `Synthesize`
//!   batch and stores it (one per process, or one per replica pulling the cluster's queue).
//! - [`model_api`]: models through the API (issue 39): uploads checked and written
//!   atomically into the models folder, deletes, the cluster's models.
//! - [`http`]: `/healthz`, `/readyz`, `/metrics`, `/api/rooms` (axum); [`metrics`]: the
//!   Prometheus metrics.
//! - [`config`]: the server's [`config::Config`] and [`config::Limits`]; [`listen`]: binds the
//!   listeners and runs until shut down ([`listen::Running`]).
//!
//! Every wire shape (protobuf conversions, a room's spec and registry entry, the JSON of the
//! HTTP side, error codes) is `crease-proto`'s. Depends on `crease-core`, `crease-proto` and
//! `crease-mocap` (a retargeting room's map and registration); the embedded demo and the
//! `crease-server` binary are in `crease-demo`.

pub mod admission;
pub mod capture;
pub mod cluster;
pub mod config;
pub mod fanout;
pub mod frames;
pub mod grpc;
pub mod http;
pub mod ingest;
pub mod job_service;
pub mod jobs;
pub mod listen;
pub mod mailbox;
pub mod metrics;
pub mod model_api;
pub mod performer;
pub mod pipeline;
pub mod registry;
pub mod room;
pub mod session;
pub mod state;
pub mod status;
pub mod stream;
pub mod take_service;
pub mod takes;
pub mod ws;

pub use config::{Config, DEFAULT_GRPC, DEFAULT_HTTP, Limits, TlsFiles, TlsPem};
pub use listen::{Running, serve};
pub use state::{AppState, OpenRoomError, join_cluster};
