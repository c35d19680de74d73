//! The WebSocket endpoint `GET /ws/rooms/{id}` on the HTTP server, for browsers:
//!
//! - **Subscribe**: every binary message the server sends is one protobuf `crease.v1.MeshFrame`
//!   (the topology first, then frames), exactly as gRPC's `Subscribe` streams them.
//!   `?level=detail` asks for the detail layer, `?encoding=palette` for palette frames (the
//!   bones, not the vertices; issue 18: a `PaletteTopology` first, then palette frames);
//!   `?subscribe=false` publishes only.
//! - **Publish**: a binary message is a protobuf `ControlFrame`, a text message the same as JSON
//!   (`{"seq": 1, "capture_time_us": 0, "positions": [x, y, z, ...], "valid": [true, ...]}`,
//!   `valid` optional); the room is the path's. Publishing needs the room's token, sent in the
//!   `Sec-WebSocket-Protocol` header (issue 21): the client offers the subprotocols
//!   `crease.v1` and `crease.token.<the token in unpadded base64url>`, and the server selects
//!   `crease.v1` (in a browser: `new WebSocket(url, ["crease.v1", "crease.token." + b64])`).
//!   A token in the URL (`?token=`) is refused with `400`: URLs are kept by proxies, access
//!   logs and browser history, a header is not; the token is never logged.
//!   Each frame is answered by a text message, the ack as JSON
//!   (`{"seq": 1, "server_latency_us": 120, "held_controls": 0, "control_residual": 0.002,
//!   "error": null}` or with
//!   `"error": {"code": 3, "message": "positions: ..."}`).
//!
//! A session is a stream for the caps on what one client address may hold
//! ([`crate::admission`]): over them the upgrade is refused with `429` naming the cap.
//!
//! A bad message is answered by an error ack and the socket stays open. The session holds its
//! room, looked up once at the upgrade: each frame goes into it through
//! [`crate::ingest::publish_into`] (the rest of gRPC's publish path), and the ack is gRPC's as JSON (`crease_proto::json`); a
//! refusal's close code, if any, comes from [`PublishError::ws_close`].

use std::sync::Arc;

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, Path, Query, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use crease_proto::json::{JsonAck, JsonControlFrame};
use crease_proto::{Encoding, Level, WireError, v1};
use futures_util::{SinkExt, StreamExt};
use prost::Message as _;
use tokio::sync::mpsc;

use crate::admission::Peer;
use crate::fanout::Channel;
use crate::ingest::{self, PublishError};
use crate::room::{Room, Subscription};
use crate::state::AppState;
use crate::status;

/// Query parameters of `/ws/rooms/{id}`.
#[derive(Debug, serde::Deserialize)]
pub struct Params {
    /// `base` (default) or `detail`.
    level: Option<String>,
    /// A publish token in the URL: refused (module docs).
    token: Option<String>,
    /// `false`: publish only, no mesh frames.
    subscribe: Option<bool>,
    /// `vertices` (default) or `palette` (issue 18).
    encoding: Option<String>,
}

/// The subprotocol the server speaks (selected when the client offers it).
pub const PROTOCOL: &str = crease_proto::WS_PROTOCOL;

/// The prefix of the subprotocol that carries the publish token (base64url, no padding).
pub const TOKEN_PROTOCOL_PREFIX: &str = "crease.token.";

/// The subprotocol entry carrying `token` (what a client offers beside [`PROTOCOL`]).
pub fn token_protocol(token: &str) -> String {
    use base64::Engine as _;
    format!(
        "{TOKEN_PROTOCOL_PREFIX}{}",
        base64::engine::general_purpose::URL_SAFE_NO_PAD.encode(token)
    )
}

/// The publish token the client offered in `Sec-WebSocket-Protocol`, if any.
///
/// # Errors
/// A token entry that is not base64url of UTF-8 text, or one offered without [`PROTOCOL`]
/// (the server could not select a protocol the client offered, and browsers then fail the
/// connection).
fn offered_token(headers: &HeaderMap) -> Result<Option<String>, String> {
    use base64::Engine as _;
    let offered: Vec<&str> = headers
        .get_all(header::SEC_WEBSOCKET_PROTOCOL)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    let Some(encoded) = offered
        .iter()
        .find_map(|p| p.strip_prefix(TOKEN_PROTOCOL_PREFIX))
    else {
        return Ok(None);
    };
    if !offered.contains(&PROTOCOL) {
        return Err(format!(
            "Sec-WebSocket-Protocol: a {TOKEN_PROTOCOL_PREFIX}... entry needs {PROTOCOL:?} offered beside it"
        ));
    }
    let bytes = base64::engine::general_purpose::URL_SAFE_NO_PAD
        .decode(encoded)
        .map_err(|e| {
            format!("Sec-WebSocket-Protocol: the {TOKEN_PROTOCOL_PREFIX}... entry is not unpadded base64url: {e}")
        })?;
    String::from_utf8(bytes).map(Some).map_err(|_| {
        format!("Sec-WebSocket-Protocol: the {TOKEN_PROTOCOL_PREFIX}... entry is not UTF-8 text")
    })
}

/// `GET /ws/rooms/{id}`: upgrades to a session on the room (module docs).
pub async fn room_socket(
    Path(id): Path<String>,
    Query(params): Query<Params>,
    State(state): State<Arc<AppState>>,
    ConnectInfo(Peer(peer)): ConnectInfo<Peer>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    if params.token.is_some() {
        return (
            StatusCode::BAD_REQUEST,
            format!(
                "token: a publish token in the URL is refused (proxies, access logs and browser history keep URLs): offer it in Sec-WebSocket-Protocol as \"{TOKEN_PROTOCOL_PREFIX}<base64url>\" beside \"{PROTOCOL}\"\n"
            ),
        )
            .into_response();
    }
    let token = match offered_token(&headers) {
        Ok(token) => token,
        Err(e) => return (StatusCode::BAD_REQUEST, format!("{e}\n")).into_response(),
    };
    let permit = match state.streams().admit(peer.ip()) {
        Ok(permit) => permit,
        Err(e) => return (StatusCode::TOO_MANY_REQUESTS, format!("{e}\n")).into_response(),
    };
    let room = match state.find_room(&id).await.map_err(PublishError::from) {
        Ok(room) => room,
        Err(e) => return (status::publish_http(&e), format!("{e}\n")).into_response(),
    };
    let level = match Level::from_query(params.level.as_deref()) {
        Ok(Level::Detail) if !room.has_detail() => {
            return (
                StatusCode::BAD_REQUEST,
                format!("level: model {:?} has no detail layer\n", room.model.name),
            )
                .into_response();
        }
        Ok(level) => level,
        Err(e) => return (StatusCode::BAD_REQUEST, format!("{e}\n")).into_response(),
    };
    let encoding = match Encoding::from_query(params.encoding.as_deref()) {
        Ok(encoding) => encoding,
        Err(e) => return (StatusCode::BAD_REQUEST, format!("{e}\n")).into_response(),
    };
    let channel = Channel::new(level, encoding);
    // The subscriber slot is taken before the upgrade, so a full room is an HTTP error.
    let subscription = if params.subscribe == Some(false) {
        None
    } else {
        // A palette stream of a DQS room: gRPC's FAILED_PRECONDITION, here as 409 Conflict
        // (the request is well formed; the room's state refuses it), with the same message.
        if let Err(e) = room.check_channel(channel) {
            return (status::channel_http(&e), format!("{e}\n")).into_response();
        }
        match room.subscribe(channel, state.config().limits.subscribers_per_room) {
            Ok(s) => Some(s),
            Err(e) => {
                return (
                    StatusCode::SERVICE_UNAVAILABLE,
                    format!("room {:?}: {e}\n", room.id),
                )
                    .into_response();
            }
        }
    };
    ws.protocols([PROTOCOL])
        .max_message_size(state.config().limits.message_bytes)
        .on_upgrade(move |socket| async move {
            // The stream slot is held for the whole session.
            let _permit = permit;
            session(state, room, channel, token, subscription, socket).await;
        })
}

async fn session(
    state: Arc<AppState>,
    room: Arc<Room>,
    channel: Channel,
    token: Option<String>,
    subscription: Option<Subscription>,
    socket: WebSocket,
) {
    let (mut sink, mut source) = socket.split();
    // Acks (and a closing frame) from the reading loop below; mesh frames come straight from
    // the room's channel: one task writes both, and a frame wakes only it.
    let (out, mut outgoing) = mpsc::channel::<Message>(4);
    let frames = subscription.map(|subscription| {
        Box::pin(crate::stream::subscribe(
            Arc::clone(&state),
            Arc::clone(&room),
            channel,
            subscription,
        ))
    });
    let writer_room = Arc::clone(&room);
    let writer = tokio::spawn(async move {
        let mut frames = frames;
        loop {
            let message = tokio::select! {
                biased;
                m = outgoing.recv() => match m {
                    Some(m) => m,
                    None => break,
                },
                msg = next_message(&mut frames) => {
                    match message_bytes(msg, &writer_room, channel).await {
                        Some(bytes) => Message::Binary(bytes),
                        // The stream ended (the room closed) or failed: no more frames, but
                        // the socket stays for its acks.
                        None => {
                            frames = None;
                            continue;
                        }
                    }
                }
            };
            if sink.send(message).await.is_err() {
                break;
            }
        }
        let _ = sink.close().await;
    });
    let mut closing = std::pin::pin!(state.closing());
    loop {
        let message = tokio::select! {
            m = source.next() => m,
            () = &mut closing => None,
        };
        let frame =
            match message {
                Some(Ok(Message::Binary(bytes))) => v1::ControlFrame::decode(bytes.as_ref())
                    .map_err(|e| {
                        WireError::new(
                            "WebSocket",
                            "message",
                            format!("not a crease.v1.ControlFrame: {e}"),
                        )
                    }),
                Some(Ok(Message::Text(text))) => JsonControlFrame::parse(text.as_str())
                    .and_then(|j| j.into_control_frame(&room.id)),
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => break,
                Some(Ok(_)) => continue,
            };
        let (seq, outcome) = match frame {
            Ok(mut f) => {
                f.room.clone_from(&room.id);
                (
                    f.seq,
                    ingest::publish_into(&state, &room, token.as_deref(), f).await,
                )
            }
            Err(e) => (0, Err(PublishError::Wire(e))),
        };
        let ack = JsonAck::from(ingest::ack(seq, &outcome));
        let close = outcome.as_ref().err().and_then(PublishError::ws_close);
        if out.send(Message::Text(ack.to_text().into())).await.is_err() {
            break;
        }
        if let Some(code) = close {
            let frame = axum::extract::ws::CloseFrame {
                code,
                reason: String::new().into(),
            };
            let _ = out.send(Message::Close(Some(frame))).await;
            break;
        }
    }
    drop(out);
    let _ = writer.await;
}

/// The next message of a subscription's stream; pending forever without one (a publishing
/// session, or once its stream ended), `None` when it ends now.
async fn next_message<S>(frames: &mut Option<std::pin::Pin<Box<S>>>) -> Option<v1::MeshFrame>
where
    S: futures_util::Stream<Item = Result<v1::MeshFrame, crate::stream::StreamError>>,
{
    match frames {
        Some(frames) => frames.next().await.and_then(Result::ok),
        None => std::future::pending().await,
    }
}

/// The bytes of a stream's message `msg` on the socket, or `None` when the stream ended.
///
/// A one-actor room's palette header is sent as the model encoded it (once, with the header,
/// on the blocking pool: `stream::first_messages`); an actor's header (it names the actor;
/// megabytes at the detail level) as the actor encoded it (once, on the blocking pool:
/// `Actor::named_palette_encoded`); the rest is small and encoded here.
async fn message_bytes(
    msg: Option<v1::MeshFrame>,
    room: &Arc<Room>,
    channel: Channel,
) -> Option<axum::body::Bytes> {
    let msg = msg?;
    match &msg.body {
        Some(v1::mesh_frame::Body::PaletteTopology(p)) if p.actor_count == 0 => Some(
            room.model
                .palette_topology_encoded(channel.level)
                .unwrap_or_else(|_| msg.encode_to_vec().into()),
        ),
        Some(v1::mesh_frame::Body::PaletteTopology(p)) => {
            let (room, i, n) = (
                Arc::clone(room),
                p.actor_index as usize,
                p.actor_count as usize,
            );
            let encoded = tokio::task::spawn_blocking(move || {
                room.actors()
                    .get(i)
                    .map(|a| a.named_palette_encoded(channel.level, i, n))
            })
            .await;
            match encoded {
                Ok(Some(Ok(bytes))) => Some(bytes),
                _ => None,
            }
        }
        _ => Some(msg.encode_to_vec().into()),
    }
}
