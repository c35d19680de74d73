//! Streams of frames: [`FrameEncoder`] / [`FrameDecoder`] with keyframes and deltas, and the
//! stateless keyframe path.

use glam::Vec3;

use super::CodecError;
use super::frame::{FrameHeader, FrameKind, MESHOPT_VERTEX_V1, parse_frame};
use super::quant::{QuantBox, lane_normal, normal_lane};

/// Default keyframe interval of [`FrameEncoder`]: half a second at 60 Hz. Keyframes cost about
/// 1.5x a delta on the horse gallop (4.5 vs 3.0 bytes per vertex), so one in 30 frames adds 1-2%
/// to the stream while bounding how long a client that joined without help waits for one.
/// Servers that hand joiners a keyframe of the current frame ([`encode_keyframe_from_lanes`])
/// can raise it.
pub const DEFAULT_KEYFRAME_INTERVAL: u32 = 30;

/// meshopt's vertex encoder level: its default (2). On the horse gallop (16 bits, deltas)
/// level 1 encodes ~30% faster but its deltas are 5% larger; level 3 is no smaller and ~25%
/// slower. Encoding happens once per frame for all subscribers, so bytes win.
const MESHOPT_LEVEL: i32 = 2;

/// One frame's lanes: `[x, y, z, w]` per vertex (see the module docs of [`crate::codec`]).
type Lanes = Vec<[u16; 4]>;

/// Checks the lengths of a frame's inputs against `vertex_count`.
fn check_inputs(
    vertex_count: usize,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
) -> Result<(), CodecError> {
    if positions.len() != vertex_count {
        return Err(CodecError::Length {
            what: "positions",
            expected: vertex_count,
            found: positions.len(),
        });
    }
    if let Some(n) = normals
        && n.len() != vertex_count
    {
        return Err(CodecError::Length {
            what: "normals",
            expected: vertex_count,
            found: n.len(),
        });
    }
    Ok(())
}

/// Quantises positions (and normals into lane `w`, else 0) into `out`, reusing its capacity.
fn quantise_lanes(qbox: &QuantBox, positions: &[Vec3], normals: Option<&[Vec3]>, out: &mut Lanes) {
    out.clear();
    match normals {
        Some(normals) => out.extend(positions.iter().zip(normals).map(|(&p, &n)| {
            let [x, y, z] = qbox.quantise(p);
            [x, y, z, normal_lane(n)]
        })),
        None => out.extend(positions.iter().map(|&p| {
            let [x, y, z] = qbox.quantise(p);
            [x, y, z, 0]
        })),
    }
}

/// Writes header + meshopt-encoded `lanes` into `out` (cleared first).
fn write_frame(
    mut header: FrameHeader,
    lanes: &[[u16; 4]],
    out: &mut Vec<u8>,
) -> Result<FrameHeader, CodecError> {
    // Version 1 explicitly: the crate's safe API takes it per call (the global
    // `meshopt_encodeVertexVersion` setter is `unsafe`).
    let payload = meshopt::encode_vertex_buffer_level(lanes, MESHOPT_LEVEL, Some(1))
        .map_err(|_| CodecError::EncoderFailed("vertex buffer"))?;
    if payload.first() != Some(&MESHOPT_VERTEX_V1) {
        return Err(CodecError::EncoderFailed("vertex buffer"));
    }
    header.payload_len =
        u32::try_from(payload.len()).map_err(|_| CodecError::TooManyVertices(lanes.len()))?;
    out.clear();
    out.reserve(super::HEADER_LEN + payload.len());
    header.write(out);
    out.extend_from_slice(&payload);
    Ok(header)
}

/// Decodes a payload of `vertex_count` vertices into lanes.
fn decode_payload(payload: &[u8], vertex_count: usize) -> Result<Lanes, CodecError> {
    super::block::decode_vertex_buffer_v1::<[u16; 4]>(payload, vertex_count)
}

/// Parses a frame and checks it is for `vertex_count` vertices.
fn parse_for(frame: &[u8], vertex_count: usize) -> Result<(FrameHeader, &[u8]), CodecError> {
    let (header, payload) = parse_frame(frame)?;
    if usize::try_from(header.vertex_count).ok() != Some(vertex_count) {
        return Err(CodecError::VertexCount {
            expected: vertex_count,
            found: header.vertex_count as usize,
        });
    }
    Ok((header, payload))
}

/// Dequantised positions of `lanes` into `out` (cleared first).
fn write_positions(qbox: &QuantBox, lanes: &[[u16; 4]], out: &mut Vec<Vec3>) {
    out.clear();
    out.extend(lanes.iter().map(|&[x, y, z, _]| qbox.dequantise([x, y, z])));
}

/// Decoded normals of `lanes` into `out` (cleared first).
fn write_normals(lanes: &[[u16; 4]], out: &mut Vec<Vec3>) {
    out.clear();
    out.extend(lanes.iter().map(|&[_, _, _, w]| lane_normal(w)));
}

/// Encodes one keyframe without an encoder's state (e.g. a snapshot, or a test).
/// Allocates its quantised lanes; streams should use [`FrameEncoder`].
///
/// # Errors
/// [`CodecError::Length`] if `normals` is not as long as `positions`,
/// [`CodecError::TooManyVertices`] past `u32::MAX`.
pub fn encode_keyframe(
    qbox: &QuantBox,
    seq: u32,
    positions: &[Vec3],
    normals: Option<&[Vec3]>,
    out: &mut Vec<u8>,
) -> Result<FrameHeader, CodecError> {
    check_inputs(positions.len(), positions, normals)?;
    let mut lanes = Vec::with_capacity(positions.len());
    quantise_lanes(qbox, positions, normals, &mut lanes);
    encode_keyframe_from_lanes(qbox, seq, &lanes, normals.is_some(), out)
}

/// Encodes a keyframe of already quantised `lanes` (`[x, y, z, w]` per vertex in `qbox`, as
/// [`FrameEncoder::lanes`] gives them; `normals`: lane `w` holds encoded normals) with
/// sequence number `seq`, into `out` (cleared first). A server keeps the lanes of the frame it
/// encoded and makes the keyframe of that same frame on demand for a subscriber that lacks the
/// delta's base: a decoder given it holds exactly those lanes and accepts the deltas that
/// follow, without the positions being quantised a second time.
///
/// # Errors
/// [`CodecError::TooManyVertices`] past `u32::MAX`.
pub fn encode_keyframe_from_lanes(
    qbox: &QuantBox,
    seq: u32,
    lanes: &[[u16; 4]],
    normals: bool,
    out: &mut Vec<u8>,
) -> Result<FrameHeader, CodecError> {
    let vertex_count =
        u32::try_from(lanes.len()).map_err(|_| CodecError::TooManyVertices(lanes.len()))?;
    let header = FrameHeader {
        kind: FrameKind::Key,
        normals,
        qbox: *qbox,
        vertex_count,
        seq,
        base_seq: seq,
        payload_len: 0,
    };
    write_frame(header, lanes, out)
}

/// Decodes one keyframe of `vertex_count` vertices without a decoder's state: positions into
/// `positions`, and normals into `normals` when given (cleared if the frame has none).
///
/// # Errors
/// Everything [`parse_frame`] reports, [`CodecError::VertexCount`], the payload errors, and
/// [`CodecError::MissingBase`] for a delta frame.
pub fn decode_keyframe(
    frame: &[u8],
    vertex_count: usize,
    positions: &mut Vec<Vec3>,
    normals: Option<&mut Vec<Vec3>>,
) -> Result<FrameHeader, CodecError> {
    let (header, payload) = parse_for(frame, vertex_count)?;
    if header.kind == FrameKind::Delta {
        return Err(CodecError::MissingBase {
            seq: header.seq,
            base: header.base_seq,
        });
    }
    let lanes = decode_payload(payload, vertex_count)?;
    write_positions(&header.qbox, &lanes, positions);
    if let Some(normals) = normals {
        if header.normals {
            write_normals(&lanes, normals);
        } else {
            normals.clear();
        }
    }
    Ok(header)
}

/// The last frame an encoder wrote, as its decoders hold it.
#[derive(Clone, Copy, Debug)]
struct Last {
    seq: u32,
    normals: bool,
}

/// Encodes a stream of frames of one mesh in one quantisation box: a keyframe first and every
/// `keyframe_interval` frames (or when forced, or when normals come or go), deltas from the
/// previous frame in between. Buffers are reused: after the first frame it allocates only inside
/// meshopt's encoder (see the module docs).
///
/// Sequence numbers count from 0 and wrap; each frame's header carries its own and its base's.
#[derive(Clone, Debug)]
pub struct FrameEncoder {
    qbox: QuantBox,
    vertex_count: usize,
    keyframe_interval: u32,
    /// The last encoded frame's lanes: exactly what a decoder holds after it.
    lanes: Lanes,
    /// The incoming frame's lanes.
    next: Lanes,
    /// The delta being encoded.
    delta: Lanes,
    last: Option<Last>,
    next_seq: u32,
    since_key: u32,
    force_key: bool,
}

impl FrameEncoder {
    /// An encoder for meshes of `vertex_count` vertices in `qbox`. `keyframe_interval`: a
    /// keyframe every that many frames; 1 sends only keyframes; 0 sends keyframes only for the
    /// first frame and when asked ([`FrameEncoder::force_keyframe`]).
    ///
    /// # Errors
    /// [`CodecError::TooManyVertices`] past `u32::MAX`.
    pub fn new(
        vertex_count: usize,
        qbox: QuantBox,
        keyframe_interval: u32,
    ) -> Result<FrameEncoder, CodecError> {
        if u32::try_from(vertex_count).is_err() {
            return Err(CodecError::TooManyVertices(vertex_count));
        }
        Ok(FrameEncoder {
            qbox,
            vertex_count,
            keyframe_interval,
            lanes: Vec::with_capacity(vertex_count),
            next: Vec::with_capacity(vertex_count),
            delta: Vec::with_capacity(vertex_count),
            last: None,
            next_seq: 0,
            since_key: 0,
            force_key: false,
        })
    }

    /// The quantisation box.
    pub fn qbox(&self) -> &QuantBox {
        &self.qbox
    }

    /// The vertex count frames must have.
    pub fn vertex_count(&self) -> usize {
        self.vertex_count
    }

    /// The sequence number the next frame will carry.
    pub fn next_seq(&self) -> u32 {
        self.next_seq
    }

    /// The last encoded frame's quantised lanes (what every decoder in sync holds).
    pub fn lanes(&self) -> &[[u16; 4]] {
        &self.lanes
    }

    /// Makes the next frame a keyframe.
    pub fn force_keyframe(&mut self) {
        self.force_key = true;
    }

    /// Encodes the next frame into `out` (cleared first) and returns its header.
    ///
    /// # Errors
    /// [`CodecError::Length`] if `positions` or `normals` do not have the encoder's vertex count.
    /// On error the encoder's state is unchanged.
    pub fn encode(
        &mut self,
        positions: &[Vec3],
        normals: Option<&[Vec3]>,
        out: &mut Vec<u8>,
    ) -> Result<FrameHeader, CodecError> {
        check_inputs(self.vertex_count, positions, normals)?;
        quantise_lanes(&self.qbox, positions, normals, &mut self.next);
        self.encode_next(normals.is_some(), out)
    }

    /// Encodes the next frame from lanes the caller fills (`fill` gets the cleared lane buffer:
    /// a stream whose lanes are not positions, e.g. `palette`'s bones), without normals.
    ///
    /// # Errors
    /// [`CodecError::Length`] if `fill` did not push one lane vertex per vertex. On error the
    /// encoder's state is unchanged.
    pub fn encode_lanes(
        &mut self,
        fill: impl FnOnce(&mut Vec<[u16; 4]>),
        out: &mut Vec<u8>,
    ) -> Result<FrameHeader, CodecError> {
        self.next.clear();
        fill(&mut self.next);
        if self.next.len() != self.vertex_count {
            return Err(CodecError::Length {
                what: "lanes",
                expected: self.vertex_count,
                found: self.next.len(),
            });
        }
        self.encode_next(false, out)
    }

    /// Encodes `self.next` (keyframe or delta, module docs).
    fn encode_next(
        &mut self,
        has_normals: bool,
        out: &mut Vec<u8>,
    ) -> Result<FrameHeader, CodecError> {
        let seq = self.next_seq;
        let base = match self.last {
            Some(last)
                if !self.force_key
                    && last.normals == has_normals
                    && (self.keyframe_interval == 0 || self.since_key < self.keyframe_interval) =>
            {
                Some(last.seq)
            }
            _ => None,
        };
        let mut header = FrameHeader {
            kind: FrameKind::Key,
            normals: has_normals,
            qbox: self.qbox,
            vertex_count: self.vertex_count as u32,
            seq,
            base_seq: seq,
            payload_len: 0,
        };
        let header = match base {
            None => write_frame(header, &self.next, out)?,
            Some(base) => {
                self.delta.clear();
                self.delta
                    .extend(self.next.iter().zip(&self.lanes).map(|(n, l)| {
                        [
                            n[0].wrapping_sub(l[0]),
                            n[1].wrapping_sub(l[1]),
                            n[2].wrapping_sub(l[2]),
                            n[3].wrapping_sub(l[3]),
                        ]
                    }));
                header.kind = FrameKind::Delta;
                header.base_seq = base;
                write_frame(header, &self.delta, out)?
            }
        };
        std::mem::swap(&mut self.lanes, &mut self.next);
        self.last = Some(Last {
            seq,
            normals: has_normals,
        });
        self.next_seq = seq.wrapping_add(1);
        self.since_key = if base.is_none() {
            1
        } else {
            self.since_key.saturating_add(1)
        };
        self.force_key = false;
        Ok(header)
    }
}

/// Decodes a stream of frames of one mesh: keeps the last frame's lanes to apply deltas to.
/// A frame that fails to decode leaves the decoder's frame as it was (and the deltas that follow
/// it are then refused for their base, until a keyframe).
#[derive(Clone, Debug)]
pub struct FrameDecoder {
    vertex_count: usize,
    lanes: Lanes,
    last: Option<FrameHeader>,
}

impl FrameDecoder {
    /// A decoder for frames of `vertex_count` vertices (from the subscription's topology).
    pub fn new(vertex_count: usize) -> FrameDecoder {
        FrameDecoder {
            vertex_count,
            lanes: Vec::new(),
            last: None,
        }
    }

    /// Decodes one frame. A keyframe replaces the decoder's frame; a delta applies to it if it is
    /// the delta's base. Returns the frame's header.
    ///
    /// # Errors
    /// Everything [`parse_frame`] reports; [`CodecError::VertexCount`];
    /// [`CodecError::MissingBase`] / [`CodecError::BaseMismatch`] /
    /// [`CodecError::BaseIncompatible`] for a delta this decoder cannot apply; the payload errors
    /// ([`CodecError::PayloadEmpty`], [`CodecError::PayloadVersion`],
    /// [`CodecError::PayloadCorrupt`]). On error the decoder's frame is unchanged.
    pub fn decode(&mut self, frame: &[u8]) -> Result<FrameHeader, CodecError> {
        let (header, payload) = parse_for(frame, self.vertex_count)?;
        if header.kind == FrameKind::Delta {
            let Some(last) = &self.last else {
                return Err(CodecError::MissingBase {
                    seq: header.seq,
                    base: header.base_seq,
                });
            };
            if last.seq != header.base_seq {
                return Err(CodecError::BaseMismatch {
                    seq: header.seq,
                    base: header.base_seq,
                    have: last.seq,
                });
            }
            if last.qbox != header.qbox {
                return Err(CodecError::BaseIncompatible {
                    seq: header.seq,
                    what: "quantisation box",
                });
            }
            if last.normals != header.normals {
                return Err(CodecError::BaseIncompatible {
                    seq: header.seq,
                    what: "normals flag",
                });
            }
        }
        let decoded = decode_payload(payload, self.vertex_count)?;
        match header.kind {
            FrameKind::Key => self.lanes = decoded,
            FrameKind::Delta => {
                for (l, d) in self.lanes.iter_mut().zip(&decoded) {
                    for k in 0..4 {
                        l[k] = l[k].wrapping_add(d[k]);
                    }
                }
            }
        }
        self.last = Some(header);
        Ok(header)
    }

    /// The header of the frame the decoder holds, if any.
    pub fn header(&self) -> Option<&FrameHeader> {
        self.last.as_ref()
    }

    /// The frame's quantised lanes (empty before the first keyframe).
    pub fn lanes(&self) -> &[[u16; 4]] {
        &self.lanes
    }

    /// The frame's positions into `out` (cleared first; left empty before the first keyframe).
    pub fn positions(&self, out: &mut Vec<Vec3>) {
        match &self.last {
            Some(h) => write_positions(&h.qbox, &self.lanes, out),
            None => out.clear(),
        }
    }

    /// The frame's normals into `out` (cleared first); `false`, with `out` empty, if the frame
    /// carries none.
    pub fn normals(&self, out: &mut Vec<Vec3>) -> bool {
        match &self.last {
            Some(h) if h.normals => {
                write_normals(&self.lanes, out);
                true
            }
            _ => {
                out.clear();
                false
            }
        }
    }

    /// Forgets the frame: the next frame must be a keyframe.
    pub fn reset(&mut self) {
        self.last = None;
        self.lanes.clear();
    }
}
