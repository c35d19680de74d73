// Synthetic palette streams for palette.test.mjs: a small mesh (an octahedron, closed or with
// a hole, Loop-subdivided), a few bones, a skin, a detail regressor, encoded as the server
// would (protobuf MeshFrame { palette_topology }: the base triangles through meshopt's index
// codec with their corner turns, the Loop level count, D and b as i16 multiples of one step in
// meshopt vertex-codec blocks, issue 41; then MeshFrame { frame } whose data are codec frames
// of palette lanes, a keyframe then deltas: core/src/codec/palette), and a reference of what
// the viewer must draw, computed here in f64 from the decoded values (web/codec.js's
// PaletteDecoder, the header's q / 65535 and q * step) and Loop steps of its own (loopStep
// below: an implementation independent of web/loop.js, on the same numbering, so that the rows
// of D line up). Lets the GPU passes of web/palette.js be checked without a server that streams
// palettes, on meshes small enough to read, with every branch the real one has (several
// subdivision steps, K up to 8, bones over 256, rows of D longer than one texel, buffers wider
// than the texture).

import { MeshoptDecoder } from "../../web/node_modules/meshoptimizer/meshopt_decoder.mjs";
import { MeshoptEncoder } from "../../web/node_modules/meshoptimizer/meshopt_encoder.js";

const f = Math.fround;

// ---- protobuf writer -----------------------------------------------------------------------

class Writer {
  constructor() {
    this.parts = [];
  }
  raw(bytes) {
    this.parts.push(bytes);
    return this;
  }
  varint(v) {
    const out = [];
    let x = BigInt(v);
    do {
      let byte = Number(x & 0x7fn);
      x >>= 7n;
      if (x > 0n) byte |= 0x80;
      out.push(byte);
    } while (x > 0n);
    return this.raw(Uint8Array.from(out));
  }
  tag(field, wire) {
    return this.varint(field * 8 + wire);
  }
  uint(field, v) {
    return v ? this.tag(field, 0).varint(v) : this;
  }
  bytes(field, b) {
    return this.tag(field, 2).varint(b.length).raw(b);
  }
  message(field, w) {
    return this.bytes(field, w.finish());
  }
  string(field, s) {
    return this.bytes(field, new TextEncoder().encode(s));
  }
  f32(field, v) {
    const b = new Uint8Array(4);
    new DataView(b.buffer).setFloat32(0, v, true);
    return this.tag(field, 5).raw(b);
  }
  finish() {
    const n = this.parts.reduce((s, p) => s + p.length, 0);
    const out = new Uint8Array(n);
    let at = 0;
    for (const p of this.parts) {
      out.set(p, at);
      at += p.length;
    }
    return out;
  }
}

const le = (Type, values) => new Uint8Array(Type.from(values).buffer);

// ---- the mesh ------------------------------------------------------------------------------

/** An octahedron, outward winding, `size` across, centred at `c`. */
function octahedron(size, c) {
  const r = size / 2;
  const v = [
    [r, 0, 0], [-r, 0, 0], [0, r, 0], [0, -r, 0], [0, 0, r], [0, 0, -r],
  ].map((p) => p.map((x, k) => f(x + c[k])));
  const t = [
    [0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4],
    [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5],
  ];
  return { positions: v, triangles: t };
}

/** One Loop subdivision step of a manifold triangle mesh, closed or with boundary (n vertices,
 * triangles): the rows (the old vertices, then one per edge in the order edges are first met,
 * each triangle [a, b, c] along ab, bc, ca), as [column, f32 weight] lists (a column may
 * repeat: the reference sums rows in f64), and the new triangles. Loop's rules with Warren's
 * beta; Hoppe's boundary rules (ARCHITECTURE.md, "Palette streams"). */
function loopStep(n, triangles) {
  const edges = new Map(); // "a,b" (a < b) -> {id, opposite: []}
  const neighbours = Array.from({ length: n }, () => new Set());
  const key = (a, b) => (a < b ? `${a},${b}` : `${b},${a}`);
  for (const [a, b, c] of triangles) {
    for (const [x, y, z] of [[a, b, c], [b, c, a], [c, a, b]]) {
      const k = key(x, y);
      if (!edges.has(k)) edges.set(k, { a: Math.min(x, y), b: Math.max(x, y), id: n + edges.size, opposite: [] });
      edges.get(k).opposite.push(z);
      neighbours[x].add(y);
      neighbours[y].add(x);
    }
  }
  for (const e of edges.values()) {
    if (e.opposite.length > 2) throw new Error("loopStep: a non-manifold edge");
  }
  const rows = [];
  for (let v = 0; v < n; v++) {
    const ring = [...neighbours[v]];
    const boundary = ring.filter((u) => edges.get(key(u, v)).opposite.length === 1);
    const k = ring.length;
    if (k === 0) rows.push([[v, 1]]);
    else if (boundary.length === 2) rows.push([[v, f(3 / 4)], ...boundary.map((u) => [u, f(1 / 8)])]);
    else if (boundary.length === 0) {
      const beta = k > 3 ? 3 / (8 * k) : 3 / 16;
      rows.push([[v, f(1 - k * beta)], ...ring.map((u) => [u, f(beta)])]);
    } else throw new Error(`loopStep: vertex ${v} has ${boundary.length} boundary edges`);
  }
  for (const e of edges.values()) {
    if (e.opposite.length === 1) rows.push([[e.a, f(1 / 2)], [e.b, f(1 / 2)]]);
    else rows.push([[e.a, f(3 / 8)], [e.b, f(3 / 8)], [e.opposite[0], f(1 / 8)], [e.opposite[1], f(1 / 8)]]);
  }
  const mid = (x, y) => edges.get(key(x, y)).id;
  const next = [];
  for (const [a, b, c] of triangles) {
    const ab = mid(a, b), bc = mid(b, c), ca = mid(c, a);
    next.push([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]);
  }
  return { rows, columns: n, triangles: next };
}

/** `triangles` ([a, b, c] lists) through meshopt's index codec (the header's `indices`). */
export function baseIndices(triangles) {
  const flat = triangles.flat();
  return MeshoptEncoder.encodeIndexBuffer(Uint32Array.from(flat), flat.length, 4);
}

/** The corner turns (2 bits a triangle, four to a byte, low bits first) that bring the
 * triangles meshopt's index codec gives back of `indices` to `triangles` (the model's): k with
 * the decoded [a, b, c] turned left k times ([b, c, a] for 1) equal to the model's. */
export function cornerTurns(indices, triangles) {
  const decoded = new Uint32Array(3 * triangles.length);
  MeshoptDecoder.decodeIndexBuffer(new Uint8Array(decoded.buffer), decoded.length, 4, indices);
  const turns = new Uint8Array(Math.ceil(triangles.length / 4));
  triangles.forEach((t, i) => {
    const d = decoded.subarray(3 * i, 3 * i + 3);
    const k = [0, 1, 2].find((k) => [0, 1, 2].every((j) => d[(j + k) % 3] === t[j]));
    if (k === undefined) throw new Error(`cornerTurns: triangle ${i} decodes as [${d}], not a rotation of [${t}]`);
    turns[i >> 2] |= k << (2 * (i & 3));
  });
  return turns;
}

/** `rows` (width i16 values per row) as the header's detail_blocks: block j holds values 2j
 * and 2j + 1 of every row (0 past the row's end), meshopt's vertex codec version 1 of 4-byte
 * vertices (level 3, as core::codec::block). */
export function detailBlocks(rows, width) {
  const count = rows.length / width;
  const blocks = [];
  for (let first = 0; first < width; first += 2) {
    const values = new Int16Array(2 * count);
    for (let v = 0; v < count; v++) {
      values[2 * v] = rows[v * width + first];
      values[2 * v + 1] = first + 1 < width ? rows[v * width + first + 1] : 0;
    }
    const data = MeshoptEncoder.encodeVertexBufferLevel(new Uint8Array(values.buffer), count, 4, 3, 1);
    if (data[0] !== 0xa1) throw new Error(`detailBlocks: meshopt wrote version byte 0x${data[0].toString(16)}, not 0xa1`);
    blocks.push(data);
  }
  return blocks;
}

/** A deterministic generator (mulberry32). */
function rng(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

function normalise(q) {
  const l = Math.hypot(...q);
  return q.map((x) => x / l);
}

/**
 * A synthetic palette stream: {header (MeshFrame bytes), frames: [MeshFrame bytes], exact (the
 * transforms and xi encoded), vertexCount, baseVertices, triangles, bounds, model (what the
 * header holds, for the reference)}. `level` "base" or "detail"; `steps` Loop levels; `K`;
 * `bones`; `examples` N; `odd` (base level): an open fan, a fan that does not chain and a
 * vertex of no triangle; `open` (either level): a triangle missing (a boundary of three
 * edges).
 */
export async function syntheticStream({
  level,
  steps = 2,
  K = 4,
  bones = 3,
  examples = 5,
  seed = 18,
  frames = 2,
  odd = false,
  open = false,
  keyframeInterval = 0,
}) {
  await MeshoptEncoder.ready;
  await MeshoptDecoder.ready;
  const rand = rng(seed);
  const base = octahedron(0.2, [0.01, 0.08, -0.005]);
  if (odd) {
    // Base level only (Loop needs a closed manifold): an open fan (a triangle missing), a
    // triangle of the other winding (a fan that does not chain) and a vertex of no triangle
    // (its normal is zero).
    if (level !== "base") throw new Error("odd meshes are for the base level");
    base.triangles = [...base.triangles.slice(1), [base.triangles[5][0], base.triangles[5][2], base.triangles[5][1]]];
    base.positions.push([0.05, 0.05, 0.05].map(f));
  }
  if (open) base.triangles = base.triangles.slice(0, -1);
  const nb = base.positions.length;
  // Skin: K slots per vertex, the first few used, weights summing to 65535.
  const skinBones = [];
  const skinWeights = [];
  for (let v = 0; v < nb; v++) {
    const used = 1 + Math.floor(rand() * K);
    const raw = Array.from({ length: used }, () => 0.05 + rand());
    const total = raw.reduce((s, x) => s + x, 0);
    const q = raw.map((x) => Math.floor((x / total) * 65535));
    q[0] += 65535 - q.reduce((s, x) => s + x, 0);
    for (let k = 0; k < K; k++) {
      skinBones.push(k < used ? Math.floor(rand() * bones) : 0);
      skinWeights.push(k < used ? q[k] : 0);
    }
  }
  let triangles = base.triangles;
  let n = nb;
  const stepList = [];
  if (level === "detail") {
    for (let s = 0; s < steps; s++) {
      const st = loopStep(n, triangles);
      stepList.push(st);
      triangles = st.triangles;
      n = st.rows.length;
    }
  }
  const N = level === "detail" ? examples : 0;
  // D and b: i16 values q, one step for all (core::codec::palette::detail_quantum's form).
  const detailRows = [];
  const detailStep = f(0.004 / 32767);
  if (level === "detail") {
    for (let v = 0; v < n; v++) {
      // Some rows small (meshopt's few-bit groups), most over the whole i16 range.
      const range = v % 5 === 0 ? 40 : 32767;
      for (let j = 0; j <= N; j++) detailRows.push(Math.round((rand() * 2 - 1) * range));
    }
  }
  // The base triangles, in model vertex ids, at both levels.
  const indices = baseIndices(base.triangles);
  const lo = [-0.15, -0.05, -0.15];
  const hi = [0.17, 0.25, 0.14];
  const topo = new Writer()
    .string(1, "synthetic")
    .uint(2, level === "detail" ? 2 : 1)
    .uint(3, 1)
    .uint(4, n)
    .uint(5, base.triangles.length)
    .bytes(6, indices)
    .message(
      7,
      new Writer()
        .message(1, new Writer().f32(1, lo[0]).f32(2, lo[1]).f32(3, lo[2]))
        .message(2, new Writer().f32(1, hi[0]).f32(2, hi[1]).f32(3, hi[2])),
    )
    .uint(8, bones)
    .uint(9, nb)
    .bytes(10, le(Float32Array, base.positions.flat()))
    .uint(11, K)
    .bytes(12, bones <= 256 ? Uint8Array.from(skinBones) : le(Uint16Array, skinBones))
    .bytes(13, le(Uint16Array, skinWeights));
  if (level === "detail") {
    topo.uint(15, N).uint(21, steps).f32(22, detailStep);
    for (const b of detailBlocks(detailRows, N + 1)) topo.bytes(23, b);
    topo.bytes(24, cornerTurns(indices, base.triangles));
  }
  const header = new Writer().message(3, topo).finish();
  // Frames: random rotations (both signs of the quaternion) and translations, a keyframe first
  // (and every keyframeInterval frames), deltas between.
  const exact = [];
  const out = [];
  const qbox = translationBox(0.06);
  const encoder = new LaneEncoder(paletteLaneCount(bones, N), qbox);
  for (let s = 0; s < frames; s++) {
    const bs = [];
    for (let b = 0; b < bones; b++) {
      let q = normalise([rand() * 2 - 1, rand() * 2 - 1, rand() * 2 - 1, rand() * 2 - 1]);
      if (b === 0 && s === 0) q = [0, 0, 0, 1]; // identity
      if (b === 1 && s === 0) q = [0, 1, 0, 0]; // a half turn (w = 0)
      bs.push({ q, t: [0.05 * (rand() * 2 - 1), 0.05 * (rand() * 2 - 1), 0.05 * (rand() * 2 - 1)] });
    }
    const xi = Array.from({ length: N }, () => f(rand() * 2 - 1));
    exact.push({ bones: bs, xi });
    const key = s === 0 || (keyframeInterval > 0 && s % keyframeInterval === 0);
    const data = encoder.encode(100 + s, paletteLanes(bs, xi, qbox), key);
    const frame = new Writer().uint(1, 100 + s).uint(3, 5).bytes(4, data);
    out.push(new Writer().message(2, frame).finish());
  }
  return {
    header,
    frames: out,
    exact,
    vertexCount: n,
    baseVertices: nb,
    triangles,
    bounds: [lo, hi],
    model: {
      rest: base.positions,
      K,
      bones,
      skinBones,
      skinWeights,
      baseTriangles: base.triangles,
      steps: stepList.map((s) => s.rows),
      N,
      detailRows,
      detailStep,
    },
  };
}

/** Lane vertices of a palette frame: 2B + ceil(N / 2). */
export function paletteLaneCount(bones, xi) {
  return 2 * bones + Math.ceil(xi / 2);
}

/** A 16-bit translation box: the cube [-r, r] (as core's translation_box). */
export function translationBox(r) {
  const min = [0, 1, 2].map(() => f(-r));
  const step = [0, 1, 2].map(() => f((2 * r) / 65535));
  return { min, step };
}

/** The palette lanes of `bones` ({q: [x, y, z, w], t: [x, y, z]}) and `xi` (palette_lanes in
 * core/src/codec/palette): Uint16Array, 4 per lane vertex. */
export function paletteLanes(bones, xi, qbox) {
  const B = bones.length;
  const lanes = new Uint16Array(4 * paletteLaneCount(B, xi.length));
  bones.forEach((b, k) => {
    const c = normalise(b.q);
    let index = 0;
    for (let j = 1; j < 4; j++) if (Math.abs(c[j]) >= Math.abs(c[index])) index = j; // the last max
    const sign = c[index] < 0 ? -1 : 1;
    let slot = 0;
    for (let j = 0; j < 4; j++) {
      if (j === index) continue;
      const v = Math.min(1, Math.max(-1, sign * c[j] * Math.SQRT2));
      lanes[8 * k + slot++] = Math.round((v + 1) * 0.5 * 65535);
    }
    lanes[8 * k + 3] = index;
    for (let j = 0; j < 3; j++) {
      const t = (f(b.t[j]) - qbox.min[j]) / qbox.step[j];
      lanes[8 * k + 4 + j] = Math.floor(Math.min(65535, Math.max(0, t)) + 0.5);
    }
  });
  const dv = new DataView(new ArrayBuffer(4));
  xi.forEach((x, j) => {
    dv.setFloat32(0, x, true);
    const bits = dv.getUint32(0, true);
    const at = 4 * (2 * B + (j >> 1)) + 2 * (j & 1);
    lanes[at] = bits & 0xffff;
    lanes[at + 1] = bits >>> 16;
  });
  return lanes;
}

/** core::codec frames (FrameHeader::write in core/src/codec/frame.rs, then meshopt's vertex
 * codec v1 of the lanes; a delta's lanes are the differences mod 2^16 from the frame before). */
export class LaneEncoder {
  constructor(vertexCount, qbox) {
    this.n = vertexCount;
    this.qbox = qbox;
    this.prev = null;
    this.prevSeq = 0;
  }
  encode(seq, lanes, key) {
    const delta = !key && this.prev;
    const body = delta ? lanes.map((v, i) => (v - this.prev[i]) & 0xffff) : lanes;
    const payload = MeshoptEncoder.encodeVertexBufferLevel(new Uint8Array(body.buffer), this.n, 8, 2, 1);
    const out = new Uint8Array(52 + payload.length);
    const dv = new DataView(out.buffer);
    out.set([0x43, 0x52, 0x53, 0x46], 0); // "CRSF"
    out[4] = 1; // version
    out[5] = delta ? 1 : 0;
    out[6] = 0; // no normals
    out[7] = 8; // vertex size
    out[8] = 16; // bits
    dv.setUint32(12, this.n, true);
    dv.setUint32(16, seq, true);
    dv.setUint32(20, delta ? this.prevSeq : seq, true);
    for (let k = 0; k < 3; k++) {
      dv.setFloat32(24 + 4 * k, this.qbox.min[k], true);
      dv.setFloat32(36 + 4 * k, this.qbox.step[k], true);
    }
    dv.setUint32(48, payload.length, true);
    out.set(payload, 52);
    this.prev = Uint16Array.from(lanes);
    this.prevSeq = seq;
    return out;
  }
}

// ---- the reference ---------------------------------------------------------------------------

function rotate([x, y, z, w], [px, py, pz]) {
  // q p q* for a unit quaternion.
  const tx = 2 * (y * pz - z * py), ty = 2 * (z * px - x * pz), tz = 2 * (x * py - y * px);
  return [px + w * tx + (y * tz - z * ty), py + w * ty + (z * tx - x * tz), pz + w * tz + (x * ty - y * tx)];
}

/** Area-weighted unit vertex normals (zero where the sum is zero), f64. */
export function vertexNormals(positions, triangles) {
  const n = positions.map(() => [0, 0, 0]);
  for (const [a, b, c] of triangles) {
    const [pa, pb, pc] = [positions[a], positions[b], positions[c]];
    const u = [pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]];
    const v = [pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]];
    const cr = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    for (const i of [a, b, c]) for (let k = 0; k < 3; k++) n[i][k] += cr[k];
  }
  return n.map((x) => {
    const l = Math.hypot(...x);
    return l > 0 ? x.map((c) => c / l) : [0, 0, 0];
  });
}

/**
 * The drawn mesh of one decoded frame (`decoded`: PaletteDecoder's {rotations, translations,
 * xi}), f64 from the header's decoded values: {positions: [[x, y, z]], normals}.
 */
export function referenceMesh(stream, decoded) {
  const m = stream.model;
  const base = m.rest.map((p, v) => {
    const out = [0, 0, 0];
    for (let k = 0; k < m.K; k++) {
      const w = f(m.skinWeights[v * m.K + k] / 65535);
      const b = m.skinBones[v * m.K + k];
      const q = Array.from(decoded.rotations.subarray(4 * b, 4 * b + 4));
      const t = decoded.translations.subarray(3 * b, 3 * b + 3);
      const r = rotate(q, p);
      for (let c = 0; c < 3; c++) out[c] += w * (r[c] + t[c]);
    }
    return out;
  });
  let level = base;
  for (const rows of m.steps) {
    level = rows.map((row) => {
      const out = [0, 0, 0];
      for (const [c, w] of row) for (let k = 0; k < 3; k++) out[k] += w * level[c][k];
      return out;
    });
  }
  let out = level;
  if (m.steps.length) {
    const n = vertexNormals(level, stream.triangles);
    out = level.map((p, v) => {
      let h = 0;
      for (let j = 0; j <= m.N; j++) {
        const d = f(m.detailRows[v * (m.N + 1) + j] * m.detailStep);
        h += d * (j < m.N ? decoded.xi[j] : 1);
      }
      return p.map((x, k) => x + h * n[v][k]);
    });
  }
  return { positions: out, normals: vertexNormals(out, stream.triangles) };
}
