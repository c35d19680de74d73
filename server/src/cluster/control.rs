//! Controls across replicas: a publisher may connect to any replica. A relay checks the frame
//! against the token's digest (the registry's) and forwards it to the owner as a NATS request
//! (`crease.control.<room>`); the owner applies the room's rate limit (so it holds per room,
//! cluster-wide), runs the frame through its pipeline as a local one, and replies with the
//! ack. The relay returns that ack to the publisher with the same fields; a refusal keeps the
//! owner's code and message.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crease_proto::errors::{ErrorCode, error_ack, frame_error};
use crease_proto::v1;
use futures_util::StreamExt;
use prost::Message as _;

use super::{Cluster, subject};
use crate::AppState;
use crate::ingest::{self, PublishError};
use crate::pipeline::Published;

/// How long a relay waits for the owner's ack.
const FORWARD_TIMEOUT: Duration = Duration::from_secs(2);

/// Relay: forwards `frame` (its token already checked here) to the owner of `room` and
/// returns the owner's outcome.
///
/// # Errors
/// The owner's refusal ([`PublishError::Forwarded`]), or [`PublishError::Unavailable`] when
/// no owner answers (it died and the room is not adopted yet, or NATS is down).
pub(crate) async fn forward(
    cluster: &Cluster,
    room: &str,
    frame: v1::ControlFrame,
    received: Instant,
) -> Result<Published, PublishError> {
    let request = v1::ForwardedControl {
        frame: Some(frame),
        replica: cluster.replica.clone(),
    };
    let unavailable = |why: String| {
        PublishError::Unavailable(format!(
            "room {room:?}: its owner does not answer ({why}); a live replica adopts it within the lease"
        ))
    };
    let reply = cluster
        .client
        .send_request(
            subject::control(room),
            async_nats::Request::new()
                .payload(request.encode_to_vec().into())
                .timeout(Some(FORWARD_TIMEOUT)),
        )
        .await
        .map_err(|e| unavailable(e.to_string()))?;
    cluster.metrics.forwarded_controls.inc();
    let ack = v1::PublishAck::decode(reply.payload.as_ref())
        .map_err(|e| PublishError::Internal(format!("the owner's ack: {e}")))?;
    match ack.error {
        Some(e) => Err(PublishError::Forwarded(e)),
        None => Ok(Published {
            held: ack.held_controls,
            latency_us: received.elapsed().as_micros().min(u32::MAX as u128) as u32,
            control_rms: ack.control_residual,
            // The owner synthesised (or not) the detail layer: not this replica's work.
            detail: false,
        }),
    }
}

/// Owner: serves the frames relays forward into `room` until the task is aborted (the room
/// changed owner or closed).
pub(crate) async fn serve(state: Arc<AppState>, cluster: Arc<Cluster>, room: String) {
    let Ok(mut sub) = cluster.client.subscribe(subject::control(&room)).await else {
        tracing::error!(%room, "cannot subscribe to forwarded controls");
        return;
    };
    while let Some(msg) = sub.next().await {
        let Some(reply) = msg.reply else {
            continue;
        };
        let ack = match v1::ForwardedControl::decode(msg.payload.as_ref()) {
            Ok(v1::ForwardedControl {
                frame: Some(mut frame),
                ..
            }) => {
                room.clone_into(&mut frame.room);
                let seq = frame.seq;
                ingest::ack(seq, &ingest::publish_forwarded(&state, frame).await)
            }
            Ok(_) => error_ack(
                0,
                frame_error(
                    ErrorCode::InvalidArgument,
                    "ForwardedControl.frame: missing",
                ),
            ),
            Err(e) => error_ack(
                0,
                frame_error(
                    ErrorCode::InvalidArgument,
                    format!("not a crease.v1.ForwardedControl: {e}"),
                ),
            ),
        };
        let _ = cluster
            .client
            .publish(reply, ack.encode_to_vec().into())
            .await;
    }
}
