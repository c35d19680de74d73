//! A take's header and summary as the server builds them (`take.proto`): [`take_header`]
//! opens a take's file, [`take_info`] is what `StartTake`, `StopTake` and `ListTakes` report
//! of one. The file format itself (records, scanning, reading) is [`crate::take`]'s.

use crate::v1;

/// The header of take `take` (labelled `name`) of a room opened with `room`, on a model of
/// SHA-256 `model_sha256` with `bones` bones and `controls` control points, started at
/// `started_unix_us`.
pub fn take_header(
    take: &str,
    name: &str,
    room: v1::OpenRoomRequest,
    model_sha256: &str,
    started_unix_us: i64,
    bones: usize,
    controls: usize,
) -> v1::TakeHeader {
    v1::TakeHeader {
        take: take.to_owned(),
        name: name.to_owned(),
        room: Some(room),
        model_sha256: model_sha256.to_owned(),
        started_unix_us,
        bones: bones as u32,
        controls: controls as u32,
        actors: Vec::new(),
    }
}

/// Actor `actor` of a take of a room of several actors (`TakeHeader.actors`): its model
/// file's digest as trained, its bones and control points.
pub fn take_actor(actor: &str, model_sha256: &str, bones: usize, controls: usize) -> v1::TakeActor {
    v1::TakeActor {
        actor: actor.to_owned(),
        model_sha256: model_sha256.to_owned(),
        bones: bones as u32,
        controls: controls as u32,
    }
}

/// What a take's file holds, for [`take_info`].
#[derive(Clone, Copy, Debug)]
pub struct TakeFile {
    /// Whole frames.
    pub frames: u64,
    /// The last whole frame's `received_us`: the take's duration.
    pub duration_us: i64,
    /// The file's size.
    pub bytes: u64,
    /// Whether a room records it now.
    pub recording: bool,
    /// Whether bytes follow the last whole record.
    pub truncated: bool,
}

/// The summary of the take of `header` whose file holds `file`. A take being written ends in
/// part of a record only for the instant of a write, so a recording take is never truncated.
pub fn take_info(header: &v1::TakeHeader, file: TakeFile) -> v1::TakeInfo {
    let room = header.room.as_ref();
    v1::TakeInfo {
        take: header.take.clone(),
        room: room.map(|r| r.room.clone()).unwrap_or_default(),
        name: header.name.clone(),
        model: room.map(|r| r.model.clone()).unwrap_or_default(),
        model_sha256: header.model_sha256.clone(),
        started_unix_us: header.started_unix_us,
        frames: file.frames,
        duration_us: file.duration_us,
        bytes: file.bytes,
        recording: file.recording,
        truncated: file.truncated && !file.recording,
    }
}

/// An empty frame record, refilled per frame by a take's recorder.
pub fn empty_take_frame() -> v1::TakeFrame {
    v1::TakeFrame::default()
}
