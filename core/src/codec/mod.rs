//! Compact per-frame vertex buffers for streaming deforming meshes to browsers and CLI clients.
//!
//! A frame is the mesh's vertex positions (and optionally normals) quantised to 16-bit integers
//! and compressed with meshoptimizer's vertex codec, format version 1, behind a small header.
//! Browsers decode the payload with meshoptimizer's own JavaScript decoder
//! (`MeshoptDecoder.decodeVertexBuffer` from `meshoptimizer/decoder`); the rest is a few lines of
//! plain JS (see "Decoding in JavaScript" below). The triangles travel once, at the start of a
//! subscription, through meshopt's index codec ([`encode_indices`], [`decode_indices`]).
//!
//! References: the meshoptimizer README, sections "Vertex compression" and "Index compression"
//! (<https://github.com/zeux/meshoptimizer>), and the bitstream specification of both codecs in
//! the glTF extension `KHR_meshopt_compression` (modes `ATTRIBUTES` and `TRIANGLES`). Octahedral
//! normals: Cigolle, Donow, Evangelakos, Mara, McGuire, Meyer, "A Survey of Efficient
//! Representations for Independent Unit Vectors", JCGT 3(2), 2014, §3.3 (CDE14 below).
//!
//! Layout:
//! - [`quant`]: [`QuantBox`] (16-bit positions in a fixed box, the half-step error bound,
//!   clamping and NaN) and the octahedral normal encoding.
//! - [`frame`]: the frame header ([`FrameHeader`]) and its parser [`parse_frame`], which never
//!   panics and names what is wrong ([`CodecError`]).
//! - [`stream`]: [`FrameEncoder`] / [`FrameDecoder`] (keyframes and deltas, reusable buffers) and
//!   the stateless keyframe path ([`encode_keyframe`], [`decode_keyframe`]).
//! - [`index`]: the index buffer (topology) through meshopt's index codec.
//! - [`palette`]: palette frames, a skinned mesh's frame as its bone transforms and detail
//!   kernel vector (quantised quaternions and translations, the error bound of a skinned vertex).
//!
//! # Vertices: 8 bytes, four 16-bit lanes
//!
//! meshopt's vertex codec needs a vertex size that is a multiple of 4 bytes, so a vertex is four
//! little-endian `u16` lanes, `[x, y, z, w]`:
//! - `x, y, z`: the position, quantised in the frame's box: `q = round((p - min) / step)`,
//!   clamped to `0..=2^bits - 1` (see [`QuantBox`] for NaN and infinities). Decoded
//!   `p' = min + q * step`; `|p' - p| <= step / 2` per axis for points inside the box, i.e.
//!   `extent / (2^bits - 1) / 2` (`extent / 65535 / 2` at 16 bits), plus the rounding of the
//!   result to `f32`.
//! - `w`: zero, or, when the frame's normals flag is set, the vertex normal octahedral-encoded
//!   (CDE14) as two signed 8-bit values: low byte `u`, high byte `v`, each `round(c * 127)` as
//!   an `i8` (two's complement). 8-bit octahedral normals are within [`OCT_MAX_ERROR_DEG`] degrees
//!   of the input direction.
//!
//! # Keyframes and deltas
//!
//! A keyframe's payload is the lanes themselves. A delta frame's payload is, lane by lane, the
//! wrapping difference `lanes[i] - base[i] (mod 2^16)` from the frame before it as the decoder
//! holds it; the decoder adds it back (`base[i] + delta[i] mod 2^16`). The vertex codec is
//! lossless, so the decoded previous frame is exactly the encoder's previous quantised frame:
//! deltas accumulate no drift, every frame is within the same half-step bound.
//!
//! Measured on the horse gallop (8,431 vertices, 48 frames, box padded by 25%), 16 bits: a
//! keyframe is about 4.5 bytes per vertex, a delta about 3.0, so deltas pay (a third smaller).
//! Fewer bits shrink deltas by about 3/8 byte per vertex per bit (12 bits: 1.7), and meshopt's
//! spatial vertex order, applied once to the model, by another 7-9%;
//! `cargo bench -p crease-core --bench codec` prints the current figures.
//!
//! A decoder applies a delta only to the frame it was computed from: the header carries the
//! frame's sequence number and its base's. A decoder that joined mid-stream, skipped a frame, or
//! failed to decode one refuses deltas ([`CodecError::MissingBase`], [`CodecError::BaseMismatch`])
//! until it gets a keyframe. [`encode_keyframe_from_lanes`] encodes a frame's quantised lanes
//! ([`FrameEncoder::lanes`] right after it) again as a keyframe with the same sequence number,
//! so a server can hand one to a joining or lagging subscriber and let it follow the shared
//! deltas from there.
//!
//! # Frame layout (version 1)
//!
//! All multi-byte fields little-endian; a frame is exactly `52 + payload length` bytes.
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0  | 4  | magic, ASCII `CRSF` (`43 52 53 46`) |
//! | 4  | 1  | format version, `1` |
//! | 5  | 1  | kind: `0` keyframe, `1` delta |
//! | 6  | 1  | flags: bit 0 set = lane `w` holds octahedral normals; other bits zero |
//! | 7  | 1  | vertex size in bytes, `8` |
//! | 8  | 1  | quantisation bits, `1..=16` (informative: the decoder needs only `min` and `step`) |
//! | 9  | 3  | reserved, zero |
//! | 12 | 4  | vertex count, `u32` |
//! | 16 | 4  | sequence number of this frame, `u32` (wraps) |
//! | 20 | 4  | base: for a delta the sequence number of the frame it applies to; for a keyframe equal to its own sequence number |
//! | 24 | 12 | box `min`, 3 × `f32` (x, y, z); finite |
//! | 36 | 12 | `step`, 3 × `f32`; finite and positive |
//! | 48 | 4  | payload length in bytes, `u32` |
//! | 52 | n  | payload: meshopt vertex codec version 1 (first byte `0xA1`), vertex count × 8 bytes once decoded |
//!
//! # Decoding in JavaScript
//!
//! ```js
//! import { MeshoptDecoder } from 'meshoptimizer/decoder';
//! await MeshoptDecoder.ready;
//! const dv = new DataView(buf.buffer, buf.byteOffset, buf.byteLength);
//! // check magic, version 1, vertex size 8, payload length === buf.length - 52 ...
//! const kind = dv.getUint8(5), n = dv.getUint32(12, true), len = dv.getUint32(48, true);
//! const lanes = new Uint16Array(n * 4);       // little-endian hosts: every browser
//! MeshoptDecoder.decodeVertexBuffer(new Uint8Array(lanes.buffer), n, 8, buf.subarray(52, 52 + len));
//! if (kind === 1) for (let i = 0; i < 4 * n; i++) lanes[i] = (base[i] + lanes[i]) & 0xffff;
//! const min = [0, 1, 2].map(k => dv.getFloat32(24 + 4 * k, true));
//! const step = [0, 1, 2].map(k => dv.getFloat32(36 + 4 * k, true));
//! // position k of vertex i, bit-identical to the Rust decoder:
//! //   Math.fround(min[k] + lanes[4 * i + k] * step[k])
//! ```
//!
//! A viewer can also upload the lanes as a `Uint16` attribute and put `min` and `step` in the
//! mesh's transform (position and scale), leaving dequantisation to the GPU. Normals decode as in
//! [`oct_decode`] (the same operations in `f64`, so JS matches it bit for bit).
//!
//! # Allocation
//!
//! [`FrameEncoder`] and [`FrameDecoder`] keep their lane buffers between frames and write into a
//! caller's `Vec<u8>` / `Vec<Vec3>`; after the first frame their own code allocates nothing. The
//! meshopt crate's safe wrappers do allocate one buffer per call (the encoded bytes, or the
//! decoded lanes); the slice-writing FFI functions are `unsafe`, which this workspace forbids.
//!
//! The test vectors in `tests/vectors/codec-v1.json` at the repository root (inputs, encoded
//! bytes, decoded values) pin this format for other decoders; `core/tests/codec.rs` documents how
//! they are regenerated.

pub mod block;
pub mod frame;
pub mod index;
pub mod palette;
pub mod quant;
pub mod stream;

pub use block::{decode_vertex_block, encode_vertex_block};
pub use frame::{FrameHeader, FrameKind, HEADER_LEN, MAGIC, VERSION, VERTEX_SIZE, parse_frame};
pub use index::{apply_corner_turns, corner_turns, decode_indices, encode_indices, spatial_order};
pub use quant::{OCT_MAX_ERROR_DEG, QuantBox, oct_decode, oct_encode};
pub use stream::{
    DEFAULT_KEYFRAME_INTERVAL, FrameDecoder, FrameEncoder, decode_keyframe, encode_keyframe,
    encode_keyframe_from_lanes,
};

/// Everything that can go wrong encoding or decoding frames and index buffers. Parsing errors
/// name the field at fault, since frames may come from the network.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CodecError {
    /// Fewer bytes than the 52-byte header.
    #[error("frame truncated: {len} bytes, the header alone needs {HEADER_LEN}")]
    Truncated {
        /// Bytes received.
        len: usize,
    },
    /// The first four bytes are not `CRSF`.
    #[error("bad magic {found:02x?}, expected \"CRSF\"")]
    BadMagic {
        /// The four bytes found.
        found: [u8; 4],
    },
    /// A format version this decoder does not read.
    #[error("unsupported frame format version {0}, this decoder reads version {VERSION}")]
    UnsupportedVersion(u8),
    /// A kind byte other than 0 (key) or 1 (delta).
    #[error("unknown frame kind {0} (0 = keyframe, 1 = delta)")]
    UnknownKind(u8),
    /// Flag bits this version does not define.
    #[error("unknown flag bits {0:#04x} (only bit 0, normals, is defined)")]
    UnknownFlags(u8),
    /// A vertex size other than 8.
    #[error("vertex size {0} bytes, format version 1 uses {VERTEX_SIZE}")]
    VertexSize(u8),
    /// Quantisation bits outside `1..=16`.
    #[error("quantisation bits {0}, expected 1..=16")]
    Bits(u8),
    /// The reserved header bytes 9..12 are not zero.
    #[error("reserved header bytes 9..12 are {0:02x?}, expected zero")]
    Reserved([u8; 3]),
    /// A keyframe whose base field is not its own sequence number.
    #[error("keyframe {seq} names base {base}; a keyframe's base is its own sequence number")]
    KeyframeBase {
        /// The frame's sequence number.
        seq: u32,
        /// Its base field.
        base: u32,
    },
    /// A quantisation box that cannot be used (non-finite min, non-positive step, bad margin).
    #[error("quantisation box: {0}")]
    InvalidBox(&'static str),
    /// The header's payload length disagrees with the bytes that follow it.
    #[error("payload length: the header declares {declared} bytes, the frame carries {actual}")]
    PayloadLength {
        /// The header's payload length.
        declared: u32,
        /// The bytes after the header.
        actual: usize,
    },
    /// A frame, or positions/normals handed to an encoder, for another vertex count.
    #[error("vertex count mismatch: expected {expected}, got {found}")]
    VertexCount {
        /// What the decoder or encoder was set up for.
        expected: usize,
        /// What the frame or the caller has.
        found: usize,
    },
    /// The payload does not start with meshopt's vertex codec version 1 header byte (`0xA1`).
    #[error(
        "payload is not a meshopt vertex buffer of version 1 (first byte {0:#04x}, expected 0xa1)"
    )]
    PayloadVersion(u8),
    /// The payload is empty.
    #[error("payload is empty")]
    PayloadEmpty,
    /// meshopt refused the payload (its error code: -1 bad header, -2 truncated or corrupt,
    /// -3 trailing bytes).
    #[error("payload failed to decode (meshopt error {0})")]
    PayloadCorrupt(i32),
    /// A delta arrived before any frame: the decoder must wait for (or be given) a keyframe.
    #[error(
        "delta frame {seq} needs frame {base}, but the decoder holds no frame yet (wait for a keyframe)"
    )]
    MissingBase {
        /// The delta's sequence number.
        seq: u32,
        /// The frame it applies to.
        base: u32,
    },
    /// A delta computed from another frame than the one the decoder holds (a skipped or failed
    /// frame): wait for a keyframe.
    #[error(
        "delta frame {seq} needs frame {base}, but the decoder holds frame {have} (wait for a keyframe)"
    )]
    BaseMismatch {
        /// The delta's sequence number.
        seq: u32,
        /// The frame it applies to.
        base: u32,
        /// The frame the decoder holds.
        have: u32,
    },
    /// A delta whose quantisation box or normals flag differs from its base frame's.
    #[error("delta frame {seq}: its {what} differs from its base frame's")]
    BaseIncompatible {
        /// The delta's sequence number.
        seq: u32,
        /// `"quantisation box"` or `"normals flag"`.
        what: &'static str,
    },
    /// Input slices of the wrong length handed to an encoder.
    #[error("{what}: expected {expected} values, got {found}")]
    Length {
        /// `"positions"` or `"normals"`.
        what: &'static str,
        /// The vertex count.
        expected: usize,
        /// The slice's length.
        found: usize,
    },
    /// More vertices than a `u32` counts.
    #[error("{0} vertices: a frame holds at most 2^32 - 1")]
    TooManyVertices(usize),
    /// A triangle names a vertex past the end.
    #[error("triangle {triangle} uses vertex {index}, but the mesh has {vertex_count} vertices")]
    IndexOutOfRange {
        /// The triangle's position in the list.
        triangle: usize,
        /// The offending index.
        index: u32,
        /// The mesh's vertex count.
        vertex_count: usize,
    },
    /// An encoded index buffer shorter than the triangle count allows (meshopt needs at least
    /// `1 + triangles + 16` bytes).
    #[error("index buffer truncated: {len} bytes, {triangles} triangles need at least {needed}")]
    IndexTruncated {
        /// Bytes received.
        len: usize,
        /// The expected triangle count.
        triangles: usize,
        /// The minimum encoded size for that many triangles.
        needed: usize,
    },
    /// The index buffer does not start with meshopt's index codec version 1 header (`0xE1`).
    #[error(
        "index buffer is not meshopt's index codec version 1 (first byte {0:#04x}, expected 0xe1)"
    )]
    IndexVersion(u8),
    /// meshopt refused the index buffer (its error code).
    #[error("index buffer failed to decode (meshopt error {0})")]
    IndexCorrupt(i32),
    /// A triangle's corner turn of 3 (turns are 0, 1 or 2).
    #[error("triangle {triangle}: corner turn 3, expected 0, 1 or 2")]
    CornerTurn {
        /// The triangle's position in the list.
        triangle: usize,
    },
    /// meshopt's encoder returned nothing (its output bound was too small): a bug.
    #[error("meshopt produced no output for a {0}")]
    EncoderFailed(&'static str),
}

/// The meshopt error code, for [`CodecError::PayloadCorrupt`] / [`CodecError::IndexCorrupt`].
fn meshopt_code(e: meshopt::Error) -> i32 {
    match e {
        meshopt::Error::Native(code) => code,
        _ => i32::MIN,
    }
}
