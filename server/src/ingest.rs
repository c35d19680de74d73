//! Ingest: the one publish path of every transport. A control frame from gRPC's `Publish`, a
//! WebSocket (binary protobuf or JSON text) or the embedded demo comes here: the room is looked
//! up (a WebSocket session holds its room: [`publish_into`]), its session entered once (the
//! token, then the rate limit: `Session::enter`), the wire frame read into the model's control
//! points and run through the room's pipeline on the blocking pool. In a cluster a relay's
//! room forwards the frame to its owner through its fan-out (`Fanout::forward`), and the owner
//! takes forwarded frames here too ([`crate::cluster::Ingest`], implemented below for the
//! server's state). What went wrong is a typed [`PublishError`], mapped once per transport:
//! [`PublishError::frame_error`] for the ack ([`ack`]; the WebSocket sends the same ack as
//! JSON), `crate::status` for a gRPC status or an HTTP status, and [`PublishError::ws_close`]
//! for whether a WebSocket closes.

use std::sync::Arc;
use std::time::Instant;

use crease_proto::errors::{AckParts, ErrorCode, actor_ack, error_ack, frame_error, ok_ack};
use crease_proto::{WireError, v1};
use futures_util::future::BoxFuture;

use crate::cluster::{self, LookupError};
use crate::pipeline::{ActorPublished, PipelineError, Published};
use crate::room::Room;
use crate::session::{Publisher, Refusal};
use crate::state::AppState;

/// Why a control frame was refused; the room is unchanged.
#[derive(Debug, thiserror::Error)]
pub enum PublishError {
    /// No room of that id.
    #[error("room: no room {0:?}")]
    NoRoom(String),
    /// Not the room's publish token (or none).
    #[error("authorization: not the publish token of room {0:?}")]
    Token(String),
    /// Over the room's publish rate.
    #[error("rate: room {room:?} accepts at most {hz} frames per second")]
    Rate {
        /// The room.
        room: String,
        /// Its limit.
        hz: f64,
    },
    /// The message is not a control frame, or a field does not fit the model.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// The predictor refused the controls.
    #[error("{0}")]
    Predict(String),
    /// The server failed (an encoder error, a panicked task): not the publisher's fault.
    #[error("internal: {0}")]
    Internal(String),
    /// In a cluster: the room's owner does not answer now, or its model cannot be had here.
    #[error("unavailable: {0}")]
    Unavailable(String),
    /// A newer frame reached the room while this one waited for the pipeline: latest wins
    /// (`crate::mailbox`); the room is at the newer frame.
    #[error("superseded: room {0:?} took a newer frame while this one waited (latest wins)")]
    Superseded(String),
    /// In a cluster: the owner refused the frame this replica forwarded (its code and message,
    /// as the owner's ack carried them).
    #[error("{}", .0.message)]
    Forwarded(v1::FrameError),
}

impl From<LookupError> for PublishError {
    fn from(e: LookupError) -> Self {
        match e {
            LookupError::NoRoom(id) => PublishError::NoRoom(id),
            LookupError::Unavailable(why) => PublishError::Unavailable(why),
            LookupError::Internal(why) => PublishError::Internal(why),
        }
    }
}

impl From<PipelineError> for PublishError {
    fn from(e: PipelineError) -> Self {
        match e {
            PipelineError::Wire(e) => PublishError::Wire(e),
            e @ PipelineError::Predict(_) => PublishError::Predict(e.to_string()),
            e @ (PipelineError::Codec(_)
            | PipelineError::Palette(_)
            | PipelineError::Panicked(_)) => PublishError::Internal(e.to_string()),
            PipelineError::Actor { actor, error } => match PublishError::from(*error) {
                PublishError::Predict(m) => PublishError::Predict(format!("actor {actor:?}: {m}")),
                PublishError::Internal(m) => {
                    PublishError::Internal(format!("actor {actor:?}: {m}"))
                }
                other => other,
            },
        }
    }
}

impl PublishError {
    /// The named code of this refusal (gRPC's status code and the ack's `FrameError.code`).
    pub fn code(&self) -> ErrorCode {
        match self {
            PublishError::NoRoom(_) => ErrorCode::NotFound,
            PublishError::Token(_) => ErrorCode::PermissionDenied,
            PublishError::Rate { .. } => ErrorCode::ResourceExhausted,
            PublishError::Wire(_) | PublishError::Predict(_) => ErrorCode::InvalidArgument,
            PublishError::Internal(_) => ErrorCode::Internal,
            PublishError::Unavailable(_) => ErrorCode::Unavailable,
            PublishError::Superseded(_) => ErrorCode::Aborted,
            PublishError::Forwarded(e) => {
                ErrorCode::from_wire(e.code).unwrap_or(ErrorCode::Internal)
            }
        }
    }

    /// The `FrameError` of the ack.
    pub fn frame_error(&self) -> v1::FrameError {
        match self {
            PublishError::Forwarded(e) => e.clone(),
            e => frame_error(e.code(), e.to_string()),
        }
    }

    /// WebSocket: the close code this refusal ends the socket with, if any. The socket's ack
    /// carries the same error as gRPC's ([`ack`], as JSON through `JsonAck`). Every refusal
    /// keeps the socket open (`None`): a viewer whose drag was refused (a wrong token, the
    /// rate) keeps watching, and a publisher fixes its next frame.
    pub fn ws_close(&self) -> Option<u16> {
        None
    }
}

/// Publishes one control frame into `frame.room` with the publisher's `token` (module docs),
/// and counts it in the metrics.
///
/// # Errors
/// [`PublishError`]; the room is unchanged then.
pub async fn publish(
    state: &Arc<AppState>,
    token: Option<&str>,
    frame: v1::ControlFrame,
) -> Result<Published, PublishError> {
    let received = Instant::now();
    let done = match state.find_room(&frame.room).await {
        Ok(room) => publish_to(state, room, token, frame, received).await,
        Err(e) => Err(e.into()),
    };
    count(state, &done);
    done
}

/// Publishes one control frame into `room`, which the publisher holds (a WebSocket session
/// looked it up once; `frame.room` is the room's), and counts it in the metrics. A room
/// closed since is refused as one looked up now would be.
///
/// # Errors
/// [`PublishError`]; the room is unchanged then.
pub async fn publish_into(
    state: &Arc<AppState>,
    room: &Arc<Room>,
    token: Option<&str>,
    frame: v1::ControlFrame,
) -> Result<Published, PublishError> {
    let received = Instant::now();
    let done = if room.is_closed() {
        Err(PublishError::NoRoom(room.id.clone()))
    } else {
        publish_to(state, Arc::clone(room), token, frame, received).await
    };
    count(state, &done);
    done
}

fn count(state: &AppState, done: &Result<Published, PublishError>) {
    let m = state.metrics();
    match done {
        Ok(p) => {
            m.frames_published.inc();
            if p.detail {
                m.detail_frames.inc();
            }
            m.frame_latency.observe(f64::from(p.latency_us) * 1e-6);
            m.frame_confidence.observe(f64::from(p.confidence));
        }
        Err(PublishError::Superseded(_)) => {
            m.frames_superseded.inc();
        }
        Err(_) => {
            m.frames_refused.inc();
        }
    }
}

/// The session entered once (the token; the rate, unless a relay forwards the frame to the
/// owner, which applies it), then the pipeline, here or at the owner.
async fn publish_to(
    state: &Arc<AppState>,
    room: Arc<Room>,
    token: Option<&str>,
    frame: v1::ControlFrame,
    received: Instant,
) -> Result<Published, PublishError> {
    let relays = room.relays();
    let hz = room_hz(state, &room);
    enter(&room, Publisher::Token(token), (!relays).then_some(hz))?;
    if !relays {
        return process(room, frame, received).await;
    }
    let ack = room
        .forward(frame)
        .await
        .map_err(PublishError::Unavailable)?;
    match ack.error {
        Some(e) => Err(PublishError::Forwarded(e)),
        None => Ok(Published {
            held: ack.held_controls,
            latency_us: received.elapsed().as_micros().min(u32::MAX as u128) as u32,
            control_rms: ack.control_residual,
            // The owner synthesised (or not) the detail layer: not this replica's work.
            detail: false,
            control_rms_capture: ack.control_residual_capture,
            confidence: ack.confidence,
            actors: ack
                .actors
                .iter()
                .map(|a| ActorPublished {
                    name: a.actor.as_str().into(),
                    held: a.held,
                    published: Published {
                        held: a.held_controls,
                        latency_us: 0,
                        control_rms: a.control_residual,
                        detail: false,
                        control_rms_capture: a.control_residual_capture,
                        confidence: a.confidence,
                        actors: Vec::new(),
                    },
                })
                .collect(),
        }),
    }
}

/// The frames per second `room` accepts: the server's limit over its actors (a frame of `n`
/// actors counts `n` times: the pipeline's work is per actor).
fn room_hz(state: &AppState, room: &Room) -> f64 {
    state.config().limits.publish_hz / room.actors().len() as f64
}

/// `room`'s session entered by `who` (the rate `hz` applied when given).
fn enter(room: &Room, who: Publisher<'_>, hz: Option<f64>) -> Result<(), PublishError> {
    room.session()
        .enter(who, hz)
        .map_err(|refusal| match refusal {
            Refusal::Token => PublishError::Token(room.id.clone()),
            Refusal::Rate => PublishError::Rate {
                room: room.id.clone(),
                hz: hz.unwrap_or_default(),
            },
        })
}

/// Owner: the frames relays forward into this server's rooms, their tokens checked there
/// (`publish_forwarded`), acked.
impl cluster::Ingest for AppState {
    fn publish_forwarded(
        self: Arc<Self>,
        frame: v1::ControlFrame,
    ) -> BoxFuture<'static, v1::PublishAck> {
        Box::pin(async move {
            let seq = frame.seq;
            ack(seq, &publish_forwarded(&self, frame).await)
        })
    }
}

/// Owner: a frame a relay forwarded (its token checked there): the rate limit, then the
/// pipeline, as a local frame; counted in the metrics like one.
///
/// # Errors
/// [`PublishError`]; the room is unchanged then.
pub(crate) async fn publish_forwarded(
    state: &Arc<AppState>,
    frame: v1::ControlFrame,
) -> Result<Published, PublishError> {
    let received = Instant::now();
    let done = match state.room(&frame.room) {
        Some(room) => match enter(&room, Publisher::Forwarded, Some(room_hz(state, &room))) {
            Ok(()) => process(room, frame, received).await,
            Err(e) => Err(e),
        },
        None => Err(PublishError::NoRoom(frame.room.clone())),
    };
    count(state, &done);
    done
}

/// Runs `frame` through `room`'s pipeline on the blocking pool, latest wins
/// ([`Room::submit`]; the hand-off every publish path and the batches share), its failure as
/// a [`PublishError`]. A batch's private room gets one frame at a time, so none is superseded.
pub(crate) async fn process(
    room: Arc<Room>,
    frame: v1::ControlFrame,
    received: Instant,
) -> Result<Published, PublishError> {
    match room.submit(frame, received).await {
        Ok(Some(result)) => result.map_err(PublishError::from),
        Ok(None) => Err(PublishError::Superseded(room.id.clone())),
        Err(_) => Err(PublishError::Internal(
            "the room's pipeline stopped before this frame ran".into(),
        )),
    }
}

/// What an ack reports of `p`.
fn ack_parts(p: &Published) -> AckParts {
    AckParts {
        server_latency_us: p.latency_us,
        held_controls: p.held,
        control_residual: p.control_rms,
        control_residual_capture: p.control_rms_capture,
        confidence: p.confidence,
    }
}

/// The ack of frame `seq`'s outcome.
pub fn ack(seq: u64, outcome: &Result<Published, PublishError>) -> v1::PublishAck {
    match outcome {
        Ok(p) => {
            let mut ack = ok_ack(seq, ack_parts(p));
            ack.actors = p
                .actors
                .iter()
                .map(|a| actor_ack(&a.name, a.held, ack_parts(&a.published)))
                .collect();
            ack
        }
        Err(e) => error_ack(seq, e.frame_error()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all() -> Vec<PublishError> {
        vec![
            PublishError::NoRoom("x".into()),
            PublishError::Token("x".into()),
            PublishError::Rate {
                room: "x".into(),
                hz: 240.0,
            },
            PublishError::Wire(WireError::new(
                "ControlFrame",
                "positions",
                "3 values, expected 6",
            )),
            PublishError::Predict("prediction: bad".into()),
            PublishError::Internal("boom".into()),
            PublishError::Superseded("x".into()),
        ]
    }

    #[test]
    fn each_refusal_maps_once_per_transport() {
        // google.rpc.Code integers, as the acks always carried them.
        let codes = [5, 7, 8, 3, 3, 13, 10];
        let grpc = [
            tonic::Code::NotFound,
            tonic::Code::PermissionDenied,
            tonic::Code::ResourceExhausted,
            tonic::Code::InvalidArgument,
            tonic::Code::InvalidArgument,
            tonic::Code::Internal,
            tonic::Code::Aborted,
        ];
        for ((e, code), grpc) in all().iter().zip(codes).zip(grpc) {
            let a = ack(4, &Err(clone(e)));
            let fe = a.error.clone().unwrap();
            assert_eq!((a.seq, fe.code, fe.frame), (4, code, None), "{e}");
            assert_eq!(fe.message, e.to_string());
            assert_eq!(crate::status::publish(e).code(), grpc, "{e}");
            assert_eq!(crate::status::publish(e).message(), e.to_string());
            // A batch names the refused frame in the details, whatever the refusal.
            let batch = crate::status::batch(e, 7);
            assert_eq!(batch.code(), grpc, "{e}");
            let be = crease_proto::errors::batch_frame_error(&batch).unwrap();
            assert_eq!((be.frame, be.code), (Some(7), code), "{e}");
            assert!(
                batch.message().starts_with("SynthesizeRequest.frames[7]"),
                "{e}"
            );
            let ws = crease_proto::json::JsonAck::from(a.clone()).error.unwrap();
            assert_eq!(ws.code, code, "{e}");
            assert_eq!(ws.message, e.to_string());
            assert_eq!(
                e.ws_close(),
                None,
                "{e}: per-frame refusals keep the socket open"
            );
        }
        assert_eq!(
            all()[1].to_string(),
            "authorization: not the publish token of room \"x\""
        );
        assert_eq!(
            all()[3].to_string(),
            "ControlFrame.positions: 3 values, expected 6"
        );
        let ok = ack(
            2,
            &Ok(Published {
                held: 1,
                latency_us: 30,
                control_rms: 0.5,
                detail: false,
                control_rms_capture: 2.5,
                confidence: 0.5,
                actors: Vec::new(),
            }),
        );
        assert_eq!(ok.control_residual_capture, 2.5);
        assert_eq!(ok.confidence, 0.5);
        assert_eq!(
            (
                ok.seq,
                ok.held_controls,
                ok.server_latency_us,
                ok.control_residual
            ),
            (2, 1, 30, 0.5)
        );
        assert!(ok.error.is_none());
    }

    /// The errors hold only strings and numbers: rebuilt from their parts.
    fn clone(e: &PublishError) -> PublishError {
        match e {
            PublishError::NoRoom(r) => PublishError::NoRoom(r.clone()),
            PublishError::Token(r) => PublishError::Token(r.clone()),
            PublishError::Rate { room, hz } => PublishError::Rate {
                room: room.clone(),
                hz: *hz,
            },
            PublishError::Wire(w) => PublishError::Wire(w.clone()),
            PublishError::Predict(m) => PublishError::Predict(m.clone()),
            PublishError::Internal(m) => PublishError::Internal(m.clone()),
            PublishError::Unavailable(m) => PublishError::Unavailable(m.clone()),
            PublishError::Superseded(r) => PublishError::Superseded(r.clone()),
            PublishError::Forwarded(e) => PublishError::Forwarded(e.clone()),
        }
    }
}
