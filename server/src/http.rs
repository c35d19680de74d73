//! The HTTP side: `GET /healthz` (the process is up), `GET /readyz` (models loaded and not
//! shutting down: send traffic), `GET /metrics` (Prometheus; on its own address instead with
//! `Config::metrics`, [`metrics_router`]), `/ws/rooms/{id}` (WebSocket,
//! [`crate::ws`]), the rooms (`/api/rooms`, `/api/rooms/{id}`), the takes (issue 22:
//! `GET /api/takes[?room=ID]`, `GET /api/takes/{id}` the file, `.../frames` as JSON for the
//! viewer's player, `.../glb` as a skinned glTF animation, `POST .../replay` opens a private
//! room to play it back in; [`crate::take_service`]), the batch jobs (issue 45: `GET
//! /api/jobs`, the viewer's job list; [`crate::job_service`]), and the static files of the browser
//! viewer (`Config::web`) at `/`.

use std::sync::Arc;

use axum::Router;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::IntoResponse;
use axum::routing::get;

use crease_proto::json::{ActorDocument, RoomDocument, RoomList, RoomOwner, TakeList, TakeSummary};

use crate::ingest::PublishError;
use crate::room::Actor;
use crate::state::AppState;
use crate::status;

/// The HTTP router over shared state.
pub fn router(state: Arc<AppState>) -> Router {
    let web = state.config().web.clone();
    let mut router = Router::new()
        .route("/healthz", get(|| async { "ok\n" }))
        .route("/readyz", get(readyz));
    if state.config().metrics.is_none() {
        router = router.route("/metrics", get(metrics));
    }
    let router = router
        .route("/ws/rooms/{id}", get(crate::ws::room_socket))
        .route("/api/rooms", get(rooms))
        .route("/api/rooms/{id}", get(room_info))
        .route("/api/jobs", get(jobs_list))
        .route("/api/takes", get(takes_list))
        .route("/api/takes/{id}", get(take_file))
        .route("/api/takes/{id}/frames", get(take_frames))
        .route("/api/takes/{id}/glb", get(take_glb))
        .route("/api/takes/{id}/replay", axum::routing::post(take_replay))
        .with_state(state);
    match web {
        // `index.html` for directories; anything else missing is a plain 404.
        Some(dir) => router.fallback_service(tower_http::services::ServeDir::new(dir)),
        None => router,
    }
}

/// The router of `Config::metrics`' own address: `GET /metrics` and `GET /healthz`.
pub fn metrics_router(state: Arc<AppState>) -> Router {
    Router::new()
        .route("/healthz", get(|| async { "ok\n" }))
        .route("/metrics", get(metrics))
        .with_state(state)
}

async fn readyz(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    if state.is_closing() {
        (StatusCode::SERVICE_UNAVAILABLE, "shutting down\n")
    } else if state.cluster().is_some_and(|c| !c.is_connected()) {
        (StatusCode::SERVICE_UNAVAILABLE, "NATS disconnected\n")
    } else if state.models().is_empty() && state.cluster().is_none() {
        (StatusCode::SERVICE_UNAVAILABLE, "no models loaded\n")
    } else {
        (StatusCode::OK, "ready\n")
    }
}

/// `GET /api/rooms`: the open rooms' ids, in order; in a cluster every room of the cluster,
/// with its model, owner and actors.
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
                    actors: k
                        .entry
                        .actors
                        .iter()
                        .filter_map(|a| a.actor.as_ref().map(|a| a.name.clone()))
                        .collect(),
                })
                .collect(),
            replica: Some(cluster.replica.clone()),
        });
    }
    axum::Json(RoomList {
        rooms: state.listed_rooms(),
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
    let room = match state.find_room(&id).await.map_err(PublishError::from) {
        Ok(room) => room,
        Err(e) => return (status::publish_http(&e), format!("{e}\n")).into_response(),
    };
    let document = |a: &Actor| {
        let p = a.pipeline();
        RoomDocument::new(
            &room.id,
            &a.model.info,
            p.beta(),
            p.has_detail(),
            p.capture().map(|c| c.wire()),
        )
        .with_skinning(p.skinning())
    };
    let mut doc = document(&room.actors()[0]);
    doc.has_detail = room.has_detail();
    doc.actors = room
        .actors()
        .iter()
        .filter_map(|a| {
            a.spec().map(|spec| ActorDocument {
                name: spec.name.clone(),
                side: Some(spec.side.as_str().to_owned()).filter(|s| !s.is_empty()),
                performer: spec.performer.clone(),
                room: document(a),
            })
        })
        .collect();
    axum::Json(doc).into_response()
}

async fn metrics(State(state): State<Arc<AppState>>) -> impl IntoResponse {
    if state.cluster().is_none() {
        state.metrics().count_jobs(&state.jobs().list());
    }
    (
        [(
            header::CONTENT_TYPE,
            "application/openmetrics-text; version=1.0.0; charset=utf-8",
        )],
        state.metrics().render(),
    )
}

/// `GET /api/jobs`: the batch jobs, newest first ([`crease_proto::json::JobList`]).
async fn jobs_list(State(state): State<Arc<AppState>>) -> axum::response::Response {
    match crate::job_service::list(&state).await {
        Ok(jobs) => axum::Json(crease_proto::json::JobList {
            jobs: jobs
                .iter()
                .map(crease_proto::json::JobSummary::from)
                .collect(),
        })
        .into_response(),
        Err(e) => (status::job_http(&e), format!("{e}\n")).into_response(),
    }
}

/// `?room=ID` of `GET /api/takes`.
#[derive(Debug, serde::Deserialize)]
struct TakesQuery {
    #[serde(default)]
    room: String,
}

/// A take operation's error as a plain-text response.
fn take_error(e: &crate::take_service::TakeOpError) -> axum::response::Response {
    (status::take_http(e), format!("{e}\n")).into_response()
}

/// `GET /api/takes[?room=ID]`: the takes, newest first ([`TakeList`]).
async fn takes_list(
    State(state): State<Arc<AppState>>,
    axum::extract::Query(q): axum::extract::Query<TakesQuery>,
) -> axum::response::Response {
    match crate::take_service::list(&state, q.room).await {
        Ok(takes) => axum::Json(TakeList {
            takes: takes.iter().map(TakeSummary::from).collect(),
        })
        .into_response(),
        Err(e) => take_error(&e),
    }
}

/// `GET /api/takes/{id}`: the take file up to its last whole frame.
async fn take_file(
    State(state): State<Arc<AppState>>,
    axum::extract::Path(id): axum::extract::Path<String>,
) -> axum::response::Response {
    match crate::take_service::bytes(&state, id.clone()).await {
        Ok(bytes) => attachment("application/octet-stream", &format!("{id}.take"), bytes),
        Err(e) => take_error(&e),
    }
}

/// `GET /api/takes/{id}/frames`: [`crease_proto::json::TakeFrames`].
async fn take_frames(
    State(state): State<Arc<AppState>>,
    axum::extract::Path(id): axum::extract::Path<String>,
) -> axum::response::Response {
    match crate::take_service::frames(&state, id).await {
        Ok(frames) => axum::Json(frames).into_response(),
        Err(e) => take_error(&e),
    }
}

/// `GET /api/takes/{id}/glb`: the take as a skinned glTF animation.
async fn take_glb(
    State(state): State<Arc<AppState>>,
    axum::extract::Path(id): axum::extract::Path<String>,
) -> axum::response::Response {
    match crate::take_service::glb(&state, id.clone()).await {
        Ok(bytes) => attachment("model/gltf-binary", &format!("{id}.glb"), bytes),
        Err(e) => take_error(&e),
    }
}

/// `POST /api/takes/{id}/replay`: a private room to play the take in
/// ([`crease_proto::json::ReplayRoom`]).
async fn take_replay(
    State(state): State<Arc<AppState>>,
    axum::extract::Path(id): axum::extract::Path<String>,
) -> axum::response::Response {
    match crate::take_service::open_replay(&state, id).await {
        Ok(room) => axum::Json(room).into_response(),
        Err(e) => take_error(&e),
    }
}

/// `bytes` as a download named `file` (ids are `[A-Za-z0-9_-]`, so the name needs no quoting
/// beyond the quotes).
fn attachment(content_type: &'static str, file: &str, bytes: Vec<u8>) -> axum::response::Response {
    (
        [
            (header::CONTENT_TYPE, content_type.to_owned()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{file}\""),
            ),
        ],
        bytes,
    )
        .into_response()
}
