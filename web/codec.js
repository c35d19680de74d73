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

// ---- Palette frames (issue 18): core/src/codec/palette (Rust) is the reference ----------------

export const PALETTE_HEADER_LEN = 44;
export const PALETTE_BONE_LEN = 13;
const PALETTE_MAGIC = [0x43, 0x52, 0x50, 0x46]; // "CRPF"
const f = Math.fround;
const FRAC_1_SQRT_2 = f(Math.SQRT1_2);

/**
 * Decodes a palette frame ("CRPF" version 1, `decode_palette_frame` in
 * core/src/codec/palette): a 44-byte header (magic, version u8 @4, flags u8 @5, reserved u16 @6,
 * seq u32 @8, bones u32 @12, xi values u32 @16, translation box min f32x3 @20 and step f32x3
 * @32), then 13 bytes per bone (the largest component's index, the other three quaternion
 * components as u16, the translation as u16x3 in the box), then the xi values as f32. Checks
 * the counts against the receiver's `bones` and `xi` (its header's). Rotations come out as
 * unit quaternions (x, y, z, w) and translations as `min + q * step`, with the f32 arithmetic
 * of the Rust decoder (Math.fround after every operation). Throws an Error naming what is
 * wrong, as the Rust decoder refuses the same frames. `out`: {rotations, translations, xi}
 * buffers to reuse when their sizes fit.
 */
export function decodePaletteFrame(bytes, bones, xi, out) {
  if (bytes.length < PALETTE_HEADER_LEN) {
    throw new Error(`palette frame truncated: ${bytes.length} bytes, expected ${PALETTE_HEADER_LEN}`);
  }
  for (let i = 0; i < 4; i++) {
    if (bytes[i] !== PALETTE_MAGIC[i]) throw new Error('palette frame: bad magic, expected "CRPF"');
  }
  const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const version = dv.getUint8(4);
  if (version !== 1) throw new Error(`unsupported palette frame version ${version}, this decoder reads version 1`);
  const flags = dv.getUint8(5);
  const reserved = dv.getUint16(6, true);
  if (flags !== 0 || reserved !== 0) {
    throw new Error(`palette frame: flags ${flags} and reserved ${reserved}, expected zero`);
  }
  const seq = dv.getUint32(8, true);
  const b = dv.getUint32(12, true);
  const n = dv.getUint32(16, true);
  if (b !== bones) throw new Error(`palette frame: bones ${b}, expected ${bones}`);
  if (n !== xi) throw new Error(`palette frame: xi values ${n}, expected ${xi}`);
  const expected = PALETTE_HEADER_LEN + b * PALETTE_BONE_LEN + 4 * n;
  if (bytes.length < expected) throw new Error(`palette frame truncated: ${bytes.length} bytes, expected ${expected}`);
  if (bytes.length > expected) {
    throw new Error(`palette frame: ${bytes.length} bytes, the header's counts need exactly ${expected}`);
  }
  const min = [0, 1, 2].map((k) => dv.getFloat32(20 + 4 * k, true));
  const step = [0, 1, 2].map((k) => dv.getFloat32(32 + 4 * k, true));
  if (!min.every(Number.isFinite) || !step.every((s) => Number.isFinite(s) && s > 0)) {
    throw new Error(`palette frame: translation box min ${min} step ${step} is not usable`);
  }
  const rotations = out && out.rotations && out.rotations.length === 4 * b ? out.rotations : new Float32Array(4 * b);
  const translations =
    out && out.translations && out.translations.length === 3 * b ? out.translations : new Float32Array(3 * b);
  const xis = out && out.xi && out.xi.length === n ? out.xi : new Float32Array(n);
  const c = [0, 0, 0, 0];
  for (let k = 0; k < b; k++) {
    const at = PALETTE_HEADER_LEN + k * PALETTE_BONE_LEN;
    const index = bytes[at];
    if (index > 3) throw new Error(`palette frame: bone ${k}: quaternion index ${index}, expected 0..=3`);
    // from_smallest_three: the three stored components in order, skipping `index`.
    let sum = 0;
    for (let j = 0, slot = 0; j < 4; j++) {
      if (j === index) continue;
      const v = dv.getUint16(at + 1 + 2 * slot++, true);
      const x = f(f(f(f(v / 65535) * 2) - 1) * FRAC_1_SQRT_2);
      c[j] = x;
      sum = f(sum + f(x * x));
    }
    c[index] = f(Math.sqrt(Math.max(0, f(1 - sum))));
    // Quat::normalize: times the reciprocal of the length (glam's SSE2 dot: (x²+z²)+(y²+w²)).
    const sq = (j) => f(c[j] * c[j]);
    const len = f(Math.sqrt(f(f(sq(0) + sq(2)) + f(sq(1) + sq(3)))));
    const rcp = f(1 / len);
    for (let j = 0; j < 4; j++) rotations[4 * k + j] = f(c[j] * rcp);
    for (let j = 0; j < 3; j++) {
      translations[3 * k + j] = f(min[j] + f(dv.getUint16(at + 7 + 2 * j, true) * step[j]));
    }
  }
  const xiAt = PALETTE_HEADER_LEN + b * PALETTE_BONE_LEN;
  for (let k = 0; k < n; k++) {
    const v = dv.getFloat32(xiAt + 4 * k, true);
    if (!Number.isFinite(v)) throw new Error(`palette frame: xi ${k} is not finite`);
    xis[k] = v;
  }
  return { seq, rotations, translations, xi: xis, min, step };
}
