//! The HTTP side: `GET /healthz` (the process is up), `GET /readyz` (models loaded and not
//! shutting down: send traffic), `GET /metrics` (Prometheus), `/ws/rooms/{id}` (WebSocket,
//! [`crate::ws`]), and the static files of the browser viewer (`Config::web`) at `/`.

use std::sync::Arc;

use axum::Router;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use axum::routing::get;

use crease_proto::json::{RoomDocument, RoomList, RoomOwner};

use crate::AppState;

/// The HTTP router over shared state.
pub fn router(state: Arc<AppState>) -> Router {
    let web = state.config.web.clone();
    let router = Router::new()
        .route("/healthz", get(|| async { "ok\n" }))
        .route("/readyz", get(readyz))
        .route("/metrics", get(metrics))
        .route("/ws/rooms/{id}", get(crate::ws::room_socket))
        .route("/api/rooms", get(rooms))
        .route("/api/rooms/{id}", get(room_info))
        .with_state(state);
    match web {
        // `index.html` for directories; anything else missing is a plain 404.
        Some(dir) => router.fallback_service(tower_http::services::ServeDir::new(dir)),
        None => router,
    }
}

async fn readyz(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    if state.is_closing() {
        (StatusCode::SERVICE_UNAVAILABLE, "shutting down\n")
    } else if state.cluster().is_some_and(|c| !c.is_connected()) {
        (StatusCode::SERVICE_UNAVAILABLE, "NATS disconnected\n")
    } else if state.models.is_empty() && state.cluster().is_none() {
        (StatusCode::SERVICE_UNAVAILABLE, "no models loaded\n")
    } else {
        (StatusCode::OK, "ready\n")
    }
}

/// `GET /api/rooms`: the open rooms' ids, in order; in a cluster every room of the cluster,
/// with its model and owner.
async fn rooms(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    if let Some(cluster) = state.cluster() {
        let rooms = cluster.rooms();
        return axum::Json(RoomList {
            rooms: rooms.keys().cloned().collect(),
            cluster: rooms
                .iter()
                .map(|(id, k)| RoomOwner {
                    room: id.clone(),
                    model: k.entry.model.clone(),
                    owner: k.entry.owner.clone(),
                })
                .collect(),
            replica: Some(cluster.replica.clone()),
        });
    }
    let mut ids: Vec<String> = state
        .rooms
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .keys()
        .cloned()
        .collect();
    ids.sort();
    axum::Json(RoomList {
        rooms: ids,
        cluster: Vec::new(),
        replica: None,
    })
}

/// `GET /api/rooms/{id}`: what a viewer needs besides the stream: the model's control points
/// (id, name, model vertex, rest position), the room's beta, the vertex counts and, for a
/// retargeting room, the markers its frames carry ([`RoomDocument`]).
async fn room_info(
    State(state): State<Arc<AppState>>,
    axum::extract::Path(id): axum::extract::Path<String>,
) -> axum::response::Response {
    let room = match state.find_room(&id).await {
        Ok(room) => room,
        Err(e) => return (e.http_status(), format!("{e}\n")).into_response(),
    };
    axum::Json(RoomDocument::new(
        &room.id,
        &room.model.info,
        room.beta(),
        room.has_detail(),
        room.pipeline().capture().map(|c| c.wire()),
    ))
    .into_response()
}

async fn metrics(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        state.metrics.render(),
    )
}
