//! Prometheus metrics (`GET /metrics`, text exposition format): frame latency, frames and bytes,
//! rooms and subscribers. Counters are shared atomics, updated from any thread.

use prometheus_client::encoding::text::encode;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::{Histogram, exponential_buckets};
use prometheus_client::registry::Registry;

/// The server's metrics.
#[derive(Debug)]
pub struct Metrics {
    registry: Registry,
    /// Control frames predicted and handed to the subscribers.
    pub frames_published: Counter,
    /// Control frames refused (bad field, unknown room, wrong token).
    pub frames_refused: Counter,
    /// Control frames superseded by a newer one of their room while they waited (`mailbox`).
    pub frames_superseded: Counter,
    /// Frames whose detail layer was synthesised (only while someone watches it).
    pub detail_frames: Counter,
    /// Seconds from a control frame's arrival to its meshes being ready.
    pub frame_latency: Histogram,
    /// How far published frames lie from their model's training examples (issue 20: 0 at an
    /// example, 1 as far as the examples are spread).
    pub frame_confidence: Histogram,
    /// Encoded mesh bytes sent to subscribers and batch clients.
    pub bytes_out: Counter,
    /// Mesh frames sent.
    pub frames_out: Counter,
    /// Open rooms.
    pub rooms: Gauge,
    /// Live mesh subscriptions.
    pub subscribers: Gauge,
    /// Tasks alive on the server's runtime, read when `/metrics` is rendered (a soak watches
    /// it for leaks).
    pub tasks: Gauge,
    /// Batch jobs accepted (issue 45).
    pub jobs_submitted: Counter,
    /// Batch jobs done, every chunk stored.
    pub jobs_done: Counter,
    /// Batch jobs failed.
    pub jobs_failed: Counter,
    /// Batch jobs cancelled.
    pub jobs_cancelled: Counter,
    /// Seconds from a job chunk's start to its result stored.
    pub job_chunk_seconds: Histogram,
    /// Batch jobs queued (no chunk done yet) and running: on a single server counted when
    /// `/metrics` is rendered; in a cluster the cluster's, counted by every replica's expiry
    /// sweep (every 30 s), so each replica reports the same number (aggregate with max).
    pub jobs_queued: Gauge,
    /// Batch jobs running (some chunks done); as [`Metrics::jobs_queued`].
    pub jobs_running: Gauge,
    /// The cluster's (zero on a single server).
    pub cluster: crate::cluster::metrics::ClusterMetrics,
}

impl Default for Metrics {
    fn default() -> Self {
        let mut registry = Registry::with_prefix("crease");
        let m = Metrics {
            frames_published: Counter::default(),
            frames_refused: Counter::default(),
            frames_superseded: Counter::default(),
            detail_frames: Counter::default(),
            // 25 µs to ~51 ms.
            frame_latency: Histogram::new(exponential_buckets(25e-6, 2.0, 12)),
            frame_confidence: Histogram::new([0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0]),
            bytes_out: Counter::default(),
            frames_out: Counter::default(),
            rooms: Gauge::default(),
            subscribers: Gauge::default(),
            tasks: Gauge::default(),
            jobs_submitted: Counter::default(),
            jobs_done: Counter::default(),
            jobs_failed: Counter::default(),
            jobs_cancelled: Counter::default(),
            // 10 ms to ~41 s.
            job_chunk_seconds: Histogram::new(exponential_buckets(0.01, 2.0, 13)),
            jobs_queued: Gauge::default(),
            jobs_running: Gauge::default(),
            cluster: crate::cluster::metrics::ClusterMetrics::default(),
            registry: Registry::default(),
        };
        m.cluster.register(&mut registry);
        registry.register(
            "frames_published",
            "Control frames predicted and handed to the subscribers",
            m.frames_published.clone(),
        );
        registry.register(
            "frames_refused",
            "Control frames refused (bad field, unknown room, wrong token)",
            m.frames_refused.clone(),
        );
        registry.register(
            "frames_superseded",
            "Control frames a newer frame of their room superseded while they waited (latest wins)",
            m.frames_superseded.clone(),
        );
        registry.register(
            "detail_frames",
            "Frames whose detail layer was synthesised",
            m.detail_frames.clone(),
        );
        registry.register(
            "frame_latency_seconds",
            "From a control frame's arrival to its meshes being ready",
            m.frame_latency.clone(),
        );
        registry.register(
            "frame_confidence",
            "How far published frames lie from the model's training examples (0 at an example, 1 as far as the examples are spread)",
            m.frame_confidence.clone(),
        );
        registry.register("bytes_out", "Encoded mesh bytes sent", m.bytes_out.clone());
        registry.register("frames_out", "Mesh frames sent", m.frames_out.clone());
        registry.register("rooms", "Open rooms", m.rooms.clone());
        registry.register(
            "subscribers",
            "Live mesh subscriptions",
            m.subscribers.clone(),
        );
        registry.register(
            "tasks",
            "Tasks alive on the server's async runtime",
            m.tasks.clone(),
        );
        registry.register(
            "jobs_submitted",
            "Batch jobs accepted",
            m.jobs_submitted.clone(),
        );
        registry.register("jobs_done", "Batch jobs done", m.jobs_done.clone());
        registry.register(
            "jobs_queued",
            "Batch jobs queued (in a cluster: the cluster's, the same on every replica)",
            m.jobs_queued.clone(),
        );
        registry.register(
            "jobs_running",
            "Batch jobs running (in a cluster: the cluster's, the same on every replica)",
            m.jobs_running.clone(),
        );
        registry.register("jobs_failed", "Batch jobs failed", m.jobs_failed.clone());
        registry.register(
            "jobs_cancelled",
            "Batch jobs cancelled",
            m.jobs_cancelled.clone(),
        );
        registry.register(
            "job_chunk_seconds",
            "From a job chunk's start to its result stored",
            m.job_chunk_seconds.clone(),
        );
        Metrics { registry, ..m }
    }
}

impl Metrics {
    /// Registers the refusals of the connection and stream caps
    /// (`crease_admission_refused_total{kind}`).
    pub fn register_admission(
        &mut self,
        connections: &crate::admission::Admission,
        streams: &crate::admission::Admission,
    ) {
        let sub = self
            .registry
            .sub_registry_with_label(("kind".into(), "connections".into()));
        sub.register(
            "admission_refused",
            "Connections or streams refused by a per-address or total cap",
            connections.refused_counter(),
        );
        let sub = self
            .registry
            .sub_registry_with_label(("kind".into(), "streams".into()));
        sub.register(
            "admission_refused",
            "Connections or streams refused by a per-address or total cap",
            streams.refused_counter(),
        );
    }

    /// Sets the queued and running gauges from every job's status.
    pub fn count_jobs(&self, jobs: &[crease_proto::job::JobStatus]) {
        use crease_proto::job::JobState;
        let count = |state| jobs.iter().filter(|j| j.state == state).count() as i64;
        self.jobs_queued.set(count(JobState::Queued));
        self.jobs_running.set(count(JobState::Running));
    }

    /// The text exposition of every metric.
    pub fn render(&self) -> String {
        if let Ok(runtime) = tokio::runtime::Handle::try_current() {
            self.tasks
                .set(i64::try_from(runtime.metrics().num_alive_tasks()).unwrap_or(i64::MAX));
        }
        let mut out = String::new();
        // Writing into a String cannot fail.
        let _ = encode(&mut out, &self.registry);
        out
    }
}
