//! Errors on the wire: [`WireError`], a message that does not fit the model (naming the
//! message and the field); the named codes a [`v1::FrameError`] carries (the integers
//! are google.rpc.Code's, unchanged on the wire), the acks that carry them, and a `Synthesize`
//! batch's error status, whose details name the refused frame by index so clients never parse
//! the status message.

use prost::Message as _;

use crate::v1;

/// A wire message that does not fit the model: the message, the field and what is wrong with it.
/// Shown as `ControlFrame.positions: 7 values, expected 45`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message_type}.{field}: {message}")]
pub struct WireError {
    /// The protobuf message the field belongs to, e.g. `ControlFrame`.
    pub message_type: &'static str,
    /// The offending field, e.g. `positions[7]` or `valid`.
    pub field: String,
    /// What was wrong: expected vs got.
    pub message: String,
}

impl WireError {
    /// An error in `field` of `message_type`.
    pub fn new(
        message_type: &'static str,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Self {
            message_type,
            field: field.into(),
            message: message.into(),
        }
    }
}

impl From<WireError> for tonic::Status {
    fn from(e: WireError) -> Self {
        tonic::Status::invalid_argument(e.to_string())
    }
}

/// The codes a [`v1::FrameError`] carries: the google.rpc.Code of each kind of refusal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorCode {
    /// A field of the frame does not fit the model (or the message is not a control frame).
    InvalidArgument,
    /// No room of that id.
    NotFound,
    /// Not the room's publish token (the viewer tells this one apart: a wrong token field).
    PermissionDenied,
    /// Over the room's publish rate.
    ResourceExhausted,
    /// The server failed while predicting (a bug, not the publisher's fault).
    Internal,
    /// In a cluster: the room's owner cannot be reached now (it died and its room is not
    /// adopted yet, or this replica lost the cluster); the publisher retries.
    Unavailable,
    /// A newer frame reached the room while this one waited for the pipeline (latest wins):
    /// nothing to fix, the room is at the newer frame.
    Aborted,
}

impl ErrorCode {
    /// The integer on the wire (google.rpc.Code).
    pub fn wire(self) -> i32 {
        match self {
            ErrorCode::InvalidArgument => 3,
            ErrorCode::NotFound => 5,
            ErrorCode::PermissionDenied => 7,
            ErrorCode::ResourceExhausted => 8,
            ErrorCode::Internal => 13,
            ErrorCode::Unavailable => 14,
            ErrorCode::Aborted => 10,
        }
    }

    /// The code of a wire integer, if it is one of ours.
    pub fn from_wire(code: i32) -> Option<ErrorCode> {
        [
            ErrorCode::InvalidArgument,
            ErrorCode::NotFound,
            ErrorCode::PermissionDenied,
            ErrorCode::ResourceExhausted,
            ErrorCode::Internal,
            ErrorCode::Unavailable,
            ErrorCode::Aborted,
        ]
        .into_iter()
        .find(|c| c.wire() == code)
    }

    /// The matching gRPC status code.
    pub fn grpc(self) -> tonic::Code {
        tonic::Code::from_i32(self.wire())
    }
}

/// A per-frame error with `code` and `message` (no batch frame index).
pub fn frame_error(code: ErrorCode, message: impl Into<String>) -> v1::FrameError {
    v1::FrameError {
        code: code.wire(),
        message: message.into(),
        frame: None,
    }
}

/// The ack of a refused frame `seq`: the room is unchanged.
pub fn error_ack(seq: u64, error: v1::FrameError) -> v1::PublishAck {
    v1::PublishAck {
        seq,
        error: Some(error),
        ..Default::default()
    }
}

/// What the server reports of a frame it published, for [`ok_ack`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AckParts {
    /// Microseconds from arrival to the meshes being handed to the subscribers.
    pub server_latency_us: u32,
    /// Control points held (invalid or occluded).
    pub held_controls: u32,
    /// RMS control residual, model units.
    pub control_residual: f32,
    /// The same in the capture's units (retargeting rooms).
    pub control_residual_capture: f32,
    /// How far the frame lies from the model's training examples.
    pub confidence: f32,
}

/// Actor `actor`'s part of a published frame's ack (a room of several actors): whether it was
/// missing from the frame and `held` its pose, and its figures (`server_latency_us` unused).
pub fn actor_ack(actor: &str, held: bool, p: AckParts) -> v1::ActorAck {
    v1::ActorAck {
        actor: actor.to_owned(),
        held,
        held_controls: p.held_controls,
        control_residual: p.control_residual,
        control_residual_capture: p.control_residual_capture,
        confidence: p.confidence,
    }
}

/// The ack of frame `seq`, published.
pub fn ok_ack(seq: u64, p: AckParts) -> v1::PublishAck {
    v1::PublishAck {
        seq,
        server_latency_us: p.server_latency_us,
        held_controls: p.held_controls,
        error: None,
        control_residual: p.control_residual,
        control_residual_capture: p.control_residual_capture,
        confidence: p.confidence,
        actors: Vec::new(),
    }
}

/// The status that ends a `Synthesize` batch whose frame `index` was refused with `code`: the
/// message says `SynthesizeRequest.frames[index].<field>: ...` (or `frames[index]: ...` when
/// no field is at fault) for people, and the details hold the [`v1::FrameError`] with
/// `frame: index` and the message relative to the frame (`positions: ...`) for programs
/// ([`batch_frame_error`]). Every per-frame refusal of a batch ends this way, whatever its code.
pub fn batch_error_status(
    index: usize,
    code: ErrorCode,
    field: Option<&str>,
    message: &str,
) -> tonic::Status {
    frame_error_status("SynthesizeRequest.frames", index, code, field, message)
}

/// The status that refuses a batch job (issue 45) whose frame `index` (counted over the whole
/// job, whichever `JobFrames` message carried it) does not fit the model, as
/// [`batch_error_status`] with `SubmitJob.frames[index]` in the message.
pub fn job_frame_status(index: usize, e: &WireError) -> tonic::Status {
    frame_error_status(
        "SubmitJob.frames",
        index,
        ErrorCode::InvalidArgument,
        Some(&e.field),
        &e.message,
    )
}

/// [`batch_error_status`]'s status, the frames named `what`.
fn frame_error_status(
    what: &str,
    index: usize,
    code: ErrorCode,
    field: Option<&str>,
    message: &str,
) -> tonic::Status {
    let (relative, shown) = match field {
        Some(field) => (
            format!("{field}: {message}"),
            format!("{what}[{index}].{field}: {message}"),
        ),
        None => (message.to_owned(), format!("{what}[{index}]: {message}")),
    };
    let error = v1::FrameError {
        code: code.wire(),
        message: relative,
        frame: Some(index as u32),
    };
    tonic::Status::with_details(code.grpc(), shown, error.encode_to_vec().into())
}

/// [`batch_error_status`] for a frame with a field that does not fit the model.
pub fn batch_status(index: usize, e: &WireError) -> tonic::Status {
    batch_error_status(
        index,
        ErrorCode::InvalidArgument,
        Some(&e.field),
        &e.message,
    )
}

/// The per-frame error a batch's status carries ([`batch_status`]), if it has one.
pub fn batch_frame_error(status: &tonic::Status) -> Option<v1::FrameError> {
    let error = v1::FrameError::decode(status.details()).ok()?;
    error.frame.is_some().then_some(error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_the_google_rpc_integers() {
        // google/rpc/code.proto: INVALID_ARGUMENT 3, NOT_FOUND 5, PERMISSION_DENIED 7,
        // RESOURCE_EXHAUSTED 8, ABORTED 10, INTERNAL 13, UNAVAILABLE 14.
        let pairs = [
            (ErrorCode::InvalidArgument, 3, tonic::Code::InvalidArgument),
            (ErrorCode::NotFound, 5, tonic::Code::NotFound),
            (
                ErrorCode::PermissionDenied,
                7,
                tonic::Code::PermissionDenied,
            ),
            (
                ErrorCode::ResourceExhausted,
                8,
                tonic::Code::ResourceExhausted,
            ),
            (ErrorCode::Internal, 13, tonic::Code::Internal),
            (ErrorCode::Unavailable, 14, tonic::Code::Unavailable),
            (ErrorCode::Aborted, 10, tonic::Code::Aborted),
        ];
        for (code, wire, grpc) in pairs {
            assert_eq!(code.wire(), wire);
            assert_eq!(code.grpc(), grpc);
            assert_eq!(ErrorCode::from_wire(wire), Some(code));
        }
        assert_eq!(ErrorCode::from_wire(4), None);
        let ack = error_ack(9, frame_error(ErrorCode::NotFound, "room: no room \"x\""));
        assert_eq!(ack.seq, 9);
        let e = ack.error.unwrap();
        assert_eq!(
            (e.code, e.message.as_str(), e.frame),
            (5, "room: no room \"x\"", None)
        );
    }

    #[test]
    fn a_batch_status_names_its_frame_in_a_field() {
        let e = WireError::new("ControlFrame", "positions", "3 values, expected 12");
        let status = batch_status(4, &e);
        assert_eq!(status.code(), tonic::Code::InvalidArgument);
        assert_eq!(
            status.message(),
            "SynthesizeRequest.frames[4].positions: 3 values, expected 12"
        );
        let error = batch_frame_error(&status).unwrap();
        assert_eq!(error.frame, Some(4));
        assert_eq!(error.code, 3);
        assert_eq!(error.message, "positions: 3 values, expected 12");
        // A refusal with no field at fault names the frame the same way.
        let status = batch_error_status(2, ErrorCode::Internal, None, "internal: boom");
        assert_eq!(status.code(), tonic::Code::Internal);
        assert_eq!(
            status.message(),
            "SynthesizeRequest.frames[2]: internal: boom"
        );
        let error = batch_frame_error(&status).unwrap();
        assert_eq!(
            (error.frame, error.code, error.message.as_str()),
            (Some(2), 13, "internal: boom")
        );
        // A plain status has no batch error.
        assert!(batch_frame_error(&tonic::Status::internal("x")).is_none());
    }
}
