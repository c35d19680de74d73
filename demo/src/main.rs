//! `crease-server`: hosts live rooms on trained models and streams predicted meshes. With no
//! arguments it runs the embedded demo (crate `crease-demo`): a hand model trained on first
//! start and cached, and room `demo` animated through the named poses. Arguments become one
//! [`crease_demo::launch::Config`]; [`crease_demo::launch::run`] does the rest.

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::Parser;

/// The allocator (RELIABILITY.md, the soak): glibc's malloc kept the memory of freed multi-MB
/// messages (palette headers, keyframes) in its per-thread arenas, and a long run's resident
/// set grew with them; mimalloc returns it.
#[cfg(feature = "mimalloc")]
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;
use crease_core::predictor::Refinement;
use crease_demo::launch::{self, Config};
use crease_proto::room::{RefineFlag, parse_refine_flag};
use crease_server::admission::Caps;
use crease_server::jobs::JobSettings;
use crease_server::{DEFAULT_GRPC, DEFAULT_HTTP, Limits, TlsFiles};

/// Hosts live rooms on trained crease models and streams predicted meshes over gRPC and
/// WebSocket. With no --models it serves the embedded demo: a hand trained on first start
/// (cached; ~15 s) and room "demo" animated through the named poses.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Folder of `*.crease` model files (`crease train --out`). Without it the server runs the
    /// embedded demo.
    #[arg(long, value_name = "DIR")]
    models: Option<PathBuf>,
    /// Also run the demo (model `demo-hand`, room `demo`) next to --models.
    #[arg(long)]
    demo: bool,
    /// Folder of marker maps (`NAME.toml`, the format of bench/mocap/) that retargeting rooms
    /// may name (`crease room open --map-name NAME`) instead of sending the map.
    #[arg(long, value_name = "DIR")]
    maps: Option<PathBuf>,
    /// Folder the rooms record their takes into (`crease take start`). Default: `takes/` in
    /// the cache folder (--cache).
    #[arg(long, value_name = "DIR")]
    takes: Option<PathBuf>,
    /// Folder batch jobs keep their results in (`crease job`, issue 45). Default: `jobs/` in
    /// the cache folder (--cache).
    #[arg(long, value_name = "DIR")]
    jobs: Option<PathBuf>,
    /// Seconds an ended job's result is kept.
    #[arg(long, value_name = "SECONDS", default_value_t = JobSettings::default().ttl.as_secs())]
    job_ttl: u64,
    /// Control frames per chunk of a job: the unit of progress, of cancelling and of storage.
    #[arg(long, value_name = "N", default_value_t = JobSettings::default().chunk_frames as u64, value_parser = clap::value_parser!(u64).range(1..))]
    job_chunk_frames: u64,
    /// Most control frames in one job.
    #[arg(long, value_name = "N", default_value_t = JobSettings::default().max_frames)]
    max_job_frames: usize,
    /// Most jobs queued or running at once; a submit over it is refused.
    #[arg(long, value_name = "N", default_value_t = JobSettings::default().max_queued)]
    max_queued_jobs: usize,
    /// Where the demo model is cached. Default: $CREASE_CACHE_DIR, else $XDG_CACHE_HOME/crease,
    /// else ~/.cache/crease.
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// The demo room's publish token (default: a random one, printed). With it, the viewer's
    /// control-point dragging can publish into room `demo`.
    #[arg(long, env = "CREASE_DEMO_TOKEN", hide_env_values = true)]
    demo_token: Option<String>,
    /// Frames per second of the demo animation.
    #[arg(long, default_value_t = Config::default().demo_rate)]
    demo_rate: f64,
    /// gRPC listen address.
    #[arg(long, default_value = DEFAULT_GRPC)]
    grpc: SocketAddr,
    /// HTTP listen address: the viewer (/), WebSocket (/ws/rooms/{id}), /healthz, /readyz,
    /// /metrics (unless --metrics-addr).
    #[arg(long, default_value = DEFAULT_HTTP)]
    http: SocketAddr,
    /// Serve /metrics (Prometheus) on this address instead, plain HTTP, so that the public
    /// port does not expose it (e.g. 127.0.0.1:9090, or an address only the scraper reaches).
    #[arg(long, value_name = "ADDR")]
    metrics_addr: Option<SocketAddr>,
    /// Static files served at / (the browser viewer). Default: the web/ folder of the source
    /// tree this binary was built from, if it exists.
    #[arg(long, value_name = "DIR")]
    web: Option<PathBuf>,
    /// The bone-level refinement of rooms and batches that do not choose one (issue 42):
    /// `ITERATIONS,STRENGTH` or `off` (the regression alone). A request chooses with
    /// `Refine` (`crease room open --refine`); the demo's own rooms keep theirs. Each iteration
    /// costs ~105 µs a frame on a 150-bone model (BENCHMARKS.md).
    #[arg(long, value_name = "ITERATIONS,STRENGTH|off", default_value_t = RefineFlag(Some(Refinement::ROOM_DEFAULT)), value_parser = parse_refine_flag)]
    refine: RefineFlag,
    /// Token that opens and closes rooms (`authorization: Bearer <token>`); without it rooms
    /// cannot be opened remotely. Also read from CREASE_ADMIN_TOKEN.
    #[arg(long, env = "CREASE_ADMIN_TOKEN", hide_env_values = true)]
    admin_token: Option<String>,
    /// TLS certificate chain (PEM): serve gRPC and HTTP/WebSocket over TLS (rustls).
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// TLS private key (PEM) of --tls-cert.
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// Most rooms open at once.
    #[arg(long, default_value_t = Limits::default().rooms)]
    max_rooms: usize,
    /// Most live subscriptions per room.
    #[arg(long, default_value_t = Limits::default().subscribers_per_room)]
    max_subscribers: usize,
    /// Most control frames per second a room accepts.
    #[arg(long, default_value_t = Limits::default().publish_hz)]
    max_publish_hz: f64,
    /// Most actors a room may hold (both hands of a performer are two).
    #[arg(long, default_value_t = Limits::default().actors_per_room)]
    max_actors: usize,
    /// Largest model file an admin may upload (`crease model upload`), bytes.
    #[arg(long, default_value_t = Limits::default().model_bytes)]
    max_model_bytes: u64,
    /// Largest gRPC or WebSocket message accepted, bytes.
    #[arg(long, default_value_t = Limits::default().message_bytes)]
    max_message_bytes: usize,
    /// Most TCP connections one client address may hold (gRPC and HTTP together); more are
    /// closed at once (HTTP: after a 503). Behind a proxy every client is the proxy: raise it.
    #[arg(long, default_value_t = Limits::default().connections.per_address)]
    max_connections_per_address: usize,
    /// Most TCP connections in total.
    #[arg(long, default_value_t = Limits::default().connections.total)]
    max_connections: usize,
    /// Most streams (gRPC Publish, Subscribe, Synthesize; WebSocket sessions) one client
    /// address may hold; more are refused (RESOURCE_EXHAUSTED, HTTP 429).
    #[arg(long, default_value_t = Limits::default().streams.per_address)]
    max_streams_per_address: usize,
    /// Most streams in total.
    #[arg(long, default_value_t = Limits::default().streams.total)]
    max_streams: usize,
    /// Join a cluster through this NATS server (JetStream on, e.g. `nats-server -js`): every
    /// replica serves every room of the cluster; a dead replica's rooms are adopted. With it,
    /// --models may be empty (models are fetched from the cluster).
    #[arg(long, value_name = "URL", env = "CREASE_NATS")]
    nats: Option<String>,
    /// This replica's id in the cluster (unique). Default: the host name and a random suffix.
    #[arg(long, value_name = "ID", requires = "nats", env = "CREASE_REPLICA_ID")]
    replica_id: Option<String>,
    /// NATS credentials file (decentralised auth: a user JWT and its nkey seed, as `nsc`
    /// writes them).
    #[arg(
        long,
        value_name = "FILE",
        requires = "nats",
        env = "CREASE_NATS_CREDS"
    )]
    nats_creds: Option<PathBuf>,
    /// NATS user name; the password comes from the environment (CREASE_NATS_PASSWORD) or
    /// --nats-password-file, never the command line.
    #[arg(long, value_name = "USER", requires = "nats", env = "CREASE_NATS_USER")]
    nats_user: Option<String>,
    /// A file whose first line is the NATS password.
    #[arg(long, value_name = "FILE", requires = "nats_user")]
    nats_password_file: Option<PathBuf>,
    /// TLS to NATS: the CA certificate (PEM) that signed the NATS server's.
    #[arg(
        long,
        value_name = "FILE",
        requires = "nats",
        env = "CREASE_NATS_TLS_CA"
    )]
    nats_tls_ca: Option<PathBuf>,
    /// Mutual TLS to NATS: this replica's certificate (PEM); with --nats-tls-key.
    #[arg(long, value_name = "FILE", requires_all = ["nats", "nats_tls_key"], env = "CREASE_NATS_TLS_CERT")]
    nats_tls_cert: Option<PathBuf>,
    /// Mutual TLS to NATS: this replica's private key (PEM).
    #[arg(
        long,
        value_name = "FILE",
        requires = "nats_tls_cert",
        env = "CREASE_NATS_TLS_KEY"
    )]
    nats_tls_key: Option<PathBuf>,
    /// The cluster's shared key (at least 32 bytes: hex, e.g. `openssl rand -hex 32`, or raw):
    /// every replica tags its frames, forwarded controls and room entries with it, and believes
    /// only tagged ones (ARCHITECTURE.md, "A cluster that trusts only its own").
    #[arg(
        long,
        value_name = "FILE",
        requires = "nats",
        env = "CREASE_CLUSTER_KEY_FILE"
    )]
    cluster_key_file: Option<PathBuf>,
    /// The owner's lease in milliseconds: a replica silent this long loses its rooms to others.
    #[arg(long, value_name = "MS", requires = "nats", default_value_t = crease_server::cluster::DEFAULT_LEASE.as_millis() as u64)]
    lease_ms: u64,
    /// Seconds a job chunk pulled by a replica may go unacknowledged before another replica
    /// gets it (the jobs' work queue's ack_wait, issue 45). A worker renews it while it runs a
    /// chunk, so this bounds how long a dead replica's chunk waits, not a chunk's length.
    #[arg(long, value_name = "SECONDS", requires = "nats", default_value_t = crease_server::cluster::DEFAULT_JOB_ACK_WAIT.as_secs_f64())]
    job_ack_wait: f64,
    /// Most threads of the blocking pool that runs the frames' work (prediction, encoding,
    /// model loading). Default: 4 per core, at least 16. More threads than cores only helps
    /// when some block for long; a pool that grows with the load costs a stack and an
    /// allocator arena per thread (tokio's own default is 512).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    blocking_threads: Option<u16>,
    /// How the log is written on stderr: `text` (for people) or `json` (one JSON object per
    /// line, for log collectors; the start-up banner becomes events too). The level comes from
    /// RUST_LOG (default `info`).
    #[arg(long, value_enum, value_name = "FORMAT", default_value_t = LogFormat::Text, env = "CREASE_LOG_FORMAT")]
    log_format: LogFormat,
}

/// `--log-format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum LogFormat {
    /// Human-readable lines.
    Text,
    /// JSON lines: `timestamp`, `level`, `target` and the event's fields (`message` among them).
    Json,
}

/// The default of `--blocking-threads`.
fn default_blocking_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    (4 * cores).max(16)
}

impl From<Args> for Config {
    fn from(args: Args) -> Self {
        Config {
            server: crease_server::Config {
                grpc: args.grpc,
                http: args.http,
                metrics: args.metrics_addr,
                admin_token: args.admin_token,
                limits: Limits {
                    rooms: args.max_rooms,
                    subscribers_per_room: args.max_subscribers,
                    publish_hz: args.max_publish_hz,
                    actors_per_room: args.max_actors,
                    model_bytes: args.max_model_bytes,
                    message_bytes: args.max_message_bytes,
                    connections: Caps {
                        per_address: args.max_connections_per_address,
                        total: args.max_connections,
                    },
                    streams: Caps {
                        per_address: args.max_streams_per_address,
                        total: args.max_streams,
                    },
                },
                web: args.web.or_else(launch::source_tree_web),
                maps: args.maps,
                takes: args.takes,
                // launch::start sets it from `models` below.
                models_dir: None,
                refine: args.refine.0,
                jobs: JobSettings {
                    dir: args.jobs,
                    ttl: std::time::Duration::from_secs(args.job_ttl),
                    chunk_frames: usize::try_from(args.job_chunk_frames).unwrap_or(usize::MAX),
                    max_frames: args.max_job_frames,
                    max_queued: args.max_queued_jobs,
                },
                tls: args
                    .tls_cert
                    .zip(args.tls_key)
                    .map(|(cert, key)| TlsFiles { cert, key }),
                ..crease_server::Config::default()
            },
            models: args.models,
            demo: args.demo,
            cache: args.cache,
            demo_token: args.demo_token,
            demo_rate: args.demo_rate,
            banner_in_log: args.log_format == LogFormat::Json,
            cluster: args.nats.map(|url| crease_server::cluster::ClusterOptions {
                lease: std::time::Duration::from_millis(args.lease_ms.max(100)),
                auth: crease_server::cluster::trust::NatsAuth {
                    creds: args.nats_creds,
                    user: args.nats_user,
                    password: std::env::var("CREASE_NATS_PASSWORD").ok(),
                    password_file: args.nats_password_file,
                    tls_ca: args.nats_tls_ca,
                    tls_client: args.nats_tls_cert.zip(args.nats_tls_key),
                },
                key_file: args.cluster_key_file,
                job_ack_wait: std::time::Duration::from_secs_f64(
                    args.job_ack_wait.clamp(0.5, 3600.0),
                ),
                ..crease_server::cluster::ClusterOptions::new(&url, args.replica_id)
            }),
            ..Config::default()
        }
    }
}

fn main() -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
    let args = Args::parse();
    let log = tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr);
    match args.log_format {
        LogFormat::Text => log.init(),
        LogFormat::Json => log.json().flatten_event(true).init(),
    }
    let blocking = args
        .blocking_threads
        .map_or_else(default_blocking_threads, usize::from);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .max_blocking_threads(blocking)
        .build()?;
    // An error that stops the server is said once, as a sentence (its Display, not a debug
    // dump), in the log and on stderr, and the exit status is 1.
    if let Err(e) = launch::run_until_signal(&runtime, args.into()) {
        tracing::error!("{e}");
        eprintln!("crease-server: {e}");
        std::process::exit(1);
    }
    Ok(())
}
