//! Controls across replicas: a publisher may connect to any replica. A relay checks the frame
//! against the token's digest (the registry's) and its room's fan-out ([`super::RoomLink`],
//! `Fanout::forward`) forwards it to the owner as a NATS request (`crease.control.<room>`); the owner applies the room's rate limit (so it holds per room,
//! cluster-wide), runs the frame through its pipeline as a local one, and replies with the
//! ack. The relay returns that ack to the publisher with the same fields; a refusal keeps the
//! owner's code and message.

use std::sync::Arc;
use std::time::Duration;

use crease_proto::cluster::{forwarded_control, read_forwarded_control};
use crease_proto::errors::{ErrorCode, error_ack, frame_error};
use crease_proto::v1;
use futures_util::StreamExt;
use futures_util::future::BoxFuture;
use prost::Message as _;

use super::trust::{self, Refusal};
use super::{Cluster, Host, subject};

/// How long a relay waits for the owner's ack. A forwarded frame normally takes about a
/// millisecond; one whose owner died mid-request would otherwise hold up the publisher's later
/// frames (they queue behind it, then arrive as a burst over the rate limit), and a live frame
/// half a second late is stale anyway.
const FORWARD_TIMEOUT: Duration = Duration::from_millis(500);

/// The owner's side of forwarded control frames: what its server does with one (the rate, the
/// pipeline, the metrics, the ack: the server's publish path, `crate::ingest`, implements it
/// for the server's state). A trait the server implements, so that the cluster does not
/// depend on the layer above it.
pub trait Ingest: Send + Sync {
    /// The ack of `frame`, which a relay forwarded into one of this server's rooms (its token
    /// checked there).
    fn publish_forwarded(
        self: Arc<Self>,
        frame: v1::ControlFrame,
    ) -> BoxFuture<'static, v1::PublishAck>;
}

/// Relay: forwards `frame` (its token already checked here) to the owner of `room` and
/// returns the owner's ack (which may carry the owner's refusal).
///
/// # Errors
/// Why no owner answered (it died and the room is not adopted yet, or NATS is down), or its
/// reply was not an ack.
pub async fn forward(
    cluster: Arc<Cluster>,
    room: String,
    frame: v1::ControlFrame,
) -> Result<v1::PublishAck, String> {
    // Read after this process was stopped, the frame may be older than what the owner has
    // predicted since: not forwarded (`stall`).
    if cluster.stall.stale() {
        cluster.metrics.stale_forwards.inc();
        return Err(format!(
            "room {room:?}: this replica was stalled and the frame may be from before; not forwarded (the next ones are)"
        ));
    }
    let request = forwarded_control(frame, &cluster.replica).encode_to_vec();
    let subject = subject::control(&room);
    let headers =
        trust::control_headers(cluster.key.as_ref(), &subject, &cluster.replica, &request);
    let reply = cluster
        .client
        .send_request(
            subject.clone(),
            async_nats::Request::new()
                .payload(request.into())
                .headers(headers)
                .timeout(Some(FORWARD_TIMEOUT)),
        )
        .await
        .map_err(|e| {
            format!(
                "room {room:?}: its owner does not answer ({e}); a live replica adopts it within the lease"
            )
        })?;
    cluster.metrics.forwarded_controls.inc();
    // The ack must be an owner's (its tag, with a key) of an epoch not older than one seen.
    let believed = trust::check_ack(
        cluster.key.as_ref(),
        &subject,
        reply.headers.as_ref(),
        &reply.payload,
    )
    .and_then(|(_, epoch)| match cluster.link(&room) {
        Some(link) if epoch < link.epoch_seen() => Err(Refusal::Stale),
        Some(link) => {
            link.note_epoch(epoch);
            Ok(())
        }
        None => Ok(()),
    });
    if let Err(refusal) = believed {
        let m = &cluster.metrics;
        match refusal {
            Refusal::Forged => m.refused_forged_frames.inc(),
            Refusal::Stale => m.refused_stale_frames.inc(),
        };
        return Err(format!(
            "room {room:?}: the reply to the forwarded frame is not its owner's ({refusal:?}): ignored"
        ));
    }
    v1::PublishAck::decode(reply.payload.as_ref())
        .map_err(|e| format!("room {room:?}: the owner's reply is not a PublishAck: {e}"))
}

/// Owner: serves the frames relays forward into `room` until the task is aborted (the room
/// changed owner or closed).
pub(crate) async fn serve(host: Arc<dyn Host>, cluster: Arc<Cluster>, room: String) {
    let subject = subject::control(&room);
    let Ok(mut sub) = cluster.client.subscribe(subject.clone()).await else {
        tracing::error!(%room, "cannot subscribe to forwarded controls");
        return;
    };
    while let Some(msg) = sub.next().await {
        let Some(reply) = msg.reply else {
            continue;
        };
        if !trust::check_control(
            cluster.key.as_ref(),
            &subject,
            msg.headers.as_ref(),
            &msg.payload,
        ) {
            // Not a replica's: no answer (the sender times out), counted.
            cluster.metrics.refused_controls.inc();
            continue;
        }
        let forwarded = v1::ForwardedControl::decode(msg.payload.as_ref());
        // The room's link, once per message: its lease (fencing) and its epoch (the ack).
        let link = cluster.link(&room);
        let lapsed = link.as_ref().is_some_and(|l| l.lease_lapsed());
        let ack = match forwarded.map(read_forwarded_control) {
            // Fencing: an owner whose lease lapsed (it was paused or cut off) predicts nothing
            // for the cluster until it renews, or learns that another replica adopted the room.
            Ok(Ok(_)) if lapsed => error_ack(
                0,
                frame_error(
                    ErrorCode::Unavailable,
                    format!("room {room:?}: its owner's lease lapsed; retry in a moment"),
                ),
            ),
            Ok(Ok(mut frame)) => {
                room.clone_into(&mut frame.room);
                Arc::clone(&host).publish_forwarded(frame).await
            }
            Ok(Err(e)) => error_ack(0, frame_error(ErrorCode::InvalidArgument, e.to_string())),
            Err(e) => error_ack(
                0,
                frame_error(
                    ErrorCode::InvalidArgument,
                    format!("not a crease.v1.ForwardedControl: {e}"),
                ),
            ),
        };
        let payload = ack.encode_to_vec();
        let epoch = link.map_or(0, |l| l.entry().0.epoch);
        let headers = trust::ack_headers(
            cluster.key.as_ref(),
            &subject,
            &cluster.replica,
            epoch,
            &payload,
        );
        let _ = cluster
            .client
            .publish_with_headers(reply, headers, payload.into())
            .await;
    }
}
