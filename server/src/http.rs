//! The HTTP side: `GET /healthz` (the process is up), `GET /readyz` (models loaded and not
//! shutting down: send traffic), `GET /metrics` (Prometheus), `/ws/rooms/{id}` (WebSocket,
//! [`crate::ws`]), and the static files of the browser viewer (`Config::web`) at `/`.

use std::sync::Arc;

use axum::Router;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use axum::routing::get;

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
    } else if state.models.is_empty() {
        (StatusCode::SERVICE_UNAVAILABLE, "no models loaded\n")
    } else {
        (StatusCode::OK, "ready\n")
    }
}

/// `GET /api/rooms`: the open rooms' ids, in order.
async fn rooms(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    let mut ids: Vec<String> = state
        .rooms
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .keys()
        .cloned()
        .collect();
    ids.sort();
    axum::Json(serde_json::json!({ "rooms": ids }))
}

/// `GET /api/rooms/{id}`: what a viewer needs besides the stream: the model's control points
/// (id, name, model vertex, rest position), the room's beta, the vertex counts.
async fn room_info(
    State(state): State<Arc<AppState>>,
    axum::extract::Path(id): axum::extract::Path<String>,
) -> axum::response::Response {
    let Some(room) = state.room(&id) else {
        return (StatusCode::NOT_FOUND, format!("room: no room {id:?}\n")).into_response();
    };
    let info = &room.model.info;
    let v3 = |v: Option<&crease_proto::v1::Vec3>| v.map_or([0.0; 3], |v| [v.x, v.y, v.z]);
    axum::Json(serde_json::json!({
        "room": room.id,
        "model": info.name,
        "beta": room.beta(),
        "has_detail": room.has_detail(),
        "base_vertices": info.base_vertices,
        "detail_vertices": info.detail_vertices,
        "bounds": info.bounds.as_ref().map(|b| [v3(b.min.as_ref()), v3(b.max.as_ref())]),
        "control_points": info.control_points.iter().map(|c| serde_json::json!({
            "id": c.id,
            "name": c.name,
            "vertex": c.vertex,
            "rest": v3(c.rest.as_ref()),
        })).collect::<Vec<_>>(),
    }))
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
