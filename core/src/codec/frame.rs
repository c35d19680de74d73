//! The frame header: 52 bytes in front of a meshopt vertex buffer (layout in the module docs of
//! [`crate::codec`]), and a parser that never panics.

use glam::Vec3;

use super::{CodecError, QuantBox};

/// The first four bytes of every frame.
pub const MAGIC: [u8; 4] = *b"CRSF";
/// The format version this module writes and reads.
pub const VERSION: u8 = 1;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 52;
/// Bytes per vertex in the payload once decoded: four `u16` lanes. meshopt's vertex codec needs
/// a multiple of 4; three lanes of position plus one for the (optional) normal fill it exactly.
pub const VERTEX_SIZE: usize = 8;
/// The flag bit saying lane `w` holds an octahedral normal.
const FLAG_NORMALS: u8 = 1;
/// The first byte of a meshopt vertex codec buffer of version 1 (`0xA0 | version`).
pub(crate) const MESHOPT_VERTEX_V1: u8 = 0xA1;

/// Whether a frame stands alone or applies to the one before it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FrameKind {
    /// The quantised lanes themselves (byte 5 = 0).
    Key,
    /// Lane-wise wrapping differences from the base frame (byte 5 = 1).
    Delta,
}

/// A parsed (or to be written) frame header.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameHeader {
    /// Keyframe or delta.
    pub kind: FrameKind,
    /// Lane `w` holds octahedral normals.
    pub normals: bool,
    /// The quantisation box (min, step, bits).
    pub qbox: QuantBox,
    /// Vertices in the payload.
    pub vertex_count: u32,
    /// This frame's sequence number.
    pub seq: u32,
    /// For a delta, the sequence number of the frame it applies to; for a keyframe, `seq`.
    pub base_seq: u32,
    /// Payload bytes after the header.
    pub payload_len: u32,
}

impl FrameHeader {
    /// Appends the 52 header bytes to `out`.
    pub fn write(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&MAGIC);
        out.push(VERSION);
        out.push(match self.kind {
            FrameKind::Key => 0,
            FrameKind::Delta => 1,
        });
        out.push(if self.normals { FLAG_NORMALS } else { 0 });
        out.push(VERTEX_SIZE as u8);
        out.push(self.qbox.bits());
        out.extend_from_slice(&[0; 3]);
        out.extend_from_slice(&self.vertex_count.to_le_bytes());
        out.extend_from_slice(&self.seq.to_le_bytes());
        out.extend_from_slice(&self.base_seq.to_le_bytes());
        for v in [self.qbox.min(), self.qbox.step()] {
            for c in v.to_array() {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        out.extend_from_slice(&self.payload_len.to_le_bytes());
    }
}

/// Little-endian `u32` at `at`; the caller has checked the length.
fn u32_at(b: &[u8; HEADER_LEN], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Three little-endian `f32`s at `at`.
fn vec3_at(b: &[u8; HEADER_LEN], at: usize) -> Vec3 {
    let f = |k: usize| f32::from_bits(u32_at(b, at + 4 * k));
    Vec3::new(f(0), f(1), f(2))
}

/// Checks a frame's header and splits off its payload. Every field is validated (magic, version,
/// kind, flags, vertex size, bits, reserved bytes, box, a keyframe's base, and that exactly the
/// declared payload follows); the payload itself is checked when decoded. Never panics.
///
/// # Errors
/// The first problem found, in header order: [`CodecError::Truncated`],
/// [`CodecError::BadMagic`], [`CodecError::UnsupportedVersion`], [`CodecError::UnknownKind`],
/// [`CodecError::UnknownFlags`], [`CodecError::VertexSize`], [`CodecError::Bits`],
/// [`CodecError::Reserved`], [`CodecError::InvalidBox`], [`CodecError::KeyframeBase`],
/// [`CodecError::PayloadLength`].
pub fn parse_frame(frame: &[u8]) -> Result<(FrameHeader, &[u8]), CodecError> {
    let Some((head, payload)) = frame.split_first_chunk::<HEADER_LEN>() else {
        return Err(CodecError::Truncated { len: frame.len() });
    };
    let magic = [head[0], head[1], head[2], head[3]];
    if magic != MAGIC {
        return Err(CodecError::BadMagic { found: magic });
    }
    if head[4] != VERSION {
        return Err(CodecError::UnsupportedVersion(head[4]));
    }
    let kind = match head[5] {
        0 => FrameKind::Key,
        1 => FrameKind::Delta,
        k => return Err(CodecError::UnknownKind(k)),
    };
    if head[6] & !FLAG_NORMALS != 0 {
        return Err(CodecError::UnknownFlags(head[6]));
    }
    if usize::from(head[7]) != VERTEX_SIZE {
        return Err(CodecError::VertexSize(head[7]));
    }
    let bits = head[8];
    if !(1..=16).contains(&bits) {
        return Err(CodecError::Bits(bits));
    }
    if head[9..12] != [0; 3] {
        return Err(CodecError::Reserved([head[9], head[10], head[11]]));
    }
    let qbox = QuantBox::from_min_step(vec3_at(head, 24), vec3_at(head, 36), bits)?;
    let (seq, base_seq) = (u32_at(head, 16), u32_at(head, 20));
    if kind == FrameKind::Key && base_seq != seq {
        return Err(CodecError::KeyframeBase {
            seq,
            base: base_seq,
        });
    }
    let payload_len = u32_at(head, 48);
    if usize::try_from(payload_len).ok() != Some(payload.len()) {
        return Err(CodecError::PayloadLength {
            declared: payload_len,
            actual: payload.len(),
        });
    }
    Ok((
        FrameHeader {
            kind,
            normals: head[6] & FLAG_NORMALS != 0,
            qbox,
            vertex_count: u32_at(head, 12),
            seq,
            base_seq,
            payload_len,
        },
        payload,
    ))
}
