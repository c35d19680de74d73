// crease frame codec, version 1, in the browser: the decoding half of core::codec (Rust), with
// meshoptimizer's own WASM decoder for the payloads. See core/src/codec/mod.rs for the format:
// a 52-byte little-endian header, then meshopt vertex codec v1 of u16 lanes [x, y, z, w]; a
// delta's lanes add to the previous frame's lanes mod 2^16. Positions decode bit-exactly as
// Math.fround(min + q * step), which is what the Rust decoder computes in f32.

// A relative path to the served package file (crease-server serves web/node_modules at
// /node_modules/), not the bare "meshoptimizer/decoder" of the page's import map: the decode
// worker (decode-worker.js) imports this module too, and module workers do not see import
// maps in every browser. Node resolves the same file (web/node_modules, after `npm ci`).
import { MeshoptDecoder } from "./node_modules/meshoptimizer/meshopt_decoder.mjs";

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
//
// A palette frame is a codec frame (above: keyframe or delta) whose "vertices" are lanes of
// bones and the detail kernel vector: lane vertex 2k is bone k's rotation [a, b, c, i]
// (smallest three: i the index of the largest component of the unit quaternion, made positive
// and dropped; a, b, c the others in order, (x sqrt 2 + 1) / 2 * 65535), lane vertex 2k + 1 its
// translation [x, y, z, 0] in the frame's box (decoded as a position: min + q * step), then
// xi two values per lane vertex [lo, hi, lo, hi] (the 16-bit halves of their f32 bits).

const f = Math.fround;
const FRAC_1_SQRT_2 = f(Math.SQRT1_2);
const bits32 = new DataView(new ArrayBuffer(4));

/** Lane vertices of a palette frame of `bones` bones and `xi` kernel values: 2B + ceil(N/2). */
export function paletteVertexCount(bones, xi) {
  return 2 * bones + Math.ceil(xi / 2);
}

/**
 * Reads a decoded palette frame (`read_palette_lanes` in core/src/codec/palette): `lanes` and
 * `positions` as decodeFrame returns them. Rotations come out as unit quaternions (x, y, z, w)
 * with the f32 arithmetic of the Rust decoder (Math.fround after every operation), translations
 * as the decoded positions of their lane vertices (min + q * step, rounded once, as
 * QuantBox::dequantise), xi from their bits. Throws an Error naming what is wrong (a lane count
 * other than the stream's, a quaternion index above 3, an xi value that is not finite). `out`:
 * {rotations, translations, xi} buffers to reuse when their sizes fit.
 */
export function readPaletteLanes(lanes, positions, bones, xi, out) {
  const expected = paletteVertexCount(bones, xi);
  const got = lanes.length / 4;
  if (got !== expected) {
    throw new Error(`palette frame: ${got} lane vertices, expected ${expected} (${bones} bones, ${xi} xi values)`);
  }
  const rotations = out && out.rotations && out.rotations.length === 4 * bones ? out.rotations : new Float32Array(4 * bones);
  const translations =
    out && out.translations && out.translations.length === 3 * bones ? out.translations : new Float32Array(3 * bones);
  const xis = out && out.xi && out.xi.length === xi ? out.xi : new Float32Array(xi);
  const c = [0, 0, 0, 0];
  for (let k = 0; k < bones; k++) {
    const at = 8 * k; // lane vertex 2k
    const index = lanes[at + 3];
    if (index > 3) throw new Error(`palette frame: bone ${k}: quaternion index ${index}, expected 0..=3`);
    // from_smallest_three: the three stored components in order, skipping `index`.
    let sum = 0;
    for (let j = 0, slot = 0; j < 4; j++) {
      if (j === index) continue;
      const x = f(f(f(f(lanes[at + slot++] / 65535) * 2) - 1) * FRAC_1_SQRT_2);
      c[j] = x;
      sum = f(sum + f(x * x));
    }
    c[index] = f(Math.sqrt(Math.max(0, f(1 - sum))));
    // Quat::normalize: times the reciprocal of the length (glam's SSE2 dot: (x²+z²)+(y²+w²)).
    const sq = (j) => f(c[j] * c[j]);
    const len = f(Math.sqrt(f(f(sq(0) + sq(2)) + f(sq(1) + sq(3)))));
    const rcp = f(1 / len);
    for (let j = 0; j < 4; j++) rotations[4 * k + j] = f(c[j] * rcp);
    translations.set(positions.subarray(3 * (2 * k + 1), 3 * (2 * k + 1) + 3), 3 * k);
  }
  for (let j = 0; j < xi; j++) {
    const at = 4 * (2 * bones + (j >> 1)) + 2 * (j & 1);
    bits32.setUint32(0, (lanes[at] | (lanes[at + 1] << 16)) >>> 0, true);
    const v = bits32.getFloat32(0, true);
    if (!Number.isFinite(v)) throw new Error(`palette frame: xi ${j} is not finite`);
    xis[j] = v;
  }
  return { rotations, translations, xi: xis };
}

/**
 * A palette stream's frame decoder (FrameDecoder + read_palette_lanes in Rust): holds the last
 * frame's lanes for the next delta. decode(bytes) returns {header, seq, rotations, translations,
 * xi, min, step} or throws an Error naming what is wrong: the codec header's (parseHeader), a
 * lane count other than the stream's, a delta on a frame it does not hold (no frame yet, another
 * seq, another box), the payload's, the lanes'. A frame the codec refuses leaves the decoder as
 * it was; one whose lanes are refused still becomes the base of the next delta (as in Rust).
 */
export class PaletteDecoder {
  constructor(bones, xi) {
    this.bones = bones;
    this.xiCount = xi;
    this.vertexCount = paletteVertexCount(bones, xi);
    this.lanes = null;
    this.last = null;
    this.spare = null;
    this.positions = null;
  }

  /** Forgets the held frame: the next must be a keyframe. */
  reset() {
    this.lanes = this.last = null;
  }

  decode(bytes, out) {
    const h = parseHeader(bytes);
    if (h.vertexCount !== this.vertexCount) {
      throw new Error(
        `palette frame ${h.seq}: ${h.vertexCount} lane vertices, expected ${this.vertexCount} ` +
          `(${this.bones} bones, ${this.xiCount} xi values)`,
      );
    }
    if (h.kind === 1) {
      if (!this.last) throw new Error(`palette frame ${h.seq}: a delta on frame ${h.baseSeq}, and no frame is held`);
      if (this.last.seq !== h.baseSeq) {
        throw new Error(`palette frame ${h.seq}: a delta on frame ${h.baseSeq}, the frame held is ${this.last.seq}`);
      }
      const same = (a, b) => a.every((v, k) => Object.is(v, b[k]));
      if (!same(h.min, this.last.min) || !same(h.step, this.last.step)) {
        throw new Error(`palette frame ${h.seq}: a delta in another quantisation box than its base's`);
      }
    }
    let r;
    try {
      r = decodeFrame(bytes, this.lanes, { lanes: this.spare, positions: this.positions });
    } catch (e) {
      throw new Error(`palette frame ${h.seq}: ${e.message}`);
    }
    this.spare = this.lanes;
    this.lanes = r.lanes;
    this.positions = r.positions;
    this.last = h;
    const bones = readPaletteLanes(r.lanes, r.positions, this.bones, this.xiCount, out);
    return { header: h, seq: h.seq, ...bones, min: h.min, step: h.step };
  }
}
