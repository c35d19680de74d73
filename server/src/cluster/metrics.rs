//! The per-replica cluster metrics (`crease_cluster_*` in `/metrics`): frames and bytes into
//! NATS and relayed out of it, forwarded controls, adoptions, the connection. The server's
//! metrics (`crate::metrics`) hold one and register it.

use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;

/// The per-replica cluster metrics (in `/metrics`, `crease_cluster_*`).
#[derive(Clone, Debug, Default)]
pub struct ClusterMetrics {
    /// Frames this replica published into NATS (owner).
    pub nats_frames_out: Counter,
    /// Their bytes.
    pub nats_bytes_out: Counter,
    /// Frames dropped on their way to NATS (the sender fell behind).
    pub nats_frames_dropped: Counter,
    /// Frames received from an owner and fanned out here (relay).
    pub relayed_frames: Counter,
    /// Their bytes.
    pub relayed_bytes: Counter,
    /// Control frames this replica forwarded to an owner.
    pub forwarded_controls: Counter,
    /// Rooms this replica adopted from a dead owner.
    pub adoptions: Counter,
    /// Frames (and acks) from NATS refused for a missing or bad tag, or an owner the room's
    /// epoch does not name (issue 40: a forger).
    pub refused_forged_frames: Counter,
    /// Frames from NATS refused for an ownership epoch older than one seen (a paused or
    /// partitioned owner that was replaced).
    pub refused_stale_frames: Counter,
    /// Room entries in the registry ignored for a missing or bad seal.
    pub refused_entries: Counter,
    /// Forwarded control frames refused for a missing or bad tag.
    pub refused_controls: Counter,
    /// Frames this replica, as owner, did not send because its lease was not renewed within a
    /// lease (it was paused or cut off, and may have been replaced).
    pub fenced_frames: Counter,
    /// Control frames this replica did not forward because it had just been stalled.
    pub stale_forwards: Counter,
    /// Job chunks this replica pulled that an earlier replica had pulled and not acked (it
    /// died or stalled; issue 45).
    pub job_redeliveries: Counter,
    /// Job chunks this replica took from the queue and ran.
    pub job_chunks: Counter,
    /// Job chunks dropped from the queue for a missing or bad tag.
    pub refused_job_chunks: Counter,
    /// 1 while connected to NATS.
    pub nats_connected: Gauge,
}

impl ClusterMetrics {
    /// Registers the metrics in `registry`.
    pub(crate) fn register(&self, registry: &mut prometheus_client::registry::Registry) {
        let r = registry.sub_registry_with_prefix("cluster");
        let counters = [
            (
                "nats_frames_out",
                "Frames published into NATS (owner)",
                &self.nats_frames_out,
            ),
            (
                "nats_bytes_out",
                "Bytes of frames published into NATS",
                &self.nats_bytes_out,
            ),
            (
                "nats_frames_dropped",
                "Frames dropped on their way to NATS",
                &self.nats_frames_dropped,
            ),
            (
                "relayed_frames",
                "Frames received from an owner and fanned out here",
                &self.relayed_frames,
            ),
            (
                "relayed_bytes",
                "Bytes of relayed frames",
                &self.relayed_bytes,
            ),
            (
                "forwarded_controls",
                "Control frames forwarded to an owner",
                &self.forwarded_controls,
            ),
            (
                "adoptions",
                "Rooms adopted from a dead owner",
                &self.adoptions,
            ),
            (
                "refused_forged_frames",
                "Frames and acks from NATS refused: no or a bad tag, or an owner its epoch does not name",
                &self.refused_forged_frames,
            ),
            (
                "refused_stale_frames",
                "Frames and acks from NATS refused: an ownership epoch older than one seen",
                &self.refused_stale_frames,
            ),
            (
                "refused_entries",
                "Room entries ignored: no or a bad seal",
                &self.refused_entries,
            ),
            (
                "refused_controls",
                "Forwarded control frames refused: no or a bad tag",
                &self.refused_controls,
            ),
            (
                "stale_forwards",
                "Control frames not forwarded: read right after this process was stalled",
                &self.stale_forwards,
            ),
            (
                "fenced_frames",
                "Frames not sent as owner: the lease was not renewed within a lease",
                &self.fenced_frames,
            ),
            (
                "job_redeliveries",
                "Job chunks pulled here after another replica pulled them and did not ack (died or stalled)",
                &self.job_redeliveries,
            ),
            (
                "job_chunks",
                "Job chunks this replica ran and stored",
                &self.job_chunks,
            ),
            (
                "refused_job_chunks",
                "Job chunks dropped from the queue: no or a bad tag",
                &self.refused_job_chunks,
            ),
        ];
        for (name, help, counter) in counters {
            r.register(name, help, counter.clone());
        }
        r.register(
            "nats_connected",
            "1 while connected to NATS",
            self.nats_connected.clone(),
        );
    }
}
