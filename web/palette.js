// Palette streams on the GPU (issue 18): the server sends once a PaletteTopology (rest mesh,
// skin, base triangles, and at the detail level the number of Loop levels and the detail
// regressor D, b; the Loop steps and the drawn triangles are rebuilt here by loop.js, issue
// 41), then per frame only the bones (and the detail kernel vector xi) as the lanes of a codec
// frame, keyframe or delta (PaletteDecoder in codec.js; core/src/codec/palette is the
// reference). This module turns them into the drawn mesh with WebGL2 float render targets, one
// full-screen pass per step:
//
//   skin      base_v = sum_k w_vk (R_k rest_v + t_k)             (linear blend skinning, K <= 8)
//   subdivide level_s = S_s level_(s-1), s = 1..L                (CSR gather, detail level only)
//   displace  out_v = high_v + (sum_j D_vj xi_j + b_v) n_v       (n of high; detail level only)
//   normals   normal_v = unit area-weighted normal of out at v   (for shading)
//
// at the base level `out` is `base`. A vertex's normal is the sum over its incident triangles
// [v, a, b] (winding order) of cross(p_a - p_v, p_b - p_v), normalised, zero when the sum is
// zero: the per-vertex neighbour chains (incidentChains) are built once at load, in CSR. Every buffer is an RGBA32F
// render target W = min(4096, max texture size) texels wide, vertex i at (i % W, i / W); the
// constant data are DataTextures (R32UI / RG32UI for indices, with weights as their f32 bits,
// RGBA32F for positions and D). Per frame the main thread decodes the palette frame and
// uploads 2 texels per bone and (N + 1) / 4 vec4s of xi (a uniform array): no per-vertex work.
//
//   const synth = new PaletteSynth(renderer);
//   synth.load(readPaletteTopology(bytes));   // throws an Error naming what is wrong
//   synth.setFrame(frameData);                 // decodes the stream's next frame (throws if bad)
//   synth.update();                            // runs the passes if a frame is pending
//   synth.positions, synth.normals             // the render targets of the drawn mesh
//   synth.readback()                           // Float32Array, x, y, z per drawn vertex
//   synth.material(params), synth.geometry()   // what draws them (gl_VertexID fetches)

import * as THREE from "three";
// The same relative path as codec.js's (the decode worker's reasons apply to this module's
// importers too): meshopt's decoder for the header's detail blocks.
import { MeshoptDecoder } from "./node_modules/meshoptimizer/meshopt_decoder.mjs";
import { PaletteDecoder, decodeIndices } from "./codec.js";
import { MAX_LEVELS, loopSteps } from "./loop.js";
import { littleEndian } from "./wire.js";

/** Whether this renderer can render into float targets (WebGL2 + EXT_color_buffer_float). */
export function floatTargetsSupported(renderer) {
  return Boolean(renderer.capabilities.isWebGL2 && renderer.extensions.has("EXT_color_buffer_float"));
}

const f32 = Math.fround;

function headerError(message) {
  return new Error(`palette header: ${message}`);
}

function expectLength(what, got, expected) {
  if (got !== expected) throw headerError(`${what} has ${got} entries, expected ${expected}`);
}

/** Stored detail values per meshopt block (`PaletteTopology.detail_blocks`). */
const BLOCK_VALUES = 2;
/** The first byte of meshopt's vertex codec, version 1 (core::codec's MESHOPT_VERTEX_V1). */
const MESHOPT_VERTEX_V1 = 0xa1;

/** Turns each base triangle left by its 2 bits of `turns` (core::codec::apply_corner_turns):
 * the index codec may start a triangle at another corner, Loop's numbering may not. */
function applyTurns(triangles, turns) {
  const count = triangles.length / 3;
  const expected = Math.ceil(count / 4);
  if (turns.length !== expected) {
    throw headerError(`triangle_turns is ${turns.length} bytes, expected ${expected} (2 bits for each of ${count} triangles)`);
  }
  for (let t = 0; t < count; t++) {
    const k = (turns[t >> 2] >> (2 * (t & 3))) & 3;
    if (k === 0) continue;
    if (k === 3) throw headerError(`triangle_turns: triangle ${t} has turn 3, expected 0, 1 or 2`);
    const a = triangles[3 * t], b = triangles[3 * t + 1], c = triangles[3 * t + 2];
    // Left k times: [b, c, a] for k = 1, [c, a, b] for k = 2.
    triangles[3 * t] = k === 1 ? b : c;
    triangles[3 * t + 1] = k === 1 ? c : a;
    triangles[3 * t + 2] = k === 1 ? a : b;
  }
}

/** The detail values: `nv` rows of `width` i16 q in meshopt blocks of BLOCK_VALUES per row
 * (`detail_blocks`), as f32(q * step). */
function decodeDetail(blocks, nv, width, step) {
  const detail = new Float32Array(nv * width);
  const bytes = new Uint8Array(4 * nv);
  const q = new Int16Array(bytes.buffer);
  blocks.forEach((data, j) => {
    const what = `detail_blocks[${j}]`;
    if (data.length === 0) throw headerError(`${what} is empty`);
    if (data[0] !== MESHOPT_VERTEX_V1) {
      throw headerError(`${what}: meshopt vertex codec byte 0x${data[0].toString(16)}, expected 0x${MESHOPT_VERTEX_V1.toString(16)} (version 1)`);
    }
    try {
      MeshoptDecoder.decodeVertexBuffer(bytes, nv, 4, data);
    } catch (e) {
      throw headerError(`${what}: ${e.message} (${data.length} bytes for ${nv} rows)`);
    }
    const first = BLOCK_VALUES * j;
    const second = first + 1 < width;
    // Typed arrays are little-endian on every platform a browser runs on (codec.js reads its
    // lanes the same way).
    for (let v = 0; v < nv; v++) {
      detail[v * width + first] = f32(q[2 * v] * step);
      if (second) detail[v * width + first + 1] = f32(q[2 * v + 1] * step);
    }
  });
  return detail;
}

/**
 * Checks a PaletteTopology (readPaletteTopology in wire.js) the way read_palette_topology and
 * PaletteHeader::validate do (proto/src/palette.rs, core/src/codec/palette/header.rs), decodes
 * its arrays and, at the detail level, rebuilds the Loop steps and the drawn triangles from the
 * base triangles (loop.js, issue 41): {model, level ("base" | "detail"), vertexCount (drawn),
 * triangleCount (drawn), triangles (Uint32Array, 3 per drawn triangle), baseTriangles (the
 * base mesh's, in the model's corner order), levels (0 at the base level), bounds, bones,
 * baseVertices, rest (Float32Array, xyz), influences, skinBones (Uint32Array), skinWeights
 * (Float32Array, q / 65535), steps [{rows, columns, rowPtr, cols (Uint32Array), weights
 * (Float32Array, one per entry)}], examples, detailStep, detail (Float32Array, N + 1 values
 * per drawn vertex: f32(q * detailStep)) or null}. Throws an Error naming the first thing that
 * is wrong.
 */
export function decodePaletteTopology(t) {
  if (t.version !== 1) throw headerError(`palette lane layout version ${t.version}, this viewer reads version 1`);
  const detailLevel = t.level === 2;
  const nb = t.baseVertices;
  const rest = littleEndian(t.restPositions, Float32Array, "rest_positions");
  expectLength("rest_positions (floats)", rest.length, 3 * nb);
  const restBad = rest.findIndex((v) => !Number.isFinite(v));
  if (restBad >= 0) throw headerError(`rest position ${Math.floor(restBad / 3)}: not finite`);
  const K = t.influences;
  if (!(K >= 1 && K <= 8)) throw headerError(`influences ${K}, expected 1..=8`);
  const skinBones = Uint32Array.from(
    littleEndian(t.skinBones, t.bones <= 256 ? Uint8Array : Uint16Array, "skin_bones"),
  );
  expectLength("skin bones", skinBones.length, nb * K);
  const badBone = skinBones.findIndex((b) => b >= t.bones);
  if (badBone >= 0) throw headerError(`skin bone ${badBone} is ${skinBones[badBone]}, expected < ${t.bones}`);
  const q = littleEndian(t.skinWeights, Uint16Array, "skin_weights");
  expectLength("skin weights", q.length, nb * K);
  const skinWeights = new Float32Array(q.length);
  for (let v = 0; v < nb; v++) {
    let sum = 0;
    for (let k = 0; k < K; k++) {
      sum += q[v * K + k];
      skinWeights[v * K + k] = f32(q[v * K + k] / 65535);
    }
    if (sum !== 65535) throw headerError(`skin weights of vertex ${v}: sum to ${sum}, expected 65535`);
  }
  // The base triangles (meshopt's index codec spends at least a byte per triangle: a count
  // past the bytes is refused before anything is allocated for it).
  if (t.triangleCount > t.indices.length) {
    throw headerError(`triangle_count ${t.triangleCount}, but indices has only ${t.indices.length} bytes`);
  }
  let baseTriangles;
  try {
    baseTriangles = decodeIndices(t.indices, t.triangleCount, nb);
  } catch (e) {
    throw headerError(e.message.startsWith("indices") ? e.message : `indices: ${e.message}`);
  }
  let steps = [];
  let triangles = baseTriangles;
  let detail = null;
  let levels = 0;
  let step = 0;
  const N = detailLevel ? t.examples : 0;
  if (detailLevel) {
    levels = t.subdivisionLevels;
    if (!(levels >= 1 && levels <= MAX_LEVELS)) {
      throw headerError(`subdivision_levels ${levels}, expected 1..=${MAX_LEVELS} at the detail level`);
    }
    applyTurns(baseTriangles, t.triangleTurns);
    step = t.detailStep;
    if (!(Number.isFinite(step) && step > 0)) throw headerError(`detail_step ${step}, expected a finite value > 0`);
    const width = N + 1;
    const blocks = Math.ceil(width / BLOCK_VALUES);
    if (t.detailBlocks.length !== blocks) {
      throw headerError(
        `detail_blocks has ${t.detailBlocks.length} blocks, expected ${blocks} (${width} values per row, ${BLOCK_VALUES} per block)`,
      );
    }
    let rebuilt;
    try {
      rebuilt = loopSteps(nb, baseTriangles, levels);
    } catch (e) {
      throw headerError(`the base triangles (indices, triangle_turns) do not subdivide: ${e.message}`);
    }
    steps = rebuilt.steps;
    triangles = rebuilt.triangles;
    const drawn = steps[steps.length - 1].rows;
    if (t.vertexCount !== drawn) {
      throw headerError(`vertex_count ${t.vertexCount}, but ${levels} Loop levels of the base mesh give ${drawn}`);
    }
    detail = decodeDetail(t.detailBlocks, drawn, width, step);
  } else if (t.vertexCount !== nb) {
    throw headerError(`vertex_count ${t.vertexCount}, expected base_vertices ${nb} at the base level`);
  }
  const b = t.bounds || { min: [0, 0, 0], max: [0, 0, 0] };
  return {
    model: t.model,
    level: detailLevel ? "detail" : "base",
    vertexCount: t.vertexCount,
    triangleCount: triangles.length / 3,
    triangles,
    baseTriangles,
    levels,
    bounds: b,
    bones: t.bones,
    baseVertices: nb,
    rest,
    influences: K,
    skinBones,
    skinWeights,
    steps,
    examples: N,
    detailStep: step,
    detail,
  };
}

/** Per vertex, the (a, b) corners of its incident triangles [v, a, b] in winding order, CSR:
 * pairs 2 * (ptr[v] .. ptr[v + 1]). */
export function incidentPairs(vertexCount, triangles) {
  const ptr = new Uint32Array(vertexCount + 1);
  for (let i = 0; i < triangles.length; i++) ptr[triangles[i] + 1]++;
  for (let v = 0; v < vertexCount; v++) ptr[v + 1] += ptr[v];
  const fill = ptr.slice(0, vertexCount);
  const pairs = new Uint32Array(2 * triangles.length);
  for (let t = 0; t < triangles.length; t += 3) {
    const a = triangles[t], b = triangles[t + 1], c = triangles[t + 2];
    let at = 2 * fill[a]++;
    pairs[at] = b;
    pairs[at + 1] = c;
    at = 2 * fill[b]++;
    pairs[at] = c;
    pairs[at + 1] = a;
    at = 2 * fill[c]++;
    pairs[at] = a;
    pairs[at + 1] = b;
  }
  return { ptr, pairs };
}

/** Separates two chains of one vertex in incidentChains. */
export const CHAIN_BREAK = 0xffffffff;

/**
 * The incident triangles of every vertex as chains of their other corners, in CSR (as
 * VertexFans in core/src/runtime/detail.rs): consecutive entries r_i, r_i+1 of a chain are the
 * (a, b) of one triangle [v, a, b], so a vertex inside a closed fan of k triangles takes k + 1
 * entries (its first neighbour repeated at the end) and each neighbour is fetched once, where
 * the pairs take 2k. Triangles that do not chain follow as further chains after CHAIN_BREAK.
 * The sum of cross(p_r_i - p_v, p_r_i+1 - p_v) over a vertex's chains is the same sum as over
 * its pairs. Returns {ptr (vertexCount + 1), chain}.
 */
export function incidentChains(vertexCount, triangles) {
  const { ptr: pptr, pairs } = incidentPairs(vertexCount, triangles);
  const ptr = new Uint32Array(vertexCount + 1);
  const chain = new Uint32Array(pairs.length / 2 + vertexCount * 2);
  let len = 0;
  const used = [];
  for (let v = 0; v < vertexCount; v++) {
    const first = pptr[v];
    const k = pptr[v + 1] - first;
    used.length = 0;
    for (let i = 0; i < k; i++) used.push(false);
    let left = k;
    let chains = 0;
    while (left > 0) {
      // Start where no unused pair leads in (an open fan's end), else anywhere.
      let start = -1;
      for (let i = 0; i < k && start < 0; i++) {
        if (used[i]) continue;
        const a = pairs[2 * (first + i)];
        let led = false;
        for (let j = 0; j < k; j++) if (!used[j] && j !== i && pairs[2 * (first + j) + 1] === a) led = true;
        if (!led) start = i;
      }
      if (start < 0) start = used.indexOf(false);
      if (chains++ > 0) chain[len++] = CHAIN_BREAK;
      used[start] = true;
      left--;
      chain[len++] = pairs[2 * (first + start)];
      let cur = pairs[2 * (first + start) + 1];
      chain[len++] = cur;
      for (;;) {
        let next = -1;
        for (let j = 0; j < k; j++) {
          if (!used[j] && pairs[2 * (first + j)] === cur) {
            next = j;
            break;
          }
        }
        if (next < 0) break;
        used[next] = true;
        left--;
        cur = pairs[2 * (first + next) + 1];
        chain[len++] = cur;
      }
    }
    ptr[v + 1] = len;
  }
  return { ptr, chain: chain.slice(0, len) };
}

// ---- Shaders -----------------------------------------------------------------------------

const QUAD_VERTEX = /* glsl */ `
void main() {
  gl_Position = vec4(position.xy, 0.0, 1.0);
}`;

// Shared by the passes: the fragment's buffer index and texel fetches by linear index.
const COMMON = /* glsl */ `
precision highp float;
precision highp int;
precision highp sampler2D;
precision highp usampler2D;
uniform int uCount;
uniform int uWidth;
out highp vec4 fragColor;
int fragIndex() {
  ivec2 c = ivec2(gl_FragCoord.xy);
  return c.y * uWidth + c.x;
}
vec4 fetch(sampler2D t, int i) {
  int w = textureSize(t, 0).x;
  return texelFetch(t, ivec2(i % w, i / w), 0);
}
uvec4 fetchu(usampler2D t, int i) {
  int w = textureSize(t, 0).x;
  return texelFetch(t, ivec2(i % w, i / w), 0);
}
`;

// glam's Quat * Vec3 (the Rust reference's rotation).
const SKIN_FRAGMENT = /* glsl */ `${COMMON}
uniform sampler2D uRest;
uniform usampler2D uSkin;   // per (vertex, slot): bone, f32 bits of the weight
uniform sampler2D uBones;   // per bone: quaternion (x, y, z, w), translation
uniform int uK;
vec3 rotate(vec4 q, vec3 p) {
  vec3 b = q.xyz;
  return p * (q.w * q.w - dot(b, b)) + b * (dot(p, b) * 2.0) + cross(b, p) * (q.w * 2.0);
}
void main() {
  int i = fragIndex();
  if (i >= uCount) { fragColor = vec4(0.0); return; }
  vec3 p = fetch(uRest, i).xyz;
  vec3 v = vec3(0.0);
  for (int k = 0; k < uK; k++) {
    uvec2 s = fetchu(uSkin, i * uK + k).xy;
    float w = uintBitsToFloat(s.y);
    int b = int(s.x);
    v += w * (rotate(fetch(uBones, 2 * b), p) + fetch(uBones, 2 * b + 1).xyz);
  }
  fragColor = vec4(v, 1.0);
}`;

const SUBDIVIDE_FRAGMENT = /* glsl */ `${COMMON}
uniform sampler2D uIn;
uniform usampler2D uRowPtr;
uniform usampler2D uEntries;  // per entry: old vertex, f32 bits of the weight
void main() {
  int i = fragIndex();
  if (i >= uCount) { fragColor = vec4(0.0); return; }
  int start = int(fetchu(uRowPtr, i).x);
  int end = int(fetchu(uRowPtr, i + 1).x);
  vec3 v = vec3(0.0);
  for (int e = start; e < end; e++) {
    uvec2 c = fetchu(uEntries, e).xy;
    v += uintBitsToFloat(c.y) * fetch(uIn, int(c.x)).xyz;
  }
  fragColor = vec4(v, 1.0);
}`;

/** xi travels as a uniform array up to this many vec4s (well inside WebGL2's 224 fragment
 * uniform vectors), as a texture beyond. */
const XI_UNIFORM_TEXELS = 64;

// The normal of uIn at vertex i; with `texels` (D's texels per vertex), uIn moved along it by
// h = D xi + b.
const NORMAL_FRAGMENT = (texels) => /* glsl */ `${COMMON}
uniform sampler2D uIn;
uniform usampler2D uFanPtr;
uniform usampler2D uFans;     // per vertex, its chains of neighbours (incidentChains)
${texels ? `#define TEXELS ${texels}` : ""}
${texels && texels <= XI_UNIFORM_TEXELS ? "#define XI_UNIFORM" : ""}
#ifdef TEXELS
uniform sampler2D uDetail;    // per vertex TEXELS texels: D_v0 .. D_v(N-1), b_v, zero padding
#ifdef XI_UNIFORM
uniform vec4 uXi[TEXELS];     // xi_0 .. xi_(N-1), 1, zero padding
#else
uniform sampler2D uXi;
#endif
#endif
void main() {
  int i = fragIndex();
  if (i >= uCount) { fragColor = vec4(0.0); return; }
  vec3 p = fetch(uIn, i).xyz;
  int start = int(fetchu(uFanPtr, i).x);
  int end = int(fetchu(uFanPtr, i + 1).x);
  vec3 n = vec3(0.0);
  vec3 q = vec3(0.0);
  bool open = false; // q holds the chain's previous corner
  for (int e = start; e < end; e++) {
    uint r = fetchu(uFans, e).x;
    if (r == ${CHAIN_BREAK}u) { open = false; continue; }
    vec3 d = fetch(uIn, int(r)).xyz - p;
    if (open) n += cross(q, d);
    q = d;
    open = true;
  }
  // glam's normalize_or_zero: times 1 / length when that is finite and positive.
  float rcp = 1.0 / length(n);
  n = (isinf(rcp) || isnan(rcp) || rcp <= 0.0) ? vec3(0.0) : n * rcp;
#ifdef TEXELS
  float h = 0.0;
  int row = i * TEXELS;
  for (int k = 0; k < TEXELS; k++) {
#ifdef XI_UNIFORM
    h += dot(fetch(uDetail, row + k), uXi[k]);
#else
    h += dot(fetch(uDetail, row + k), fetch(uXi, k));
#endif
  }
  fragColor = vec4(p + h * n, 1.0);
#else
  fragColor = vec4(n, 0.0);
#endif
}`;

// ---- The synthesiser ---------------------------------------------------------------------

export class PaletteSynth {
  /** `options.width`: texels per row of every buffer (default min(4096, max texture size));
   * the tests make it small to cross rows. */
  constructor(renderer, options = {}) {
    this.renderer = renderer;
    this.W = Math.min(options.width || 4096, renderer.capabilities.maxTextureSize);
    this.header = null;
    this.resources = [];
    this.pending = null; // decoded frame waiting for update()
    this.displayed = null; // decoded frame whose mesh the targets hold
    this.spare = null;
    const quad = new THREE.BufferGeometry();
    // One triangle over the whole viewport: no diagonal seam.
    quad.setAttribute("position", new THREE.BufferAttribute(new Float32Array([-1, -1, 0, 3, -1, 0, -1, 3, 0]), 3));
    this.quad = new THREE.Mesh(quad);
    this.quad.frustumCulled = false;
    this.quadScene = new THREE.Scene();
    this.quadScene.add(this.quad);
    this.quadCamera = new THREE.Camera();
    this.drawUniforms = { creasePositions: { value: null }, creaseNormals: { value: null } };
  }

  /** A DataTexture of `data` (`channels` per texel, 1, 2 or 4), float or uint. */
  texture(data, channels, uint) {
    const texels = Math.max(1, Math.ceil(data.length / channels));
    const w = Math.min(this.W, texels);
    const h = Math.ceil(texels / w);
    const padded = new data.constructor(w * h * channels);
    padded.set(data);
    const formats = uint
      ? { 1: THREE.RedIntegerFormat, 2: THREE.RGIntegerFormat, 4: THREE.RGBAIntegerFormat }
      : { 1: THREE.RedFormat, 2: THREE.RGFormat, 4: THREE.RGBAFormat };
    const internal = { 1: "R32", 2: "RG32", 4: "RGBA32" }[channels] + (uint ? "UI" : "F");
    const tex = new THREE.DataTexture(padded, w, h, formats[channels], uint ? THREE.UnsignedIntType : THREE.FloatType);
    tex.internalFormat = internal;
    tex.minFilter = tex.magFilter = THREE.NearestFilter;
    tex.generateMipmaps = false;
    tex.flipY = false;
    tex.needsUpdate = true;
    this.resources.push(tex);
    return tex;
  }

  /** An RGBA32F render target holding `n` items. */
  target(n) {
    const w = Math.min(this.W, Math.max(1, n));
    const rt = new THREE.WebGLRenderTarget(w, Math.max(1, Math.ceil(n / w)), {
      type: THREE.FloatType,
      format: THREE.RGBAFormat,
      minFilter: THREE.NearestFilter,
      magFilter: THREE.NearestFilter,
      depthBuffer: false,
      stencilBuffer: false,
      generateMipmaps: false,
    });
    rt.count = n;
    this.resources.push(rt);
    return rt;
  }

  pass(fragmentShader, uniforms, out) {
    const material = new THREE.ShaderMaterial({
      glslVersion: THREE.GLSL3,
      vertexShader: QUAD_VERTEX,
      fragmentShader,
      uniforms: { ...uniforms, uCount: { value: out.count }, uWidth: { value: out.width } },
      depthTest: false,
      depthWrite: false,
      blending: THREE.NoBlending,
    });
    this.resources.push(material);
    return { material, out };
  }

  /** Builds everything for a PaletteTopology (readPaletteTopology); throws an Error naming
   * what is wrong (nothing of the previous header is kept either way). */
  load(topology) {
    this.dispose();
    const h = decodePaletteTopology(topology);
    const nb = h.baseVertices;
    const K = h.influences;
    const rest4 = new Float32Array(4 * nb);
    for (let v = 0; v < nb; v++) rest4.set(h.rest.subarray(3 * v, 3 * v + 3), 4 * v);
    const skin = new Uint32Array(2 * nb * K);
    const weightBits = new Uint32Array(h.skinWeights.buffer);
    for (let e = 0; e < nb * K; e++) {
      skin[2 * e] = h.skinBones[e];
      skin[2 * e + 1] = weightBits[e];
    }
    this.boneData = new Float32Array(8 * Math.max(1, h.bones));
    this.bonesTex = this.texture(this.boneData, 4, false);
    this.boneData = this.bonesTex.image.data; // the padded array the texture uploads
    const passes = [];
    const base = this.target(nb);
    passes.push(
      this.pass(
        SKIN_FRAGMENT,
        {
          uRest: { value: this.texture(rest4, 4, false) },
          uSkin: { value: this.texture(skin, 2, true) },
          uBones: { value: this.bonesTex },
          uK: { value: K },
        },
        base,
      ),
    );
    let level = base;
    for (const s of h.steps) {
      const entries = new Uint32Array(2 * s.cols.length);
      const bits = new Uint32Array(s.weights.buffer, s.weights.byteOffset, s.weights.length);
      for (let e = 0; e < s.cols.length; e++) {
        entries[2 * e] = s.cols[e];
        entries[2 * e + 1] = bits[e];
      }
      const next = this.target(s.rows);
      passes.push(
        this.pass(
          SUBDIVIDE_FRAGMENT,
          {
            uIn: { value: level.texture },
            uRowPtr: { value: this.texture(s.rowPtr, 1, true) },
            uEntries: { value: this.texture(entries, 2, true) },
          },
          next,
        ),
      );
      level = next;
    }
    const n = h.vertexCount;
    const fans = incidentChains(n, h.triangles);
    const fanUniforms = {
      uFanPtr: { value: this.texture(fans.ptr, 1, true) },
      uFans: { value: this.texture(fans.chain, 1, true) },
    };
    let out = level;
    this.xiTex = null;
    this.xiData = null;
    if (h.detail) {
      const N = h.examples;
      const texels = Math.ceil((N + 1) / 4);
      const d = new Float32Array(4 * texels * n);
      for (let v = 0; v < n; v++) d.set(h.detail.subarray(v * (N + 1), (v + 1) * (N + 1)), 4 * texels * v);
      if (texels <= XI_UNIFORM_TEXELS) {
        this.xiData = new Float32Array(4 * texels);
        this.xiUniform = { value: this.xiData };
      } else {
        this.xiTex = this.texture(new Float32Array(4 * texels), 4, false);
        this.xiData = this.xiTex.image.data;
        this.xiUniform = { value: this.xiTex };
      }
      this.xiData[N] = 1; // b_v's coefficient
      out = this.target(n);
      passes.push(
        this.pass(
          NORMAL_FRAGMENT(texels),
          { uIn: { value: level.texture }, ...fanUniforms, uDetail: { value: this.texture(d, 4, false) }, uXi: this.xiUniform },
          out,
        ),
      );
    }
    const normals = this.target(n);
    passes.push(this.pass(NORMAL_FRAGMENT(0), { uIn: { value: out.texture }, ...fanUniforms }, normals));
    this.passes = passes;
    this.out = out;
    this.normalTarget = normals;
    this.drawUniforms.creasePositions.value = out.texture;
    this.drawUniforms.creaseNormals.value = normals.texture;
    this.header = h;
    this.decoder = new PaletteDecoder(h.bones, h.examples);
    this.pending = this.displayed = this.spare = null;
    return h;
  }

  /** Decodes the stream's next frame (Frame.data: a codec frame of palette lanes, keyframe or
   * delta on the frame before) for the next update(); throws an Error on a frame it cannot
   * use (the frame shown and the one pending stay as they were). Returns the decoded frame
   * ({header, seq, rotations, translations, xi, ...}). */
  setFrame(bytes) {
    if (!this.header) throw new Error("palette frame before the palette header");
    const spare = this.spare;
    const frame = this.decoder.decode(bytes, spare || undefined);
    this.spare = this.pending && this.pending !== this.displayed ? this.pending : null;
    this.pending = frame;
    return frame;
  }

  /** Runs the passes for the pending frame, if any; returns whether it did. */
  update() {
    const frame = this.pending;
    if (!frame || frame === this.displayed) return false;
    const B = this.header.bones;
    for (let k = 0; k < B; k++) {
      this.boneData.set(frame.rotations.subarray(4 * k, 4 * k + 4), 8 * k);
      this.boneData.set(frame.translations.subarray(3 * k, 3 * k + 3), 8 * k + 4);
    }
    this.bonesTex.needsUpdate = true;
    if (this.xiData) {
      this.xiData.set(frame.xi);
      if (this.xiTex) this.xiTex.needsUpdate = true;
    }
    const r = this.renderer;
    const previous = r.getRenderTarget();
    // In an XR session three.js swaps the XR cameras in for any camera it renders with, render
    // targets included: the passes' quads would be drawn through the eyes' projections.
    const xr = r.xr.enabled;
    r.xr.enabled = false;
    for (const p of this.passes) {
      this.quad.material = p.material;
      r.setRenderTarget(p.out);
      r.render(this.quadScene, this.quadCamera);
    }
    r.xr.enabled = xr;
    r.setRenderTarget(previous);
    this.spare = this.displayed;
    this.displayed = frame;
    return true;
  }

  /** The render targets of the drawn mesh: positions and unit normals, vertex i at texel i. */
  get positions() {
    return this.out;
  }
  get normals() {
    return this.normalTarget;
  }

  /** x, y, z per drawn vertex (model order) of the frame shown, read from the float target
   * (`which`: "positions", or "normals" for the shading normals). */
  readback(which = "positions") {
    const rt = which === "normals" ? this.normalTarget : this.out;
    const px = new Float32Array(4 * rt.width * rt.height);
    this.renderer.readRenderTargetPixels(rt, 0, 0, rt.width, rt.height, px);
    const n = this.header.vertexCount;
    const xyz = new Float32Array(3 * n);
    for (let i = 0; i < n; i++) {
      xyz[3 * i] = px[4 * i];
      xyz[3 * i + 1] = px[4 * i + 1];
      xyz[3 * i + 2] = px[4 * i + 2];
    }
    return xyz;
  }

  /** Base vertex `v` skinned on the CPU with the bones of the frame shown (for a handful of
   * vertices: the control points' handles). Sets and returns `out` (a THREE.Vector3). */
  skinVertex(v, out) {
    const h = this.header;
    const f = this.displayed;
    out.set(0, 0, 0);
    if (!h || !f || v >= h.baseVertices) return out;
    const px = h.rest[3 * v], py = h.rest[3 * v + 1], pz = h.rest[3 * v + 2];
    for (let k = 0; k < h.influences; k++) {
      const w = h.skinWeights[v * h.influences + k];
      if (w === 0) continue;
      const b = h.skinBones[v * h.influences + k];
      const [x, y, z, qw] = f.rotations.subarray(4 * b, 4 * b + 4);
      const s = qw * qw - (x * x + y * y + z * z);
      const d2 = 2 * (px * x + py * y + pz * z);
      const rx = px * s + x * d2 + (y * pz - z * py) * 2 * qw;
      const ry = py * s + y * d2 + (z * px - x * pz) * 2 * qw;
      const rz = pz * s + z * d2 + (x * py - y * px) * 2 * qw;
      out.x += w * (rx + f.translations[3 * b]);
      out.y += w * (ry + f.translations[3 * b + 1]);
      out.z += w * (rz + f.translations[3 * b + 2]);
    }
    return out;
  }

  /** A MeshStandardMaterial (same look as the vertex path's) whose vertex shader reads the
   * position and normal of vertex gl_VertexID from this synthesiser's targets. */
  material(parameters) {
    const m = new THREE.MeshStandardMaterial(parameters);
    const uniforms = this.drawUniforms;
    m.onBeforeCompile = (shader) => {
      Object.assign(shader.uniforms, uniforms);
      shader.vertexShader =
        `uniform highp sampler2D creasePositions;\n` +
        `uniform highp sampler2D creaseNormals;\n` +
        `vec4 creaseFetch(highp sampler2D t, int i) {\n` +
        `  int w = textureSize(t, 0).x;\n` +
        `  return texelFetch(t, ivec2(i % w, i / w), 0);\n` +
        `}\n` +
        shader.vertexShader
          .replace(
            "#include <beginnormal_vertex>",
            "vec3 objectNormal = creaseFetch(creaseNormals, gl_VertexID).xyz;",
          )
          .replace("#include <begin_vertex>", "vec3 transformed = creaseFetch(creasePositions, gl_VertexID).xyz;");
    };
    m.customProgramCacheKey = () => "crease-palette";
    return m;
  }

  /** The drawn mesh's geometry: its triangles, a dummy position attribute (three.js draws
   * index.count corners; the shader ignores it) and a bounding sphere from the header's box. */
  geometry() {
    const h = this.header;
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3 * h.vertexCount), 3));
    g.setIndex(new THREE.BufferAttribute(h.triangles, 1));
    const lo = new THREE.Vector3(...h.bounds.min);
    const hi = new THREE.Vector3(...h.bounds.max);
    g.boundingSphere = new THREE.Sphere(lo.clone().add(hi).multiplyScalar(0.5), hi.distanceTo(lo) / 2);
    g.boundingBox = new THREE.Box3(lo, hi);
    return g;
  }

  /** Frees the GPU resources of the current header. */
  dispose() {
    for (const r of this.resources) r.dispose();
    this.resources = [];
    this.header = null;
    this.pending = this.displayed = this.spare = null;
  }
}
