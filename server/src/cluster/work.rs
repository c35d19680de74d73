//! Batch jobs across the replicas (issue 45), the JetStream side: the work queue every replica
//! pulls chunks from, the jobs' records, and their results. Nothing here runs a prediction:
//! `crate::job_service` is the worker (the same one the in-process store feeds), and this
//! module is its transport.
//!
//! - **The queue**: the stream `CREASE_JOBS` (work-queue retention: a chunk leaves it when it
//!   is acked), subjects `crease.jobs.<job>`, one `JobChunk` a message, pulled one at a time
//!   through the durable consumer `crease-job-workers` that every replica shares. A chunk not
//!   acked within the consumer's `ack_wait` (`--job-ack-wait`) goes to another replica; a
//!   worker that is still running it says so (a progress ack) every third of that, so only a
//!   dead or stalled replica's chunk is redelivered.
//! - **Records**: the key-value bucket `crease-jobs`, job id -> `JobRecord` (the `JobInfo`
//!   clients see, the resolved spec, the model's digest, a bitmap of the chunks counted),
//!   changed only by a compare-and-set on its revision ([`WorkQueue::update`]).
//! - **Results**: the object store `crease-job-results`, `<job>/topology` and
//!   `<job>/<chunk>`. A chunk's worker stores its result, then counts it in the record, then
//!   acks; a redelivered chunk whose result is stored is not run again, and one already
//!   counted is only acked. So a replica killed at any point costs at most one chunk's work,
//!   and every chunk is stored and counted exactly once.
//! - **Trust** (issue 40): with a cluster key, chunks carry a tag header over their subject and
//!   payload, records a seal over the id and the record, results a tag in their metadata; a
//!   chunk, record or result whose tag does not hold is not believed.

use std::collections::HashMap;
use std::time::Duration;

use async_nats::HeaderMap;
use async_nats::jetstream::{self, AckKind, consumer::PullConsumer, kv, object_store};
use crease_proto::job::{JobPlan, JobState, JobStatus, end_job, job_chunk, job_record};
use crease_proto::v1;
use futures_util::StreamExt;
use futures_util::stream::BoxStream;
use prost::Message as _;
use tokio::io::AsyncReadExt;

use super::trust::{ClusterKey, TAG};
use super::{Cluster, ClusterError};
use crate::jobs::JobError;

/// The work queue's stream.
pub const JOBS_STREAM: &str = "CREASE_JOBS";
/// The replicas' shared pull consumer.
pub const JOBS_CONSUMER: &str = "crease-job-workers";
/// The records' bucket.
pub const JOBS_BUCKET: &str = "crease-jobs";
/// The results' object store.
pub const RESULTS_BUCKET: &str = "crease-job-results";
/// How long a record stays listed after its result expired.
const RECORD_AFTER_EXPIRY: Duration = Duration::from_secs(7 * 24 * 3600);

/// The subject of job `job`'s chunks.
pub fn subject(job: &str) -> String {
    format!("crease.jobs.{job}")
}

/// The result object of `job`'s chunk `chunk` (`None`: its topology).
pub fn object_name(job: &str, chunk: Option<u32>) -> String {
    match chunk {
        Some(c) => format!("{job}/{c:05}"),
        None => format!("{job}/topology"),
    }
}

/// The cluster's side of batch jobs (module docs).
pub struct WorkQueue {
    js: jetstream::Context,
    stream: jetstream::stream::Stream,
    consumer: PullConsumer,
    records: kv::Store,
    results: object_store::ObjectStore,
    key: Option<ClusterKey>,
    ack_wait: Duration,
}

impl std::fmt::Debug for WorkQueue {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WorkQueue")
            .field("ack_wait", &self.ack_wait)
            .field("key", &self.key.is_some())
            .finish_non_exhaustive()
    }
}

/// A chunk pulled from the queue ([`WorkQueue::next`]).
pub struct Pulled {
    /// The chunk.
    pub chunk: v1::JobChunk,
    /// Whether an earlier delivery of it was not acked (a replica died or stalled).
    pub redelivered: bool,
    message: jetstream::Message,
}

impl std::fmt::Debug for Pulled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pulled")
            .field("job", &self.chunk.job)
            .field("chunk", &self.chunk.chunk)
            .field("redelivered", &self.redelivered)
            .finish_non_exhaustive()
    }
}

fn unavailable(what: &str) -> impl Fn(String) -> JobError + '_ {
    move |e| JobError::Io {
        path: format!("(cluster {what})"),
        message: e,
    }
}

/// Microseconds since the Unix epoch.
pub(crate) fn now_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

/// Makes JetStream's stream `name` unless it is there (another replica may be making it at
/// the same moment).
async fn ensure_stream(
    js: &jetstream::Context,
    config: jetstream::stream::Config,
    bucket: &'static str,
) -> Result<jetstream::stream::Stream, ClusterError> {
    let name = config.name.clone();
    if let Ok(stream) = js.get_stream(&name).await {
        return Ok(stream);
    }
    let created = js.create_stream(config).await.map_err(|e| e.to_string());
    match created {
        Ok(stream) => Ok(stream),
        Err(first) => js
            .get_stream(&name)
            .await
            .map_err(|_| ClusterError::Bucket {
                bucket,
                message: first,
            }),
    }
}

impl WorkQueue {
    /// Opens (making them if they are not there) the queue, its consumer (`ack_wait`), the
    /// records' bucket and the results' store; `key` is the cluster's.
    ///
    /// # Errors
    /// [`ClusterError::Bucket`]: JetStream refused one.
    pub(super) async fn open(
        js: &jetstream::Context,
        key: Option<ClusterKey>,
        ack_wait: Duration,
    ) -> Result<WorkQueue, ClusterError> {
        let stream = ensure_stream(
            js,
            jetstream::stream::Config {
                name: JOBS_STREAM.into(),
                description: Some(
                    "crease batch jobs' chunks: crease.jobs.<job> -> JobChunk (cluster.proto)"
                        .into(),
                ),
                subjects: vec!["crease.jobs.>".into()],
                retention: jetstream::stream::RetentionPolicy::WorkQueue,
                storage: jetstream::stream::StorageType::File,
                num_replicas: 1,
                ..Default::default()
            },
            JOBS_STREAM,
        )
        .await?;
        let consumer: PullConsumer = stream
            .create_consumer(jetstream::consumer::pull::Config {
                durable_name: Some(JOBS_CONSUMER.into()),
                description: Some("every crease replica pulls job chunks here".into()),
                ack_policy: jetstream::consumer::AckPolicy::Explicit,
                ack_wait,
                ..Default::default()
            })
            .await
            .map_err(|e| ClusterError::Bucket {
                bucket: JOBS_STREAM,
                message: format!("its consumer {JOBS_CONSUMER}: {e}"),
            })?;
        // The records' bucket's stream, made as the rooms' bucket is (`registry::open_kv`).
        ensure_stream(
            js,
            jetstream::stream::Config {
                name: format!("KV_{JOBS_BUCKET}"),
                description: Some("crease batch jobs: id -> JobRecord (cluster.proto)".into()),
                subjects: vec![format!("$KV.{JOBS_BUCKET}.>")],
                max_messages_per_subject: 1,
                allow_rollup: true,
                allow_direct: true,
                discard: jetstream::stream::DiscardPolicy::New,
                num_replicas: 1,
                ..Default::default()
            },
            JOBS_BUCKET,
        )
        .await?;
        let records = js
            .get_key_value(JOBS_BUCKET)
            .await
            .map_err(|e| ClusterError::Bucket {
                bucket: JOBS_BUCKET,
                message: e.to_string(),
            })?;
        let results = match js.get_object_store(RESULTS_BUCKET).await {
            Ok(store) => store,
            Err(_) => {
                let created = js
                    .create_object_store(object_store::Config {
                        bucket: RESULTS_BUCKET.into(),
                        description: Some(
                            "crease batch jobs' results: <job>/topology, <job>/<chunk>".into(),
                        ),
                        ..Default::default()
                    })
                    .await;
                match created {
                    Ok(store) => store,
                    Err(e) => js.get_object_store(RESULTS_BUCKET).await.map_err(|_| {
                        ClusterError::Bucket {
                            bucket: RESULTS_BUCKET,
                            message: e.to_string(),
                        }
                    })?,
                }
            }
        };
        Ok(WorkQueue {
            js: js.clone(),
            stream,
            consumer,
            records,
            results,
            key,
            ack_wait,
        })
    }

    /// The consumer's `ack_wait`: a worker says it is alive every third of it.
    pub fn ack_wait(&self) -> Duration {
        self.ack_wait
    }

    fn seal(&self, id: &str, record: &mut v1::JobRecord) {
        match &self.key {
            Some(key) => key.seal_job(id, record),
            None => record.tag.clear(),
        }
    }

    fn decode(&self, id: &str, value: &[u8]) -> Option<v1::JobRecord> {
        match v1::JobRecord::decode(value) {
            Ok(r) if believed(self.key.as_ref(), id, &r) => Some(r),
            Ok(_) => {
                tracing::warn!(job = id, "a job record whose seal does not hold: ignored");
                None
            }
            Err(e) => {
                tracing::warn!(job = id, "a job record that does not decode: {e}");
                None
            }
        }
    }

    /// Job `id`'s record and its revision.
    ///
    /// # Errors
    /// [`JobError::NoJob`], or the bucket unreadable.
    pub async fn record(&self, id: &str) -> Result<(v1::JobRecord, u64), JobError> {
        if !crease_proto::job::is_job_id(id) {
            return Err(JobError::NoJob(id.to_owned()));
        }
        let entry = self
            .records
            .entry(id)
            .await
            .map_err(|e| unavailable("jobs bucket")(e.to_string()))?;
        match entry {
            Some(e) if e.operation == kv::Operation::Put => self
                .decode(id, &e.value)
                .map(|r| (r, e.revision))
                .ok_or_else(|| JobError::NoJob(id.to_owned())),
            _ => Err(JobError::NoJob(id.to_owned())),
        }
    }

    /// Changes job `id`'s record by `change` (which returns whether it changed anything) with
    /// a compare-and-set, read again and retried when another replica wrote between; returns
    /// the record as written (or as read, unchanged).
    ///
    /// # Errors
    /// [`WorkQueue::record`]'s, or the bucket unwritable.
    pub async fn update(
        &self,
        id: &str,
        mut change: impl FnMut(&mut v1::JobRecord) -> bool,
    ) -> Result<(v1::JobRecord, bool), JobError> {
        loop {
            let (mut record, revision) = self.record(id).await?;
            if !change(&mut record) {
                return Ok((record, false));
            }
            self.seal(id, &mut record);
            match self
                .records
                .update(id, record.encode_to_vec().into(), revision)
                .await
            {
                Ok(_) => return Ok((record, true)),
                Err(e) if e.kind() == kv::UpdateErrorKind::WrongLastRevision => continue,
                Err(e) => return Err(unavailable("jobs bucket")(e.to_string())),
            }
        }
    }

    /// Queues a job: its record (state queued), then every chunk on the queue. A chunk larger
    /// than NATS's message limit is refused before anything is written.
    ///
    /// # Errors
    /// [`JobError::Full`] (a chunk too large), the bucket or the queue unavailable (the job is
    /// then failed, naming why).
    pub async fn submit(
        &self,
        status: &JobStatus,
        plan: &JobPlan,
        model_sha256: &str,
        chunks: Vec<Vec<v1::ControlFrame>>,
        max_payload: usize,
        ttl: Duration,
    ) -> Result<(), JobError> {
        let id = status.job.clone();
        let subject = subject(&id);
        let messages: Vec<Vec<u8>> = chunks
            .into_iter()
            .enumerate()
            .map(|(c, frames)| job_chunk(&id, c as u32, frames).encode_to_vec())
            .collect();
        if let Some((c, m)) = messages
            .iter()
            .enumerate()
            .find(|(_, m)| m.len() + 1024 > max_payload)
        {
            return Err(JobError::Full(format!(
                "SubmitJob: chunk {c} is {} bytes, over the NATS server's message limit of {max_payload} bytes: lower --job-chunk-frames",
                m.len()
            )));
        }
        let mut record = job_record(status, plan, model_sha256);
        self.seal(&id, &mut record);
        self.records
            .create(&id, record.encode_to_vec().into())
            .await
            .map_err(|e| unavailable("jobs bucket")(e.to_string()))?;
        // Published with at most 64 acks awaited at once.
        let mut pending = futures_util::stream::FuturesOrdered::new();
        let mut failed = None;
        for payload in messages {
            let mut headers = HeaderMap::new();
            if let Some(key) = &self.key {
                headers.insert(TAG, key.tag(&[b"job-chunk", subject.as_bytes(), &payload]));
            }
            match self
                .js
                .publish_with_headers(subject.clone(), headers, payload.into())
                .await
            {
                Ok(ack) => pending.push_back(ack.into_future()),
                Err(e) => {
                    failed = Some(e.to_string());
                    break;
                }
            }
            if pending.len() >= 64
                && let Some(Err(e)) = pending.next().await
            {
                failed = Some(e.to_string());
                break;
            }
        }
        while failed.is_none()
            && let Some(ack) = pending.next().await
        {
            if let Err(e) = ack {
                failed = Some(e.to_string());
            }
        }
        if let Some(why) = failed {
            self.fail(&id, format!("queueing its chunks: {why}"), ttl)
                .await;
            return Err(unavailable("jobs queue")(why));
        }
        Ok(())
    }

    /// Ends job `id` failed with `why` (unless it has ended) and drops its queued chunks.
    pub async fn fail(&self, id: &str, why: String, ttl: Duration) {
        let ended = self
            .update(id, |r| {
                let Some(info) = r.info.as_mut() else {
                    return false;
                };
                if JobState::from_wire(info.state).ended() {
                    return false;
                }
                end_job(info, JobState::Failed, why.clone(), now_us(), ttl);
                true
            })
            .await;
        if let Err(e) = ended {
            tracing::warn!(job = id, "failing the job: {e}");
        }
        self.drop_queued(id).await;
    }

    /// Drops job `id`'s chunks still on the queue.
    async fn drop_queued(&self, id: &str) {
        if let Err(e) = self.stream.purge().filter(subject(id)).await {
            tracing::warn!(job = id, "dropping the job's queued chunks: {e}");
        }
    }

    /// Cancels job `id`: no chunk of it starts after this returns (a worker reads the record
    /// before each chunk), and its queued chunks are dropped.
    ///
    /// # Errors
    /// [`JobError::NoJob`], [`JobError::Ended`], the bucket unavailable.
    pub async fn cancel(&self, id: &str, ttl: Duration) -> Result<JobStatus, JobError> {
        let mut ended_as = None;
        let (record, changed) = self
            .update(id, |r| {
                let Some(info) = r.info.as_mut() else {
                    return false;
                };
                let state = JobState::from_wire(info.state);
                if state.ended() {
                    ended_as = Some(state);
                    return false;
                }
                end_job(
                    info,
                    JobState::Cancelled,
                    "cancelled by CancelJob".into(),
                    now_us(),
                    ttl,
                );
                true
            })
            .await?;
        if let (Some(state), false) = (ended_as, changed) {
            return Err(JobError::Ended {
                job: id.to_owned(),
                state: state.as_str(),
            });
        }
        self.drop_queued(id).await;
        Ok(status_of(&record))
    }

    /// Every job's status, newest first.
    ///
    /// # Errors
    /// The bucket unreadable.
    pub async fn list(&self) -> Result<Vec<JobStatus>, JobError> {
        let mut keys = self
            .records
            .keys()
            .await
            .map_err(|e| unavailable("jobs bucket")(e.to_string()))?;
        let mut all = Vec::new();
        while let Some(key) = keys.next().await {
            let Ok(key) = key else { continue };
            if let Ok((record, _)) = self.record(&key).await {
                all.push(status_of(&record));
            }
        }
        all.sort_by_key(|s| std::cmp::Reverse(s.submitted_us));
        Ok(all)
    }

    /// Job `id`'s status now, then each change, ending after the job's last.
    ///
    /// # Errors
    /// [`JobError::NoJob`], the bucket unreadable.
    pub async fn watch(&self, id: &str) -> Result<BoxStream<'static, JobStatus>, JobError> {
        if !crease_proto::job::is_job_id(id) {
            return Err(JobError::NoJob(id.to_owned()));
        }
        let watch = self
            .records
            .watch(id)
            .await
            .map_err(|e| unavailable("jobs bucket")(e.to_string()))?;
        // Read after the watch began: no change falls between the two.
        let first = status_of(&self.record(id).await?.0);
        let key = self.key.clone();
        let id = id.to_owned();
        let later = watch.filter_map(move |entry| {
            let status = entry.ok().and_then(|e| {
                let r = v1::JobRecord::decode(e.value.as_ref()).ok()?;
                believed(key.as_ref(), &id, &r).then(|| status_of(&r))
            });
            async move { status }
        });
        let updates = futures_util::stream::unfold(
            (Some(first), Box::pin(later), false),
            |(first, mut later, stopped)| async move {
                if stopped {
                    return None;
                }
                let status = match first {
                    Some(s) => s,
                    None => later.next().await?,
                };
                let ended = status.state.ended();
                Some((status, (None, later, ended)))
            },
        );
        Ok(Box::pin(updates))
    }

    /// Job `id`'s result, when it is done: its topology and each chunk's frames, in order.
    ///
    /// # Errors
    /// [`JobError::NoJob`], [`JobError::NotDone`], [`JobError::Expired`].
    pub async fn result(
        &self,
        id: &str,
    ) -> Result<BoxStream<'static, Result<v1::MeshFrame, JobError>>, JobError> {
        let (record, _) = self.record(id).await?;
        let status = status_of(&record);
        // Expired: swept, or past its time and not yet swept (`expire` runs every 30 s).
        if record.expired || (status.expires_us != 0 && status.expires_us <= now_us()) {
            return Err(JobError::Expired(id.to_owned()));
        }
        crate::jobs::check_done(&status)?;
        let names: Vec<(String, bool)> = std::iter::once((object_name(id, None), false))
            .chain((0..status.chunks_total).map(|c| (object_name(id, Some(c)), true)))
            .collect();
        let results = self.results.clone();
        let key = self.key.clone();
        let stream = futures_util::stream::iter(names)
            .then(move |(name, delimited)| {
                let (results, key) = (results.clone(), key.clone());
                async move { read_result(&results, key.as_ref(), &name, delimited).await }
            })
            .flat_map(|read| match read {
                Ok(messages) => futures_util::stream::iter(messages.into_iter().map(Ok)).boxed(),
                Err(e) => futures_util::stream::once(async move { Err(e) }).boxed(),
            });
        Ok(Box::pin(stream))
    }

    /// The next chunk on the queue, waiting at most a few seconds (`None`: nothing came, or
    /// the queue cannot be read now, logged). A chunk whose tag does not hold is dropped.
    pub async fn next(&self, metrics: &super::ClusterMetrics) -> Option<Pulled> {
        let batch = self
            .consumer
            .batch()
            .max_messages(1)
            .expires(Duration::from_secs(5))
            .messages()
            .await;
        let mut batch = match batch {
            Ok(b) => b,
            Err(e) => {
                tracing::debug!("pulling a job chunk: {e}");
                tokio::time::sleep(Duration::from_secs(1)).await;
                return None;
            }
        };
        let message = match batch.next().await? {
            Ok(m) => m,
            Err(e) => {
                tracing::debug!("pulling a job chunk: {e}");
                return None;
            }
        };
        let subject = message.subject.to_string();
        if let Some(key) = &self.key {
            let tag = message
                .headers
                .as_ref()
                .and_then(|h| h.get(TAG))
                .map(|v| v.as_str().to_owned())
                .unwrap_or_default();
            if !key.verify(&[b"job-chunk", subject.as_bytes(), &message.payload], &tag) {
                metrics.refused_job_chunks.inc();
                tracing::warn!(%subject, "a job chunk whose tag does not hold: dropped");
                let _ = message.ack_with(AckKind::Term).await;
                return None;
            }
        }
        let chunk = match v1::JobChunk::decode(message.payload.as_ref()) {
            Ok(c) if subject == self::subject(&c.job) => c,
            _ => {
                tracing::warn!(%subject, "a job chunk that does not decode: dropped");
                let _ = message.ack_with(AckKind::Term).await;
                return None;
            }
        };
        let redelivered = message.info().is_ok_and(|i| i.delivered > 1);
        Some(Pulled {
            chunk,
            redelivered,
            message,
        })
    }

    /// Tells the queue the chunk is still being worked on (its `ack_wait` starts again).
    pub async fn in_progress(&self, pulled: &Pulled) {
        let _ = pulled.message.ack_with(AckKind::Progress).await;
    }

    /// Acks the chunk: it leaves the queue (after its result is stored and counted, or when
    /// its job has ended).
    pub async fn ack(&self, pulled: Pulled) {
        if let Err(e) = pulled.message.double_ack().await {
            // Redelivered later: stored and counted, so only acked then.
            tracing::warn!(job = %pulled.chunk.job, chunk = pulled.chunk.chunk, "acking a job chunk: {e}");
        }
    }

    /// Whether chunk `chunk` of job `job` has a stored result (a redelivery after its store).
    pub async fn has_result(&self, job: &str, chunk: u32) -> bool {
        self.results
            .info(object_name(job, Some(chunk)))
            .await
            .is_ok_and(|i| !i.deleted)
    }

    /// Stores chunk `chunk`'s result (`bytes`: its frames, length-delimited) and, with
    /// `topology`, the job's topology first.
    ///
    /// # Errors
    /// The store unwritable.
    pub async fn store(
        &self,
        job: &str,
        chunk: u32,
        topology: Option<&v1::MeshFrame>,
        bytes: &[u8],
    ) -> Result<(), JobError> {
        if let Some(t) = topology {
            self.put(&object_name(job, None), &t.encode_to_vec())
                .await?;
        }
        self.put(&object_name(job, Some(chunk)), bytes).await
    }

    async fn put(&self, name: &str, bytes: &[u8]) -> Result<(), JobError> {
        let mut metadata = HashMap::new();
        if let Some(key) = &self.key {
            metadata.insert(
                "tag".to_owned(),
                key.tag(&[b"job-result", name.as_bytes(), bytes]),
            );
        }
        let meta = object_store::ObjectMetadata {
            name: name.to_owned(),
            metadata,
            ..Default::default()
        };
        self.results
            .put(meta, &mut &bytes[..])
            .await
            .map(|_| ())
            .map_err(|e| JobError::Io {
                path: format!("{RESULTS_BUCKET}/{name}"),
                message: e.to_string(),
            })
    }

    /// Deletes the results of ended jobs past their expiry (the record stays listed, expired,
    /// for a week), as one replica: the one whose compare-and-set marks it expired. Returns
    /// every job's status as read (the caller counts them for the gauges); `None` when the
    /// bucket cannot be read.
    pub async fn expire(&self) -> Option<Vec<JobStatus>> {
        let all = self.list().await.ok()?;
        let now = now_us();
        for status in &all {
            if !status.state.ended() || status.expires_us == 0 || status.expires_us > now {
                continue;
            }
            let marked = self
                .update(&status.job, |r| !std::mem::replace(&mut r.expired, true))
                .await;
            match marked {
                Ok((_, true)) => {
                    for name in std::iter::once(object_name(&status.job, None))
                        .chain((0..status.chunks_total).map(|c| object_name(&status.job, Some(c))))
                    {
                        let _ = self.results.delete(&name).await;
                    }
                    tracing::info!(job = %status.job, "job result expired: deleted");
                }
                Ok((_, false)) => {
                    let forget = RECORD_AFTER_EXPIRY.as_micros() as i64;
                    if status.expires_us.saturating_add(forget) <= now {
                        let _ = self.records.purge(&status.job).await;
                    }
                }
                Err(e) => tracing::debug!(job = %status.job, "expiring: {e}"),
            }
        }
        Some(all)
    }
}

/// Whether job `id`'s `record` is believed: always without a key, with one only when its
/// seal holds.
fn believed(key: Option<&ClusterKey>, id: &str, record: &v1::JobRecord) -> bool {
    key.is_none_or(|k| k.check_job(id, record))
}

/// The status a record says.
pub fn status_of(record: &v1::JobRecord) -> JobStatus {
    JobStatus::from_wire(&record.info.clone().unwrap_or_default())
}

/// A result object's messages (one, or length-delimited ones), its tag checked with a key.
async fn read_result(
    results: &object_store::ObjectStore,
    key: Option<&ClusterKey>,
    name: &str,
    delimited: bool,
) -> Result<Vec<v1::MeshFrame>, JobError> {
    let io = |message: String| JobError::Io {
        path: format!("{RESULTS_BUCKET}/{name}"),
        message,
    };
    let mut object = results.get(name).await.map_err(|e| io(e.to_string()))?;
    let tag = object
        .info()
        .metadata
        .get("tag")
        .cloned()
        .unwrap_or_default();
    let mut bytes = Vec::new();
    object
        .read_to_end(&mut bytes)
        .await
        .map_err(|e| io(e.to_string()))?;
    if let Some(key) = key
        && !key.verify(&[b"job-result", name.as_bytes(), &bytes], &tag)
    {
        return Err(io("its tag does not hold: not believed".into()));
    }
    crate::jobs::decode_messages(&bytes, delimited).map_err(|e| io(format!("not a result: {e}")))
}

impl Cluster {
    /// The cluster's batch jobs.
    pub fn work(&self) -> &WorkQueue {
        &self.work
    }
}
