//! How each typed error of the library reads on the wire, once per transport: its gRPC status
//! (`tonic::Status`, for [`crate::grpc`], whose mesh streams end in a [`StreamError`]) and its
//! HTTP status (for [`crate::http`] and the WebSocket upgrade, [`crate::ws`]). Nothing below
//! the transports builds a status: the library returns [`OpenRoomError`], [`PublishError`],
//! [`StreamError`], [`TakeOpError`] and the like, and this is the one place that says what
//! each becomes.

use axum::http::StatusCode;
use tonic::Status;

use crate::ingest::PublishError;
use crate::jobs::JobError;
use crate::model_api::ModelOpError;
use crate::pipeline::BuildError;
use crate::room::{ChannelRefused, RoomError};
use crate::state::OpenRoomError;
use crate::stream::StreamError;
use crate::take_service::TakeOpError;
use crate::takes::TakeError;
use crease_proto::errors::{ErrorCode, batch_error_status, batch_status};
use crease_proto::room::SpecError;

/// gRPC: a refused frame as the status of a call that fails as a whole.
pub fn publish(e: &PublishError) -> Status {
    Status::new(e.code().grpc(), e.to_string())
}

/// gRPC: the status that ends a `Synthesize` batch at its frame `index`, the frame index in
/// its details ([`batch_error_status`]).
pub fn batch(e: &PublishError, index: usize) -> Status {
    match e {
        PublishError::Wire(w) => batch_status(index, w),
        e => batch_error_status(index, e.code(), None, &e.to_string()),
    }
}

/// gRPC: why a mesh stream ended early: a palette header the model cannot give is the
/// request's precondition, a refused batch frame its batch status, the rest a server bug.
pub fn stream(e: &StreamError) -> Status {
    match e {
        StreamError::PaletteHeader(m) => Status::failed_precondition(m.clone()),
        StreamError::Internal { .. } => Status::internal(e.to_string()),
        StreamError::Batch { index, error } => batch(error, *index),
    }
}

/// HTTP: the status of a room lookup's refusal (`/api/rooms/{id}`, the WebSocket upgrade).
pub fn publish_http(e: &PublishError) -> StatusCode {
    match e.code() {
        ErrorCode::NotFound => StatusCode::NOT_FOUND,
        _ => StatusCode::SERVICE_UNAVAILABLE,
    }
}

/// gRPC: why a room could not be opened or closed.
pub fn open(e: &OpenRoomError) -> Status {
    let m = e.to_string();
    match e {
        OpenRoomError::NoModel(_)
        | OpenRoomError::NoRoom(_)
        | OpenRoomError::NoActorModel { .. } => Status::not_found(m),
        OpenRoomError::TooManyActors { .. } => Status::invalid_argument(m),
        OpenRoomError::Actor { error, .. } => Status::new(open(error).code(), m),
        OpenRoomError::Spec(SpecError::TokenDigest(_)) => Status::internal(m),
        OpenRoomError::Spec(_) | OpenRoomError::Capture(_) => Status::invalid_argument(m),
        OpenRoomError::Room(RoomError::BadId(_)) => Status::invalid_argument(format!("room: {m}")),
        OpenRoomError::Room(RoomError::Build(BuildError::Predictor(p))) => {
            Status::invalid_argument(format!("beta: {p}"))
        }
        OpenRoomError::Room(RoomError::Build(BuildError::Codec(c))) => {
            Status::internal(format!("model: {c}"))
        }
        OpenRoomError::Room(RoomError::Panicked(_)) | OpenRoomError::NoCluster(_) => {
            Status::internal(m)
        }
        OpenRoomError::Exists(_) | OpenRoomError::ExistsInCluster(_) => Status::already_exists(m),
        OpenRoomError::Limit(_) | OpenRoomError::Install(_) => Status::resource_exhausted(m),
        OpenRoomError::Registry(_) | OpenRoomError::ModelUnavailable(_) => Status::unavailable(m),
        OpenRoomError::Mirror(_) => Status::failed_precondition(m),
    }
}

/// gRPC: a subscription on a channel the room cannot serve.
pub fn channel(e: &ChannelRefused) -> Status {
    Status::failed_precondition(e.to_string())
}

/// HTTP: the same (the request is well formed; the room's state refuses it).
pub fn channel_http(_: &ChannelRefused) -> StatusCode {
    StatusCode::CONFLICT
}

/// gRPC: a take's or the takes folder's error.
pub fn take_error(e: &TakeError) -> Status {
    let m = e.to_string();
    match e {
        TakeError::NoFolder
        | TakeError::Recording { .. }
        | TakeError::NotRecording(_)
        | TakeError::Elsewhere { .. } => Status::failed_precondition(m),
        TakeError::NoTake(_) => Status::not_found(m),
        TakeError::Name(_) => Status::invalid_argument(m),
        TakeError::Io { .. } | TakeError::File { .. } => Status::internal(m),
    }
}

/// HTTP: a take's or the takes folder's error.
pub fn take_error_http(e: &TakeError) -> StatusCode {
    match e {
        TakeError::NoTake(_) => StatusCode::NOT_FOUND,
        TakeError::Name(_) => StatusCode::BAD_REQUEST,
        TakeError::Io { .. } | TakeError::File { .. } => StatusCode::INTERNAL_SERVER_ERROR,
        _ => StatusCode::CONFLICT,
    }
}

/// gRPC: a take operation's error.
pub fn take(e: &TakeOpError) -> Status {
    match e {
        TakeOpError::Take(e) => take_error(e),
        TakeOpError::Room(e) => publish(e),
        TakeOpError::Model(m) => Status::failed_precondition(m.clone()),
        TakeOpError::Open(m) => Status::invalid_argument(format!("replay room: {m}")),
        TakeOpError::Replays(_) => Status::resource_exhausted(e.to_string()),
        TakeOpError::Panicked(_) => Status::internal(e.to_string()),
    }
}

/// HTTP: a take operation's error.
pub fn take_http(e: &TakeOpError) -> StatusCode {
    match e {
        TakeOpError::Take(e) => take_error_http(e),
        TakeOpError::Room(e) => publish_http(e),
        TakeOpError::Model(_) => StatusCode::CONFLICT,
        TakeOpError::Open(_) => StatusCode::BAD_REQUEST,
        TakeOpError::Replays(_) => StatusCode::TOO_MANY_REQUESTS,
        TakeOpError::Panicked(_) => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

/// gRPC: a job call's error (issue 45).
pub fn job(e: &JobError) -> Status {
    match e {
        JobError::NoJob(_) => Status::not_found(e.to_string()),
        JobError::NotDone { .. } | JobError::Expired(_) | JobError::Ended { .. } => {
            Status::failed_precondition(e.to_string())
        }
        JobError::Full(_) => Status::resource_exhausted(e.to_string()),
        JobError::Io { .. } => Status::internal(e.to_string()),
    }
}

/// HTTP: a job call's error (`GET /api/jobs`).
pub fn job_http(e: &JobError) -> StatusCode {
    match e {
        JobError::NoJob(_) => StatusCode::NOT_FOUND,
        JobError::NotDone { .. } | JobError::Expired(_) | JobError::Ended { .. } => {
            StatusCode::CONFLICT
        }
        JobError::Full(_) => StatusCode::TOO_MANY_REQUESTS,
        JobError::Io { .. } => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

/// gRPC: a refused model upload or delete (issue 39).
pub fn model_op(e: &ModelOpError) -> Status {
    use ModelOpError as E;
    let message = e.to_string();
    match e {
        E::NoFolder | E::NotInFolder(_) | E::InUse { .. } => Status::failed_precondition(message),
        E::NoName
        | E::BadName(_)
        | E::BadDigest(_)
        | E::TooLong { .. }
        | E::Digest { .. }
        | E::NotAModel { .. } => Status::invalid_argument(message),
        E::TooLarge { .. } => Status::resource_exhausted(message),
        E::Truncated { .. } | E::Stream(_) => Status::data_loss(message),
        E::Exists { .. } => Status::already_exists(message),
        E::NoModel(_) => Status::not_found(message),
        E::Io { .. } => Status::internal(message),
    }
}
