//! A crease server in this process, on free loopback ports: [`serve_model`] (one model),
//! [`serve_models`] (several) and [`serve_config`] (any configuration) return a [`Served`] guard that stops the server when dropped, so a
//! test holds it for as long as it talks to the server.
//!
//! This file names only `crease_core`, `crease_server` and `tonic`, never `crate::`:
//! crease-server's own tests, which cannot take the kit as a dev-dependency (it depends on the
//! server), compile it into their `tests/common` with `#[path]`.

use std::net::SocketAddr;
use std::time::Duration;

use crease_core::model::TrainedModel;
use crease_server::registry::ModelRegistry;
use crease_server::{AppState, Config, Limits, Running};

/// A running server; dropping it stops the server.
///
/// Drop drops crease-server's [`Running`], whose shutdown handle going away starts the server's
/// own graceful shutdown (as [`Running::shutdown`] does): both listeners close at once, open
/// calls and streams are ended. [`Served::shutdown`] does the same and waits for the drain.
#[derive(Debug)]
pub struct Served {
    /// The gRPC address bound.
    pub grpc: SocketAddr,
    /// The HTTP (and WebSocket) address bound.
    pub http: SocketAddr,
    /// The metrics address bound, when the configuration asked for one.
    pub metrics: Option<SocketAddr>,
    /// `Some` until [`Served::shutdown`] takes it.
    running: Option<Running>,
}

impl Served {
    /// [`Running::shutdown`]: stops accepting, ends the streams, lets in-flight calls finish for
    /// up to `drain`, then drops what is left.
    pub async fn shutdown(mut self, drain: Duration) -> Result<(), tonic::transport::Error> {
        match self.running.take() {
            Some(running) => running.shutdown(drain).await,
            None => Ok(()),
        }
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        // Explicit, though field drop would do the same: the server stops here.
        drop(self.running.take());
    }
}

/// Limits with no publish rate limit, for tests that publish as fast as the room predicts.
pub fn unthrottled() -> Limits {
    Limits {
        publish_hz: f64::INFINITY,
        ..Limits::default()
    }
}

/// A server hosting `model` as `name` (see [`serve_models`]).
pub async fn serve_model(
    name: &str,
    model: &TrainedModel,
    admin: Option<&str>,
    limits: Limits,
) -> Served {
    serve_models([(name, model.clone())], admin, limits).await
}

/// A server on free loopback ports (gRPC and HTTP) hosting each `(name, model)`, with `admin`
/// as its admin token (none: no admin calls) and `limits`, its rooms predicting by the
/// regression alone unless a request asks for the refinement (`Config.refine = None`: the
/// tests compare rooms with a plain predictor); the rest of [`Config`] is its default. Call it
/// inside a tokio runtime: the server runs on it.
///
/// # Panics
/// If the loopback ports cannot be bound.
pub async fn serve_models<'a>(
    models: impl IntoIterator<Item = (&'a str, TrainedModel)>,
    admin: Option<&str>,
    limits: Limits,
) -> Served {
    serve_config(
        models,
        Config {
            admin_token: admin.map(str::to_owned),
            limits,
            refine: None,
            ..Config::default()
        },
    )
    .await
}

/// A server hosting each `(name, model)` with `config`, on free loopback ports whatever its
/// addresses say (its metrics address too, when it has one). Call it inside a tokio runtime.
///
/// # Panics
/// If the loopback ports cannot be bound.
pub async fn serve_config<'a>(
    models: impl IntoIterator<Item = (&'a str, TrainedModel)>,
    config: Config,
) -> Served {
    let registry = ModelRegistry::default();
    for (name, model) in models {
        registry.insert(name, model);
    }
    let loopback = SocketAddr::from(([127, 0, 0, 1], 0));
    let state = AppState::new(
        registry,
        Config {
            grpc: loopback,
            http: loopback,
            metrics: config.metrics.map(|_| loopback),
            ..config
        },
    );
    let running = crease_server::serve(state)
        .await
        .expect("a test server binds free loopback ports");
    Served {
        grpc: running.grpc,
        http: running.http,
        metrics: running.metrics,
        running: Some(running),
    }
}
