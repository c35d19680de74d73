//! The tube model and the in-process server: the model streams, and dropping the [`Served`]
//! guard stops the server (both ports refuse connections), as does `shutdown`.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use crease_testkit::model::{AROUND, RINGS, model, tube};
use crease_testkit::server::{Served, serve_model, serve_models, unthrottled};

/// Whether `addr` accepts a TCP connection.
async fn accepts(addr: SocketAddr) -> bool {
    tokio::net::TcpStream::connect(addr).await.is_ok()
}

/// Waits up to 10 s for `addr` to refuse connections.
async fn refuses_soon(addr: SocketAddr) -> bool {
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if !accepts(addr).await {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    false
}

#[test]
fn the_tube_model_is_trained_on_the_tube() {
    let model = model();
    assert_eq!(model.rig.rest, tube());
    assert_eq!(model.rig.rest.vertex_count(), RINGS * AROUND);
    let controls: Vec<u32> = model.controls.iter().map(|c| c.vertex).collect();
    assert_eq!(controls, [0, 45, 42]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dropping_the_guard_stops_the_server() {
    let model = model();
    let served: Served = serve_model("tube", &model, Some("admin"), unthrottled()).await;
    let (grpc, http) = (served.grpc, served.http);
    assert!(grpc.ip().is_loopback() && grpc.port() != 0, "{grpc}");
    assert!(accepts(grpc).await && accepts(http).await);
    drop(served);
    assert!(
        refuses_soon(grpc).await,
        "gRPC still accepts after the drop"
    );
    assert!(
        refuses_soon(http).await,
        "HTTP still accepts after the drop"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shutdown_drains_and_stops_a_server_of_several_models() {
    let model = model();
    let served = serve_models(
        [("a", model.clone()), ("b", model)],
        None,
        crease_server::Limits::default(),
    )
    .await;
    let grpc = served.grpc;
    assert!(accepts(grpc).await);
    served.shutdown(Duration::from_secs(2)).await.unwrap();
    assert!(
        refuses_soon(grpc).await,
        "gRPC still accepts after shutdown"
    );
}
