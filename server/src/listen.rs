//! Listening: [`serve`] binds the gRPC and HTTP listeners (over TLS when configured) and runs
//! them until [`Running::shutdown`], which ends the mesh streams and drains the calls.

use std::future::IntoFuture;
use std::net::SocketAddr;
use std::sync::Arc;

use crate::state::AppState;
use crate::{admission, grpc, http};

/// A running server: its bound addresses and a handle to stop it.
#[derive(Debug)]
pub struct Running {
    /// The gRPC address actually bound.
    pub grpc: SocketAddr,
    /// The HTTP address actually bound.
    pub http: SocketAddr,
    /// The metrics address actually bound (`Config::metrics`), if any.
    pub metrics: Option<SocketAddr>,
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
    let tls = state
        .config()
        .tls
        .as_ref()
        .map(crate::config::TlsFiles::load)
        .transpose()?;
    let listener = tokio::net::TcpListener::bind(state.config().grpc).await?;
    let grpc = listener.local_addr()?;
    let http_listener = tokio::net::TcpListener::bind(state.config().http).await?;
    let http = http_listener.local_addr()?;
    // `/metrics` on its own address: plain HTTP, ended with the rest (a scrape is short).
    let metrics = match state.config().metrics {
        Some(addr) => {
            let listener = tokio::net::TcpListener::bind(addr).await?;
            let bound = listener.local_addr()?;
            tokio::spawn(
                axum::serve(listener, http::metrics_router(Arc::clone(&state)))
                    .with_graceful_shutdown(state.closing())
                    .into_future(),
            );
            tracing::info!(metrics = %bound, "metrics listening");
            Some(bound)
        }
        None => None,
    };
    let closing = state.closing();
    let app = http::router(Arc::clone(&state));
    let http_task = match &tls {
        None => tokio::spawn(
            axum::serve(
                admission::AdmittedListener::new(http_listener, state.connections()),
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
            // The connection caps before the handshake (`admission::AdmissionAcceptor`), the
            // stream caps as everywhere.
            let acceptor = axum_server::tls_rustls::RustlsAcceptor::new(config)
                .acceptor(admission::AdmissionAcceptor::new(state.connections()));
            let server = axum_server::from_tcp(http_listener.into_std()?)?.acceptor(acceptor);
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
    let incoming = admission::incoming(listener, state.connections());
    let task = tokio::spawn(router.serve_with_incoming_shutdown(incoming, async move {
        let _ = rx.await;
        state.shut_down();
    }));
    tracing::info!(%grpc, "gRPC listening");
    Ok(Running {
        grpc,
        http,
        metrics,
        shutdown: Some(tx),
        task,
        http_task,
    })
}
