//! Take files (issue 22): what a room recorded, laid out as `proto/crease/v1/take.proto`
//! says: a magic, then length- and CRC-framed records, a [`v1::TakeHeader`] first and one
//! [`v1::TakeFrame`] per predicted frame after it.
//!
//! - Writing: [`write_header`] starts a file; [`fill_frame`] refills one reused
//!   [`v1::TakeFrame`] and [`encode_record`] frames it into one reused buffer, so a recording
//!   room allocates nothing per frame; the writer appends each buffer with one write.
//! - Reading: [`scan`] walks a file record by record and stops at the first record that is
//!   short or fails its CRC (a crash while writing it), [`read_take`] keeps every frame.
//! - Using: [`frame_transforms`] / [`frame_controls`] / [`all_transforms`] check and unpack
//!   frames' arrays, [`keyframe_times`] gives the frames' times, [`check_model`] and
//!   [`take_skinning`] what a model must be and how the room skinned. Exporting a take as
//!   glTF is its users' (the server's download, `crease take export`), through
//!   `core::model::gltf_export`; the contract runs no predictor.

use std::io::{self, Read, Write};

use crease_core::glam::{Quat, Vec3};
use crease_core::model::TrainedModel;
use crease_core::runtime::skin::{RigidTransform, Skinning};
use prost::Message as _;

use crate::v1;

/// The first 8 bytes of a take file; the last byte is the layout's version.
pub const MAGIC: [u8; 8] = *b"CRTAKE\0\x01";

/// Bytes before each record's payload: its length and its CRC-32, u32 LE each.
pub const RECORD_HEADER_BYTES: usize = 8;

/// The largest record a reader accepts (a frame of 65536 bones is under 2 MiB).
pub const MAX_RECORD_BYTES: u32 = 64 << 20;

/// What is wrong with a take file.
#[derive(Debug, thiserror::Error)]
pub enum TakeError {
    /// Reading or writing failed.
    #[error(transparent)]
    Io(#[from] io::Error),
    /// The file does not start with [`MAGIC`].
    #[error("not a take file: it starts with {got:?}, a take with {MAGIC:?}")]
    Magic {
        /// The first bytes.
        got: Vec<u8>,
    },
    /// The header record is missing, short, or does not decode.
    #[error("the take's header: {0}")]
    Header(String),
    /// A frame's arrays do not fit the header.
    #[error("frame {frame}: {what} has {got} values, expected {expected}")]
    FrameShape {
        /// The frame's index.
        frame: usize,
        /// `controls` or `transforms`.
        what: &'static str,
        /// The length the header implies.
        expected: usize,
        /// The frame's.
        got: usize,
    },
    /// The take cannot be exported with this model.
    #[error("export: {0}")]
    Export(String),
}

/// Frames `message` into `out` (cleared first) as one record: length, CRC, payload.
pub fn encode_record(message: &impl prost::Message, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&[0; RECORD_HEADER_BYTES]);
    // Encoding into a Vec only fails when it lacks room, and a Vec grows.
    let _ = message.encode(out);
    let len = (out.len() - RECORD_HEADER_BYTES) as u32;
    let crc = crc32fast::hash(&out[RECORD_HEADER_BYTES..]);
    out[..4].copy_from_slice(&len.to_le_bytes());
    out[4..8].copy_from_slice(&crc.to_le_bytes());
}

/// Starts a take file: the magic and the header record.
///
/// # Errors
/// The writer's.
pub fn write_header(out: &mut impl Write, header: &v1::TakeHeader) -> io::Result<()> {
    let mut record = Vec::new();
    encode_record(header, &mut record);
    out.write_all(&MAGIC)?;
    out.write_all(&record)
}

/// Refills `record` (reusing its arrays) with a predicted frame: the control frame as it came
/// (room emptied), its arrival after the take's start, the controls the prediction used and
/// the bone transforms it predicted.
pub fn fill_frame(
    record: &mut v1::TakeFrame,
    frame: &v1::ControlFrame,
    received_us: i64,
    controls: &[Vec3],
    transforms: &[RigidTransform],
) {
    fill_control_frame(record, frame, received_us);
    fill_pose(
        &mut record.controls,
        &mut record.transforms,
        controls,
        transforms,
    );
    record.actors.clear();
}

/// [`fill_frame`] for a room of several actors: the frame (every actor's points, in its
/// `actors`), then each actor's pose by [`fill_actor_pose`]. Buffers are reused: `actors`
/// keeps its entries from frame to frame.
pub fn fill_actors_frame(
    record: &mut v1::TakeFrame,
    frame: &v1::ControlFrame,
    received_us: i64,
    actors: usize,
) {
    fill_control_frame(record, frame, received_us);
    record.controls.clear();
    record.transforms.clear();
    record.actors.resize_with(actors, Default::default);
}

/// Actor `k`'s pose in a record [`fill_actors_frame`] began.
///
/// # Panics
/// If `k` is not below the actor count given there.
pub fn fill_actor_pose(
    record: &mut v1::TakeFrame,
    k: usize,
    controls: &[Vec3],
    transforms: &[RigidTransform],
) {
    let pose = &mut record.actors[k];
    fill_pose(
        &mut pose.controls,
        &mut pose.transforms,
        controls,
        transforms,
    );
}

/// The control frame and arrival time of a record (its pose left as it is).
fn fill_control_frame(record: &mut v1::TakeFrame, frame: &v1::ControlFrame, received_us: i64) {
    let f = record.frame.get_or_insert_with(Default::default);
    f.room.clear();
    f.seq = frame.seq;
    f.capture_time_us = frame.capture_time_us;
    for (to, from) in [
        (&mut f.positions, &frame.positions),
        (&mut f.markers, &frame.markers),
    ] {
        to.clear();
        to.extend_from_slice(from);
    }
    for (to, from) in [
        (&mut f.valid, &frame.valid),
        (&mut f.markers_valid, &frame.markers_valid),
    ] {
        to.clear();
        to.extend_from_slice(from);
    }
    // A room of several actors' parts, their buffers reused.
    f.actors.resize_with(frame.actors.len(), Default::default);
    for (to, from) in f.actors.iter_mut().zip(&frame.actors) {
        to.actor.clone_from(&from.actor);
        to.positions.clone_from(&from.positions);
        to.valid.clone_from(&from.valid);
        to.markers.clone_from(&from.markers);
        to.markers_valid.clone_from(&from.markers_valid);
    }
    record.received_us = received_us;
}

/// Flat control points and transforms (module docs of the file layout).
fn fill_pose(
    to_controls: &mut Vec<f32>,
    to_transforms: &mut Vec<f32>,
    controls: &[Vec3],
    transforms: &[RigidTransform],
) {
    to_controls.clear();
    to_controls.extend(controls.iter().flat_map(|c| c.to_array()));
    to_transforms.clear();
    to_transforms.extend(transforms.iter().flat_map(|t| {
        let (q, p) = (t.rotation, t.translation);
        [q.x, q.y, q.z, q.w, p.x, p.y, p.z]
    }));
}

/// What [`scan`] found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scan {
    /// The header.
    pub header: v1::TakeHeader,
    /// Whole frames.
    pub frames: u64,
    /// The last whole frame's `received_us` (0 without frames).
    pub last_received_us: i64,
    /// Bytes up to the end of the last whole record.
    pub whole_bytes: u64,
    /// Whether bytes follow the last whole record (a record cut short or failing its CRC).
    pub truncated: bool,
}

/// Reads one record's payload into `payload`; `Ok(false)` at the end of the file or at a
/// record that is cut short or fails its CRC (then `*torn` says whether any byte of it was
/// there).
fn next_record(r: &mut impl Read, payload: &mut Vec<u8>, torn: &mut bool) -> io::Result<bool> {
    let mut head = [0u8; RECORD_HEADER_BYTES];
    let got = read_full(r, &mut head)?;
    if got < RECORD_HEADER_BYTES {
        *torn = got > 0;
        return Ok(false);
    }
    let len = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
    let crc = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
    if len > MAX_RECORD_BYTES {
        *torn = true;
        return Ok(false);
    }
    payload.resize(len as usize, 0);
    if read_full(r, payload)? < payload.len() || crc32fast::hash(payload) != crc {
        *torn = true;
        return Ok(false);
    }
    Ok(true)
}

/// Reads until `buf` is full or the reader ends; how many bytes came.
fn read_full(r: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// Walks a take file: checks the magic, decodes the header, and hands every whole frame to
/// `on_frame` in order, stopping at the first record that is cut short or fails its CRC (the
/// take is then [`Scan::truncated`]). A frame that passes its CRC but does not decode is
/// treated the same way.
///
/// # Errors
/// [`TakeError::Magic`], [`TakeError::Header`], the reader's I/O error, or `on_frame`'s.
pub fn scan(
    mut r: impl Read,
    mut on_frame: impl FnMut(v1::TakeFrame) -> Result<(), TakeError>,
) -> Result<Scan, TakeError> {
    let mut magic = [0u8; 8];
    let got = read_full(&mut r, &mut magic)?;
    if got < magic.len() || magic != MAGIC {
        return Err(TakeError::Magic {
            got: magic[..got].to_vec(),
        });
    }
    let mut payload = Vec::new();
    let mut torn = false;
    if !next_record(&mut r, &mut payload, &mut torn)? {
        return Err(TakeError::Header(
            "missing or cut short (a server that died as the take began)".into(),
        ));
    }
    let header =
        v1::TakeHeader::decode(payload.as_slice()).map_err(|e| TakeError::Header(e.to_string()))?;
    let mut scan = Scan {
        whole_bytes: (MAGIC.len() + RECORD_HEADER_BYTES + payload.len()) as u64,
        header,
        ..Scan::default()
    };
    while next_record(&mut r, &mut payload, &mut torn)? {
        let Ok(frame) = v1::TakeFrame::decode(payload.as_slice()) else {
            torn = true;
            break;
        };
        scan.frames += 1;
        scan.last_received_us = frame.received_us;
        scan.whole_bytes += (RECORD_HEADER_BYTES + payload.len()) as u64;
        on_frame(frame)?;
    }
    scan.truncated = torn;
    Ok(scan)
}

/// A take read whole.
#[derive(Clone, Debug, PartialEq)]
pub struct Take {
    /// What [`scan`] found (header, counts, truncation).
    pub scan: Scan,
    /// Every whole frame, in order.
    pub frames: Vec<v1::TakeFrame>,
}

impl Take {
    /// The header.
    pub fn header(&self) -> &v1::TakeHeader {
        &self.scan.header
    }
}

/// Reads a take file whole ([`scan`], keeping the frames).
///
/// # Errors
/// [`scan`]'s.
pub fn read_take(r: impl Read) -> Result<Take, TakeError> {
    let mut frames = Vec::new();
    let scan = scan(r, |f| {
        frames.push(f);
        Ok(())
    })?;
    Ok(Take { scan, frames })
}

/// Frame `index`'s bone transforms, checked against the header's bone count.
///
/// # Errors
/// [`TakeError::FrameShape`].
pub fn frame_transforms(
    take: &Take,
    index: usize,
    out: &mut Vec<RigidTransform>,
) -> Result<(), TakeError> {
    let bones = take.header().bones as usize;
    let values = &take.frames[index].transforms;
    if values.len() != 7 * bones {
        return Err(TakeError::FrameShape {
            frame: index,
            what: "transforms",
            expected: 7 * bones,
            got: values.len(),
        });
    }
    out.clear();
    out.extend(values.chunks_exact(7).map(|v| RigidTransform {
        rotation: Quat::from_xyzw(v[0], v[1], v[2], v[3]),
        translation: Vec3::new(v[4], v[5], v[6]),
    }));
    Ok(())
}

/// Frame `index`'s controls as the prediction used them, checked against the header.
///
/// # Errors
/// [`TakeError::FrameShape`].
pub fn frame_controls(take: &Take, index: usize, out: &mut Vec<Vec3>) -> Result<(), TakeError> {
    let n = take.header().controls as usize;
    let values = &take.frames[index].controls;
    if values.len() != 3 * n {
        return Err(TakeError::FrameShape {
            frame: index,
            what: "controls",
            expected: 3 * n,
            got: values.len(),
        });
    }
    out.clear();
    out.extend(values.chunks_exact(3).map(Vec3::from_slice));
    Ok(())
}

/// Each frame's time in seconds after the first: its capture time when the publisher's
/// capture times increase through the take, else its arrival (`received_us`). Strictly
/// increasing either way (a repeated arrival time is moved on by a microsecond).
pub fn keyframe_times(take: &Take) -> Vec<f64> {
    let capture: Vec<i64> = take
        .frames
        .iter()
        .map(|f| f.frame.as_ref().map_or(0, |c| c.capture_time_us))
        .collect();
    let use_capture = capture.windows(2).all(|w| w[0] < w[1]);
    let mut last = i64::MIN;
    let us: Vec<i64> = take
        .frames
        .iter()
        .zip(&capture)
        .map(|(f, &c)| {
            let t = if use_capture { c } else { f.received_us };
            let t = t.max(last.saturating_add(1));
            last = t;
            t
        })
        .collect();
    let first = us.first().copied().unwrap_or(0);
    us.iter().map(|&t| (t - first) as f64 * 1e-6).collect()
}

/// Checks that `model` is the take's (name and SHA-256 `sha256`, hex).
///
/// # Errors
/// [`TakeError::Export`] naming both checksums.
pub fn check_model(take: &Take, model: &TrainedModel, sha256: &str) -> Result<(), TakeError> {
    let want = &take.header().model_sha256;
    if !want.eq_ignore_ascii_case(sha256) {
        return Err(TakeError::Export(format!(
            "the take was recorded on model {:?} with SHA-256 {want}; this model file's is {sha256}",
            take.header().room.as_ref().map_or("", |r| r.model.as_str()),
        )));
    }
    let (bones, controls) = (model.rig.bone_count, model.controls.len());
    if take.header().bones as usize != bones || take.header().controls as usize != controls {
        return Err(TakeError::Export(format!(
            "the take has {} bones and {} control points, the model {bones} and {controls}",
            take.header().bones,
            take.header().controls
        )));
    }
    Ok(())
}

/// The skinning the take's room used: its own choice, else the model's default.
pub fn take_skinning(take: &Take, model: &TrainedModel) -> Skinning {
    let wire = take.header().room.as_ref().map_or(0, |r| r.skinning);
    crate::convert::skinning_from_wire("TakeHeader.room", wire)
        .ok()
        .flatten()
        .unwrap_or(model.skinning)
}

/// Every frame's bone transforms, frame after frame (`frames × bones`, as
/// `core::model::gltf_export::skinned_recording_to_glb` takes them), each frame checked
/// against the header.
///
/// # Errors
/// [`TakeError::FrameShape`].
pub fn all_transforms(take: &Take) -> Result<Vec<RigidTransform>, TakeError> {
    let mut all = Vec::with_capacity(take.frames.len() * take.header().bones as usize);
    let mut one = Vec::new();
    for i in 0..take.frames.len() {
        frame_transforms(take, i, &mut one)?;
        all.extend_from_slice(&one);
    }
    Ok(all)
}

/// A take of a room of several actors (issue 38): actor `k`'s predicted transforms of every
/// frame, frame after frame (`TakeHeader.actors[k].bones` per frame).
///
/// # Errors
/// [`TakeError::FrameShape`]: a frame without actor `k`'s pose, or with another length.
pub fn actor_transforms(take: &Take, k: usize) -> Result<Vec<RigidTransform>, TakeError> {
    let bones = take.header().actors.get(k).map_or(0, |a| a.bones as usize);
    let mut all = Vec::with_capacity(take.frames.len() * bones);
    for (i, f) in take.frames.iter().enumerate() {
        let values = f.actors.get(k).map_or(&[][..], |p| p.transforms.as_slice());
        if bones == 0 || values.len() != 7 * bones {
            return Err(TakeError::FrameShape {
                frame: i,
                what: "actors[k].transforms",
                expected: 7 * bones,
                got: values.len(),
            });
        }
        all.extend(values.chunks_exact(7).map(|v| RigidTransform {
            rotation: Quat::from_xyzw(v[0], v[1], v[2], v[3]),
            translation: Vec3::new(v[4], v[5], v[6]),
        }));
    }
    Ok(all)
}

/// One actor of a take of a room of several actors, as an export needs it
/// ([`actor_recordings`]).
#[derive(Clone, Debug)]
pub struct ActorRecording {
    /// The actor's name.
    pub name: String,
    /// Its model's name, as the room named it.
    pub model: String,
    /// The plane its model was mirrored across, if it was.
    pub mirror: Option<crease_core::model::MirrorPlane>,
    /// How the room skinned it (`None`: the model's default).
    pub skinning: Option<Skinning>,
    /// Its predicted transforms, frame after frame.
    pub transforms: Vec<RigidTransform>,
}

/// Every actor of a take of a room of several actors (issue 38), in the room's order: what a
/// skinned glTF of the take needs of each (`gltf_export::skinned_parts_recording_to_glb`, on
/// the actor's model mirrored as [`ActorRecording::mirror`] says).
///
/// # Errors
/// [`TakeError::Export`] naming the actor: an unreadable mirror plane or skinning, a frame
/// without its pose.
pub fn actor_recordings(take: &Take) -> Result<Vec<ActorRecording>, TakeError> {
    let room = take.header().room.clone().unwrap_or_default();
    room.actors
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let bad = |e: String| TakeError::Export(format!("actor {:?}: {e}", a.name));
            let mirror = match a.mirror.trim() {
                "" => None,
                plane => Some(
                    crease_core::model::MirrorPlane::parse(plane)
                        .map_err(|e| bad(format!("mirror: {e}")))?,
                ),
            };
            let skinning = crate::convert::skinning_from_wire("Actor", a.skinning)
                .map_err(|e| bad(e.to_string()))?;
            Ok(ActorRecording {
                name: a.name.clone(),
                model: a.model.clone(),
                mirror,
                skinning,
                transforms: actor_transforms(take, k).map_err(|e| bad(e.to_string()))?,
            })
        })
        .collect()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn header() -> v1::TakeHeader {
        v1::TakeHeader {
            take: "t-1".into(),
            bones: 2,
            controls: 1,
            ..Default::default()
        }
    }

    fn frame(i: u64) -> v1::TakeFrame {
        let mut record = v1::TakeFrame::default();
        let control = v1::ControlFrame {
            room: "ignored".into(),
            seq: i,
            capture_time_us: 1000 * i as i64,
            positions: vec![i as f32, 1.0, 2.0],
            ..Default::default()
        };
        let t = RigidTransform {
            rotation: Quat::from_rotation_z(0.1 * i as f32),
            translation: Vec3::new(i as f32, 0.0, 0.0),
        };
        fill_frame(&mut record, &control, 10 * i as i64, &[Vec3::X], &[t, t]);
        record
    }

    fn file(frames: u64) -> (Vec<u8>, Vec<usize>) {
        let mut out = Vec::new();
        write_header(&mut out, &header()).unwrap();
        let mut ends = vec![out.len()];
        let mut record = Vec::new();
        for i in 0..frames {
            encode_record(&frame(i), &mut record);
            out.extend_from_slice(&record);
            ends.push(out.len());
        }
        (out, ends)
    }

    #[test]
    fn a_take_reads_back_what_was_written() {
        let (bytes, ends) = file(5);
        let take = read_take(bytes.as_slice()).unwrap();
        assert_eq!(take.header(), &header());
        assert_eq!(take.frames.len(), 5);
        assert!(!take.scan.truncated);
        assert_eq!(take.scan.whole_bytes, *ends.last().unwrap() as u64);
        assert_eq!(take.scan.last_received_us, 40);
        for (i, f) in take.frames.iter().enumerate() {
            assert_eq!(f, &frame(i as u64));
            assert_eq!(
                f.frame.as_ref().unwrap().room,
                "",
                "the room field is emptied"
            );
        }
        let mut t = Vec::new();
        frame_transforms(&take, 3, &mut t).unwrap();
        assert_eq!(t[1].translation, Vec3::new(3.0, 0.0, 0.0));
        assert!((t[1].rotation.angle_between(Quat::from_rotation_z(0.3))).abs() < 1e-6);
        assert_eq!(keyframe_times(&take), vec![0.0, 0.001, 0.002, 0.003, 0.004]);
    }

    #[test]
    fn a_take_cut_anywhere_keeps_its_whole_frames() {
        let (bytes, ends) = file(4);
        for cut in ends[0]..bytes.len() {
            let take = read_take(&bytes[..cut]).unwrap();
            let whole = ends.iter().filter(|&&e| e <= cut).count() - 1;
            assert_eq!(take.frames.len(), whole, "cut at {cut}");
            assert_eq!(take.scan.truncated, !ends.contains(&cut), "cut at {cut}");
            assert_eq!(take.scan.whole_bytes, ends[whole] as u64);
        }
    }

    #[test]
    fn a_corrupted_frame_ends_the_take_there() {
        let (mut bytes, ends) = file(4);
        // A flipped byte inside frame 2's payload fails its CRC.
        bytes[ends[2] + RECORD_HEADER_BYTES + 1] ^= 0x40;
        let take = read_take(bytes.as_slice()).unwrap();
        assert_eq!(take.frames.len(), 2);
        assert!(take.scan.truncated);
    }

    #[test]
    fn damaged_files_never_panic_and_keep_a_prefix_of_whole_frames() {
        // A deterministic xorshift: flipped bytes, zeroed runs, huge lengths, cuts.
        let (bytes, _) = file(6);
        let whole = read_take(bytes.as_slice()).unwrap().frames;
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for _ in 0..2000 {
            let mut damaged = bytes.clone();
            for _ in 0..1 + next() % 4 {
                let len = damaged.len();
                let at = (next() as usize) % len;
                match next() % 3 {
                    0 => damaged[at] ^= 1 << (next() % 8),
                    1 => damaged[at..(at + 4).min(len)].fill(0xff),
                    _ => damaged.truncate(at.max(1)),
                }
            }
            if let Ok(take) = read_take(damaged.as_slice()) {
                // Whatever survives is a prefix of the frames written (a CRC-32 collision on a
                // 2000-case run is not expected).
                assert!(take.frames.len() <= whole.len());
                assert_eq!(take.frames[..], whole[..take.frames.len()]);
            }
        }
    }

    #[test]
    fn not_a_take_and_a_missing_header_are_errors() {
        let err = read_take(&b"PK\x03\x04 zip"[..]).unwrap_err();
        assert!(matches!(err, TakeError::Magic { .. }), "{err}");
        let (bytes, ends) = file(0);
        let err = read_take(&bytes[..ends[0] - 1]).unwrap_err();
        assert!(matches!(err, TakeError::Header(_)), "{err}");
    }

    #[test]
    fn frame_arrays_are_checked_against_the_header() {
        let (bytes, _) = file(2);
        let mut take = read_take(bytes.as_slice()).unwrap();
        take.frames[1].transforms.pop();
        let err = frame_transforms(&take, 1, &mut Vec::new()).unwrap_err();
        assert!(
            err.to_string()
                .contains("transforms has 13 values, expected 14"),
            "{err}"
        );
    }

    #[test]
    fn times_fall_back_to_arrival_when_capture_times_do_not_increase() {
        let (bytes, _) = file(3);
        let mut take = read_take(bytes.as_slice()).unwrap();
        for f in &mut take.frames {
            f.frame.as_mut().unwrap().capture_time_us = 7;
        }
        take.frames[2].received_us = take.frames[1].received_us;
        let times = keyframe_times(&take);
        assert_eq!(times.len(), 3);
        for (t, want) in times.iter().zip([0.0, 10e-6, 11e-6]) {
            assert!((t - want).abs() < 1e-12, "{times:?}");
        }
    }
}
