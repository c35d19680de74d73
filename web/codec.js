// crease frame codec, version 1, in the browser: the decoding half of core::codec (Rust), with
// meshoptimizer's own WASM decoder for the payloads. See core/src/codec/mod.rs for the format:
// a 52-byte little-endian header, then meshopt vertex codec v1 of u16 lanes [x, y, z, w]; a
// delta's lanes add to the previous frame's lanes mod 2^16. Positions decode bit-exactly as
// Math.fround(min + q * step), which is what the Rust decoder computes in f32.

import { MeshoptDecoder } from "meshoptimizer/decoder";

export const HEADER_LEN = 52;
const MAGIC = [0x43, 0x52, 0x53, 0x46]; // "CRSF"

/** Resolves when meshopt's WASM decoder is ready. */
export const ready = MeshoptDecoder.ready;

/**
 * Parses a frame header (`FrameHeader::write` in core/src/codec/frame.rs): magic "CRSF",
 * version u8 @4, kind u8 @5 (0 key, 1 delta), flags u8 @6 (1 = normals), vertex size u8 @7,
 * bits u8 @8, 3 reserved, vertex count u32 @12, seq u32 @16, base seq u32 @20, min f32x3 @24,
 * step f32x3 @36, payload length u32 @48. Throws an Error naming what is wrong.
 */
export function parseHeader(bytes) {
  if (bytes.length < HEADER_LEN) {
    throw new Error(`frame: ${bytes.length} bytes, shorter than the ${HEADER_LEN}-byte header`);
  }
  for (let i = 0; i < 4; i++) {
    if (bytes[i] !== MAGIC[i]) throw new Error("frame: not a crease frame (magic)");
  }
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const version = dv.getUint8(4);
  if (version !== 1) throw new Error(`frame: version ${version}, expected 1`);
  const kind = dv.getUint8(5);
  if (kind > 1) throw new Error(`frame: kind ${kind}, expected 0 (key) or 1 (delta)`);
  const flags = dv.getUint8(6);
  const vertexSize = dv.getUint8(7);
  const bits = dv.getUint8(8);
  if (vertexSize !== 8) throw new Error(`frame: vertex size ${vertexSize}, expected 8`);
  const vertexCount = dv.getUint32(12, true);
  const seq = dv.getUint32(16, true);
  const baseSeq = dv.getUint32(20, true);
  const min = [0, 1, 2].map((k) => dv.getFloat32(24 + 4 * k, true));
  const step = [0, 1, 2].map((k) => dv.getFloat32(36 + 4 * k, true));
  const payloadLen = dv.getUint32(48, true);
  if (payloadLen !== bytes.length - HEADER_LEN) {
    throw new Error(
      `frame: payload length ${payloadLen}, but ${bytes.length - HEADER_LEN} bytes follow the header`,
    );
  }
  return { kind, normals: (flags & 1) !== 0, bits, vertexCount, seq, baseSeq, min, step, payloadLen };
}

/**
 * Decodes one frame. `prev`: the previous frame's lanes (needed for a delta). Returns the
 * header, this frame's lanes (keep them for the next delta) and the positions (xyz per vertex).
 * `out`: optional {lanes, positions} buffers to reuse when their sizes fit.
 */
export function decodeFrame(bytes, prev, out) {
  const h = parseHeader(bytes);
  const n = h.vertexCount;
  const lanes = out && out.lanes && out.lanes.length === 4 * n ? out.lanes : new Uint16Array(4 * n);
  MeshoptDecoder.decodeVertexBuffer(
    new Uint8Array(lanes.buffer, lanes.byteOffset, lanes.byteLength),
    n,
    8,
    bytes.subarray(HEADER_LEN, HEADER_LEN + h.payloadLen),
  );
  if (h.kind === 1) {
    if (!prev || prev.length !== 4 * n) {
      throw new Error(`frame ${h.seq}: a delta on frame ${h.baseSeq}, which this decoder does not hold`);
    }
    for (let i = 0; i < 4 * n; i++) lanes[i] = (prev[i] + lanes[i]) & 0xffff;
  }
  const positions =
    out && out.positions && out.positions.length === 3 * n ? out.positions : new Float32Array(3 * n);
  const [mx, my, mz] = h.min;
  const [sx, sy, sz] = h.step;
  for (let i = 0; i < n; i++) {
    positions[3 * i] = Math.fround(mx + lanes[4 * i] * sx);
    positions[3 * i + 1] = Math.fround(my + lanes[4 * i + 1] * sy);
    positions[3 * i + 2] = Math.fround(mz + lanes[4 * i + 2] * sz);
  }
  return { header: h, lanes, positions };
}

/** Decodes `triangleCount` triangles of meshopt's index codec (3 indices each). */
export function decodeIndices(bytes, triangleCount, vertexCount) {
  const out = new Uint32Array(3 * triangleCount);
  MeshoptDecoder.decodeIndexBuffer(new Uint8Array(out.buffer), 3 * triangleCount, 4, bytes);
  for (let i = 0; i < out.length; i++) {
    if (out[i] >= vertexCount) {
      throw new Error(`indices: triangle ${Math.floor(i / 3)} has vertex ${out[i]}, only ${vertexCount}`);
    }
  }
  return out;
}
