//! Takes (issue 22): a room records the frames it predicts into the server's takes folder
//! (`Config::takes`), one file per take, laid out as `proto/crease/v1/take.proto` says
//! (`crease_proto::take` writes and reads it).
//!
//! A [`Recorder`] sits in the room's pipeline while the take runs: per predicted frame it
//! refills one reused record and hands an encoded buffer to the take's writer thread, which
//! appends it with one write and hands the buffer back, so recording allocates nothing per
//! frame after the first few and never waits on the disk (a frame the writer is more than
//! [`QUEUE`] frames behind on is dropped and counted). Every record is written whole with one
//! `write`, so a server killed mid-take leaves all it wrote but at most the last record, which
//! readers drop ([`crease_proto::take::scan`]); the file is synced when the take stops.

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use crease_core::glam::Vec3;
use crease_core::runtime::skin::RigidTransform;
use crease_proto::take::{self, Scan};
use crease_proto::take_info::{TakeFile, empty_take_frame, take_header, take_info};
use crease_proto::v1;

/// Frames a take's writer may be behind before the room drops the next one.
pub const QUEUE: usize = 256;

/// The takes folder.
#[derive(Debug)]
pub struct Takes {
    dir: PathBuf,
    /// Makes ids unique within a second.
    counter: AtomicU64,
}

/// Why a take could not start or stop.
#[derive(Debug, thiserror::Error)]
pub enum TakeError {
    /// The server has no takes folder.
    #[error("this server records no takes: start it with --takes DIR")]
    NoFolder,
    /// The room records already.
    #[error("room {room:?} is recording take {take:?} already: stop it first")]
    Recording {
        /// The room.
        room: String,
        /// Its take.
        take: String,
    },
    /// The room records nothing.
    #[error("room {0:?} is not recording")]
    NotRecording(String),
    /// No take of that id.
    #[error("take: no take {0:?}")]
    NoTake(String),
    /// The room is predicted on another replica (a cluster): its takes are recorded there.
    #[error("room {room:?} is predicted on replica {owner:?}: start and stop its takes there")]
    Elsewhere {
        /// The room.
        room: String,
        /// The replica that owns it.
        owner: String,
    },
    /// The label is too long.
    #[error("name: {0} bytes, at most 200")]
    Name(usize),
    /// The file could not be created, written or read.
    #[error("take {path}: {error}")]
    Io {
        /// The take's file.
        path: PathBuf,
        /// What failed.
        error: std::io::Error,
    },
    /// The file is not a readable take.
    #[error("take {path}: {error}")]
    File {
        /// The take's file.
        path: PathBuf,
        /// What is wrong with it.
        error: take::TakeError,
    },
}

/// Whether `id` can name a take: 1-160 characters of `[A-Za-z0-9_-]` (a room id, a stamp and a
/// counter), so it is a plain file name.
pub fn valid_take_id(id: &str) -> bool {
    crease_proto::room::check_identifier(id, 160).is_ok()
}

/// `secs` after the Unix epoch as `YYYYMMDDTHHMMSSZ` (UTC; the proleptic Gregorian calendar,
/// days to civil date as in Hinnant's `civil_from_days`).
pub fn utc_stamp(secs: i64) -> String {
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// Microseconds since the Unix epoch, now.
fn unix_us() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

impl Takes {
    /// The takes folder `dir`, created if missing.
    ///
    /// # Errors
    /// [`TakeError::Io`] when it cannot be created.
    pub fn new(dir: impl Into<PathBuf>) -> Result<Takes, TakeError> {
        let dir = dir.into();
        std::fs::create_dir_all(&dir).map_err(|error| TakeError::Io {
            path: dir.clone(),
            error,
        })?;
        Ok(Takes {
            dir,
            counter: AtomicU64::new(0),
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The file of take `id`, if `id` is a [valid](valid_take_id) id and the file exists.
    ///
    /// # Errors
    /// [`TakeError::NoTake`].
    pub fn path(&self, id: &str) -> Result<PathBuf, TakeError> {
        let path = self.dir.join(format!("{id}.take"));
        if valid_take_id(id) && path.is_file() {
            Ok(path)
        } else {
            Err(TakeError::NoTake(id.to_owned()))
        }
    }

    /// Creates take file for `room` (its settings as `OpenRoomRequest`, no token) and starts
    /// its writer. Blocking (creates and writes a file).
    ///
    /// # Errors
    /// [`TakeError::Name`], [`TakeError::Io`].
    pub fn start(
        &self,
        room: v1::OpenRoomRequest,
        name: &str,
        model_sha256: &str,
        bones: usize,
        controls: usize,
        actors: Vec<v1::TakeActor>,
    ) -> Result<Recorder, TakeError> {
        if name.len() > 200 {
            return Err(TakeError::Name(name.len()));
        }
        // The folder again: someone may have removed it while the server ran (an operator
        // clearing old takes); a take must not fail for that.
        std::fs::create_dir_all(&self.dir).map_err(|error| TakeError::Io {
            path: self.dir.clone(),
            error,
        })?;
        let started_unix_us = unix_us();
        let (path, file, id) = loop {
            let n = self.counter.fetch_add(1, Ordering::Relaxed);
            let id = format!(
                "{}-{}-{n}",
                room.room,
                utc_stamp(started_unix_us.div_euclid(1_000_000))
            );
            let path = self.dir.join(format!("{id}.take"));
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(file) => break (path, file, id),
                // A take of a previous run of the server with this id.
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(error) => return Err(TakeError::Io { path, error }),
            }
        };
        let mut header = take_header(
            &id,
            name,
            room,
            model_sha256,
            started_unix_us,
            bones,
            controls,
        );
        header.actors = actors;
        let mut file = file;
        let mut head = Vec::new();
        take::write_header(&mut head, &header).expect("a Vec takes every write");
        file.write_all(&head).map_err(|error| TakeError::Io {
            path: path.clone(),
            error,
        })?;
        Ok(Recorder::new(id, path, file, header))
    }

    /// Every take of `room` (all with `None`), newest first, as [`v1::TakeInfo`]; `recording`
    /// names the takes rooms are recording now. Blocking (reads the files). A file that is not
    /// a readable take is skipped with a warning.
    pub fn list(&self, room: Option<&str>, recording: &[String]) -> Vec<v1::TakeInfo> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut takes: Vec<v1::TakeInfo> = entries
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "take"))
            .filter_map(|path| match info_of(&path, recording) {
                Ok(info) => Some(info),
                Err(e) => {
                    tracing::warn!(error = %e, "takes: skipped");
                    None
                }
            })
            .filter(|t| room.is_none_or(|r| t.room == r))
            .collect();
        takes.sort_by(|a, b| {
            b.started_unix_us
                .cmp(&a.started_unix_us)
                .then(b.take.cmp(&a.take))
        });
        takes
    }

    /// Take `id`'s [`v1::TakeInfo`]. Blocking.
    ///
    /// # Errors
    /// [`TakeError::NoTake`], or the file's.
    pub fn info(&self, id: &str, recording: &[String]) -> Result<v1::TakeInfo, TakeError> {
        info_of(&self.path(id)?, recording)
    }

    /// Take `id` read whole (its whole frames). Blocking.
    ///
    /// # Errors
    /// [`TakeError::NoTake`], or the file's.
    pub fn read(&self, id: &str) -> Result<take::Take, TakeError> {
        let path = self.path(id)?;
        let file = std::fs::File::open(&path).map_err(|error| TakeError::Io {
            path: path.clone(),
            error,
        })?;
        take::read_take(std::io::BufReader::new(file))
            .map_err(|error| TakeError::File { path, error })
    }

    /// Take `id`'s bytes up to its last whole record. Blocking.
    ///
    /// # Errors
    /// [`TakeError::NoTake`], or the file's.
    pub fn bytes(&self, id: &str) -> Result<Vec<u8>, TakeError> {
        let path = self.path(id)?;
        let io = |error| TakeError::Io {
            path: path.clone(),
            error,
        };
        let mut bytes = std::fs::read(&path).map_err(io)?;
        let scan = take::scan(bytes.as_slice(), |_| Ok(())).map_err(|error| TakeError::File {
            path: path.clone(),
            error,
        })?;
        bytes.truncate(scan.whole_bytes as usize);
        Ok(bytes)
    }
}

/// The [`v1::TakeInfo`] of the take file at `path`.
fn info_of(path: &Path, recording: &[String]) -> Result<v1::TakeInfo, TakeError> {
    let file = std::fs::File::open(path).map_err(|error| TakeError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let bytes = file.metadata().map_or(0, |m| m.len());
    let scan =
        take::scan(std::io::BufReader::new(file), |_| Ok(())).map_err(|error| TakeError::File {
            path: path.to_path_buf(),
            error,
        })?;
    let mut info = info(&scan, bytes, recording);
    // The id is the file's stem (a copied or renamed file is its own take).
    if let Some(stem) = path.file_stem().and_then(|s| s.to_str()) {
        info.take = stem.to_owned();
        info.recording = recording.iter().any(|r| r == stem);
    }
    Ok(info)
}

/// A take's summary.
fn info(scan: &Scan, bytes: u64, recording: &[String]) -> v1::TakeInfo {
    let h = &scan.header;
    take_info(
        h,
        TakeFile {
            frames: scan.frames,
            duration_us: scan.last_received_us,
            bytes,
            recording: recording.contains(&h.take),
            truncated: scan.truncated,
        },
    )
}

/// A take being recorded: lives in its room's pipeline (module docs).
#[derive(Debug)]
pub struct Recorder {
    id: String,
    path: PathBuf,
    header: v1::TakeHeader,
    started: Instant,
    /// The reused record.
    record: v1::TakeFrame,
    /// Encoded records to the writer, and the buffers it hands back.
    to_writer: Option<mpsc::SyncSender<Vec<u8>>>,
    free: mpsc::Receiver<Vec<u8>>,
    writer: Option<std::thread::JoinHandle<std::io::Result<()>>>,
    frames: u64,
    dropped: u64,
    last_received_us: i64,
    failed: bool,
}

impl Recorder {
    fn new(id: String, path: PathBuf, file: std::fs::File, header: v1::TakeHeader) -> Recorder {
        let (to_writer, records) = mpsc::sync_channel::<Vec<u8>>(QUEUE);
        let (give_back, free) = mpsc::channel::<Vec<u8>>();
        let mut file = file;
        let writer = std::thread::Builder::new()
            .name(format!("take-{id}"))
            .spawn(move || {
                for record in records {
                    // One whole record per write (module docs).
                    file.write_all(&record)?;
                    let _ = give_back.send(record);
                }
                file.sync_all()
            })
            .map_err(|e| tracing::warn!(take = %id, error = %e, "take: no writer thread"))
            .ok();
        Recorder {
            id,
            path,
            header,
            started: Instant::now(),
            record: empty_take_frame(),
            to_writer: writer.as_ref().map(|_| to_writer),
            free,
            writer,
            frames: 0,
            dropped: 0,
            last_received_us: 0,
            failed: false,
        }
    }

    /// The take's id.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// Records one predicted frame: the control frame as it came, when it arrived, the
    /// controls the prediction used and the transforms it predicted. Allocates only while the
    /// writer has not yet handed back enough buffers.
    pub(crate) fn record(
        &mut self,
        frame: &v1::ControlFrame,
        received: Instant,
        controls: &[Vec3],
        transforms: &[RigidTransform],
    ) {
        let received_us = self.received_us(received);
        take::fill_frame(&mut self.record, frame, received_us, controls, transforms);
        self.write(received_us);
    }

    /// Records one predicted frame of a room of `actors` actors: the control frame as it came
    /// (every actor's part), when it arrived, and each actor's pose, which `poses` fills in
    /// (`crease_proto::take::fill_actor_pose`, once per actor).
    pub(crate) fn record_actors(
        &mut self,
        frame: &v1::ControlFrame,
        received: Instant,
        actors: usize,
        poses: impl FnOnce(&mut v1::TakeFrame),
    ) {
        let received_us = self.received_us(received);
        take::fill_actors_frame(&mut self.record, frame, received_us, actors);
        poses(&mut self.record);
        self.write(received_us);
    }

    /// Microseconds from the take's start to `received`.
    fn received_us(&self, received: Instant) -> i64 {
        received
            .saturating_duration_since(self.started)
            .as_micros()
            .min(i64::MAX as u128) as i64
    }

    /// Hands the filled record to the writer (dropped, and counted, when it is behind).
    fn write(&mut self, received_us: i64) {
        let Some(tx) = &self.to_writer else {
            return;
        };
        let mut buf = self.free.try_recv().unwrap_or_default();
        take::encode_record(&self.record, &mut buf);
        match tx.try_send(buf) {
            Ok(()) => {
                self.frames += 1;
                self.last_received_us = received_us;
            }
            Err(mpsc::TrySendError::Full(_)) => {
                self.dropped += 1;
                if self.dropped.is_power_of_two() {
                    tracing::warn!(take = %self.id, dropped = self.dropped, "take: the disk is behind; frames dropped");
                }
            }
            Err(mpsc::TrySendError::Disconnected(_)) => {
                // The writer stopped on an error; `finish` reports it.
                if !std::mem::replace(&mut self.failed, true) {
                    tracing::warn!(take = %self.id, "take: the writer failed; recording stopped");
                }
                self.to_writer = None;
            }
        }
    }

    /// Stops the take: the writer writes what is queued and syncs the file. Blocking.
    ///
    /// # Errors
    /// [`TakeError::Io`]: a write or the sync failed (the file holds the frames before it).
    pub fn finish(mut self) -> Result<v1::TakeInfo, TakeError> {
        drop(self.to_writer.take());
        let result = match self.writer.take().map(std::thread::JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(std::io::Error::other("the take's writer panicked")),
            None => Err(std::io::Error::other("the take had no writer thread")),
        };
        result.map_err(|error| TakeError::Io {
            path: self.path.clone(),
            error,
        })?;
        if self.dropped > 0 {
            tracing::warn!(take = %self.id, dropped = self.dropped, "take stopped; frames dropped while the disk was behind");
        }
        let bytes = std::fs::metadata(&self.path).map_or(0, |m| m.len());
        let scan = Scan {
            header: std::mem::take(&mut self.header),
            frames: self.frames,
            last_received_us: self.last_received_us,
            whole_bytes: bytes,
            truncated: false,
        };
        Ok(info(&scan, bytes, &[]))
    }

    /// Stops the take and deletes its file (a take that lost the race to start).
    pub fn discard(self) {
        let path = self.path.clone();
        let _ = self.finish();
        let _ = std::fs::remove_file(path);
    }

    /// What [`Recorder::finish`] would report, while recording.
    pub fn info(&self) -> v1::TakeInfo {
        let scan = Scan {
            header: self.header.clone(),
            frames: self.frames,
            last_received_us: self.last_received_us,
            whole_bytes: 0,
            truncated: false,
        };
        let mut info = info(&scan, 0, std::slice::from_ref(&self.id));
        info.bytes = std::fs::metadata(&self.path).map_or(0, |m| m.len());
        info
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn utc_stamps_match_known_dates() {
        // Dates checked against `date -u -d @SECS +%Y%m%dT%H%M%SZ`.
        assert_eq!(utc_stamp(0), "19700101T000000Z");
        assert_eq!(utc_stamp(951_782_400), "20000229T000000Z");
        assert_eq!(utc_stamp(1_796_300_000), "20261203T121320Z");
        assert_eq!(utc_stamp(-1), "19691231T235959Z");
    }

    #[test]
    fn take_ids_are_plain_file_names() {
        assert!(valid_take_id("demo-20261203T111320Z-0"));
        for bad in ["", "../x", "a/b", "a.take", "a b", &"x".repeat(161)] {
            assert!(!valid_take_id(bad), "{bad:?}");
        }
    }

    #[test]
    fn a_recorded_take_lists_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let takes = Takes::new(dir.path()).unwrap();
        let room = v1::OpenRoomRequest {
            room: "r1".into(),
            model: "m".into(),
            ..Default::default()
        };
        let mut rec = takes
            .start(room, "first", "ab12", 1, 1, Vec::new())
            .unwrap();
        let id = rec.id().to_owned();
        let t0 = Instant::now();
        for i in 0..10u64 {
            let frame = v1::ControlFrame {
                seq: i,
                positions: vec![i as f32, 0.0, 0.0],
                ..Default::default()
            };
            rec.record(
                &frame,
                t0,
                &[Vec3::X * i as f32],
                &[RigidTransform::IDENTITY],
            );
        }
        let live = takes.list(None, std::slice::from_ref(&id));
        assert_eq!(live.len(), 1);
        assert!(live[0].recording);
        let done = rec.finish().unwrap();
        assert_eq!(done.frames, 10);
        assert_eq!((done.room.as_str(), done.name.as_str()), ("r1", "first"));
        let listed = takes.list(Some("r1"), &[]);
        assert_eq!(listed.len(), 1);
        assert_eq!(listed[0].frames, 10);
        assert!(!listed[0].recording && !listed[0].truncated);
        assert!(takes.list(Some("other"), &[]).is_empty());
        let take = takes.read(&id).unwrap();
        let seqs: Vec<u64> = take
            .frames
            .iter()
            .map(|f| f.frame.as_ref().unwrap().seq)
            .collect();
        assert_eq!(seqs, (0..10).collect::<Vec<_>>());
        assert_eq!(take.frames[7].controls, vec![7.0, 0.0, 0.0]);
        assert!(matches!(takes.read("nope"), Err(TakeError::NoTake(_))));
        assert!(matches!(takes.path("../etc"), Err(TakeError::NoTake(_))));
    }

    /// The browser test once removed the takes folder after the server had created it, and
    /// every take start then failed with "No such file or directory".
    #[test]
    fn a_take_starts_after_its_folder_was_removed() {
        let dir = tempfile::tempdir().unwrap();
        let folder = dir.path().join("takes");
        let takes = Takes::new(&folder).unwrap();
        std::fs::remove_dir_all(&folder).unwrap();
        let room = v1::OpenRoomRequest {
            room: "r1".into(),
            ..Default::default()
        };
        let rec = takes
            .start(room, "again", "ab12", 1, 1, Vec::new())
            .unwrap();
        assert!(folder.join(format!("{}.take", rec.id())).is_file());
        assert_eq!(rec.finish().unwrap().frames, 0);
    }
}
