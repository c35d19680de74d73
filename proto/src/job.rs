//! Batch jobs on the wire (issue 45): a job's control frames checked and cut into chunks that
//! each carry the held state at their start ([`chunk_frames`]), and a job's status as the
//! `JobInfo` clients watch ([`JobStatus`]).
//!
//! A chunk runs as a fresh batch (its own predictor context, every control point at rest),
//! while one long batch holds an occluded point at its last valid position from frame to
//! frame. So the first frame of every chunk after the first carries, for each point it
//! occludes, that point's last valid position marked valid: the chunk's held state then
//! equals the long batch's (the predictor keeps no other state between frames), and a chunked
//! job equals a local `crease synth` frame for frame, as `crease synth --server` does across
//! its requests.

use crease_core::glam::Vec3;

use crate::control::{control_frame, read_control_frame};
use crate::convert::{Encoding, Level, skinning_from_wire};
use crate::errors::WireError;
use crate::room::{RoomOptions, refine_wire, refinement};
use crate::v1;
use std::time::Duration;

/// What a job runs: the model, the level and the batch options, resolved where it was
/// submitted (the server's refinement default applied), and its label.
#[derive(Clone, Debug, PartialEq)]
pub struct JobPlan {
    /// The model's name.
    pub model: String,
    /// The level synthesised.
    pub level: Level,
    /// Beta, refinement, skinning (no filter: a batch).
    pub options: RoomOptions,
    /// The job's label.
    pub name: String,
    /// How its result's frames travel: every vertex, or the palette (the bone transforms).
    pub encoding: Encoding,
}

impl JobPlan {
    /// The plan as a resolved `JobSpec` (a cluster's `JobRecord.spec`): the refinement always
    /// set (`iterations = 0` for off), so that [`JobPlan::from_spec`] on another replica reads
    /// it back whatever that replica's default.
    pub fn to_spec(&self) -> v1::JobSpec {
        v1::JobSpec {
            model: self.model.clone(),
            level: match self.level {
                Level::Base => v1::Level::Base,
                Level::Detail => v1::Level::Detail,
            } as i32,
            beta: self.options.beta.unwrap_or(0.0),
            refine: Some(refine_wire(self.options.refine)),
            skinning: self
                .options
                .skinning
                .map_or(v1::Skinning::Unspecified, v1::Skinning::from) as i32,
            take: String::new(),
            name: self.name.clone(),
            encoding: v1::Encoding::from(self.encoding) as i32,
            // Retargeted at submit: the job's frames are control points.
            retarget: None,
        }
    }

    /// The plan of a resolved spec ([`JobPlan::to_spec`]).
    ///
    /// # Errors
    /// A field that is not a level, a skinning or a valid refinement, named in `JobSpec`.
    pub fn from_spec(spec: &v1::JobSpec) -> Result<JobPlan, WireError> {
        let refine = refinement(spec.refine, None)
            .map_err(|e| WireError::new("JobSpec", "refine", e.to_string()))?;
        Ok(JobPlan {
            model: spec.model.clone(),
            level: Level::from_wire("JobSpec", spec.level)?,
            options: RoomOptions {
                beta: (spec.beta != 0.0).then_some(spec.beta),
                filter: None,
                refine,
                skinning: skinning_from_wire("JobSpec", spec.skinning)?,
            },
            name: spec.name.clone(),
            encoding: Encoding::from_wire("JobSpec", spec.encoding)?,
        })
    }
}

/// Characters of a job id ([`new_job_id`]).
pub const JOB_ID_LEN: usize = 12;

/// A fresh job id: [`JOB_ID_LEN`] characters of `[a-z0-9]` from `random` (any source of
/// random bytes; the server's is the OS's).
pub fn new_job_id(random: [u8; JOB_ID_LEN]) -> String {
    const ALPHABET: &[u8; 36] = b"abcdefghijklmnopqrstuvwxyz0123456789";
    random
        .iter()
        .map(|b| ALPHABET[*b as usize % ALPHABET.len()] as char)
        .collect()
}

/// Whether `id` has the form of a job id (so it is also a plain file name).
pub fn is_job_id(id: &str) -> bool {
    id.len() == JOB_ID_LEN
        && id
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit())
}

/// A frame of a job that does not fit its model: its index over the whole job and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("SubmitJob.frames[{index}].{}: {}", .error.field, .error.message)]
pub struct JobFrameError {
    /// The frame's index in the job (from 0).
    pub index: usize,
    /// What is wrong with it.
    pub error: WireError,
}

/// Checks a job's `frames` against a model of `count` control points and cuts them into chunks
/// of at most `chunk` frames (`chunk` >= 1), each frame numbered by its index in the job
/// (`seq`), each chunk's first frame carrying the points it occludes at their last valid
/// position (module docs). A point never seen before stays occluded.
///
/// # Errors
/// The first frame that does not fit (point count, a non-finite valid point, the mask's
/// length, markers instead of points), by its index in the job.
pub fn chunk_frames(
    frames: &[v1::ControlFrame],
    count: usize,
    chunk: usize,
) -> Result<Vec<Vec<v1::ControlFrame>>, JobFrameError> {
    let chunk = chunk.max(1);
    let mut positions = vec![Vec3::ZERO; count];
    let mut valid = vec![false; count];
    let mut last_valid: Vec<Option<Vec3>> = vec![None; count];
    let (mut sent, mut sent_valid) = (vec![Vec3::ZERO; count], vec![false; count]);
    let mut chunks = Vec::with_capacity(frames.len().div_ceil(chunk));
    for (index, frame) in frames.iter().enumerate() {
        read_control_frame(frame, &mut positions, &mut valid)
            .map_err(|error| JobFrameError { index, error })?;
        let starts_chunk = index % chunk == 0;
        if starts_chunk {
            chunks.push(Vec::with_capacity(chunk.min(frames.len() - index)));
        }
        sent.copy_from_slice(&positions);
        sent_valid.copy_from_slice(&valid);
        for i in 0..count {
            if valid[i] {
                last_valid[i] = Some(positions[i]);
            } else if starts_chunk && let Some(held) = last_valid[i] {
                sent[i] = held;
                sent_valid[i] = true;
            }
        }
        if let Some(last) = chunks.last_mut() {
            last.push(control_frame(
                "",
                index as u64,
                frame.capture_time_us,
                &sent,
                &sent_valid,
            ));
        }
    }
    Ok(chunks)
}

/// A cluster's record of a job just queued (`JobRecord`, cluster.proto): its status, its plan
/// resolved ([`JobPlan::to_spec`]), its model's digest, no chunk counted.
pub fn job_record(status: &JobStatus, plan: &JobPlan, model_sha256: &str) -> v1::JobRecord {
    v1::JobRecord {
        info: Some(v1::JobInfo::from(status)),
        spec: Some(plan.to_spec()),
        model_sha256: model_sha256.to_owned(),
        done: Vec::new(),
        started_us: 0,
        expired: false,
        tag: Vec::new(),
    }
}

/// Chunk `chunk` of job `job` as the work queue carries it (`JobChunk`, cluster.proto).
pub fn job_chunk(job: &str, chunk: u32, frames: Vec<v1::ControlFrame>) -> v1::JobChunk {
    v1::JobChunk {
        job: job.to_owned(),
        chunk,
        frames,
    }
}

/// Whether bit `chunk` of `done` is set.
pub fn is_done(done: &[u8], chunk: u32) -> bool {
    done.get(chunk as usize / 8)
        .is_some_and(|b| b & (1 << (chunk % 8)) != 0)
}

fn set_done(done: &mut Vec<u8>, chunk: u32) {
    let byte = chunk as usize / 8;
    if done.len() <= byte {
        done.resize(byte + 1, 0);
    }
    done[byte] |= 1 << (chunk % 8);
}

/// Counts chunk `chunk` (stored) in a cluster's job record: the record's bitmap makes a
/// redelivered chunk count once (cluster.proto, `JobRecord.done`).
///
/// Counts chunk `chunk` of `frames` frames, begun at `began_us`, in `record` at `now` (µs):
/// the chunk's bit, the totals, the rate since the first chunk began and the time left; the
/// last chunk ends the job done, its result expiring `ttl` later. Returns false (nothing
/// changed) when the chunk was counted before or the job has ended.
pub fn count_chunk(
    record: &mut v1::JobRecord,
    chunk: u32,
    frames: u64,
    began_us: i64,
    now: i64,
    ttl: Duration,
) -> bool {
    let Some(info) = record.info.as_mut() else {
        return false;
    };
    if is_done(&record.done, chunk) || JobState::from_wire(info.state).ended() {
        return false;
    }
    set_done(&mut record.done, chunk);
    if record.started_us == 0 || began_us < record.started_us {
        record.started_us = began_us;
    }
    info.chunks_done += 1;
    info.frames_done += frames;
    let secs = (now - record.started_us).max(1) as f64 / 1e6;
    info.frames_per_second = info.frames_done as f64 / secs;
    info.eta_seconds =
        info.frames_total.saturating_sub(info.frames_done) as f64 / info.frames_per_second;
    info.state = v1::JobState::Running as i32;
    if info.chunks_done >= info.chunks_total {
        end_job(info, JobState::Done, String::new(), now, ttl);
    }
    true
}

/// Ends a cluster's job `info` in `state` at `now`, its result expiring `ttl` later.
pub fn end_job(info: &mut v1::JobInfo, state: JobState, error: String, now: i64, ttl: Duration) {
    info.state = v1::JobState::from(state) as i32;
    info.error = error;
    info.finished_us = now;
    info.expires_us = now.saturating_add(ttl.as_micros().min(i64::MAX as u128) as i64);
    info.eta_seconds = 0.0;
}

/// A job's state (`JobState`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum JobState {
    /// Accepted, no chunk done yet.
    #[default]
    Queued,
    /// Some chunks done.
    Running,
    /// Every chunk stored.
    Done,
    /// Failed; the status's `error` says why.
    Failed,
    /// Cancelled.
    Cancelled,
}

impl JobState {
    /// Whether the job has ended (done, failed or cancelled).
    pub fn ended(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }

    /// Its name as the CLI prints it.
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }

    /// The state of a wire `JobInfo.state` (unspecified reads as queued).
    pub fn from_wire(state: i32) -> JobState {
        match v1::JobState::try_from(state) {
            Ok(v1::JobState::Running) => JobState::Running,
            Ok(v1::JobState::Done) => JobState::Done,
            Ok(v1::JobState::Failed) => JobState::Failed,
            Ok(v1::JobState::Cancelled) => JobState::Cancelled,
            _ => JobState::Queued,
        }
    }
}

impl From<JobState> for v1::JobState {
    fn from(s: JobState) -> Self {
        match s {
            JobState::Queued => v1::JobState::Queued,
            JobState::Running => v1::JobState::Running,
            JobState::Done => v1::JobState::Done,
            JobState::Failed => v1::JobState::Failed,
            JobState::Cancelled => v1::JobState::Cancelled,
        }
    }
}

/// What `JobInfo` says about a job.
#[derive(Clone, Debug, PartialEq)]
pub struct JobStatus {
    /// The job's id.
    pub job: String,
    /// Its label.
    pub name: String,
    /// The model's name.
    pub model: String,
    /// The level synthesised.
    pub level: Level,
    /// Where it stands.
    pub state: JobState,
    /// Control frames in the job.
    pub frames_total: u64,
    /// Frames whose chunk is stored.
    pub frames_done: u64,
    /// Chunks in the job.
    pub chunks_total: u32,
    /// Chunks stored.
    pub chunks_done: u32,
    /// Frames per second since the first chunk started.
    pub frames_per_second: f64,
    /// Seconds left at that rate (0 when unknown or ended).
    pub eta_seconds: f64,
    /// Why it failed or was cancelled.
    pub error: String,
    /// When it was submitted (server clock, µs since the Unix epoch).
    pub submitted_us: i64,
    /// When it ended (0: not yet).
    pub finished_us: i64,
    /// When its result is deleted (0: not ended).
    pub expires_us: i64,
    /// How its result's frames travel.
    pub encoding: Encoding,
}

impl JobStatus {
    /// The status a `JobInfo` says (a cluster's record).
    pub fn from_wire(info: &v1::JobInfo) -> JobStatus {
        JobStatus {
            job: info.job.clone(),
            name: info.name.clone(),
            model: info.model.clone(),
            level: Level::from_wire("JobInfo", info.level).unwrap_or(Level::Base),
            state: JobState::from_wire(info.state),
            frames_total: info.frames_total,
            frames_done: info.frames_done,
            chunks_total: info.chunks_total,
            chunks_done: info.chunks_done,
            frames_per_second: info.frames_per_second,
            eta_seconds: info.eta_seconds,
            error: info.error.clone(),
            submitted_us: info.submitted_us,
            finished_us: info.finished_us,
            expires_us: info.expires_us,
            encoding: Encoding::from_wire("JobInfo", info.encoding).unwrap_or_default(),
        }
    }
}

impl From<&JobStatus> for v1::JobInfo {
    fn from(s: &JobStatus) -> Self {
        v1::JobInfo {
            job: s.job.clone(),
            name: s.name.clone(),
            model: s.model.clone(),
            level: match s.level {
                Level::Base => v1::Level::Base,
                Level::Detail => v1::Level::Detail,
            } as i32,
            state: v1::JobState::from(s.state) as i32,
            frames_total: s.frames_total,
            frames_done: s.frames_done,
            chunks_total: s.chunks_total,
            chunks_done: s.chunks_done,
            frames_per_second: s.frames_per_second,
            eta_seconds: s.eta_seconds,
            error: s.error.clone(),
            submitted_us: s.submitted_us,
            finished_us: s.finished_us,
            expires_us: s.expires_us,
            encoding: v1::Encoding::from(s.encoding) as i32,
        }
    }
}

/// The settings of a job's spec as a batch asks for them (`SynthesizeRequest` without the
/// frames), for the server's batch path.
pub fn spec_as_batch(spec: &v1::JobSpec) -> v1::SynthesizeRequest {
    v1::SynthesizeRequest {
        model: spec.model.clone(),
        level: spec.level,
        beta: spec.beta,
        frames: Vec::new(),
        refine: spec.refine,
        skinning: spec.skinning,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn frame(points: &[Option<[f32; 3]>]) -> v1::ControlFrame {
        let positions: Vec<Vec3> = points
            .iter()
            .map(|p| p.map_or(Vec3::ZERO, Vec3::from_array))
            .collect();
        let valid: Vec<bool> = points.iter().map(Option::is_some).collect();
        control_frame("ignored", 99, 7, &positions, &valid)
    }

    #[test]
    fn chunks_carry_the_held_points_and_number_the_frames() {
        let a = Some([1.0, 0.0, 0.0]);
        let b = Some([2.0, 0.0, 0.0]);
        let frames = [
            frame(&[a, None]),    // 0: point 1 never seen: stays occluded
            frame(&[None, b]),    // 1: point 0 held by the batch itself
            frame(&[None, None]), // 2: starts chunk 2: both held points sent as valid
            frame(&[None, b]),    // 3
            frame(&[a, b]),       // 4: starts chunk 3, nothing occluded
        ];
        let chunks = chunk_frames(&frames, 2, 2).unwrap();
        assert_eq!(chunks.iter().map(Vec::len).collect::<Vec<_>>(), [2, 2, 1]);
        let seqs: Vec<u64> = chunks.iter().flatten().map(|f| f.seq).collect();
        assert_eq!(seqs, [0, 1, 2, 3, 4]);
        let read = |f: &v1::ControlFrame| {
            let (mut p, mut v) = (vec![Vec3::ZERO; 2], vec![false; 2]);
            read_control_frame(f, &mut p, &mut v).unwrap();
            (p, v)
        };
        assert_eq!(read(&chunks[0][0]).1, [true, false]);
        assert_eq!(
            read(&chunks[0][1]).1,
            [false, true],
            "inside a chunk: as sent"
        );
        let (p, v) = read(&chunks[1][0]);
        assert_eq!(v, [true, true]);
        assert_eq!(p, [Vec3::X, Vec3::new(2.0, 0.0, 0.0)]);
        assert_eq!(read(&chunks[1][1]).1, [false, true]);
        assert_eq!(chunks[1][0].capture_time_us, 7);
        assert!(chunks.iter().flatten().all(|f| f.room.is_empty()));
    }

    #[test]
    fn a_frame_that_does_not_fit_is_named_by_its_index_in_the_job() {
        let ok = frame(&[Some([0.0; 3]), Some([1.0; 3])]);
        let short = frame(&[Some([0.0; 3])]);
        let e = chunk_frames(&[ok.clone(), ok.clone(), ok, short], 2, 2).unwrap_err();
        assert_eq!(e.index, 3);
        assert_eq!(
            e.to_string(),
            "SubmitJob.frames[3].positions: 3 values, expected 6 (x, y, z of 2 control points)"
        );
    }

    #[test]
    fn a_plan_and_a_status_survive_the_wire() {
        use crease_core::predictor::Refinement;
        use crease_core::runtime::skin::Skinning;
        let plans = [
            JobPlan {
                model: "hand".into(),
                level: Level::Detail,
                options: RoomOptions {
                    beta: Some(2.5),
                    filter: None,
                    refine: Some(Refinement::ROOM_DEFAULT),
                    skinning: Some(Skinning::Dqs),
                },
                name: "take 3".into(),
                encoding: Encoding::Vertices,
            },
            JobPlan {
                model: "horse".into(),
                level: Level::Base,
                options: RoomOptions::default(),
                name: String::new(),
                encoding: Encoding::Palette,
            },
        ];
        for plan in plans {
            let spec = plan.to_spec();
            assert!(spec.refine.is_some(), "the refinement travels resolved");
            assert_eq!(JobPlan::from_spec(&spec).unwrap(), plan);
        }
        let status = JobStatus {
            job: "abcdefghijkl".into(),
            name: "n".into(),
            model: "m".into(),
            level: Level::Detail,
            state: JobState::Running,
            frames_total: 10,
            frames_done: 4,
            chunks_total: 5,
            chunks_done: 2,
            frames_per_second: 3.5,
            eta_seconds: 1.5,
            error: "e".into(),
            submitted_us: 1,
            finished_us: 2,
            expires_us: 3,
            encoding: Encoding::Palette,
        };
        assert_eq!(JobStatus::from_wire(&v1::JobInfo::from(&status)), status);
    }

    #[test]
    fn job_ids_are_plain_names() {
        let id = new_job_id([0, 25, 26, 35, 36, 255, 1, 2, 3, 4, 5, 6]);
        assert_eq!(id, "az09adbcdefg");
        assert!(is_job_id(&id));
        assert!(!is_job_id("../etc/passw"));
        assert!(!is_job_id("short"));
    }

    fn record(chunks: u32, frames: u64) -> v1::JobRecord {
        v1::JobRecord {
            info: Some(v1::JobInfo {
                job: "abcdefghijkl".into(),
                chunks_total: chunks,
                frames_total: frames,
                state: v1::JobState::Queued as i32,
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    #[test]
    fn a_chunk_is_counted_once_and_the_last_ends_the_job() {
        let ttl = Duration::from_secs(10);
        let mut r = record(3, 25);
        assert!(count_chunk(&mut r, 1, 10, 1_000_000, 2_000_000, ttl));
        assert!(
            !count_chunk(&mut r, 1, 10, 1_000_000, 2_500_000, ttl),
            "a redelivered chunk already counted"
        );
        let info = r.info.clone().unwrap();
        assert_eq!((info.chunks_done, info.frames_done), (1, 10));
        assert_eq!(JobState::from_wire(info.state), JobState::Running);
        // 10 frames in the second since the first chunk began; 15 left.
        assert!((info.frames_per_second - 10.0).abs() < 1e-9);
        assert!((info.eta_seconds - 1.5).abs() < 1e-9);
        assert!(count_chunk(&mut r, 0, 10, 500_000, 3_000_000, ttl));
        assert_eq!(r.started_us, 500_000, "the earliest chunk's start");
        assert!(count_chunk(&mut r, 2, 5, 2_000_000, 4_000_000, ttl));
        let info = r.info.clone().unwrap();
        assert_eq!(JobState::from_wire(info.state), JobState::Done);
        assert_eq!((info.chunks_done, info.frames_done), (3, 25));
        assert_eq!(info.finished_us, 4_000_000);
        assert_eq!(info.expires_us, 14_000_000);
        assert!((0..3).all(|c| is_done(&r.done, c)) && !is_done(&r.done, 3));
        assert!(!count_chunk(&mut r, 3, 1, 0, 5_000_000, ttl), "ended");
    }

    #[test]
    fn the_done_bitmap_grows_as_needed() {
        let mut done = Vec::new();
        for c in [0, 9, 17, 800] {
            set_done(&mut done, c);
        }
        assert_eq!(done.len(), 101);
        let set: Vec<u32> = (0..1000).filter(|&c| is_done(&done, c)).collect();
        assert_eq!(set, [0, 9, 17, 800]);
    }
}
