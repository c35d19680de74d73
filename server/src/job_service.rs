//! Batch jobs (issue 45): the one way both the transports and the workers reach them, in the
//! process or across a cluster.
//!
//! - **Without a cluster** the store is this process's ([`crate::jobs`]): a bounded queue that
//!   one worker drains, one job after another.
//! - **In a cluster** (`--nats`) the store is the cluster's ([`crate::cluster::work`]): the
//!   chunks wait on a JetStream work queue and every replica runs a worker
//!   ([`start_cluster_worker`]) that pulls one chunk at a time, runs it, stores its result,
//!   counts it in the job's record and only then acks it. A replica whose live rooms took
//!   frames since its last chunk waits after each chunk as long as the chunk took (twice for
//!   two such rooms, at most four times), so live rooms keep their CPU and idle replicas take
//!   more of the queue.
//!
//! Either way a chunk runs as a fresh batch through `Synthesize`'s path
//! (`AppState::batch_room`, `crate::stream::batch`): [`synthesize`]. Cancelling is seen
//! between chunks.

use std::path::Path;
use std::sync::{Arc, Weak};
use std::time::{Duration, Instant};

use crease_proto::job::{JobPlan, JobState, JobStatus, new_job_id};
use crease_proto::v1;
use futures_util::stream::BoxStream;
use prost::Message;
use tokio_stream::StreamExt;

use crate::cluster::Cluster;
use crate::cluster::work::{Pulled, now_us, status_of};
use crate::fanout::Channel;
use crate::jobs::{Job, JobError};
use crate::registry::LoadedModel;
use crate::state::AppState;
use crate::stream::StreamError;
use crease_proto::job::{count_chunk, is_done};

/// The model a job names: this server's, or in a cluster the cluster's (fetched and checked).
/// `None`: no such model.
///
/// # Errors
/// A cluster's copy that cannot be had (named).
pub async fn model(state: &AppState, name: &str) -> Result<Option<Arc<LoadedModel>>, JobError> {
    match state.cluster() {
        Some(cluster) => crate::cluster::models::named(state.models(), cluster, name)
            .await
            .map_err(|message| JobError::Io {
                path: "(cluster models)".into(),
                message,
            }),
        None => Ok(state.models().get(name)),
    }
}

/// Frames per chunk for a job of `frames`: `--job-chunk-frames`, and in a cluster few enough
/// that a chunk fits in one NATS message.
pub fn chunk_frames(state: &AppState, frames: &[v1::ControlFrame]) -> usize {
    let setting = state.jobs().settings().chunk_frames.max(1);
    let Some(cluster) = state.cluster() else {
        return setting;
    };
    let largest = frames.iter().map(Message::encoded_len).max().unwrap_or(1) + 16;
    let room = cluster.max_payload().saturating_sub(4096);
    setting.min((room / largest).max(1))
}

/// Queues a job of `chunks` (checked, [`crease_proto::job::chunk_frames`]; at most
/// `--max-job-frames`, which `crate::grpc` checks as it reads them) running `plan` on `model`,
/// and returns its status. Without a cluster the worker starts with the first job.
///
/// # Errors
/// The store's refusal ([`JobError`]: the queue full, a chunk too large, NATS unavailable).
pub async fn submit(
    state: &Arc<AppState>,
    plan: JobPlan,
    model: &LoadedModel,
    chunks: Vec<Vec<v1::ControlFrame>>,
) -> Result<JobStatus, JobError> {
    let status = match state.cluster() {
        Some(cluster) => {
            let settings = state.jobs().settings();
            let frames: usize = chunks.iter().map(Vec::len).sum();
            let open = cluster
                .work()
                .list()
                .await?
                .iter()
                .filter(|s| !s.state.ended())
                .count();
            if open >= settings.max_queued {
                return Err(JobError::Full(format!(
                    "the cluster's job queue is full ({open} jobs queued or running, --max-queued-jobs): try again when one ends"
                )));
            }
            let status = crate::jobs::queued_status(
                new_job_id(rand::random()),
                &plan,
                frames as u64,
                chunks.len() as u32,
            );
            cluster
                .work()
                .submit(
                    &status,
                    &plan,
                    model.sha256(),
                    chunks,
                    cluster.max_payload(),
                    settings.ttl,
                )
                .await?;
            status
        }
        None => {
            let status = state.jobs().enqueue(plan, chunks)?;
            if let Some(mut queue) = state.jobs().take_queue() {
                let dir = state.jobs().dir()?;
                let state = Arc::downgrade(state);
                tokio::spawn(async move {
                    while let Some(job) = queue.recv().await {
                        run(&state, &dir, &job).await;
                    }
                });
            }
            status
        }
    };
    state.metrics().jobs_submitted.inc();
    Ok(status)
}

/// Job `id`'s status now, then each change, ending after the job's last.
///
/// # Errors
/// [`JobError::NoJob`], or the cluster's store unavailable.
pub async fn watch(state: &AppState, id: &str) -> Result<BoxStream<'static, JobStatus>, JobError> {
    if let Some(cluster) = state.cluster() {
        return cluster.work().watch(id).await;
    }
    let rx = state.jobs().watch(id)?;
    Ok(Box::pin(futures_util::stream::unfold(
        (rx, true, false),
        |(mut rx, first, ended)| async move {
            if ended || (!first && rx.changed().await.is_err()) {
                return None;
            }
            let status = rx.borrow_and_update().clone();
            let ended = status.state.ended();
            Some((status, (rx, false, ended)))
        },
    )))
}

/// Every job's status, newest first.
///
/// # Errors
/// The cluster's store unavailable.
pub async fn list(state: &AppState) -> Result<Vec<JobStatus>, JobError> {
    match state.cluster() {
        Some(cluster) => cluster.work().list().await,
        None => Ok(state.jobs().list()),
    }
}

/// Cancels a queued or running job: no chunk of it starts after this returns.
///
/// # Errors
/// [`JobError::NoJob`], [`JobError::Ended`], the cluster's store unavailable.
pub async fn cancel(state: &AppState, id: &str) -> Result<JobStatus, JobError> {
    match state.cluster() {
        Some(cluster) => {
            let status = cluster
                .work()
                .cancel(id, state.jobs().settings().ttl)
                .await?;
            state.metrics().jobs_cancelled.inc();
            Ok(status)
        }
        None => state.jobs().cancel(id),
    }
}

/// A done job's result: its topology message, then every frame in order.
///
/// # Errors
/// [`JobError::NoJob`], [`JobError::NotDone`], [`JobError::Expired`].
pub async fn result(
    state: &AppState,
    id: &str,
) -> Result<BoxStream<'static, Result<v1::MeshFrame, JobError>>, JobError> {
    match state.cluster() {
        Some(cluster) => cluster.work().result(id).await,
        None => Ok(Box::pin(state.jobs().result(id)?.messages())),
    }
}

/// Runs `job`'s chunks in order, ending it done, failed or cancelled (without a cluster).
async fn run(state: &Weak<AppState>, dir: &Path, job: &Arc<Job>) {
    let Some(ttl) = state.upgrade().map(|s| s.jobs().settings().ttl) else {
        return;
    };
    if job.has_ended() {
        // Cancelled while queued (`Jobs::cancel` ended it).
        if let Some(state) = state.upgrade() {
            state.metrics().jobs_cancelled.inc();
        }
        return;
    }
    let started = Instant::now();
    for (c, frames) in job.take_chunks().into_iter().enumerate() {
        let Some(state) = state.upgrade() else { return };
        if job.is_cancelled() {
            state.metrics().jobs_cancelled.inc();
            job.end(JobState::Cancelled, "cancelled by CancelJob".into(), ttl);
            return;
        }
        let count = frames.len() as u64;
        let chunk_started = Instant::now();
        let stored = match synthesize(&state, job.plan(), frames).await {
            Ok((topology, bytes)) => {
                let (job, dir) = (Arc::clone(job), dir.to_owned());
                tokio::task::spawn_blocking(move || {
                    let topology = topology.filter(|_| c == 0);
                    job.store_chunk(&dir, c as u32, topology.as_ref(), &bytes)
                })
                .await
                .map_err(|e| e.to_string())
                .and_then(|r| r.map_err(|e| e.to_string()))
            }
            Err(e) => Err(e),
        };
        if let Err(e) = stored {
            state.metrics().jobs_failed.inc();
            job.end(JobState::Failed, format!("chunk {c}: {e}"), ttl);
            return;
        }
        state
            .metrics()
            .job_chunk_seconds
            .observe(chunk_started.elapsed().as_secs_f64());
        job.chunk_done(count, started.elapsed().as_secs_f64());
    }
    if let Some(state) = state.upgrade() {
        state.metrics().jobs_done.inc();
    }
    job.end(JobState::Done, String::new(), ttl);
}

/// One chunk: a fresh batch room on `plan`'s model, its frames encoded as `Synthesize` sends
/// them. Returns the stream's topology message and the frames, each length-delimited.
///
/// # Errors
/// The model gone (named), a frame refused (named by its index in the job), an encoding
/// failure.
pub async fn synthesize(
    state: &Arc<AppState>,
    plan: &JobPlan,
    frames: Vec<v1::ControlFrame>,
) -> Result<(Option<v1::MeshFrame>, Vec<u8>), String> {
    let room = state
        .batch_room(&plan.model, plan.options)
        .await
        .map_err(|e| e.to_string())?;
    let first_seq = frames.first().map_or(0, |f| f.seq);
    let mut stream = std::pin::pin!(crate::stream::batch(
        Arc::clone(state),
        room,
        Channel::new(plan.level, plan.encoding),
        frames
    ));
    let mut topology = None;
    let mut bytes = Vec::new();
    while let Some(message) = stream.next().await {
        let message = message.map_err(|e| match e {
            StreamError::Batch { index, error } => {
                format!("frame {}: {error}", first_seq + index as u64)
            }
            other => other.to_string(),
        })?;
        if topology.is_none() {
            topology = Some(message);
            continue;
        }
        message
            .encode_length_delimited(&mut bytes)
            .map_err(|e| e.to_string())?;
    }
    Ok((topology, bytes))
}

/// How often the cluster's worker looks for expired results.
const EXPIRY_SWEEP: Duration = Duration::from_secs(30);

/// Starts this replica's part of the cluster's jobs (module docs): the worker that pulls
/// chunks, and the sweep that deletes expired results. Call once, after joining the cluster.
pub fn start_cluster_worker(state: &Arc<AppState>) {
    let Some(cluster) = state.cluster().cloned() else {
        return;
    };
    let weak = Arc::downgrade(state);
    tokio::spawn(cluster_worker(weak.clone(), Arc::clone(&cluster)));
    tokio::spawn(async move {
        loop {
            tokio::time::sleep(EXPIRY_SWEEP).await;
            let Some(state) = weak.upgrade() else { return };
            if cluster.is_connected()
                && let Some(all) = cluster.work().expire().await
            {
                state.metrics().count_jobs(&all);
            }
        }
    });
}

/// The rooms that took frames since the last look (the worker's live load).
#[derive(Default)]
struct LiveLoad {
    seen: std::collections::HashMap<String, u64>,
}

impl LiveLoad {
    /// How many rooms took frames since the last call, given each room's frames accepted so
    /// far (`AppState::published_counts`): a room is live when its count moved; a room new
    /// since the last look counts from the next one.
    fn rooms(&mut self, now: impl IntoIterator<Item = (String, u64)>) -> u32 {
        let now: std::collections::HashMap<String, u64> = now.into_iter().collect();
        let live = now
            .iter()
            .filter(|(id, published)| self.seen.get(*id).is_some_and(|b| b != *published))
            .count();
        self.seen = now;
        u32::try_from(live).unwrap_or(u32::MAX)
    }
}

/// Live rooms first (issue 45): after a chunk that took `chunk`, a replica with `live` rooms
/// taking frames waits `chunk` times their number (at most 4) before pulling the next, so it
/// spends at most 1/(1 + live) of its time on jobs while it serves rooms, and idle replicas
/// take the queue.
fn pause_after(chunk: Duration, live: u32) -> Duration {
    chunk * live.min(4)
}

async fn cluster_worker(state: Weak<AppState>, cluster: Arc<Cluster>) {
    let mut live = LiveLoad::default();
    loop {
        let busy = match state.upgrade() {
            Some(s) => live.rooms(s.published_counts()),
            None => return,
        };
        if !cluster.is_connected() {
            tokio::time::sleep(Duration::from_secs(1)).await;
            continue;
        }
        let Some(pulled) = cluster.work().next(&cluster.metrics).await else {
            continue;
        };
        let started = Instant::now();
        run_pulled(&state, &cluster, pulled).await;
        let pause = pause_after(started.elapsed(), busy);
        if !pause.is_zero() {
            tokio::time::sleep(pause).await;
        }
    }
}

/// One pulled chunk (module docs): skipped when its job has ended or it was counted, run
/// unless its result is stored (a redelivery after the store), counted, acked. Left unacked
/// (so redelivered) only when the store or the record cannot be reached.
async fn run_pulled(state: &Weak<AppState>, cluster: &Arc<Cluster>, mut pulled: Pulled) {
    let work = cluster.work();
    let (job, c) = (pulled.chunk.job.clone(), pulled.chunk.chunk);
    let Some(state) = state.upgrade() else { return };
    if pulled.redelivered {
        cluster.metrics.job_redeliveries.inc();
        tracing::info!(%job, chunk = c, "a chunk redelivered (its first replica did not ack it)");
    }
    let ttl = state.jobs().settings().ttl;
    let record = match work.record(&job).await {
        Ok((r, _)) => r,
        Err(JobError::NoJob(_)) => {
            tracing::warn!(%job, chunk = c, "a chunk of no known job: dropped");
            work.ack(pulled).await;
            return;
        }
        Err(e) => {
            tracing::warn!(%job, chunk = c, "reading the job's record: {e}");
            return;
        }
    };
    if status_of(&record).state.ended() || is_done(&record.done, c) {
        work.ack(pulled).await;
        return;
    }
    let frames = pulled.chunk.frames.len() as u64;
    let began = now_us();
    if !work.has_result(&job, c).await {
        let chunk_started = Instant::now();
        let chunk_frames = std::mem::take(&mut pulled.chunk.frames);
        let outcome = async {
            let plan = record
                .spec
                .as_ref()
                .ok_or_else(|| "the job's record has no spec".to_owned())
                .and_then(|s| JobPlan::from_spec(s).map_err(|e| e.to_string()))?;
            crate::cluster::models::ensure(
                state.models(),
                cluster,
                &plan.model,
                &record.model_sha256,
            )
            .await?;
            synthesize(&state, &plan, chunk_frames).await
        };
        // Runs the chunk, telling the queue it is alive every third of its ack_wait.
        let mut outcome = std::pin::pin!(outcome);
        let mut alive = tokio::time::interval(work.ack_wait() / 3);
        alive.tick().await;
        let outcome = loop {
            tokio::select! {
                out = &mut outcome => break out,
                _ = alive.tick() => work.in_progress(&pulled).await,
            }
        };
        let stored = match outcome {
            Ok((topology, bytes)) => {
                let topology = topology.filter(|_| c == 0);
                work.store(&job, c, topology.as_ref(), &bytes)
                    .await
                    .map_err(|e| e.to_string())
            }
            Err(e) => Err(e),
        };
        if let Err(e) = stored {
            state.metrics().jobs_failed.inc();
            tracing::warn!(%job, chunk = c, "the job failed: {e}");
            work.fail(&job, format!("chunk {c}: {e}"), ttl).await;
            work.ack(pulled).await;
            return;
        }
        cluster.metrics.job_chunks.inc();
        state
            .metrics()
            .job_chunk_seconds
            .observe(chunk_started.elapsed().as_secs_f64());
    }
    match work
        .update(&job, |r| count_chunk(r, c, frames, began, now_us(), ttl))
        .await
    {
        Ok((r, changed)) => {
            if changed && status_of(&r).state == JobState::Done {
                state.metrics().jobs_done.inc();
                tracing::info!(%job, "job done");
            }
            work.ack(pulled).await;
        }
        Err(e) => {
            tracing::warn!(%job, chunk = c, "counting the chunk (it will be redelivered): {e}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(c: &[(&str, u64)]) -> Vec<(String, u64)> {
        c.iter().map(|(id, n)| ((*id).to_owned(), *n)).collect()
    }

    #[test]
    fn a_room_is_live_when_its_frames_move() {
        let mut load = LiveLoad::default();
        assert_eq!(load.rooms(counts(&[("a", 5), ("b", 0)])), 0, "first look");
        assert_eq!(load.rooms(counts(&[("a", 9), ("b", 0)])), 1);
        assert_eq!(
            load.rooms(counts(&[("a", 9), ("b", 3), ("c", 1)])),
            1,
            "c is new"
        );
        assert_eq!(load.rooms(counts(&[("a", 10), ("b", 4), ("c", 2)])), 3);
        assert_eq!(
            load.rooms(counts(&[("b", 4)])),
            0,
            "closed rooms and idle ones"
        );
    }

    #[test]
    fn a_replica_serving_rooms_takes_fewer_chunks() {
        let chunk = Duration::from_millis(300);
        assert_eq!(
            pause_after(chunk, 0),
            Duration::ZERO,
            "idle: the next chunk at once"
        );
        assert_eq!(
            pause_after(chunk, 1),
            chunk,
            "one live room: half its time on jobs"
        );
        assert_eq!(pause_after(chunk, 3), chunk * 3);
        assert_eq!(pause_after(chunk, 40), chunk * 4, "never less than a fifth");
    }
}
