//! `crease-server`: serves the models of a model directory over gRPC (issue 6, in progress:
//! the HTTP/WebSocket side, the embedded demo and the operations endpoints come next).

use std::net::SocketAddr;
use std::path::PathBuf;

use clap::Parser;
use crease_server::registry::ModelRegistry;
use crease_server::{AppState, Config, Limits};

/// Hosts live rooms on trained crease models and streams predicted meshes.
#[derive(Debug, Parser)]
#[command(version)]
struct Args {
    /// Folder of `*.crease` model files (`crease train --out`).
    #[arg(long, value_name = "DIR")]
    models: PathBuf,
    /// gRPC listen address.
    #[arg(long, default_value = "0.0.0.0:50051")]
    grpc: SocketAddr,
    /// HTTP listen address (/healthz, /readyz, /metrics).
    #[arg(long, default_value = "0.0.0.0:8080")]
    http: SocketAddr,
    /// Token that opens and closes rooms (`authorization: Bearer <token>`); without it rooms
    /// cannot be opened remotely. Also read from CREASE_ADMIN_TOKEN.
    #[arg(long, env = "CREASE_ADMIN_TOKEN", hide_env_values = true)]
    admin_token: Option<String>,
    /// Most rooms open at once.
    #[arg(long, default_value_t = Limits::default().rooms)]
    max_rooms: usize,
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
    let models = ModelRegistry::load_dir(&args.models)?;
    if models.is_empty() {
        return Err(format!("{}: no *.crease model files", args.models.display()).into());
    }
    for m in models.iter() {
        tracing::info!(model = %m.name, vertices = m.info.base_vertices, detail = m.info.detail_vertices, "loaded");
    }
    let state = AppState::new(
        models,
        Config {
            grpc: args.grpc,
            http: args.http,
            admin_token: args.admin_token,
            limits: Limits {
                rooms: args.max_rooms,
                ..Limits::default()
            },
            ..Config::default()
        },
    );
    let running = crease_server::serve(state).await?;
    eprintln!(
        "crease-server: gRPC on {}, HTTP on {} (/healthz /readyz /metrics)",
        running.grpc, running.http
    );
    tokio::signal::ctrl_c().await?;
    eprintln!("shutting down");
    running.shutdown(std::time::Duration::from_secs(5)).await?;
    Ok(())
}
