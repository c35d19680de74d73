//! Batch jobs' worker (issue 45, without a cluster): queues a checked job in the store
//! ([`crate::jobs`]) and runs the queue, one job after another, each chunk a fresh batch
//! through `Synthesize`'s path (`AppState::batch_room`, `crate::stream::batch`), its encoded
//! frames stored before the chunk counts as done. Cancelling is seen between chunks.

use std::path::Path;
use std::sync::{Arc, Weak};
use std::time::Instant;

use crease_proto::job::{JobState, JobStatus};
use crease_proto::v1;
use prost::Message;
use tokio_stream::StreamExt;

use crate::jobs::{Job, JobError, JobPlan};
use crate::state::AppState;
use crate::stream::StreamError;

/// Queues a job of `chunks` running `plan` on `state`'s store, starting the worker with the
/// first job, and returns its status.
///
/// # Errors
/// The store's refusal ([`JobError`]).
pub fn submit(
    state: &Arc<AppState>,
    plan: JobPlan,
    chunks: Vec<Vec<v1::ControlFrame>>,
) -> Result<JobStatus, JobError> {
    let status = state.jobs().enqueue(plan, chunks)?;
    state.metrics().jobs_submitted.inc();
    if let Some(mut queue) = state.jobs().take_queue() {
        let dir = state.jobs().dir()?;
        let state = Arc::downgrade(state);
        tokio::spawn(async move {
            while let Some(job) = queue.recv().await {
                run(&state, &dir, &job).await;
            }
        });
    }
    Ok(status)
}

/// Runs `job`'s chunks in order, ending it done, failed or cancelled.
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
        if let Err(e) = run_chunk(&state, job, dir, c as u32, frames).await {
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

/// One chunk: a fresh batch room, its frames encoded as `Synthesize` sends them, stored.
async fn run_chunk(
    state: &Arc<AppState>,
    job: &Arc<Job>,
    dir: &Path,
    chunk: u32,
    frames: Vec<v1::ControlFrame>,
) -> Result<(), String> {
    let plan = job.plan();
    let room = state
        .batch_room(&plan.model, plan.options)
        .await
        .map_err(|e| e.to_string())?;
    let first_seq = frames.first().map_or(0, |f| f.seq);
    let mut stream = std::pin::pin!(crate::stream::batch(
        Arc::clone(state),
        room,
        plan.level,
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
    let (job, dir) = (Arc::clone(job), dir.to_owned());
    tokio::task::spawn_blocking(move || {
        let topology = topology.filter(|_| chunk == 0);
        job.store_chunk(&dir, chunk, topology.as_ref(), &bytes)
    })
    .await
    .map_err(|e| e.to_string())?
    .map_err(|e| e.to_string())
}
