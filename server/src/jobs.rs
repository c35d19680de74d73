//! Batch jobs in this process (issue 45, without a cluster), the store: a job's chunks (cut by
//! [`crease_proto::job::chunk_frames`], each carrying the held state at its start) wait in a
//! bounded queue that `crate::job_service`'s one worker drains, running each chunk as a fresh
//! batch through the same path as `Synthesize` and storing its encoded frames here
//! ([`Job::store_chunk`]) before the chunk counts as done. A job's status is a watch channel
//! (`WatchJob`); its result is read back from the folder chunk by chunk (`GetJobResult`) until
//! it expires. Nothing here runs a prediction: the store sits below the state that owns it.
//!
//! Folder layout, `DIR/<job id>/`: `topology.bin` (the stream's first `MeshFrame`, encoded) and
//! `chunk-<nnnnn>.frames` (the chunk's `MeshFrame`s, each length-delimited), each written to a
//! temporary name and renamed, so a chunk file is whole or absent.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use crease_proto::job::{JobState, JobStatus, new_job_id};
use crease_proto::v1;
use prost::Message;
use tokio::sync::{mpsc, watch};

pub use crate::config::JobSettings;
pub use crease_proto::job::JobPlan;

/// Why a job call was refused; each transport maps it once (`crate::status`).
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    /// No job of that id (or never one).
    #[error("job: no job {0:?}")]
    NoJob(String),
    /// The job has not ended well: its result cannot be read.
    #[error("job {job:?} is {state}: {why}")]
    NotDone {
        /// The job.
        job: String,
        /// Its state.
        state: &'static str,
        /// What the caller can do.
        why: String,
    },
    /// The job's result was deleted.
    #[error("job {0:?}: its result expired (results are kept --job-ttl after the job ends)")]
    Expired(String),
    /// The job has ended: nothing to cancel.
    #[error("job {job:?} already ended ({state}): nothing to cancel")]
    Ended {
        /// The job.
        job: String,
        /// Its state.
        state: &'static str,
    },
    /// The queue is full or the job too long.
    #[error("{0}")]
    Full(String),
    /// The jobs' store failed: the jobs folder, or in a cluster its bucket, object store or
    /// queue (`crate::cluster::work`).
    #[error("job store {path}: {message}")]
    Io {
        /// The file or folder, or the cluster's store (in parentheses).
        path: String,
        /// The failure.
        message: String,
    },
}

/// One job: its plan, the chunks not yet run, its status.
#[derive(Debug)]
pub struct Job {
    id: String,
    plan: JobPlan,
    /// The chunks not yet run (taken by the worker).
    chunks: Mutex<Vec<Vec<v1::ControlFrame>>>,
    status: watch::Sender<JobStatus>,
    cancelled: AtomicBool,
    /// The result was deleted.
    expired: AtomicBool,
}

/// The jobs of this server (module docs).
#[derive(Debug)]
pub struct Jobs {
    settings: JobSettings,
    /// The folder in use, and the temporary folder it is, when no `dir` was given.
    dir: Result<PathBuf, String>,
    _temporary: Option<tempfile::TempDir>,
    table: Mutex<BTreeMap<String, Arc<Job>>>,
    queue: mpsc::Sender<Arc<Job>>,
    /// The queue's receiving end until the worker takes it ([`Jobs::take_queue`]).
    worker: Mutex<Option<mpsc::Receiver<Arc<Job>>>>,
}

impl Job {
    /// Its id.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// What it runs.
    pub fn plan(&self) -> &JobPlan {
        &self.plan
    }

    /// Its chunks, taken once (by the worker).
    pub fn take_chunks(&self) -> Vec<Vec<v1::ControlFrame>> {
        std::mem::take(
            &mut *self
                .chunks
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner),
        )
    }

    /// Whether `CancelJob` asked it to stop.
    pub fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::SeqCst)
    }

    /// Whether it has ended.
    pub fn has_ended(&self) -> bool {
        self.status.borrow().state.ended()
    }

    /// Stores chunk `chunk`'s encoded frames (and, with the first chunk, the stream's
    /// topology) under `dir` (the jobs folder), whole or not at all. Blocking: call it off
    /// the executor.
    ///
    /// # Errors
    /// The file that could not be written.
    pub fn store_chunk(
        &self,
        dir: &Path,
        chunk: u32,
        topology: Option<&v1::MeshFrame>,
        frames: &[u8],
    ) -> Result<(), JobError> {
        let job_dir = dir.join(&self.id);
        if let Some(t) = topology {
            write_atomically(&job_dir.join("topology.bin"), &t.encode_to_vec())?;
        }
        write_atomically(&chunk_path(&job_dir, chunk), frames)
    }

    /// Counts a stored chunk of `frames` frames, `secs` after the job's first chunk began.
    pub fn chunk_done(&self, frames: u64, secs: f64) {
        self.status.send_modify(|s| {
            s.state = JobState::Running;
            s.chunks_done += 1;
            s.frames_done += frames;
            s.frames_per_second = s.frames_done as f64 / secs.max(1e-9);
            s.eta_seconds = (s.frames_total - s.frames_done) as f64 / s.frames_per_second;
        });
    }

    /// Ends it in `state` (with `error` for a failure or a cancel) unless it has ended; its
    /// result expires `ttl` later.
    pub fn end(&self, state: JobState, error: String, ttl: Duration) {
        self.status.send_if_modified(|s| {
            if s.state.ended() {
                return false;
            }
            let now = now_us();
            s.state = state;
            s.error = error;
            s.finished_us = now;
            s.expires_us = now.saturating_add(ttl.as_micros().min(i64::MAX as u128) as i64);
            s.eta_seconds = 0.0;
            true
        });
    }
}

/// Microseconds since the Unix epoch.
fn now_us() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

fn io_error(path: &Path) -> impl Fn(std::io::Error) -> JobError + '_ {
    move |e| JobError::Io {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

impl Jobs {
    /// The jobs of a server with `settings`; the folder is created here (an unusable one
    /// refuses every submit, naming why).
    pub fn new(settings: JobSettings) -> Jobs {
        let (dir, temporary) = match &settings.dir {
            Some(dir) => (
                std::fs::create_dir_all(dir)
                    .map(|()| dir.clone())
                    .map_err(|e| format!("{}: {e}", dir.display())),
                None,
            ),
            None => match tempfile::Builder::new().prefix("crease-jobs-").tempdir() {
                Ok(t) => (Ok(t.path().to_owned()), Some(t)),
                Err(e) => (Err(format!("a temporary jobs folder: {e}")), None),
            },
        };
        let (queue, worker) = mpsc::channel(settings.max_queued.max(1));
        Jobs {
            settings,
            dir,
            _temporary: temporary,
            table: Mutex::new(BTreeMap::new()),
            queue,
            worker: Mutex::new(Some(worker)),
        }
    }

    /// The settings.
    pub fn settings(&self) -> &JobSettings {
        &self.settings
    }

    fn table(&self) -> std::sync::MutexGuard<'_, BTreeMap<String, Arc<Job>>> {
        self.table
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn job(&self, id: &str) -> Result<Arc<Job>, JobError> {
        self.expire();
        self.table()
            .get(id)
            .cloned()
            .ok_or_else(|| JobError::NoJob(id.to_owned()))
    }

    /// The folder results are stored in.
    ///
    /// # Errors
    /// [`JobError::Io`]: the folder could not be made.
    pub fn dir(&self) -> Result<PathBuf, JobError> {
        self.dir.clone().map_err(|message| JobError::Io {
            path: "(jobs)".into(),
            message,
        })
    }

    /// The queue's receiving end, once: the worker's (`crate::job_service`).
    pub fn take_queue(&self) -> Option<mpsc::Receiver<Arc<Job>>> {
        self.worker
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
    }

    /// Queues a job of `chunks` (checked frames, [`crease_proto::job::chunk_frames`]; the
    /// frame cap checked where they were read, `crate::grpc`) running `plan` and returns its
    /// status; the worker must be running (`crate::job_service`).
    ///
    /// # Errors
    /// [`JobError::Full`] (the queue), [`JobError::Io`] (the folder).
    pub fn enqueue(
        &self,
        plan: JobPlan,
        chunks: Vec<Vec<v1::ControlFrame>>,
    ) -> Result<JobStatus, JobError> {
        let dir = self.dir()?;
        let frames: usize = chunks.iter().map(Vec::len).sum();
        let id = new_job_id(rand::random());
        let job_dir = dir.join(&id);
        std::fs::create_dir_all(&job_dir).map_err(io_error(&job_dir))?;
        let status = queued_status(id.clone(), &plan, frames as u64, chunks.len() as u32);
        let job = Arc::new(Job {
            id: id.clone(),
            plan,
            chunks: Mutex::new(chunks),
            status: watch::channel(status.clone()).0,
            cancelled: AtomicBool::new(false),
            expired: AtomicBool::new(false),
        });
        if let Err(e) = self.queue.try_send(Arc::clone(&job)) {
            let _ = std::fs::remove_dir_all(&job_dir);
            return Err(JobError::Full(match e {
                mpsc::error::TrySendError::Full(_) => format!(
                    "the job queue is full ({} jobs queued or running, --max-queued-jobs): try again when one ends",
                    self.settings.max_queued
                ),
                mpsc::error::TrySendError::Closed(_) => "the server is shutting down".into(),
            }));
        }
        self.table().insert(id, job);
        Ok(status)
    }

    /// A job's status now, and a receiver of its changes.
    ///
    /// # Errors
    /// [`JobError::NoJob`].
    pub fn watch(&self, id: &str) -> Result<watch::Receiver<JobStatus>, JobError> {
        Ok(self.job(id)?.status.subscribe())
    }

    /// Every job's status, newest first.
    pub fn list(&self) -> Vec<JobStatus> {
        self.expire();
        let mut all: Vec<JobStatus> = self
            .table()
            .values()
            .map(|j| j.status.borrow().clone())
            .collect();
        all.sort_by_key(|s| std::cmp::Reverse(s.submitted_us));
        all
    }

    /// Cancels a queued or running job: no chunk of it starts after this returns.
    ///
    /// # Errors
    /// [`JobError::NoJob`], [`JobError::Ended`].
    pub fn cancel(&self, id: &str) -> Result<JobStatus, JobError> {
        let job = self.job(id)?;
        let state = job.status.borrow().state;
        if state.ended() {
            return Err(JobError::Ended {
                job: id.to_owned(),
                state: state.as_str(),
            });
        }
        job.cancelled.store(true, Ordering::SeqCst);
        // The worker checks the flag before each chunk and ends the job; a queued job ends
        // here so that watchers learn at once.
        if state == JobState::Queued {
            job.end(
                JobState::Cancelled,
                "cancelled by CancelJob".into(),
                self.settings.ttl,
            );
        }
        Ok(job.status.borrow().clone())
    }

    /// A done job's result: its topology message and its chunk files, in order.
    ///
    /// # Errors
    /// [`JobError::NoJob`], [`JobError::NotDone`], [`JobError::Expired`].
    pub fn result(&self, id: &str) -> Result<JobResult, JobError> {
        let job = self.job(id)?;
        if job.expired.load(Ordering::SeqCst) {
            return Err(JobError::Expired(id.to_owned()));
        }
        let status = job.status.borrow().clone();
        check_done(&status)?;
        let job_dir = self.dir()?.join(&job.id);
        Ok(JobResult {
            topology: job_dir.join("topology.bin"),
            chunks: (0..status.chunks_total)
                .map(|c| chunk_path(&job_dir, c))
                .collect(),
        })
    }

    /// Deletes the results of ended jobs past their expiry (the job stays listed, expired).
    fn expire(&self) {
        let now = now_us();
        let Ok(dir) = &self.dir else { return };
        for job in self.table().values() {
            let s = job.status.borrow();
            if s.state.ended()
                && s.expires_us != 0
                && s.expires_us <= now
                && !job.expired.swap(true, Ordering::SeqCst)
            {
                let _ = std::fs::remove_dir_all(dir.join(&job.id));
            }
        }
    }
}

/// The status of job `id` as it is queued: `frames` frames of `plan` in `chunks` chunks,
/// submitted now.
pub fn queued_status(id: String, plan: &JobPlan, frames: u64, chunks: u32) -> JobStatus {
    JobStatus {
        job: id,
        name: plan.name.clone(),
        model: plan.model.clone(),
        level: plan.level,
        state: JobState::Queued,
        frames_total: frames,
        frames_done: 0,
        chunks_total: chunks,
        chunks_done: 0,
        frames_per_second: 0.0,
        eta_seconds: 0.0,
        error: String::new(),
        submitted_us: now_us(),
        finished_us: 0,
        expires_us: 0,
        encoding: plan.encoding,
    }
}

/// Whether a job's result can be read: it is done (else [`JobError::NotDone`], saying why).
///
/// # Errors
/// [`JobError::NotDone`].
pub fn check_done(status: &JobStatus) -> Result<(), JobError> {
    if status.state == JobState::Done {
        return Ok(());
    }
    Err(JobError::NotDone {
        job: status.job.clone(),
        state: status.state.as_str(),
        why: match status.state {
            JobState::Failed => format!("it failed: {}", status.error),
            JobState::Cancelled => "it was cancelled: it has no result".into(),
            _ => format!(
                "{} of {} frames done: wait for it (crease job watch)",
                status.frames_done, status.frames_total
            ),
        },
    })
}

/// Where a done job's result lies ([`Jobs::result`]).
#[derive(Clone, Debug)]
pub struct JobResult {
    /// The encoded topology message.
    pub topology: PathBuf,
    /// The chunk files, in order.
    pub chunks: Vec<PathBuf>,
}

impl JobResult {
    /// The result as the messages `GetJobResult` streams: the topology, then every frame.
    pub fn messages(
        self,
    ) -> impl tokio_stream::Stream<Item = Result<v1::MeshFrame, JobError>> + Send + 'static {
        let (tx, rx) = mpsc::channel(64);
        tokio::spawn(async move {
            let files = std::iter::once((self.topology, false))
                .chain(self.chunks.into_iter().map(|c| (c, true)));
            for (path, delimited) in files {
                let read = tokio::task::spawn_blocking(move || read_messages(&path, delimited))
                    .await
                    .unwrap_or_else(|e| {
                        Err(JobError::Io {
                            path: "(reader)".into(),
                            message: e.to_string(),
                        })
                    });
                match read {
                    Ok(messages) => {
                        for m in messages {
                            if tx.send(Ok(m)).await.is_err() {
                                return;
                            }
                        }
                    }
                    Err(e) => {
                        let _ = tx.send(Err(e)).await;
                        return;
                    }
                }
            }
        });
        tokio_stream::wrappers::ReceiverStream::new(rx)
    }
}

/// The messages of a result file: one, or length-delimited ones.
fn read_messages(path: &Path, delimited: bool) -> Result<Vec<v1::MeshFrame>, JobError> {
    let bytes = std::fs::read(path).map_err(io_error(path))?;
    decode_messages(&bytes, delimited).map_err(|e| JobError::Io {
        path: path.display().to_string(),
        message: format!("not a result file: {e}"),
    })
}

/// The messages of a stored result: one (the topology), or length-delimited ones (a chunk).
///
/// # Errors
/// Bytes that are not such messages.
pub fn decode_messages(
    mut bytes: &[u8],
    delimited: bool,
) -> Result<Vec<v1::MeshFrame>, prost::DecodeError> {
    if !delimited {
        return v1::MeshFrame::decode(bytes).map(|m| vec![m]);
    }
    let mut out = Vec::new();
    while !bytes.is_empty() {
        out.push(v1::MeshFrame::decode_length_delimited(&mut bytes)?);
    }
    Ok(out)
}

fn chunk_path(job_dir: &Path, chunk: u32) -> PathBuf {
    job_dir.join(format!("chunk-{chunk:05}.frames"))
}

/// Writes `bytes` to `path` whole or not at all (a temporary name, then a rename).
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), JobError> {
    let tmp = path.with_extension("partial");
    std::fs::write(&tmp, bytes).map_err(io_error(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io_error(path))
}
