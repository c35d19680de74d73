//! The server's configuration: [`Config`] (addresses, admin token, [`Limits`], stream settings,
//! TLS, the web, maps and takes folders) and the TLS files it reads ([`TlsFiles`]).

use std::net::SocketAddr;

use crate::admission;

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
    /// Most actors a room may hold (`OpenRoomRequest.actors`, issue 38).
    pub actors_per_room: usize,
    /// Largest model file `UploadModel` accepts, bytes (issue 39).
    pub model_bytes: u64,
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
            // Two performers' hands and bodies with room to spare; each actor costs a
            // prediction per frame.
            actors_per_room: 8,
            model_bytes: 512 << 20,
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

/// How jobs are run and kept (`crease-server --jobs`, `--job-ttl`, `--job-chunk-frames`,
/// `--max-job-frames`, `--max-queued-jobs`).
#[derive(Clone, Debug)]
pub struct JobSettings {
    /// Where results are stored; `None`: a temporary folder removed with the server.
    pub dir: Option<std::path::PathBuf>,
    /// How long an ended job's result is kept.
    pub ttl: std::time::Duration,
    /// Control frames per chunk.
    pub chunk_frames: usize,
    /// Most control frames in one job.
    pub max_frames: usize,
    /// Most jobs queued or running at once.
    pub max_queued: usize,
}

impl Default for JobSettings {
    fn default() -> Self {
        Self {
            dir: None,
            ttl: std::time::Duration::from_secs(24 * 3600),
            // A few seconds of work at the detail level: progress moves, a cancel lands soon,
            // and a chunk's file stays a few MB.
            chunk_frames: 500,
            // An hour of capture at 120 Hz (432,000 frames) fits; the frames are held in memory
            // until the job ends (~0.3 KB each for 15 control points).
            max_frames: 500_000,
            max_queued: 16,
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
    /// Serve `GET /metrics` on this address (plain HTTP) instead of the HTTP one, so the
    /// public port need not expose it (issue 47: `crease-server --metrics-addr`, the
    /// Prometheus habit); `None`: on the HTTP address.
    pub metrics: Option<SocketAddr>,
    /// Token required to open and close rooms (`None`: nobody can).
    pub admin_token: Option<String>,
    /// Limits.
    pub limits: Limits,
    /// How live rooms stream their meshes (bits, vertex order).
    pub stream: crate::pipeline::StreamSettings,
    /// Static files served at `/` (the browser viewer), if any.
    pub web: Option<std::path::PathBuf>,
    /// Serve gRPC and HTTP (and so WebSocket) over TLS with this certificate and key.
    pub tls: Option<TlsFiles>,
    /// Folder of marker maps (`*.toml`) a retargeting room may name (`Retarget.map_name`).
    pub maps: Option<std::path::PathBuf>,
    /// Folder rooms record their takes into (`StartTake`); `None`: no takes.
    pub takes: Option<std::path::PathBuf>,
    /// The models folder the server loaded at start, where `UploadModel` writes and
    /// `DeleteModel` removes (issue 39); `None`: models come only from the start.
    pub models_dir: Option<std::path::PathBuf>,
    /// The bone-level refinement of rooms, actors and batches whose request leaves it unset
    /// (issue 42; `crease-server --refine`): by default
    /// [`Refinement::ROOM_DEFAULT`](crease_core::predictor::Refinement::ROOM_DEFAULT), `None`:
    /// the regression alone. A request's `Refine.iterations = 0` turns it off for its room.
    pub refine: Option<crease_core::predictor::Refinement>,
    /// Batch jobs (issue 45): where results are kept, for how long, chunk size and caps.
    pub jobs: JobSettings,
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
            metrics: None,
            admin_token: None,
            limits: Limits::default(),
            stream: crate::pipeline::StreamSettings::default(),
            web: None,
            tls: None,
            maps: None,
            takes: None,
            models_dir: None,
            refine: Some(crease_core::predictor::Refinement::ROOM_DEFAULT),
            jobs: JobSettings::default(),
        }
    }
}
