//! `crease-server`: hosts live rooms on trained models and streams predicted meshes. With no
//! arguments it runs the embedded demo (module `demo`): a hand model trained on first start and
//! cached, and room `demo` animated through the named poses.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use clap::Parser;
use crease_server::demo::{self, DEMO_BETA, DEMO_MODEL, DEMO_ROOM, DemoAnimation};
use crease_server::registry::ModelRegistry;
use crease_server::room::Room;
use crease_server::{AppState, Config, DEFAULT_GRPC, DEFAULT_HTTP, Limits, TlsFiles};

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
    /// Where the demo model is cached. Default: $CREASE_CACHE_DIR, else $XDG_CACHE_HOME/crease,
    /// else ~/.cache/crease.
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// The demo room's publish token (default: a random one, printed). With it, the viewer's
    /// control-point dragging can publish into room `demo`.
    #[arg(long, env = "CREASE_DEMO_TOKEN", hide_env_values = true)]
    demo_token: Option<String>,
    /// Frames per second of the demo animation.
    #[arg(long, default_value_t = 60.0)]
    demo_rate: f64,
    /// gRPC listen address.
    #[arg(long, default_value = DEFAULT_GRPC)]
    grpc: SocketAddr,
    /// HTTP listen address: the viewer (/), WebSocket (/ws/rooms/{id}), /healthz, /readyz,
    /// /metrics.
    #[arg(long, default_value = DEFAULT_HTTP)]
    http: SocketAddr,
    /// Static files served at / (the browser viewer). Default: the web/ folder of the source
    /// tree this binary was built from, if it exists.
    #[arg(long, value_name = "DIR")]
    web: Option<PathBuf>,
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
    /// Largest gRPC or WebSocket message accepted, bytes.
    #[arg(long, default_value_t = Limits::default().message_bytes)]
    max_message_bytes: usize,
}

#[tokio::main]
async fn main() -> Result<(), Box<dyn std::error::Error>> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "info".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let args = Args::parse();
    let mut models = match &args.models {
        Some(dir) => {
            let models = ModelRegistry::load_dir(dir)?;
            if models.is_empty() && !args.demo {
                return Err(format!(
                    "{}: no *.crease model files (train one with `crease train`, or add --demo)",
                    dir.display()
                )
                .into());
            }
            models
        }
        None => ModelRegistry::default(),
    };
    let run_demo = args.models.is_none() || args.demo;
    let demo_model = if run_demo {
        let cache = args.cache.clone().unwrap_or_else(demo::default_cache_dir);
        let model = tokio::task::spawn_blocking(move || {
            demo::demo_model(&cache, &mut |line| eprintln!("demo: {line}"))
        })
        .await??;
        let animation = DemoAnimation::new(&model)?;
        Some((models.insert(DEMO_MODEL, model), animation))
    } else {
        None
    };
    for m in models.iter() {
        tracing::info!(model = %m.name, vertices = m.info.base_vertices, detail = m.info.detail_vertices, "loaded");
    }
    let web = args.web.clone().or_else(|| {
        let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../web"));
        dir.is_dir().then_some(dir)
    });
    if let Some(dir) = &web
        && !dir.join("node_modules/three").is_dir()
    {
        eprintln!(
            "warning: {} has no node_modules: the viewer needs three.js and meshoptimizer \
             (run `npm ci --prefix {}`)",
            dir.display(),
            dir.display()
        );
    }
    let state = AppState::new(
        models,
        Config {
            grpc: args.grpc,
            http: args.http,
            admin_token: args.admin_token,
            limits: Limits {
                rooms: args.max_rooms,
                subscribers_per_room: args.max_subscribers,
                publish_hz: args.max_publish_hz,
                message_bytes: args.max_message_bytes,
            },
            web,
            tls: args
                .tls_cert
                .clone()
                .zip(args.tls_key.clone())
                .map(|(cert, key)| TlsFiles { cert, key }),
            ..Config::default()
        },
    );
    let mut demo_token = None;
    if let Some((model, animation)) = demo_model {
        // Keyframe mode: the control points are followed closely (HZY11 Fig. 11: beta ~3).
        let mut room = Room::open(DEMO_ROOM, model, Some(DEMO_BETA), state.config.stream)?;
        if let Some(token) = &args.demo_token {
            room = room.with_token(token);
        }
        let room = state.add_room(room)?;
        demo_token = Some(room.token().to_owned());
        tokio::spawn(demo::drive(
            Arc::clone(&state),
            room,
            animation,
            args.demo_rate,
        ));
    }
    let running = crease_server::serve(state).await?;
    eprintln!(
        "crease-server: gRPC on {}, HTTP on {} (/healthz /readyz /metrics /ws/rooms/ROOM)",
        running.grpc, running.http
    );
    if run_demo {
        let host = if running.http.ip().is_unspecified() {
            "localhost".to_owned()
        } else {
            running.http.ip().to_string()
        };
        let scheme = if args.tls_cert.is_some() {
            "https"
        } else {
            "http"
        };
        eprintln!(
            "demo: room {DEMO_ROOM:?} is live. Open {scheme}://{host}:{}/?room={DEMO_ROOM} or run \
             `crease watch --server {scheme}://{host}:{} --room {DEMO_ROOM}`",
            running.http.port(),
            running.grpc.port()
        );
        if args.demo_token.is_none()
            && let Some(token) = &demo_token
        {
            eprintln!(
                "demo: publish token {token} (enter it in the viewer to drag control points)"
            );
        }
    }
    shutdown_signal().await?;
    eprintln!("shutting down");
    running.shutdown(std::time::Duration::from_secs(5)).await?;
    Ok(())
}

/// Resolves on Ctrl-C, or on SIGTERM (what container runtimes send) on Unix.
async fn shutdown_signal() -> std::io::Result<()> {
    #[cfg(unix)]
    {
        let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())?;
        tokio::select! {
            r = tokio::signal::ctrl_c() => r,
            _ = term.recv() => Ok(()),
        }
    }
    #[cfg(not(unix))]
    tokio::signal::ctrl_c().await
}
